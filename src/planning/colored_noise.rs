//! Gaussian noise with a power spectrum ∝ f^(−β) along time: iCEM's
//! temporally correlated action samples (Pinneri et al. 2020), as the
//! `colorednoise` package's `powerlaw_psd_gaussian` that mbrl-lib calls
//! draws it: random Fourier coefficients scaled by f^(−β/2) (frequencies
//! below 1/H raised to 1/H), then the inverse real DFT, divided by the
//! package's normaliser (about unit variance). β = 0 is white noise; β = 2 (iCEM's default) is red, smooth in time.

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Draws `count` series of `length` steps, `[count, length]` row-major.
pub struct ColoredNoise {
    length: usize,
    /// f^(−β/2) of each of the length/2 + 1 frequencies.
    scale: Vec<f64>,
    /// The series' expected standard deviation before normalising.
    sigma: f64,
    /// cos and sin of 2π·k·t/length, `[length][frequencies]`.
    cos: Vec<f64>,
    sin: Vec<f64>,
}

impl ColoredNoise {
    /// The spectrum of exponent `beta` over series of `length` ≥ 1 steps.
    pub fn new(beta: f64, length: usize) -> Self {
        let frequencies = length / 2 + 1;
        let n = length as f64;
        // rfftfreq: k / n; the zero frequency raised to the lowest, 1/n.
        let scale: Vec<f64> = (0..frequencies)
            .map(|k| (k.max(1) as f64 / n).powf(-beta / 2.0))
            .collect();
        let mut weights: Vec<f64> = scale[1..].to_vec();
        if let Some(last) = weights.last_mut() {
            // The Nyquist frequency of an even length counts once.
            *last *= (1 + length % 2) as f64 / 2.0;
        }
        let sigma = 2.0 * weights.iter().map(|w| w * w).sum::<f64>().sqrt() / n;
        let angle = |t: usize, k: usize| std::f64::consts::TAU * (k * t) as f64 / n;
        let table = |f: fn(f64) -> f64| -> Vec<f64> {
            (0..length)
                .flat_map(|t| (0..frequencies).map(move |k| f(angle(t, k))))
                .collect()
        };
        Self {
            length,
            sigma,
            cos: table(f64::cos),
            sin: table(f64::sin),
            scale,
        }
    }

    /// `count` independent series.
    pub fn sample(&self, count: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
        let mut out = Vec::with_capacity(count * self.length);
        for _ in 0..count {
            out.extend(self.series(rng));
        }
        out
    }

    fn series(&self, rng: &mut ChaCha8Rng) -> Vec<f64> {
        let (length, frequencies) = (self.length, self.scale.len());
        let mut normal = || -> f64 { rng.sample(StandardNormal) };
        // One step has no spectrum (the package divides by zero there): white.
        if length == 1 {
            return vec![normal()];
        }
        let mut real: Vec<f64> = self.scale.iter().map(|s| s * normal()).collect();
        let mut imaginary: Vec<f64> = self.scale.iter().map(|s| s * normal()).collect();
        // The zero and (even length) Nyquist coefficients are real; their
        // share of the variance is kept by √2.
        let real_only = if length.is_multiple_of(2) && length > 1 {
            vec![0, frequencies - 1]
        } else {
            vec![0]
        };
        for k in real_only {
            imaginary[k] = 0.0;
            real[k] *= std::f64::consts::SQRT_2;
        }
        // numpy's irfft: (1/n)·Σ over the full spectrum, its upper half the
        // conjugate of the lower: the middle coefficients count twice.
        let twice = |k: usize| k != 0 && !(length.is_multiple_of(2) && k == frequencies - 1);
        (0..length)
            .map(|t| {
                let row = t * frequencies;
                let sum: f64 = (0..frequencies)
                    .map(|k| {
                        let term = real[k] * self.cos[row + k] - imaginary[k] * self.sin[row + k];
                        if twice(k) { 2.0 * term } else { term }
                    })
                    .sum();
                sum / length as f64 / self.sigma
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// E[x²] and the lag-1 autocorrelation over many series.
    fn moments(beta: f64, length: usize) -> (f64, f64) {
        let noise = ColoredNoise::new(beta, length);
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let count = 4000;
        let x = noise.sample(count, &mut rng);
        let variance = x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64;
        let lagged: f64 = (x.chunks_exact(length))
            .flat_map(|s| s.windows(2).map(|w| w[0] * w[1]))
            .sum::<f64>()
            / (count * (length - 1)) as f64;
        (variance, lagged / variance)
    }

    /// The package's recipe run with numpy's `irfft` over 200 000 series
    /// (its variance is not exactly 1: the zero frequency and an even
    /// length's Nyquist one are not in its normaliser): (β, length, E[x²],
    /// lag-1 autocorrelation).
    const NUMPY: [(f64, usize, f64, f64); 6] = [
        (0.0, 10, 1.1756, -0.001),
        (2.0, 10, 1.3558, 0.659),
        (0.0, 11, 1.0992, -0.001),
        (2.0, 11, 1.3394, 0.688),
        (0.0, 30, 1.0529, 0.0),
        (2.0, 30, 1.3177, 0.883),
    ];

    #[test]
    fn one_step_is_white_noise() {
        let x = ColoredNoise::new(2.0, 1).sample(4000, &mut ChaCha8Rng::seed_from_u64(1));
        let square = x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64;
        assert!(
            x.iter().all(|v| v.is_finite()) && (square - 1.0).abs() < 0.06,
            "{square}"
        );
    }

    #[test]
    fn white_and_red_noise_have_the_moments_numpy_gives_the_same_recipe() {
        for (beta, length, square, correlation) in NUMPY {
            let (got_square, got_correlation) = moments(beta, length);
            assert!(
                (got_square - square).abs() < 0.06,
                "β {beta}, {length} steps: E[x²] {got_square} vs numpy's {square}"
            );
            assert!(
                (got_correlation - correlation).abs() < 0.03,
                "β {beta}, {length} steps: lag-1 {got_correlation} vs numpy's {correlation}"
            );
        }
    }
}
