//! The paper's model analyses (Section 5.2, Appendix E.1), for any model
//! behind [`BatchDynamics`], so NUNO's SDE and MOPO's ensemble are measured
//! by the same code:
//! - Figure 5: open-loop multi-step prediction error per horizon step, on
//!   trajectories of a dataset ([`prediction_error`]);
//! - Figure 3: the model's uncertainty at dataset states for the dataset's,
//!   uniformly random and a policy's actions ([`uncertainty_by_action`]);
//! - Figure 4: model exploitation, a policy's return in the model with and
//!   without the penalty against its return in the real task, and how many of
//!   the states it reaches in each lie outside the data's range ([`exploitation`]).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::ExperimentError;
use crate::agent::{
    RolloutActions, RolloutConfig, RolloutTrace, StateBox, TruncatedStep, rollout_model,
};
use crate::data::{Dataset, WindowBatch, WindowSampler};
use crate::envs::{MujocoTask, Rules, TaskConfig};
use crate::shared::{BatchDynamics, BatchPolicy, SeedStream, derive_seed};

/// How the open-loop prediction error is measured.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PredictionConfig {
    /// Steps predicted from each window's start.
    pub horizon: usize,
    /// At most this many windows (non-overlapping, drawn uniformly).
    pub windows: usize,
    /// Samples per window; their mean is the prediction.
    pub particles: usize,
    pub seed: u64,
}

/// Error of the mean prediction at each horizon step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PredictionError {
    /// RMSE over windows and observation dimensions, each dimension divided by
    /// its scale: entry k is step k + 1.
    pub rmse: Vec<f64>,
    /// Windows whose prediction reached each step (the model may end one
    /// early: a terminal or diverged state).
    pub windows: Vec<usize>,
}

/// Figure 5: rolls `dynamics` open-loop on each window's dataset actions and
/// compares the mean of its particles with the dataset's observations, per
/// step, in units of `scale` (one per observation dimension; use the same
/// scale for every dataset compared).
pub fn prediction_error(
    dynamics: &dyn BatchDynamics,
    rules: &Rules,
    dataset: &Dataset,
    scale: &[f32],
    config: &PredictionConfig,
) -> Result<PredictionError, ExperimentError> {
    let obs_dim = dynamics.obs_dim();
    if scale.len() != obs_dim || dataset.obs_dim() != obs_dim {
        return Err(ExperimentError::Invalid(format!(
            "the model observes {obs_dim} values, the dataset {} and the scale {}",
            dataset.obs_dim(),
            scale.len()
        )));
    }
    if config.horizon == 0 || config.windows == 0 || config.particles == 0 {
        return Err(ExperimentError::Invalid(
            "horizon, windows and particles must each be at least 1".into(),
        ));
    }
    let sampler = WindowSampler::non_overlapping(dataset, config.horizon).map_err(|e| {
        ExperimentError::Invalid(format!("windows of {} steps: {e}", config.horizon))
    })?;
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let starts = sampler.draw_distinct(config.windows, &mut rng);
    let windows = sampler.gather(&starts);
    let rollout = rollout_model(
        dynamics,
        RolloutActions::Sequence(&windows.actions),
        rules,
        &windows.first_states(),
        &RolloutConfig::unpenalised(config.horizon, config.particles, dynamics),
        &mut rng,
    );
    let errors = StepErrors::of(&rollout.trace, &windows, scale, config.particles);
    Ok(errors.rmse())
}

/// Per horizon step, the summed scaled squared error of the windows' mean
/// predictions and how many windows reached the step.
struct StepErrors {
    squared: Vec<f64>,
    reached: Vec<usize>,
}

impl StepErrors {
    fn of(trace: &RolloutTrace, windows: &WindowBatch, scale: &[f32], particles: usize) -> Self {
        let (horizon, obs_dim) = (windows.horizon, scale.len());
        let mut errors = Self {
            squared: vec![0.0; horizon],
            reached: vec![0; horizon],
        };
        let window_width = (horizon + 1) * obs_dim;
        for w in 0..windows.batch {
            let rows = w * particles..(w + 1) * particles;
            for k in 0..horizon {
                // The mean over the particles that got this far.
                let alive: Vec<usize> = rows.clone().filter(|&r| trace.kept[r] > k).collect();
                if alive.is_empty() {
                    break;
                }
                let at = w * window_width + (k + 1) * obs_dim;
                let truth = &windows.states[at..at + obs_dim];
                let predicted = |d: usize| {
                    let sum: f64 = (alive.iter())
                        .map(|&r| f64::from(trace.observations[r][(k + 1) * obs_dim + d]))
                        .sum();
                    sum / alive.len() as f64
                };
                let error: f64 = (0..obs_dim)
                    .map(|d| ((predicted(d) - f64::from(truth[d])) / f64::from(scale[d])).powi(2))
                    .sum();
                errors.squared[k] += error / obs_dim as f64;
                errors.reached[k] += 1;
            }
        }
        errors
    }

