//! How sharply a model's next state answers the action, against the task's:
//! the Jacobian ∂s′/∂a of the model's noise-free step (an SDE's drift, an
//! ensemble's elite mean) and of the simulator's own step, by central
//! differences at dataset states. A policy trained in a model climbs the
//! model's ∂s′/∂a; where it is steeper than the task's at the actions a
//! saturated policy plays, the model pays for actions the task does not.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::{ActionSource, ExperimentError};
use crate::data::Dataset;
use crate::envs::{MujocoTask, TaskConfig};
use crate::shared::BatchDynamics;

/// How [`action_sensitivity`] measures.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SensitivityConfig {
    /// Dataset states (drawn uniformly) the Jacobians are taken at.
    pub states: usize,
    /// The action step of the differences; at a bound of the action box the
    /// difference is one-sided, inward, as neither a model's nor the task's
    /// actuators see beyond it.
    pub delta: f32,
    pub seed: u64,
}

/// One action source's Jacobians, model against task: means over the states
/// of the Frobenius norms ‖∂s′/∂a‖ (observation units per unit of action).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ActionSensitivity {
    pub actions: ActionSource,
    pub model: f64,
    pub task: f64,
    /// ‖J_model − J_task‖, the model's error in its answer to the action.
    pub error: f64,
    /// The median over states of ‖J_model‖ / ‖J_task‖.
    pub median_ratio: f64,
    pub states: usize,
}

/// ∂s′/∂a of `dynamics`' noise-free step and of `task`'s simulator at
/// `config.states` of `dataset`'s states, for the dataset's actions, uniform
/// random ones and saturated ones (a uniformly drawn corner of the box).
pub fn action_sensitivity(
    dynamics: &dyn BatchDynamics,
    task: &TaskConfig,
    dataset: &Dataset,
    config: &SensitivityConfig,
) -> Result<Vec<ActionSensitivity>, ExperimentError> {
    let invalid = |e: crate::envs::EnvError| ExperimentError::Invalid(e.to_string());
    let mut env = MujocoTask::new(task).map_err(invalid)?;
    let (obs_dim, act_dim) = (env.obs_dim(), env.act_dim());
    if (dynamics.obs_dim(), dynamics.act_dim()) != (obs_dim, act_dim) {
        return Err(ExperimentError::Invalid(format!(
            "the model's observations and actions ({}, {}) are not {}'s ({obs_dim}, {act_dim})",
            dynamics.obs_dim(),
            dynamics.act_dim(),
            task.task.name()
        )));
    }
    let (low, high) = env.action_bounds();
    let bounds: Vec<(f32, f32)> = low
        .iter()
        .zip(&high)
        .map(|(&l, &h)| (l as f32, h as f32))
        .collect();
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let rows: Vec<usize> = (0..config.states.min(dataset.len()))
        .map(|_| rng.random_range(0..dataset.len()))
        .collect();
    let observations: Vec<f32> = (rows.iter())
        .flat_map(|&t| dataset.observations.row(t).to_vec())
        .collect();
    let sources = action_sources(dataset, &rows, &bounds, &mut rng);
    let model_step = |states: &[f32], actions: &[f32]| -> Vec<f32> {
        let states = dynamics.states_from_observations(states);
        let noise = vec![0.0; actions.len() / act_dim * dynamics.noise_dim()];
        let next = dynamics.step(&states, actions, &noise).next_states;
        let state_dim = dynamics.state_dim();
        (next.chunks_exact(state_dim))
            .flat_map(|row| row[..obs_dim].to_vec())
            .collect()
    };
    let mut task_step = |states: &[f32], actions: &[f32]| -> Result<Vec<f32>, ExperimentError> {
        let mut next = Vec::with_capacity(states.len());
        for (s, a) in states
            .chunks_exact(obs_dim)
            .zip(actions.chunks_exact(act_dim))
        {
            let s: Vec<f64> = s.iter().map(|&x| f64::from(x)).collect();
            let a: Vec<f64> = a.iter().map(|&x| f64::from(x)).collect();
            env.set_observation(&s).map_err(invalid)?;
            let step = env.step(&a).map_err(invalid)?;
            next.extend(step.observation.iter().map(|&x| x as f32));
        }
        Ok(next)
    };
    let mut measured = Vec::with_capacity(sources.len());
    for (source, actions) in sources {
        let at = (&observations[..], &actions[..]);
        let model = jacobians(|s, a| Ok(model_step(s, a)), at, &bounds, config.delta)?;
        let task = jacobians(&mut task_step, at, &bounds, config.delta)?;
        measured.push(compare(source, &model, &task));
    }
    Ok(measured)
}

/// The actions the Jacobians are taken at, per source, one row per dataset
/// row of `rows`: the dataset's own, uniform over `bounds`, and a uniformly
/// drawn corner of the box.
fn action_sources(
    dataset: &Dataset,
    rows: &[usize],
    bounds: &[(f32, f32)],
    rng: &mut ChaCha8Rng,
) -> [(ActionSource, Vec<f32>); 3] {
    let act_dim = bounds.len();
    let dataset_actions = (rows.iter())
        .flat_map(|&t| dataset.actions.row(t).to_vec())
        .collect();
    let random = (0..rows.len() * act_dim)
        .map(|i| {
            let (l, h) = bounds[i % act_dim];
            rng.random_range(l..=h)
        })
        .collect();
    let saturated = (0..rows.len() * act_dim)
        .map(|i| {
            let (l, h) = bounds[i % act_dim];
            if rng.random_bool(0.5) { h } else { l }
        })
        .collect();
    [
        (ActionSource::Dataset, dataset_actions),
        (ActionSource::Random, random),
        (ActionSource::Saturated, saturated),
    ]
}

