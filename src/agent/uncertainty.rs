//! Which uncertainty a method penalises and truncates on, and where it
//! truncates: NUNO's η at ε(h, α) from the model's table (computed when the
//! model was fitted); NUNO^al's aleatoric ‖σ_ϕ‖ at an ε(h, α) computed the
//! same way on it (Appendix D); TATU's ensemble disagreement at its largest
//! value over the dataset divided by the pessimism coefficient (TATU's
//! `compute_max_disc`).

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::AgentError;
use super::model_rollout::{RolloutActions, RolloutConfig, rollout_model};
use crate::data::{Dataset, WindowSampler};
use crate::envs::TaskRules;
use crate::sde::ThresholdConfig;
use crate::shared::{BatchDynamics, BatchShape, ModelStep};

/// NUNO^al (Appendix D): the model unchanged (its diffusion still σ + h(η)),
/// but the uncertainty it reports, so the one rollouts penalise and truncate
/// on, is the aleatoric term: ‖σ_ϕ(s, a)‖₂ over the state's dimensions.
pub struct AleatoricAsEta<'a> {
    inner: &'a dyn BatchDynamics,
}

impl<'a> AleatoricAsEta<'a> {
    pub fn new(inner: &'a dyn BatchDynamics) -> Self {
        Self { inner }
    }
}

impl BatchDynamics for AleatoricAsEta<'_> {
    fn shape(&self) -> BatchShape {
        self.inner.shape()
    }

    fn sample_noise_scale(&self) -> f32 {
        self.inner.sample_noise_scale()
    }

    fn noise_dim(&self) -> usize {
        self.inner.noise_dim()
    }

    fn step(&self, states: &[f32], actions: &[f32], noise: &[f32]) -> ModelStep {
        let mut step = self.inner.step(states, actions, noise);
        step.eta = step
            .sigma
            .chunks_exact(self.state_dim())
            .map(|sigma| sigma.iter().map(|s| s * s).sum::<f32>().sqrt())
            .collect();
        step
    }
}

/// ε(h, α) of `dynamics`' truncation signal on `dataset`, by the recipe of the
/// model's own table (`crate::sde::compute_thresholds`): up to
/// `config.max_windows` non-overlapping windows of length `horizon`, each rolled
/// open-loop on the dataset's actions with `config.particles` particles, the
/// signal summed along each particle's trajectory, CVaR at `alpha` over them.
/// A trajectory the model ends early (a terminal or a diverged state) counts
/// with the steps it took.
pub fn rollout_threshold(
    dynamics: &dyn BatchDynamics,
    rules: &TaskRules,
    dataset: &Dataset,
    horizon: usize,
    alpha: f64,
    config: &ThresholdConfig,
) -> Result<f32, AgentError> {
    config
        .validate()
        .map_err(|e| AgentError::Threshold(e.to_string()))?;
    let sampler = WindowSampler::non_overlapping(dataset, horizon)
        .map_err(|e| AgentError::Threshold(format!("windows of length {horizon}: {e}")))?;
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let starts = sampler.draw_distinct(config.max_windows, &mut rng);
    let rollout = RolloutConfig {
        horizon,
        particles: config.particles,
        penalty: 0.0,
        threshold: None,
        noise_scale: dynamics.sample_noise_scale(),
    };
    let mut totals = Vec::with_capacity(starts.len() * config.particles);
    for chunk in starts.chunks(config.chunk) {
        let windows = sampler.gather(chunk);
        let result = rollout_model(
            dynamics,
            RolloutActions::Sequence(&windows.actions),
            rules,
            &windows.first_states(),
            &rollout,
            &mut rng,
        );
        totals.extend(
            result
                .trace
                .accumulated_eta
                .iter()
                .map(|sums| sums.last().copied().unwrap_or(0.0)),
        );
    }
    config
        .epsilon(&totals, alpha)
        .ok_or_else(|| AgentError::Threshold("the dataset gave no windows".into()))
}

/// TATU's threshold: the largest truncation signal of `dynamics` over every
/// `(s, a)` of `dataset` (stepped `chunk` rows at a time, without noise),
/// divided by `pessimism`.
pub fn dataset_max_threshold(
    dynamics: &dyn BatchDynamics,
    dataset: &Dataset,
    pessimism: f64,
    chunk: usize,
) -> Result<f32, AgentError> {
    if !(pessimism.is_finite() && pessimism > 0.0) {
        return Err(AgentError::Threshold(format!(
            "the pessimism coefficient must be positive, got {pessimism}"
        )));
    }
    let chunk = chunk.max(1);
    let mut largest = f32::NEG_INFINITY;
    for first in (0..dataset.len()).step_by(chunk) {
        let rows = first..(first + chunk).min(dataset.len());
        let flat = |a: &ndarray::Array2<f32>| -> Vec<f32> {
            a.slice(ndarray::s![rows.clone(), ..])
                .iter()
                .copied()
                .collect()
        };
        let states = dynamics.states_from_observations(&flat(&dataset.observations));
        let noise = vec![0.0; rows.len() * dynamics.noise_dim()];
        let step = dynamics.step(&states, &flat(&dataset.actions), &noise);
        for (i, row) in rows.enumerate() {
            let signal = step.truncation_at(i);
            if !signal.is_finite() {
                return Err(AgentError::Threshold(format!(
                    "the model's uncertainty at dataset row {row} is {signal}"
                )));
            }
            largest = largest.max(signal);
        }
    }
    if largest == f32::NEG_INFINITY {
        return Err(AgentError::Threshold("the dataset is empty".into()));
    }
    Ok((f64::from(largest) / pessimism) as f32)
}
