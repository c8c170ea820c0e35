//! Truncation thresholds ε(h, α) (Section 4.3): roll the SDE open-loop on the
//! dataset's actions from the starts of each trajectory's non-overlapping
//! windows of length h, accumulate η along each rollout (averaged over
//! particles), and take the CVaR at level α of the accumulated values over the
//! dataset (α = 1: the maximum).

use burn::config::Config;
use burn::tensor::Device;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::SdeError;
use super::model::NeuralSde;
use super::rollout::OpenLoop;
use crate::data::{Dataset, WindowSampler};

/// Which thresholds to compute (Appendix C.3's search grid).
#[derive(Config, Debug, PartialEq)]
pub struct ThresholdConfig {
    /// Rollout lengths h.
    #[config(default = "vec![5, 10, 15, 20]")]
    pub horizons: Vec<usize>,
    /// CVaR levels α.
    #[config(default = "vec![0.9, 0.95, 0.98, 0.99, 1.0]")]
    pub alphas: Vec<f64>,
    /// Particles per window (NUNO's code: 5).
    #[config(default = 5)]
    pub particles: usize,
    /// At most this many windows per h, drawn uniformly without replacement
    /// (a 1M-transition dataset has 200k windows at h = 5; a CPU fit keeps this bounded).
    #[config(default = 4096)]
    pub max_windows: usize,
    /// Rollouts stepped together.
    #[config(default = 1024)]
    pub chunk: usize,
    #[config(default = 0)]
    pub seed: u64,
}

/// ε(h, α) for every horizon and level.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ThresholdTable {
    pub horizons: Vec<usize>,
    pub alphas: Vec<f64>,
    /// `values[i][j]` = ε(horizons[i], alphas[j]); `None` where the dataset has no window of that length.
    pub values: Vec<Vec<Option<f32>>>,
    /// Windows the statistics were taken over, per horizon.
    pub windows: Vec<usize>,
    pub particles: usize,
}

impl ThresholdTable {
    /// ε(h, α), if it was computed.
    pub fn get(&self, horizon: usize, alpha: f64) -> Option<f32> {
        let i = self.horizons.iter().position(|&h| h == horizon)?;
        let j = self.alphas.iter().position(|&a| (a - alpha).abs() < 1e-9)?;
        self.values[i][j]
    }
}

/// CVaR_α of `values`: the mean of the values at or above the α-quantile; α ≥ 1 gives the maximum.
pub fn cvar(values: &[f32], alpha: f64) -> f32 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f32::total_cmp);
    if alpha >= 1.0 {
        return *sorted.last().unwrap_or(&0.0);
    }
    let n = sorted.len();
    let var_index = ((alpha * (n - 1) as f64).floor() as usize).min(n - 1);
    let tail = &sorted[var_index..];
    tail.iter().sum::<f32>() / tail.len() as f32
}

/// Accumulated η of open-loop rollouts from each window start, averaged over particles.
pub fn accumulated_eta(
    model: &NeuralSde,
    dataset: &Dataset,
    starts: &[usize],
    horizon: usize,
    config: &ThresholdConfig,
    rng: &mut ChaCha8Rng,
    device: &Device,
) -> Vec<f32> {
    let reward_model = model.constants.config.reward_model;
    let mut totals = Vec::with_capacity(starts.len());
    for chunk in starts.chunks(config.chunk.max(1)) {
        let mut initial = Vec::new();
        let mut actions = Vec::new();
        for &t in chunk {
            initial.extend(dataset.observations.row(t).iter());
            if reward_model {
                initial.push(0.0);
            }
            for k in t..t + horizon {
                actions.extend(dataset.actions.row(k).iter());
            }
        }
        let plan = OpenLoop {
            horizon,
            particles: config.particles,
            noise_scale: 1.0,
        };
        let rollout = model.rollout_open_loop(&initial, &actions, plan, rng, device);
        for eta in rollout.eta.chunks_exact(config.particles * horizon) {
            totals.push(eta.iter().sum::<f32>() / config.particles as f32);
        }
    }
    totals
}

/// Computes the table of ε(h, α) on `dataset`.
pub fn compute_thresholds(
    model: &NeuralSde,
    dataset: &Dataset,
    config: &ThresholdConfig,
    device: &Device,
) -> Result<ThresholdTable, SdeError> {
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let mut values = Vec::new();
    let mut windows = Vec::new();
    for &h in &config.horizons {
        let Ok(sampler) = WindowSampler::non_overlapping(dataset, h) else {
            values.push(vec![None; config.alphas.len()]);
            windows.push(0);
            continue;
        };
        let mut starts = sampler.starts().to_vec();
        starts.shuffle(&mut rng);
        starts.truncate(config.max_windows);
        let totals = accumulated_eta(model, dataset, &starts, h, config, &mut rng, device);
        values.push(
            config
                .alphas
                .iter()
                .map(|&a| Some(cvar(&totals, a)))
                .collect(),
        );
        windows.push(totals.len());
    }
    Ok(ThresholdTable {
        horizons: config.horizons.clone(),
        alphas: config.alphas.clone(),
        values,
        windows,
        particles: config.particles,
    })
}
