//! Model-predictive control in the real task: at every step of every episode
//! the planner runs in the model from the observed state, warm-started from
//! that episode's previous plan shifted one step, and the plan's first action
//! is taken (mbrl-lib's `TrajectoryOptimizerAgent`, replanning every step).

use std::collections::HashMap;

use rand_chacha::ChaCha8Rng;

use super::PlanningError;
use super::plan::{Plan, PlanConfig, PlanStart, check, plan};
use crate::envs::{
    EnvError, EpisodeController, EvaluationConfig, EvaluationReport, MujocoTask, Rules,
    evaluate_controlled,
};
use crate::shared::{BatchDynamics, Cancel};

/// The planner as a controller of evaluated episodes: it keeps each
/// episode's last plan (and iCEM's elites).
struct Mpc<'a> {
    dynamics: &'a dyn BatchDynamics,
    rules: &'a Rules,
    config: &'a PlanConfig,
    action_box: &'a [(f32, f32)],
    plans: HashMap<usize, Plan>,
}

impl EpisodeController for Mpc<'_> {
    fn obs_dim(&self) -> usize {
        self.dynamics.obs_dim()
    }

    fn act_dim(&self) -> usize {
        self.dynamics.act_dim()
    }

    fn act(
        &mut self,
        episodes: &[usize],
        observations: &[f32],
        rng: &mut ChaCha8Rng,
        cancel: &Cancel,
    ) -> Result<Vec<f32>, EnvError> {
        let (obs_dim, act_dim) = (self.obs_dim(), self.act_dim());
        let mut actions = Vec::with_capacity(episodes.len() * act_dim);
        for (&episode, state) in episodes.iter().zip(observations.chunks_exact(obs_dim)) {
            let last = self.plans.get(&episode);
            let start = PlanStart {
                state,
                action_box: self.action_box,
                warm: last.map(|p| p.actions.as_slice()),
                elites: last.map_or(&[], |p| p.elites.as_slice()),
            };
            let found =
                plan(self.dynamics, self.rules, &start, self.config, rng, cancel).map_err(|e| {
                    match e {
                        PlanningError::Cancelled(c) => EnvError::Cancelled(c),
                        other => EnvError::Controller(other.to_string()),
                    }
                })?;
            actions.extend_from_slice(&found.actions[..act_dim]);
            self.plans.insert(episode, found);
        }
        Ok(actions)
    }
}

/// Runs `evaluation`'s episodes in the real task with MPC: `config`'s planner
/// in `dynamics`, inside the task's action box; the report is the evaluator's,
/// so it reads beside a policy's evaluated with the same seed.
pub fn evaluate_mpc(
    dynamics: &dyn BatchDynamics,
    rules: &Rules,
    config: &PlanConfig,
    evaluation: &EvaluationConfig,
    cancel: &Cancel,
) -> Result<EvaluationReport, PlanningError> {
    let (low, high) = MujocoTask::new(&evaluation.task)?.action_bounds();
    let action_box: Vec<(f32, f32)> = (low.iter().zip(&high))
        .map(|(&l, &h)| (l as f32, h as f32))
        .collect();
    check(config, &action_box, None, dynamics.act_dim())?;
    let controller = || Mpc {
        dynamics,
        rules,
        config,
        action_box: &action_box,
        plans: HashMap::new(),
    };
    Ok(evaluate_controlled(&controller, evaluation, cancel)?)
}
