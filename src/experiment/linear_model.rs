//! The baseline any learned dynamics should beat: s' = W·[s, a, 1], fitted
//! by least squares on a dataset's transitions, with each dimension's
//! residual spread as a constant σ. `analyze --linear-baseline` rolls it
//! beside the learned models (Figure 5's prediction error, issue 32's
//! measurement on systems described as data).

use super::ExperimentError;
use crate::data::Dataset;
use crate::shared::{BatchDynamics, BatchShape, ModelStep};

/// A ridge this small only keeps the normal equations solvable when a
/// column is constant (an action the log never varied); it moves no fit.
const RIDGE: f64 = 1e-8;

/// A fitted linear model of one-step dynamics.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearModel {
    obs_dim: usize,
    act_dim: usize,
    dt: f64,
    /// `[obs_dim][obs_dim + act_dim + 1]`: each next-observation entry's
    /// weights on the observation, the action and 1.
    weights: Vec<Vec<f64>>,
    /// Each dimension's residual standard deviation on the fitted data over
    /// √dt: the constant diffusion whose one-step spread σ·√dt it is (the
    /// convention of [`ModelStep`], which callers sample by).
    sigma: Vec<f32>,
}

impl LinearModel {
    /// The least-squares fit of `dataset`'s next observations on its
    /// observations and actions; `dt` is the data's step.
    pub fn fit(dataset: &Dataset, dt: f64) -> Result<Self, ExperimentError> {
        let (obs_dim, act_dim) = (dataset.obs_dim(), dataset.act_dim());
        let inputs = obs_dim + act_dim + 1;
        let row = |i: usize| -> Vec<f64> {
            let s = dataset.observations.row(i);
            let a = dataset.actions.row(i);
            s.iter()
                .chain(a.iter())
                .map(|&x| f64::from(x))
                .chain(std::iter::once(1.0))
                .collect()
        };
        let mut gram = vec![vec![0.0; inputs]; inputs];
        let mut cross = vec![vec![0.0; obs_dim]; inputs];
        for i in 0..dataset.len() {
            let x = row(i);
            let next = dataset.next_observations.row(i);
            for (j, &xj) in x.iter().enumerate() {
                for (k, &xk) in x.iter().enumerate() {
                    gram[j][k] += xj * xk;
                }
                for (d, &y) in next.iter().enumerate() {
                    cross[j][d] += xj * f64::from(y);
                }
            }
        }
        let scale = dataset.len().max(1) as f64;
        for (j, gram_row) in gram.iter_mut().enumerate() {
            gram_row[j] += RIDGE * scale;
        }
        let solution = solve(gram, cross).ok_or_else(|| {
            ExperimentError::Invalid("the linear baseline's normal equations are singular".into())
        })?;
        let weights: Vec<Vec<f64>> = (0..obs_dim)
            .map(|d| solution.iter().map(|w| w[d]).collect())
            .collect();
        let mut squared = vec![0.0; obs_dim];
        for i in 0..dataset.len() {
            let x = row(i);
            for (d, w) in weights.iter().enumerate() {
                let predicted: f64 = w.iter().zip(&x).map(|(w, x)| w * x).sum();
                squared[d] += (predicted - f64::from(dataset.next_observations[[i, d]])).powi(2);
            }
        }
        let sigma = squared
            .iter()
            .map(|s| ((s / scale).sqrt() / dt.sqrt()) as f32)
            .collect();
        Ok(Self {
            obs_dim,
            act_dim,
            dt,
            weights,
            sigma,
        })
    }
}

/// Solves `a · x = b` (`a` square, `b` with one column per right-hand side)
/// by Gauss–Jordan elimination with partial pivoting; none when singular.
fn solve(mut a: Vec<Vec<f64>>, mut b: Vec<Vec<f64>>) -> Option<Vec<Vec<f64>>> {
    let n = a.len();
    for col in 0..n {
        let pivot = (col..n).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col].abs() < f64::MIN_POSITIVE {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        let (pivot_a, pivot_b) = (a[col].clone(), b[col].clone());
        for row in (0..n).filter(|&row| row != col) {
            let factor = a[row][col] / pivot_a[col];
            for (x, p) in a[row][col..].iter_mut().zip(&pivot_a[col..]) {
                *x -= factor * p;
            }
            for (x, p) in b[row].iter_mut().zip(&pivot_b) {
                *x -= factor * p;
            }
        }
    }
    Some(
        (0..n)
            .map(|i| b[i].iter().map(|v| v / a[i][i]).collect())
            .collect(),
    )
}

impl BatchDynamics for LinearModel {
    fn shape(&self) -> BatchShape {
        BatchShape {
            obs_dim: self.obs_dim,
            act_dim: self.act_dim,
            learns_reward: false,
            dt: self.dt,
        }
    }