    /// RMSE per step over the windows that reached it (NaN where none did).
    fn rmse(self) -> PredictionError {
        let rmse = (self.squared.iter().zip(&self.reached))
            .map(|(s, &n)| {
                if n == 0 {
                    f64::NAN
                } else {
                    (s / n as f64).sqrt()
                }
            })
            .collect();
        PredictionError {
            rmse,
            windows: self.reached,
        }
    }
}

/// Whose actions the uncertainty is probed at.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ActionSource {
    Dataset,
    /// Uniform over the task's action box.
    Random,
    Policy,
    /// A corner of the action box, drawn uniformly: what a policy whose tanh
    /// has saturated plays.
    Saturated,
}

impl ActionSource {
    pub fn as_str(self) -> &'static str {
        match self {
            ActionSource::Dataset => "dataset",
            ActionSource::Random => "random",
            ActionSource::Policy => "policy",
            ActionSource::Saturated => "saturated",
        }
    }
}

/// Figure 3: the model's uncertainty (its η) at `states` dataset
/// transitions' states for their own actions, uniformly random actions in
/// `bounds` (one `(low, high)` per action dimension) and, given one, the
/// policy's: each source's values sorted ascending.
pub fn uncertainty_by_action(
    dynamics: &dyn BatchDynamics,
    dataset: &Dataset,
    policy: Option<&dyn BatchPolicy>,
    bounds: &[(f32, f32)],
    states: usize,
    seed: u64,
) -> Vec<(ActionSource, Vec<f32>)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let rows: Vec<usize> = (0..states.min(dataset.len()))
        .map(|_| rng.random_range(0..dataset.len()))
        .collect();
    let observations: Vec<f32> = rows
        .iter()
        .flat_map(|&t| dataset.observations.row(t).to_vec())
        .collect();
    let mut sources = vec![
        (
            ActionSource::Dataset,
            rows.iter()
                .flat_map(|&t| dataset.actions.row(t).to_vec())
                .collect::<Vec<f32>>(),
        ),
        (
            ActionSource::Random,
            (0..rows.len())
                .flat_map(|_| {
                    bounds
                        .iter()
                        .map(|&(low, high)| rng.random_range(low..=high))
                        .collect::<Vec<f32>>()
                })
                .collect(),
        ),
    ];
    if let Some(policy) = policy {
        sources.push((ActionSource::Policy, policy.act(&observations, &mut rng)));
    }
    let state_rows = dynamics.states_from_observations(&observations);
    let noise = vec![0.0; rows.len() * dynamics.noise_dim()];
    sources
        .into_iter()
        .map(|(source, actions)| {
            let mut eta = dynamics.step(&state_rows, &actions, &noise).eta;
            eta.sort_by(f32::total_cmp);
            (source, eta)
        })
        .collect()
}

/// Figure 4: one policy's mean cumulative return per step, in the real task
/// and in the model (its reward, and penalised by λ·η), from the same starts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Exploitation {
    /// Entry k: mean over starts of the return of steps 1..=k + 1 (an ended
    /// trajectory adds nothing after its end).
    pub real: Vec<f64>,
    pub model: Vec<f64>,
    pub model_penalized: Vec<f64>,
    pub penalty: f64,
    /// Entry k: the share of the trajectories that took step k + 1 whose
    /// state after it lies outside the data's range in some dimension (NaN
    /// where none took it): where a model's rollouts escape the data, and
    /// where the policy itself leaves it in the real task.
    pub real_outside_data: Vec<f64>,
    pub model_outside_data: Vec<f64>,
}

/// Per step: trajectories that took it, and how many of them ended it
/// outside the data's range.
struct OutsideCounts(Vec<(usize, usize)>);

impl OutsideCounts {
    fn new(horizon: usize) -> Self {
        Self(vec![(0, 0); horizon])
    }

    fn count(&mut self, step: usize, state: &[f32], data: &StateBox) {
        let (took, outside) = &mut self.0[step];
        *took += 1;
        *outside += usize::from(!data.contains(state));
    }

