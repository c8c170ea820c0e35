//! Per-dimension normalisation of states, actions and rewards: `(x − mean) / std`
//! with the std floored, so constant dimensions do not blow up. Fitted once on
//! the training data and saved with every artifact.

use ndarray::{ArrayView2, Axis};
use serde::{Deserialize, Serialize};

use super::Dataset;

/// Knobs of the normaliser.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NormalizerConfig {
    /// Smallest std used per dimension (in the data's units).
    pub std_floor: f32,
}

impl Default for NormalizerConfig {
    fn default() -> Self {
        Self { std_floor: 1e-3 }
    }
}

/// Mean and (floored) standard deviation of each dimension.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Stats {
    pub mean: Vec<f32>,
    pub std: Vec<f32>,
}

impl Stats {
    /// Column statistics of `rows` (`[n, dim]`), accumulated in f64.
    pub fn fit(rows: ArrayView2<f32>, config: &NormalizerConfig) -> Self {
        let n = rows.nrows().max(1) as f64;
        let (mut mean, mut std) = (Vec::new(), Vec::new());
        for column in rows.axis_iter(Axis(1)) {
            let m = column.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
            let var = column
                .iter()
                .map(|&v| (f64::from(v) - m).powi(2))
                .sum::<f64>()
                / n;
            mean.push(m as f32);
            std.push((var.sqrt() as f32).max(config.std_floor));
        }
        Self { mean, std }
    }

    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Normalises row-major `values` (`[n, dim]`) in place.
    pub fn normalize(&self, values: &mut [f32]) {
        for row in values.chunks_exact_mut(self.dim()) {
            for ((v, m), s) in row.iter_mut().zip(&self.mean).zip(&self.std) {
                *v = (*v - m) / s;
            }
        }
    }

    /// Inverse of [`normalize`](Self::normalize), in place.
    pub fn denormalize(&self, values: &mut [f32]) {
        for row in values.chunks_exact_mut(self.dim()) {
            for ((v, m), s) in row.iter_mut().zip(&self.mean).zip(&self.std) {
                *v = *v * s + m;
            }
        }
    }
}

/// Statistics of everything a model sees.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Normalizer {
    pub state: Stats,
    pub action: Stats,
    pub reward: Stats,
}

impl Normalizer {
    /// Fits states (observations), actions and rewards of `dataset`.
    pub fn fit(dataset: &Dataset, config: &NormalizerConfig) -> Self {
        Self {
            state: Stats::fit(dataset.observations.view(), config),
            action: Stats::fit(dataset.actions.view(), config),
            reward: Stats::fit(dataset.rewards.view().insert_axis(Axis(1)), config),
        }
    }
}