    /// s' = W·[s, a, 1] + σ·√dt·ε: the residual's spread once per step.
    fn step(&self, states: &[f32], actions: &[f32], noise: &[f32]) -> ModelStep {
        let rows = states.len() / self.obs_dim;
        let mut means = Vec::with_capacity(states.len());
        for r in 0..rows {
            let s = &states[r * self.obs_dim..(r + 1) * self.obs_dim];
            let a = &actions[r * self.act_dim..(r + 1) * self.act_dim];
            for w in &self.weights {
                let (w_s, rest) = w.split_at(self.obs_dim);
                let (w_a, bias) = rest.split_at(self.act_dim);
                let dot = |w: &[f64], x: &[f32]| -> f64 {
                    w.iter().zip(x).map(|(w, &x)| w * f64::from(x)).sum()
                };
                means.push((dot(w_s, s) + dot(w_a, a) + bias[0]) as f32);
            }
        }
        let sigma: Vec<f32> = (0..rows).flat_map(|_| self.sigma.iter().copied()).collect();
        let sqrt_dt = self.dt.sqrt() as f32;
        let next_states = means
            .iter()
            .zip(&sigma)
            .zip(noise)
            .map(|((m, s), e)| m + s * sqrt_dt * e)
            .collect();
        ModelStep {
            next_states,
            means,
            sigma,
            h_eta: vec![0.0; states.len()],
            eta: vec![0.0; rows],
            truncation_signal: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use ndarray::{Array1, Array2};

    use super::*;
    use crate::data::{DatasetMetadata, DatasetParts};

    /// Transitions of s' = A·s + B·a + c, by hand, from scattered states.
    fn linear_system_data(noise: f32) -> Dataset {
        let (a, b, c) = ([[0.9, 0.1], [-0.2, 1.0]], [0.5, -1.0], [0.05, -0.02]);
        let n = 400;
        let state = |i: usize| {
            [
                ((i * 37) % 101) as f32 / 50.0 - 1.0,
                ((i * 53) % 89) as f32 / 40.0 - 1.0,
            ]
        };
        let action = |i: usize| ((i * 29) % 61) as f32 / 30.0 - 1.0;
        // A deterministic ±noise pattern with mean 0 and spread `noise`.
        let jitter = |i: usize, d: usize| {
            if (i + d).is_multiple_of(2) {
                noise
            } else {
                -noise
            }
        };
        let observations = Array2::from_shape_fn((n, 2), |(i, d)| state(i)[d]);
        let actions = Array2::from_shape_fn((n, 1), |(i, _)| action(i));
        let next_observations = Array2::from_shape_fn((n, 2), |(i, d)| {
            let s = state(i);
            a[d][0] * s[0] + a[d][1] * s[1] + b[d] * action(i) + c[d] + jitter(i, d)
        });
        let parts = DatasetParts {
            observations,
            actions,
            rewards: Array1::zeros(n),
            next_observations,
            terminals: vec![false; n],
            timeouts: vec![false; n],
            qpos: None,
            qvel: None,
            action_log_probs: None,
            metadata: DatasetMetadata::new(),
        };
        Dataset::from_parts(parts, std::path::Path::new("linear")).unwrap()
    }

    #[test]
    fn the_fit_recovers_a_linear_system_and_its_residual() {
        let dt = 0.04;
        let model = LinearModel::fit(&linear_system_data(0.0), dt).unwrap();
        let expected = [[0.9, 0.1, 0.5, 0.05], [-0.2, 1.0, -1.0, -0.02]];
        for (w, e) in model.weights.iter().zip(expected) {
            for (w, e) in w.iter().zip(e) {
                assert!((w - e).abs() < 1e-5, "{:?}", model.weights);
            }
        }
        // One step by hand: A·[0.2, -0.4] + B·0.3 + c.
        let step = model.step(&[0.2, -0.4], &[0.3], &[0.0, 0.0]);
        let by_hand = [
            0.9 * 0.2 + 0.1 * -0.4 + 0.15 + 0.05,
            -0.2 * 0.2 - 0.4 - 0.3 - 0.02,
        ];
        for (m, h) in step.means.iter().zip(by_hand) {
            assert!((f64::from(*m) - h).abs() < 1e-5, "{:?}", step.means);
        }
        // ±0.01 residuals: a one-step spread of 0.01, σ·√dt.
        let noisy = LinearModel::fit(&linear_system_data(0.01), dt).unwrap();
        for s in &noisy.sigma {
            assert!(
                (f64::from(*s) * dt.sqrt() - 0.01).abs() < 1e-3,
                "{:?}",
                noisy.sigma
            );
        }
    }
}
