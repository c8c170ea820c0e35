//! Truncation thresholds ε(h, α) (Section 4.3): roll the SDE open-loop on the
//! dataset's actions from the starts of each trajectory's non-overlapping
//! windows of length h (NUNO's code; Section 4.3 speaks of "all possible
//! sequences of horizon h"), accumulate η along each particle's trajectory, and take
//! the CVaR at level α of the accumulated values over all of them (α = 1: the
//! maximum). Each particle trajectory is one sample, as in NUNO's code and as
//! model rollouts compare their own trajectory's sum against ε.

use burn::config::Config;
use burn::tensor::Device;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::SdeError;
use super::config::zero_count;
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
    /// ε(h, α ≥ 1) is this multiple of the largest accumulated η: 1 takes the
    /// maximum (nuno's paper recipe); NUNO's code takes 1.1 × it (`Recipe::Code`).
    #[config(default = 1.0)]
    pub max_margin: f32,
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
    /// `ThresholdConfig::max_margin` of ε(h, α ≥ 1); absent from tables
    /// written before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_margin: Option<f32>,
}

impl ThresholdConfig {
    /// ε at level `alpha` over accumulated-η `totals`: their CVaR, or
    /// `max_margin` × their maximum for α ≥ 1.
    pub fn epsilon(&self, totals: &[f32], alpha: f64) -> Option<f32> {
        let tail = cvar(totals, alpha)?;
        Some(if alpha >= 1.0 {
            tail * self.max_margin
        } else {
            tail
        })
    }

    /// Refuses settings no threshold can be computed from, naming the field.
    pub fn validate(&self) -> Result<(), SdeError> {
        let bad = |message: String| SdeError::Config(format!("threshold config: {message}"));
        if self.horizons.is_empty() || self.horizons.contains(&0) {
            return Err(bad(format!(
                "horizons {:?}: need at least one, each >= 1",
                self.horizons
            )));
        }
        if let Some(a) = self.alphas.iter().find(|a| !(**a > 0.0 && **a <= 1.0)) {
            return Err(bad(format!("alpha {a}: must lie in (0, 1]")));
        }
        if self.alphas.is_empty() {
            return Err(bad("alphas: need at least one level".into()));
        }
        if let Some(message) = zero_count(&[
            ("particles", self.particles),
            ("max_windows", self.max_windows),
            ("chunk", self.chunk),
        ]) {
            return Err(bad(message));
        }
        if !(self.max_margin.is_finite() && self.max_margin >= 1.0) {
            return Err(bad(format!(
                "max_margin = {}: must be finite and >= 1",
                self.max_margin
            )));
        }
        Ok(())
    }
}

impl ThresholdTable {
    /// ε(h, α), if it was computed.
    pub fn get(&self, horizon: usize, alpha: f64) -> Option<f32> {
        let i = self.horizons.iter().position(|&h| h == horizon)?;
        let j = self.alphas.iter().position(|&a| (a - alpha).abs() < 1e-9)?;
        self.values[i][j]
    }
}

/// The truncation threshold a caller asks for: `threshold` outright, or
/// ε(h = `horizon`, α = `alpha`) from a model's `table`; neither is none.
pub fn requested_threshold(
    table: Option<&ThresholdTable>,
    threshold: Option<f32>,
    alpha: Option<f64>,
    horizon: usize,
) -> Result<Option<f32>, SdeError> {
    let refuse = |message: String| Err(SdeError::Threshold(message));
    match (threshold, alpha) {
        (Some(_), Some(_)) => refuse("give `alpha` or `threshold`, not both".into()),
        (Some(t), None) if t.is_finite() => Ok(Some(t)),
        (Some(t), None) => refuse(format!("`threshold` must be finite, got {t}")),
        (None, Some(alpha)) => match table.and_then(|t| t.get(horizon, alpha)) {
            Some(epsilon) => Ok(Some(epsilon)),
            None => refuse(format!(
                "the model has no ε(h = {horizon}, α = {alpha}); its table covers h ∈ {:?}, α ∈ {:?}",
                table.map(|t| t.horizons.clone()).unwrap_or_default(),
                table.map(|t| t.alphas.clone()).unwrap_or_default()
            )),
        },
        (None, None) => Ok(None),
    }
}

