//! How well a model predicts: open-loop prediction error by horizon on held-out
//! windows of a dataset, next to the constant-velocity predictor (`pos' = pos +
//! vel·dt`, `vel' = vel`) as the baseline a learned model must beat; and one
//! action sequence run in the model and in the real MuJoCo task side by side
//! ([`compare_with_task`], the server's `/validate`).

use burn::tensor::Device;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::model::NeuralSde;
use super::rollout::OpenLoop;
use crate::data::{Dataset, WindowSampler};
use crate::envs::{EnvError, MujocoTask, Rules, TaskConfig};
use crate::shared::{BatchDynamics, Cancel, scaled_noise};

/// RMSE after `horizon` open-loop steps, in normalised state units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HorizonError {
    pub horizon: usize,
    pub windows: usize,
    pub model_rmse: f64,
    pub constant_velocity_rmse: f64,
}

/// Prediction error of `model` on `dataset` for horizons `1..=max_horizon`
/// (those with at least one window), over at most `max_windows` windows each.
pub fn prediction_error(
    model: &NeuralSde,
    dataset: &Dataset,
    max_horizon: usize,
    max_windows: usize,
    seed: u64,
    device: &Device,
) -> Vec<HorizonError> {
    let spec = model.spec().clone();
    let std = &model.constants.scales.normalizer.state.std;
    let reward_model = model.constants.config.reward_model;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::new();
    for horizon in 1..=max_horizon {
        let Ok(sampler) = WindowSampler::new(dataset, horizon) else {
            break;
        };
        let mut starts = sampler.starts().to_vec();
        starts.shuffle(&mut rng);
        starts.truncate(max_windows);
        let windows = sampler.gather(&starts);
        let obs = spec.obs_dim;
        let mut initial = Vec::with_capacity(starts.len() * (obs + 1));
        for w in 0..starts.len() {
            let row = w * (horizon + 1) * obs;
            initial.extend_from_slice(&windows.states[row..row + obs]);
            if reward_model {
                initial.push(0.0);
            }
        }
        let plan = OpenLoop {
            horizon,
            particles: 1,
            noise_scale: 0.0,
        };
        let rollout = model.rollout_open_loop(&initial, &windows.actions, plan, &mut rng, device);
        let (mut model_se, mut baseline_se) = (0.0f64, 0.0f64);
        for w in 0..starts.len() {
            let base = w * (horizon + 1) * obs;
            let first = &windows.states[base..base + obs];
            let truth = &windows.states[base + horizon * obs..base + (horizon + 1) * obs];
            let predicted = rollout.state(w, 0, horizon);
            let mut baseline = first.to_vec();
            for (&p, &v) in spec
                .split
                .positions
                .iter()
                .zip(&spec.split.position_velocity)
            {
                baseline[p] += horizon as f32 * first[v] * spec.dt as f32;
            }
            for d in 0..obs {
                model_se += f64::from((predicted[d] - truth[d]) / std[d]).powi(2);
                baseline_se += f64::from((baseline[d] - truth[d]) / std[d]).powi(2);
            }
        }
        let n = (starts.len() * obs) as f64;
        out.push(HorizonError {
            horizon,
            windows: starts.len(),
            model_rmse: (model_se / n).sqrt(),
            constant_velocity_rmse: (baseline_se / n).sqrt(),
        });
    }
    out
}

/// One action sequence in the model and in the real task, from the same start.
#[derive(Debug, Clone, PartialEq)]
pub struct TaskComparison {
    pub obs_dim: usize,
    /// Steps compared: until the sequence ends, the real task terminates, or a
    /// model particle terminates (the task's rule) or stops being finite.
    pub steps: usize,
    /// Real observations, `[steps + 1, obs_dim]`.
    pub real_states: Vec<f32>,
    /// The model's particle-mean observations, `[steps + 1, obs_dim]`.
    pub model_states: Vec<f32>,
    /// RMSE over the observation entries after each step, physical units: `[steps]`.
    pub rmse: Vec<f32>,
    /// The same with each entry divided by `state_std`: `[steps]`.
    pub normalized_rmse: Vec<f32>,
}

/// How [`compare_with_task`] samples the model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TaskComparisonConfig {
    /// The real task resets with this seed; the model's noise is seeded by it too.
    pub seed: u64,
    /// Model samples averaged per step.
    pub particles: usize,
    /// Multiplies ε (0: the drift alone).
    pub noise_scale: f32,
}