    fn shares(self) -> Vec<f64> {
        (self.0.into_iter())
            .map(|(took, outside)| match took {
                0 => f64::NAN,
                _ => outside as f64 / took as f64,
            })
            .collect()
    }
}

/// How [`exploitation`] runs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ExploitationConfig {
    /// Starts: the task's reset states for seeds `seed..seed + starts`.
    pub starts: usize,
    pub horizon: usize,
    /// λ of the penalised return.
    pub penalty: f64,
    pub seed: u64,
}

/// The real task's part of [`exploitation`]: per step, the summed reward
/// over the episodes and where they leave `data`; and the reset states.
fn real_task(
    task: &TaskConfig,
    policy: &dyn BatchPolicy,
    data: &StateBox,
    config: &ExploitationConfig,
    rng: &mut ChaCha8Rng,
) -> Result<(Vec<f64>, OutsideCounts, Vec<f32>), ExperimentError> {
    let invalid = |e: crate::envs::EnvError| ExperimentError::Invalid(e.to_string());
    let mut env = MujocoTask::new(task).map_err(invalid)?;
    let mut real = vec![0.0f64; config.horizon];
    let mut outside = OutsideCounts::new(config.horizon);
    let mut starts = Vec::with_capacity(config.starts * env.obs_dim());
    for i in 0..config.starts as u64 {
        let mut obs: Vec<f32> = env
            .reset(Some(derive_seed(config.seed, SeedStream::Episode(i))))
            .iter()
            .map(|&x| x as f32)
            .collect();
        starts.extend_from_slice(&obs);
        for (k, total) in real.iter_mut().enumerate() {
            let action = policy.act(&obs, rng);
            let action: Vec<f64> = action.iter().map(|&a| f64::from(a)).collect();
            let step = env.step(&action).map_err(invalid)?;
            *total += step.reward;
            obs = step.observation.iter().map(|&x| x as f32).collect();
            outside.count(k, &obs, data);
            if step.terminated || step.truncated {
                break;
            }
        }
    }
    Ok((real, outside, starts))
}

/// Runs `policy` from the task's reset states in the real task and in
/// `dynamics`, up to `horizon` steps or the end of each episode; `data` is
/// the dataset's range per dimension (`StateBox::around(bounds, 0)`).
pub fn exploitation(
    (dynamics, rules): (&dyn BatchDynamics, &Rules),
    task: &TaskConfig,
    policy: &dyn BatchPolicy,
    data: &StateBox,
    config: &ExploitationConfig,
) -> Result<Exploitation, ExperimentError> {
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let (real, real_outside, starts) = real_task(task, policy, data, config, &mut rng)?;
    let rollout = rollout_model(
        dynamics,
        RolloutActions::Policy(policy),
        rules,
        &starts,
        &RolloutConfig {
            horizon: config.horizon,
            particles: 1,
            penalty: config.penalty,
            threshold: None,
            noise_scale: dynamics.sample_noise_scale(),
            halt: None,
            state_box: None,
            observation_clip: None,
            truncated_step: TruncatedStep::Drop,
        },
        &mut rng,
    );
    let trace = &rollout.trace;
    let obs_dim = policy.obs_dim();
    let mut model = vec![0.0f64; config.horizon];
    let mut penalized = vec![0.0f64; config.horizon];
    let mut model_outside = OutsideCounts::new(config.horizon);
    for row in 0..trace.rows {
        for k in 0..trace.kept[row] {
            // The trace holds the start, then the state after each kept step.
            let state = &trace.observations[row][(k + 1) * obs_dim..(k + 2) * obs_dim];
            model_outside.count(k, state, data);
            let (r, eta) = (
                f64::from(trace.rewards[row][k]),
                f64::from(trace.eta[row][k]),
            );
            model[k] += r;
            penalized[k] += r - config.penalty * eta;
        }
    }
    let cumulative_mean = |per_step: Vec<f64>| -> Vec<f64> {
        per_step
            .iter()
            .scan(0.0, |sum, x| {
                *sum += x / config.starts.max(1) as f64;
                Some(*sum)
            })
            .collect()
    };
    Ok(Exploitation {
        real: cumulative_mean(real),
        model: cumulative_mean(model),
        model_penalized: cumulative_mean(penalized),
        penalty: config.penalty,
        real_outside_data: real_outside.shares(),
        model_outside_data: model_outside.shares(),
    })
}