/// CVaR_α of `values`: the mean of the values at or above the α-quantile; α ≥ 1
/// gives the maximum. `None` for no values (there is no tail to average).
pub fn cvar(values: &[f32], alpha: f64) -> Option<f32> {
    let mut sorted = values.to_vec();
    sorted.sort_by(f32::total_cmp);
    let n = sorted.len();
    if n == 0 {
        return None;
    }
    if alpha >= 1.0 {
        return Some(sorted[n - 1]);
    }
    let var_index = ((alpha * (n - 1) as f64).floor() as usize).min(n - 1);
    let tail = &sorted[var_index..];
    Some(tail.iter().sum::<f32>() / tail.len() as f32)
}

/// Accumulated η of open-loop rollouts from each window start on the dataset's
/// actions: one value per particle trajectory, `particles` in a row per start.
pub fn accumulated_eta(
    model: &NeuralSde,
    dataset: &Dataset,
    starts: &[usize],
    horizon: usize,
    config: &ThresholdConfig,
    rng: &mut ChaCha8Rng,
    device: &Device,
) -> Vec<f32> {
    let (initial, actions) = window_starts_and_actions(model, dataset, starts, horizon);
    accumulated_eta_along(model, &initial, &actions, horizon, config, rng, device)
}

/// The start state (with r_c = 0 for NUNO^R) and the `horizon` dataset actions
/// of each window: `[starts, state_dim]` and `[starts, horizon, act_dim]`.
pub fn window_starts_and_actions(
    model: &NeuralSde,
    dataset: &Dataset,
    starts: &[usize],
    horizon: usize,
) -> (Vec<f32>, Vec<f32>) {
    let reward_model = model.constants.config.reward_model;
    let mut initial = Vec::with_capacity(starts.len() * model.constants.state_dim());
    let mut actions = Vec::with_capacity(starts.len() * horizon * dataset.act_dim());
    for &t in starts {
        initial.extend(dataset.observations.row(t).iter());
        if reward_model {
            initial.push(0.0);
        }
        for k in t..t + horizon {
            actions.extend(dataset.actions.row(k).iter());
        }
    }
    (initial, actions)
}

/// Accumulated η of open-loop rollouts from `initial` (`[n, state_dim]`) along
/// `actions` (`[n, horizon, act_dim]`), `config.particles` trajectories each,
/// stepped `config.chunk` starts at a time: one value per particle trajectory.
pub fn accumulated_eta_along(
    model: &NeuralSde,
    initial: &[f32],
    actions: &[f32],
    horizon: usize,
    config: &ThresholdConfig,
    rng: &mut ChaCha8Rng,
    device: &Device,
) -> Vec<f32> {
    let state_dim = model.constants.state_dim();
    let plan_width = horizon * model.spec().act_dim;
    let chunk = config.chunk.max(1);
    let plan = OpenLoop {
        horizon,
        particles: config.particles,
        noise_scale: model.constants.config.sample_noise_scale,
    };
    let mut totals = Vec::with_capacity(initial.len() / state_dim * config.particles);
    for (starts, actions) in initial
        .chunks(chunk * state_dim)
        .zip(actions.chunks(chunk * plan_width))
    {
        let rollout = model.rollout_open_loop(starts, actions, plan, rng, device);
        totals.extend(
            rollout
                .eta
                .chunks_exact(horizon)
                .map(|eta| eta.iter().sum::<f32>()),
        );
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
    config.validate()?;
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let mut values = Vec::new();
    let mut windows = Vec::new();
    for &h in &config.horizons {
        let Ok(sampler) = WindowSampler::non_overlapping(dataset, h) else {
            values.push(vec![None; config.alphas.len()]);
            windows.push(0);
            continue;
        };
        let starts = sampler.draw_distinct(config.max_windows, &mut rng);
        let totals = accumulated_eta(model, dataset, &starts, h, config, &mut rng, device);
        values.push(
            config
                .alphas
                .iter()
                .map(|&a| config.epsilon(&totals, a))
                .collect(),
        );
        windows.push(starts.len());
    }
    Ok(ThresholdTable {
        horizons: config.horizons.clone(),
        alphas: config.alphas.clone(),
        values,
        windows,
        particles: config.particles,
        max_margin: Some(config.max_margin),
    })
}