/// Runs `actions` (`[horizon, act_dim]`) open loop in the real task from its
/// reset state and in `dynamics` from the same observation, and compares them
/// step by step. Stops with [`EnvError::Cancelled`] between steps once
/// `cancel` is set.
pub fn compare_with_task(
    dynamics: &dyn BatchDynamics,
    task: TaskConfig,
    rules: &Rules,
    state_std: &[f32],
    actions: &[f32],
    config: &TaskComparisonConfig,
    cancel: &Cancel,
) -> Result<TaskComparison, EnvError> {
    let obs_dim = dynamics.obs_dim();
    let act_dim = dynamics.act_dim();
    let real_states = real_open_loop(&task, config.seed, actions, act_dim, cancel)?;
    let start = &real_states[..obs_dim];
    let real_steps = real_states.len() / obs_dim - 1;
    let actions = &actions[..real_steps * act_dim];
    let model_states = model_open_loop(dynamics, rules, start, actions, config, cancel)?;
    let steps = model_states.len() / obs_dim - 1;
    let real_states = real_states[..(steps + 1) * obs_dim].to_vec();
    Ok(TaskComparison {
        obs_dim,
        steps,
        rmse: rmse_per_step(&model_states, &real_states, obs_dim, &|_| 1.0),
        normalized_rmse: rmse_per_step(&model_states, &real_states, obs_dim, &|i| state_std[i]),
        real_states,
        model_states,
    })
}

/// The real task's observations from its reset with `seed` under `actions` (`act_dim`
/// wide), until they end or the task terminates: `[steps + 1, obs_dim]`.
fn real_open_loop(
    task: &TaskConfig,
    seed: u64,
    actions: &[f32],
    act_dim: usize,
    cancel: &Cancel,
) -> Result<Vec<f32>, EnvError> {
    let mut real_task = MujocoTask::new(task)?;
    let to_f32 = |values: &[f64]| values.iter().map(|&x| x as f32).collect::<Vec<_>>();
    let mut states = to_f32(&real_task.reset(Some(seed)));
    for action in actions.chunks_exact(act_dim) {
        cancel.check()?;
        let action: Vec<f64> = action.iter().map(|&a| f64::from(a)).collect();
        let step = real_task.step(&action)?;
        states.extend(to_f32(&step.observation));
        if step.terminated {
            break;
        }
    }
    Ok(states)
}

/// The model's particle-mean observations from `start` under `actions`: the particles step
/// in lockstep, and the rollout ends where the first one terminates or leaves the finite
/// numbers (as a rollout drops it): `[steps + 1, obs_dim]`.
fn model_open_loop(
    dynamics: &dyn BatchDynamics,
    rules: &Rules,
    start: &[f32],
    actions: &[f32],
    config: &TaskComparisonConfig,
    cancel: &Cancel,
) -> Result<Vec<f32>, EnvError> {
    let (obs_dim, act_dim) = (dynamics.obs_dim(), dynamics.act_dim());
    let state_dim = dynamics.state_dim();
    let particles = config.particles.max(1);
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let mut observations: Vec<f32> = start.repeat(particles);
    let mut model_states = start.to_vec();
    for action in actions.chunks_exact(act_dim) {
        cancel.check()?;
        let states = dynamics.states_from_observations(&observations);
        let noise = scaled_noise(
            particles * dynamics.noise_dim(),
            config.noise_scale,
            &mut rng,
        );
        let step = dynamics.step(&states, &action.repeat(particles), &noise);
        if !(step.eta.iter().chain(&step.next_states)).all(|x| x.is_finite()) {
            break;
        }
        let next: Vec<f32> = step
            .next_states
            .chunks_exact(state_dim)
            .flat_map(|row| row[..obs_dim].iter().copied())
            .collect();
        model_states.extend(
            (0..obs_dim)
                .map(|i| next.chunks_exact(obs_dim).map(|p| p[i]).sum::<f32>() / particles as f32),
        );
        let terminal = next.chunks_exact(obs_dim).any(|obs| rules.terminal(obs));
        observations = next;
        if terminal {
            break;
        }
    }
    Ok(model_states)
}

/// RMSE over the observation entries after each step, each divided by `scale(entry)`.
fn rmse_per_step(
    model_states: &[f32],
    real_states: &[f32],
    obs_dim: usize,
    scale: &dyn Fn(usize) -> f32,
) -> Vec<f32> {
    let steps = model_states.len() / obs_dim - 1;
    (1..=steps)
        .map(|k| {
            let sum: f32 = (0..obs_dim)
                .map(|i| {
                    let at = k * obs_dim + i;
                    ((model_states[at] - real_states[at]) / scale(i)).powi(2)
                })
                .sum();
            (sum / obs_dim as f32).sqrt()
        })
        .collect()
}
