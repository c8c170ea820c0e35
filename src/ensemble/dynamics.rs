//! A fitted ensemble behind [`BatchDynamics`], as MOPO steps it: every member
//! predicts a Gaussian over (s' − s, r); each row samples from one elite,
//! picked by the row's last noise column (Φ(z) uniform over the elites), and
//! reports as its uncertainty "η" the model's disagreement in MOPO's or
//! TATU's form. The state carries the reward like NUNO^R's (r_c), so rewards
//! come from the model; dt is one step.

use std::cell::RefCell;

use burn::tensor::{Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};

use super::fit::{EnsembleFit, Scaler};
use super::model::{GaussianEnsemble, softplus};
use crate::infer::{DenseMlp, MlpScratch, Rows, row_chunks, run_tiles, tile_rows, with_buffers};
use crate::nn::{fill_standard_normal, to_f32_vec};
use crate::shared::{BatchDynamics, BatchShape, ModelStep, step_batch};

thread_local! {
    static MLP_SCRATCH: RefCell<MlpScratch> = RefCell::new(MlpScratch::default());
    static OUTPUT: RefCell<Vec<f32>> = const { RefCell::new(Vec::new()) };
}

/// What a step reports as its uncertainty (the rollout's η).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EnsembleUncertainty {
    /// MOPO's penalty: max over members of ‖σᵢ(s, a)‖₂.
    #[default]
    MaxAleatoric,
    /// TATU's disagreement: max over members of ‖μᵢ(s, a) − μ̄(s, a)‖₂ over
    /// the observation's dimensions (TATU's `compute_disc` leaves the reward out).
    MaxDisagreement,
    /// MOReL's USAD discrepancy: max over pairs of members of ‖μᵢ(s, a) −
    /// μⱼ(s, a)‖₂ over the observation's dimensions (MOReL's models predict
    /// the next state alone).
    MaxPairwise,
}

/// The members' weights on the fused CPU path (`crate::infer`), with the
/// shared log-variance limits.
#[derive(Debug, Clone)]
struct FusedMembers {
    members: Vec<DenseMlp>,
    max_logvar: Vec<f32>,
    min_logvar: Vec<f32>,
}

/// A fitted ensemble ready to step.
#[derive(Debug, Clone)]
pub struct EnsembleDynamics {
    model: GaussianEnsemble,
    /// When set, predictions run here instead of through burn.
    fused: Option<FusedMembers>,
    scaler: Scaler,
    elites: Vec<usize>,
    obs_dim: usize,
    act_dim: usize,
    uncertainty: EnsembleUncertainty,
    /// Reported as the step's truncation signal when set (TATU+MOPO).
    truncation: Option<EnsembleUncertainty>,
    device: Device,
}

impl EnsembleDynamics {
    pub fn new(
        fit: &EnsembleFit,
        obs_dim: usize,
        act_dim: usize,
        uncertainty: EnsembleUncertainty,
    ) -> Self {
        Self {
            model: fit.model.clone(),
            scaler: fit.scaler.clone(),
            elites: fit.elites.clone(),
            obs_dim,
            act_dim,
            uncertainty,
            truncation: None,
            fused: None,
            device: Device::flex(),
        }
    }

    /// The same model predicting on the fused CPU path (the same weights;
    /// values equal burn's to float rounding).
    pub fn on_fused_path(&self) -> Self {
        Self {
            fused: Some(FusedMembers {
                members: self.model.members.iter().map(DenseMlp::from_burn).collect(),
                max_logvar: to_f32_vec(self.model.max_logvar.val()),
                min_logvar: to_f32_vec(self.model.min_logvar.val()),
            }),
            ..self.clone()
        }
    }

    /// The same model reporting `uncertainty` as η.
    pub fn with_uncertainty(&self, uncertainty: EnsembleUncertainty) -> Self {
        Self {
            uncertainty,
            ..self.clone()
        }
    }

    /// The same model also reporting `signal` as each step's truncation signal
    /// (TATU+MOPO: η = MOPO's penalty, truncation on the disagreement).
    pub fn with_truncation_signal(&self, signal: EnsembleUncertainty) -> Self {
        Self {
            truncation: Some(signal),
            ..self.clone()
        }
    }

