//! The task's known reward and termination, as functions of observations: what
//! model rollouts use in place of the simulator (NUNO without a reward model;
//! MOPO's `termination_fn`, written here from Gymnasium's own rules).
//!
//! The forward reward is Gymnasium's finite difference `(x' − x)/dt` where the
//! observations hold the root x (NeoRL's layout, as NUNO's code does); D4RL's
//! observations omit it, so there the observed root x velocity after the step
//! stands in (see docs/paper-map.md, deviations). A run may read that velocity
//! on NeoRL's observations too ([`RootXReward::Velocity`], an ablation).

use std::sync::Arc;

use super::EnvError;
use super::mujoco_task::{MujocoTask, TaskConfig};
use super::system::{SystemReward, SystemSpec};
use super::task::{HealthRule, Task};

/// Which observed root x velocity stands in for the forward velocity where the
/// observations omit root x (D4RL's layout).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ForwardVelocity {
    /// The velocity after the step (nuno's paper recipe).
    #[default]
    Next,
    /// The mean of the velocities before and after the step, as NUNO's code's
    /// known rewards (`static_fns/hopper.py`, walker2d and halfcheetah alike).
    Mean,
}

crate::shared::named_enum!(ForwardVelocity, "forward velocity", ForwardVelocity::Next => "next", ForwardVelocity::Mean => "mean");

/// What the forward reward reads where the observations hold root x (NeoRL's layout).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RootXReward {
    /// `(x' − x)/dt` of the observed root x: Gymnasium's, the NeoRL data's own
    /// and NUNO's code's.
    #[default]
    Difference,
    /// The observed root x velocity, as [`ForwardVelocity`] picks it: a model's
    /// noise in x then reaches the reward without the 1/dt (125 on walker2d)
    /// the difference multiplies it by.
    Velocity,
}

crate::shared::named_enum!(RootXReward, "root x reward", RootXReward::Difference => "difference", RootXReward::Velocity => "velocity");

/// Reward and termination of one task variant, on observations.
#[derive(Debug, Clone, PartialEq)]
pub struct TaskRules {
    task: Task,
    /// The first qpos entry the observations hold (observation 0).
    qpos_from: usize,
    /// Observation index of qvel[0], the root x velocity.
    x_velocity: usize,
    /// Observation index of qpos[0], the root x, where it is observed.
    root_x: Option<usize>,
    /// The task's dt between observations.
    dt: f64,
    /// The velocity the reward reads where root x is not observed.
    forward_velocity: ForwardVelocity,
    /// Whether the reward reads root x's difference or a velocity where root x is observed.
    root_x_reward: RootXReward,
}

impl TaskRules {
    /// Seconds between two observations the rules are applied to.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// The rules of `task` with its own observation split and step (what a
    /// model that steps once per task step, like an ensemble, follows).
    pub fn of_task(task: &TaskConfig) -> Result<Self, EnvError> {
        let dt = MujocoTask::new(task)?.dt();
        Ok(Self::new(task, dt))
    }

    /// The rules of `task`, whose observations are `dt` apart.
    pub fn new(task: &TaskConfig, dt: f64) -> Self {
        let spec = task.task.spec();
        let qpos_from = task.layout.qpos_from(spec);
        Self {
            x_velocity: spec.nq - qpos_from,
            root_x: task.observes_root_x().then_some(0),
            qpos_from,
            task: task.task.clone(),
            dt,
            forward_velocity: ForwardVelocity::Next,
            root_x_reward: RootXReward::Difference,
        }
    }

    /// These rules with the forward reward read from `velocity` where root x is
    /// not observed, or where [`RootXReward::Velocity`] asks for it.
    pub fn with_forward_velocity(&self, velocity: ForwardVelocity) -> Self {
        Self {
            forward_velocity: velocity,
            ..self.clone()
        }
    }

    /// These rules with the forward reward read as `reward` says where root x
    /// is observed (D4RL's layout observes no root x: unchanged there).
    pub fn with_root_x_reward(&self, reward: RootXReward) -> Self {
        Self {
            root_x_reward: reward,
            ..self.clone()
        }
    }

    /// Root x's observation index where the reward reads its difference.
    fn differenced_root_x(&self) -> Option<usize> {
        self.root_x
            .filter(|_| self.root_x_reward == RootXReward::Difference)
    }

    /// `r(s, a, s')`: forward velocity, healthy bonus (paid on every step, as in
    /// Gymnasium v4) and control cost.
    pub fn reward(&self, obs: &[f32], action: &[f32], next_obs: &[f32]) -> f32 {
        let spec = self.task.spec();
        let control: f64 = action.iter().map(|&a| f64::from(a).powi(2)).sum();
        let after = f64::from(next_obs[self.x_velocity]);
        let velocity = match (self.differenced_root_x(), self.forward_velocity) {
            (Some(x), _) => (f64::from(next_obs[x]) - f64::from(obs[x])) / self.dt,
            (None, ForwardVelocity::Next) => after,
            (None, ForwardVelocity::Mean) => 0.5 * (f64::from(obs[self.x_velocity]) + after),
        };
        let forward = spec.forward_reward_weight * velocity;
        (forward + spec.healthy_reward - spec.ctrl_cost_weight * control) as f32
    }

    /// Whether `next_obs` is a terminal state (the robot fell).
    pub fn terminal(&self, next_obs: &[f32]) -> bool {
        !self.task.spec().health.is_healthy(next_obs, self.qpos_from)
    }

