//! Which uncertainty a method penalises and truncates on, and where it
//! truncates: NUNO's η at ε(h, α) from the model's table (computed when the
//! model was fitted); NUNO^al's aleatoric ‖σ_ϕ‖ at an ε(h, α) computed the
//! same way on it (Appendix D); TATU's ensemble disagreement at its largest
//! value over the dataset divided by the pessimism coefficient (TATU's
//! `compute_max_disc`).

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::AgentError;
use super::method::{Method, Truncation};
use super::model_rollout::{RolloutActions, RolloutConfig, rollout_model};
use super::policy_loop::{LoopContext, PolicyLoopConfig};
use crate::data::{Dataset, WindowSampler};
use crate::envs::Rules;
use crate::sde::{ThresholdConfig, ThresholdTable};
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
    rules: &Rules,
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
    let rollout = RolloutConfig::unpenalised(horizon, config.particles, dynamics);
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

/// Transitions stepped together while [`dataset_max_threshold`] scans a dataset.
const DATASET_SCAN_CHUNK: usize = 10_000;

/// A run's truncation threshold, and how it was found (what a run records).
#[derive(Debug, Clone, PartialEq)]
pub struct RunThreshold {
    pub value: f32,
    pub how: String,
}

impl Truncation {
    /// Whether a run computes its threshold (so a resumed run should reuse
    /// the value rather than spend the time again), rather than reading it
    /// from the model's table or having none.
    pub fn computed_per_run(self) -> bool {
        matches!(
            self,
            Truncation::AleatoricCvar | Truncation::DatasetDisagreement | Truncation::Halt
        )
    }
}

/// Where `method`'s rollouts truncate under `config` (none when truncation is
/// off): NUNO's ε(h, α) read from the model's `table`; NUNO^al's computed on
/// ‖σ‖ the same way (Appendix D); TATU's from the ensemble's largest
/// disagreement over the dataset over `pessimism`, which TATU needs; MOReL's
/// HALT at `pessimism` × its largest pairwise discrepancy there.
pub fn run_threshold(
    method: Method,
    config: &PolicyLoopConfig,
    table: Option<&ThresholdTable>,
    ctx: &LoopContext,
    pessimism: Option<f64>,
) -> Result<Option<RunThreshold>, AgentError> {
    if !config.truncate {
        return Ok(None);
    }
    let (value, how) = match method.truncation() {
        Truncation::Never => return Ok(None),
        Truncation::ModelTable => {
            let value = config.threshold_from(table)?;
            let how = format!(
                "ε(h = {}, α = {}) from the model's table",
                config.horizon, config.cvar_alpha
            );
            (value.expect("truncation is on"), how)
        }
        Truncation::AleatoricCvar => {
            let thresholds = ThresholdConfig::new().with_seed(config.seed);
            let value = rollout_threshold(
                ctx.dynamics,
                &ctx.rules,
                ctx.dataset,
                config.horizon,
                config.cvar_alpha,
                &thresholds,
            )?;
            let how = format!(
                "CVaR at α = {} of ‖σ‖ accumulated over h = {} along {} particles of up to {} dataset windows",
                config.cvar_alpha, config.horizon, thresholds.particles, thresholds.max_windows
            );
            (value, how)
        }
        Truncation::DatasetDisagreement => {
            let pessimism = pessimism.ok_or_else(|| {
                AgentError::Threshold("TATU's threshold needs its pessimism coefficient".into())
            })?;
            let value =
                dataset_max_threshold(ctx.dynamics, ctx.dataset, pessimism, DATASET_SCAN_CHUNK)?;
            let how = format!(
                "the ensemble's largest disagreement over the dataset's {} transitions / pessimism {pessimism}",
                ctx.dataset.len()
            );
            (value, how)
        }
        Truncation::Halt => {
            let pessimism = pessimism.ok_or_else(|| {
                AgentError::Threshold("MOReL's threshold needs its pessimism coefficient".into())
            })?;
            // MOReL multiplies the largest discrepancy by its coefficient (TATU divides).
            let value = dataset_max_threshold(
                ctx.dynamics,
                ctx.dataset,
                1.0 / pessimism,
                DATASET_SCAN_CHUNK,
            )?;
            let how = format!(
                "MOReL's HALT at pessimism {pessimism} × the ensemble's largest pairwise discrepancy over the dataset's {} transitions",
                ctx.dataset.len()
            );
            (value, how)
        }
    };
    Ok(Some(RunThreshold { value, how }))
}