    /// `kind` of the members' predictions at row `r` (`means`, `stds`: `[members][batch · state_dim]`).
    fn uncertainty(
        &self,
        kind: EnsembleUncertainty,
        means: &[Vec<f32>],
        stds: &[Vec<f32>],
        r: usize,
    ) -> f32 {
        let s = self.state_dim();
        let norm = |v: &mut dyn Iterator<Item = f32>| v.map(|x| x * x).sum::<f32>().sqrt();
        match kind {
            EnsembleUncertainty::MaxAleatoric => stds
                .iter()
                .map(|std| norm(&mut std[r * s..(r + 1) * s].iter().copied()))
                .fold(0.0, f32::max),
            EnsembleUncertainty::MaxDisagreement => {
                let obs = r * s..r * s + self.obs_dim;
                let members = means.len() as f32;
                let centre: Vec<f32> = obs
                    .clone()
                    .map(|i| means.iter().map(|m| m[i]).sum::<f32>() / members)
                    .collect();
                means
                    .iter()
                    .map(|m| norm(&mut obs.clone().zip(&centre).map(|(i, c)| m[i] - c)))
                    .fold(0.0, f32::max)
            }
            EnsembleUncertainty::MaxPairwise => {
                let obs = r * s..r * s + self.obs_dim;
                let mut largest = 0.0f32;
                for (i, a) in means.iter().enumerate() {
                    for b in &means[i + 1..] {
                        largest = largest.max(norm(&mut obs.clone().map(|k| a[k] - b[k])));
                    }
                }
                largest
            }
        }
    }

    /// MOBILE's next states (OfflineRL-Kit's `sample_next_obss`): `samples`
    /// draws s' = s + μ_e + σ_e·ε from every elite e's Gaussian at each row,
    /// `[elite][sample][row][obs_dim]` flattened, ε from `rng`.
    pub fn elite_next_observations(
        &self,
        observations: &[f32],
        actions: &[f32],
        samples: usize,
        rng: &mut impl rand::Rng,
    ) -> Vec<f32> {
        let (o, s) = (self.obs_dim, self.state_dim());
        let batch = observations.len() / o;
        // The state row carries the reward last; the means do not read it.
        let states: Vec<f32> = observations
            .chunks_exact(o)
            .flat_map(|row| row.iter().copied().chain([0.0]))
            .collect();
        let (means, stds) = self.predict(&states, actions, batch);
        let mut eps = Vec::new();
        fill_standard_normal(&mut eps, self.elites.len() * samples * batch * o, rng);
        let mut next = Vec::with_capacity(eps.len());
        for &elite in &self.elites {
            for _ in 0..samples {
                for r in 0..batch {
                    for d in 0..o {
                        let (i, mean) = (r * s + d, means[elite][r * s + d]);
                        next.push(
                            observations[r * o + d] + mean + stds[elite][i] * eps[next.len()],
                        );
                    }
                }
            }
        }
        next
    }

    /// The members, scaler and elites (RAMBO's adversarial training starts from them).
    pub(super) fn parts(&self) -> (&GaussianEnsemble, &Scaler, &[usize]) {
        (&self.model, &self.scaler, &self.elites)
    }

    /// The same dynamics with `model`'s weights (on the fused path if this one is).
    pub fn with_model(&self, model: GaussianEnsemble) -> Self {
        let plain = Self {
            model,
            fused: None,
            ..self.clone()
        };
        if self.fused.is_some() {
            plain.on_fused_path()
        } else {
            plain
        }
    }

    /// The number of elites, the members rollouts sample from.
    pub fn elite_count(&self) -> usize {
        self.elites.len()
    }

    /// Every member's mean and std, `[members][batch · (obs_dim + 1)]`.
    fn predict(
        &self,
        states: &[f32],
        actions: &[f32],
        batch: usize,
    ) -> (Vec<Vec<f32>>, Vec<Vec<f32>>) {
        let (o, a, s) = (self.obs_dim, self.act_dim, self.state_dim());
        let x = self.scaler.inputs((states, s), &actions[..batch * a], a);
        if let Some(fused) = &self.fused {
            return fused.predict(&x, o + a, batch);
        }
        let x = Tensor::<2>::from_data(TensorData::new(x, [batch, o + a]), &self.device);
        (0..self.model.members.len())
            .map(|m| {
                let (mean, logvar) = self.model.member(m, x.clone());
                (to_f32_vec(mean), to_f32_vec((logvar * 0.5).exp()))
            })
            .unzip()
    }
}