    /// The task's own clip of its observed velocities (Gymnasium's Hopper and
    /// Walker2d clip qvel to ±10), over the observation's qvel entries; `None`
    /// where the task observes them unclipped (HalfCheetah).
    pub fn observation_clip(&self) -> Option<ObservationClip> {
        (self.task.spec().velocity_clip).map(|limit| ObservationClip {
            from: self.x_velocity,
            limit: limit as f32,
        })
    }

    /// What [`reward`](Self::reward) and [`terminal`](Self::terminal) compute,
    /// as data: for writing the same rules in another form (the ONNX export).
    pub fn terms(&self) -> RuleTerms {
        let spec = self.task.spec();
        let x_velocity = self.x_velocity;
        RuleTerms {
            forward: match (self.differenced_root_x(), self.forward_velocity) {
                (Some(root_x), _) => ForwardTerm::Difference {
                    root_x,
                    dt: self.dt,
                },
                (None, ForwardVelocity::Next) => ForwardTerm::Next { x_velocity },
                (None, ForwardVelocity::Mean) => ForwardTerm::Mean { x_velocity },
            },
            forward_reward_weight: spec.forward_reward_weight,
            healthy_reward: spec.healthy_reward,
            ctrl_cost_weight: spec.ctrl_cost_weight,
            health: spec.health,
            qpos_from: self.qpos_from,
        }
    }
}

/// Observation entries `from..` clipped to `±limit`, as the task clips what
/// it observes: applied to a model's next observations, it keeps them where
/// the task's own observations can be.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ObservationClip {
    pub from: usize,
    pub limit: f32,
}

impl ObservationClip {
    /// Clips `observation` in place; a non-finite entry stays as it is, so a
    /// diverged step still reads as diverged.
    pub fn apply(&self, observation: &mut [f32]) {
        for x in observation.iter_mut().skip(self.from) {
            if x.is_finite() {
                *x = x.clamp(-self.limit, self.limit);
            }
        }
    }
}

/// A task's rules as data: `r = w·v + healthy − c·|a|²`, terminal where
/// `health` fails on the observation (whose entry 0 is qpos[`qpos_from`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RuleTerms {
    pub forward: ForwardTerm,
    pub forward_reward_weight: f64,
    pub healthy_reward: f64,
    pub ctrl_cost_weight: f64,
    pub health: HealthRule,
    pub qpos_from: usize,
}

/// Where the forward velocity v of the reward is read, by observation index.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ForwardTerm {
    /// `(x' − x)/dt` of the observed root x.
    Difference { root_x: usize, dt: f64 },
    /// The root x velocity after the step.
    Next { x_velocity: usize },
    /// The mean of the root x velocities before and after the step.
    Mean { x_velocity: usize },
}

/// Reward and termination on observations, of a built-in task or of a
/// system described in a file: what model rollouts and the server apply to
/// each sampled transition.
#[derive(Debug, Clone)]
pub enum Rules {
    Task(TaskRules),
    System(Arc<SystemSpec>),
}

impl From<TaskRules> for Rules {
    fn from(rules: TaskRules) -> Self {
        Self::Task(rules)
    }
}

impl Rules {
    /// Seconds between two observations the rules are applied to.
    pub fn dt(&self) -> f64 {
        match self {
            Self::Task(rules) => rules.dt(),
            Self::System(system) => system.dt,
        }
    }

    /// A task's rules with the forward reward read from `velocity` where it
    /// reads a velocity, and from root x as `root_x` says where root x is
    /// observed (see [`TaskRules::with_forward_velocity`] and
    /// [`TaskRules::with_root_x_reward`]); a file's system has its own reward.
    pub fn with_forward_reward(&self, velocity: ForwardVelocity, root_x: RootXReward) -> Self {
        match self {
            Self::Task(rules) => Self::Task(
                rules
                    .with_forward_velocity(velocity)
                    .with_root_x_reward(root_x),
            ),
            Self::System(_) => self.clone(),
        }
    }

    /// Whether the reward is the model's to learn (a system whose file says
    /// `learned = true`): then [`Rules::reward`] is never asked, since a
    /// model of such a system learns it (checked where the two meet).
    pub fn learned_reward(&self) -> bool {
        matches!(self, Self::System(system) if matches!(system.reward, SystemReward::Learned))
    }

    /// `r(s, a, s')` of one transition (NaN where the reward is learned).
    pub fn reward(&self, obs: &[f32], action: &[f32], next_obs: &[f32]) -> f32 {
        match self {
            Self::Task(rules) => rules.reward(obs, action, next_obs),
            Self::System(system) => match &system.reward {
                SystemReward::Expression(expression) => expression.reward(obs, action, next_obs),
                SystemReward::Learned => f32::NAN,
            },
        }
    }

    /// The task's own observation clip ([`TaskRules::observation_clip`]); a
    /// file's system observes what its model predicts, unclipped.
    pub fn observation_clip(&self) -> Option<ObservationClip> {
        match self {
            Self::Task(rules) => rules.observation_clip(),
            Self::System(_) => None,
        }
    }

    /// Whether `next_obs` is a terminal state.
    pub fn terminal(&self, next_obs: &[f32]) -> bool {
        match self {
            Self::Task(rules) => rules.terminal(next_obs),
            Self::System(system) => system.terminated(next_obs),
        }
    }
}
