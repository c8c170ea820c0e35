//! The task's known reward and termination, as functions of observations: what
//! model rollouts use in place of the simulator (NUNO without a reward model;
//! MOPO's `termination_fn`, written here from Gymnasium's own rules).
//!
//! Observations omit the root x position, so the forward reward uses the
//! observed root x velocity after the step instead of Gymnasium's finite
//! difference `(x' − x)/dt` (see docs/paper-map.md, deviations).

use super::mujoco_task::TaskConfig;
use super::task::{ObservationLayout, StateSplit, TaskSpec};

/// Reward and termination of one task variant, on observations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TaskRules {
    spec: &'static TaskSpec,
    /// Observation index of qpos[1] (root height for hopper/walker2d).
    root_z: usize,
    /// Observation index of qvel[0], the root x velocity.
    x_velocity: usize,
}

impl TaskRules {
    /// The rules of `task`, whose observations split as `split`.
    pub fn new(task: TaskConfig, split: &StateSplit) -> Self {
        let spec = task.name.spec();
        let root_z = match task.layout {
            ObservationLayout::D4rl => 0,
            ObservationLayout::Neorl => 1,
        };
        Self {
            spec,
            root_z,
            x_velocity: split.velocities[0],
        }
    }

    /// `r(s, a, s')`: forward velocity, healthy bonus (paid on every step, as in
    /// Gymnasium v4) and control cost.
    pub fn reward(&self, action: &[f32], next_obs: &[f32]) -> f32 {
        let spec = self.spec;
        let control: f64 = action.iter().map(|&a| f64::from(a).powi(2)).sum();
        let forward = spec.forward_reward_weight * f64::from(next_obs[self.x_velocity]);
        (forward + spec.healthy_reward - spec.ctrl_cost_weight * control) as f32
    }

    /// Whether `next_obs` is a terminal state (the robot fell).
    pub fn terminal(&self, next_obs: &[f32]) -> bool {
        let z = f64::from(next_obs[self.root_z]);
        let angle = f64::from(next_obs[self.root_z + 1]);
        let rest = next_obs[self.root_z + 1..].iter().map(|&x| f64::from(x));
        !self.spec.health.is_healthy(z, angle, rest)
    }
}