impl FusedMembers {
    /// [`EnsembleDynamics::predict`] on normalised inputs `x` (`[batch, width]`),
    /// in tiles of rows per member over the cores.
    fn predict(&self, x: &[f32], width: usize, batch: usize) -> (Vec<Vec<f32>>, Vec<Vec<f32>>) {
        let d = self.max_logvar.len();
        let members = self.members.len();
        let mut means = vec![vec![0.0f32; batch * d]; members];
        let mut stds = vec![vec![0.0f32; batch * d]; members];
        let rows = tile_rows(batch);
        let mut tiles = Vec::new();
        for ((member, mean), std) in self.members.iter().zip(&mut means).zip(&mut stds) {
            for ((x, mean), std) in x
                .chunks(rows * width)
                .zip(row_chunks(mean, rows, d))
                .zip(row_chunks(std, rows, d))
            {
                tiles.push((member, x, mean, std));
            }
        }
        run_tiles(tiles, |(member, x, mean, std)| {
            let n = x.len() / width;
            with_buffers(&OUTPUT, |out| {
                out.resize(n * 2 * d, 0.0);
                with_buffers(&MLP_SCRATCH, |scratch| {
                    member.forward(Rows::dense(x, width), out, scratch);
                });
                for r in 0..n {
                    let row = &out[r * 2 * d..(r + 1) * 2 * d];
                    mean[r * d..(r + 1) * d].copy_from_slice(&row[..d]);
                    for j in 0..d {
                        // GaussianEnsemble::member's soft bounds, then σ = exp(½ log σ²).
                        let (max, min) = (self.max_logvar[j], self.min_logvar[j]);
                        let logvar = max - softplus(max - row[d + j]);
                        let logvar = min + softplus(logvar - min);
                        std[r * d + j] = (0.5 * logvar).exp();
                    }
                }
            });
        });
        (means, stds)
    }
}

impl BatchDynamics for EnsembleDynamics {
    fn shape(&self) -> BatchShape {
        BatchShape {
            obs_dim: self.obs_dim,
            act_dim: self.act_dim,
            learns_reward: true,
            dt: 1.0,
        }
    }

    /// The state's noise, then one column that picks the elite.
    fn noise_dim(&self) -> usize {
        self.state_dim() + 1
    }

    fn step(&self, states: &[f32], actions: &[f32], noise: &[f32]) -> ModelStep {
        let batch = step_batch(self, states, actions, noise);
        let (s, k) = (self.state_dim(), self.noise_dim());
        let (means, stds) = self.predict(states, actions, batch);
        let mut out = ModelStep {
            next_states: Vec::with_capacity(batch * s),
            means: Vec::with_capacity(batch * s),
            sigma: Vec::with_capacity(batch * s),
            h_eta: vec![0.0; batch * s],
            eta: Vec::with_capacity(batch),
            truncation_signal: None,
        };
        for r in 0..batch {
            let row = r * s..(r + 1) * s;
            let eps = &noise[r * k..(r + 1) * k];
            let pick = standard_normal_cdf(f64::from(eps[s])) * self.elites.len() as f64;
            let elite = self.elites[(pick as usize).min(self.elites.len() - 1)];
            for d in 0..s {
                let mean = states[row.start + d] + means[elite][row.start + d];
                let std = stds[elite][row.start + d];
                out.means.push(mean);
                out.sigma.push(std);
                out.next_states.push(mean + std * eps[d]);
            }
            out.eta
                .push(self.uncertainty(self.uncertainty, &means, &stds, r));
        }
        if let Some(signal) = self.truncation {
            out.truncation_signal = Some(
                (0..batch)
                    .map(|r| self.uncertainty(signal, &means, &stds, r))
                    .collect(),
            );
        }
        out
    }
}

/// Φ(z), the standard normal CDF (Abramowitz & Stegun 7.1.26, |error| < 1.5e-7:
/// ample for picking among a handful of elites).
fn standard_normal_cdf(z: f64) -> f64 {
    let x = z.abs() / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.327_591_1 * x);
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    let erf = 1.0 - poly * (-x * x).exp();
    if z >= 0.0 {
        0.5 * (1.0 + erf)
    } else {
        0.5 * (1.0 - erf)
    }
}

#[cfg(test)]
mod tests {
    use super::standard_normal_cdf;

    #[test]
    fn the_normal_cdf_matches_known_values() {
        // Φ at 0, ±1, ±1.96, 3 from standard tables.
        for (z, p) in [
            (0.0, 0.5),
            (1.0, 0.841_344_7),
            (-1.0, 0.158_655_3),
            (1.96, 0.975_002_1),
            (-1.96, 0.024_997_9),
            (3.0, 0.998_650_1),
        ] {
            assert!((standard_normal_cdf(z) - p).abs() < 2e-7, "Φ({z})");
        }
    }
}