/// The source's mean norms, mean error and median norm ratio over its states.
fn compare(actions: ActionSource, model: &[Vec<f64>], task: &[Vec<f64>]) -> ActionSensitivity {
    let norm = |j: &[f64]| j.iter().map(|x| x * x).sum::<f64>().sqrt();
    let states = model.len();
    let mean = |values: Vec<f64>| values.iter().sum::<f64>() / states.max(1) as f64;
    let mut ratios: Vec<f64> = (model.iter().zip(task))
        .map(|(m, t)| norm(m) / norm(t))
        .collect();
    ratios.sort_by(f64::total_cmp);
    let errors = (model.iter().zip(task))
        .map(|(m, t)| {
            let difference: Vec<f64> = m.iter().zip(t).map(|(m, t)| m - t).collect();
            norm(&difference)
        })
        .collect();
    ActionSensitivity {
        actions,
        model: mean(model.iter().map(|j| norm(j)).collect()),
        task: mean(task.iter().map(|j| norm(j)).collect()),
        error: mean(errors),
        median_ratio: ratios.get(states / 2).copied().unwrap_or(f64::NAN),
        states,
    }
}

/// ∂s′/∂a of `step` at each (s, a) row of `at`, `[obs_dim × act_dim]` row-major
/// per row, by differences of `delta` inside `bounds` (one `(low, high)` per
/// action dimension); `step` maps state rows and action rows to next-state rows.
fn jacobians(
    mut step: impl FnMut(&[f32], &[f32]) -> Result<Vec<f32>, ExperimentError>,
    (observations, actions): (&[f32], &[f32]),
    bounds: &[(f32, f32)],
    delta: f32,
) -> Result<Vec<Vec<f64>>, ExperimentError> {
    let act_dim = bounds.len();
    let rows = actions.len() / act_dim;
    let obs_dim = observations.len() / rows.max(1);
    // Row r·act_dim + j of each batch moves action j of row r up (or down).
    let (mut states, mut up, mut down) = (Vec::new(), Vec::new(), Vec::new());
    let mut spans = Vec::with_capacity(rows * act_dim);
    for (s, a) in observations
        .chunks_exact(obs_dim)
        .zip(actions.chunks_exact(act_dim))
    {
        for (j, &(low, high)) in bounds.iter().enumerate() {
            let (mut plus, mut minus) = (a.to_vec(), a.to_vec());
            plus[j] = (a[j] + delta).min(high);
            minus[j] = (a[j] - delta).max(low);
            spans.push(f64::from(plus[j]) - f64::from(minus[j]));
            states.extend_from_slice(s);
            up.extend(plus);
            down.extend(minus);
        }
    }
    let (after_up, after_down) = (step(&states, &up)?, step(&states, &down)?);
    Ok((0..rows)
        .map(|r| {
            let mut jacobian = vec![0.0; obs_dim * act_dim];
            for j in 0..act_dim {
                let column = r * act_dim + j;
                let rows_of =
                    |next: &[f32]| next[column * obs_dim..(column + 1) * obs_dim].to_vec();
                let (u, d) = (rows_of(&after_up), rows_of(&after_down));
                for i in 0..obs_dim {
                    jacobian[i * act_dim + j] = (f64::from(u[i]) - f64::from(d[i])) / spans[column];
                }
            }
            jacobian
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// s′ = s + B·a with B by hand: the differences give B exactly, inside the
    /// box and at its bounds (one-sided there).
    #[test]
    fn the_differences_of_a_linear_step_are_its_action_matrix() {
        let b = [[0.5, -1.0], [2.0, 0.25], [0.0, 3.0]];
        let step = |s: &[f32], a: &[f32]| -> Result<Vec<f32>, ExperimentError> {
            Ok((s.chunks_exact(3).zip(a.chunks_exact(2)))
                .flat_map(|(s, a)| (0..3).map(move |i| s[i] + b[i][0] * a[0] + b[i][1] * a[1]))
                .collect())
        };
        let observations = [0.1, -0.2, 0.3, 1.0, 2.0, -3.0];
        let actions = [0.2, -0.4, 1.0, -1.0];
        let bounds = [(-1.0, 1.0); 2];
        let found = jacobians(step, (&observations, &actions), &bounds, 0.01).unwrap();
        assert_eq!(found.len(), 2);
        for jacobian in &found {
            for i in 0..3 {
                for j in 0..2 {
                    let (got, want) = (jacobian[i * 2 + j], f64::from(b[i][j]));
                    assert!(
                        (got - want).abs() < 1e-3,
                        "({i}, {j}): {got} against {want}"
                    );
                }
            }
        }
    }

    /// The comparison's norms, error and ratio, by hand on two states.
    #[test]
    fn the_comparison_averages_norms_and_takes_the_median_ratio() {
        let model = [vec![3.0, 4.0], vec![0.0, 2.0]];
        let task = [vec![0.0, 5.0], vec![0.0, 1.0]];
        let c = compare(ActionSource::Saturated, &model, &task);
        assert_eq!((c.model, c.task), (3.5, 3.0));
        // ‖(3, −1)‖ = √10 and ‖(0, 1)‖ = 1.
        assert!((c.error - (10f64.sqrt() + 1.0) / 2.0).abs() < 1e-12);
        // Ratios 1 and 2: the upper median.
        assert_eq!(c.median_ratio, 2.0);
        assert_eq!(c.states, 2);
    }
}
