//! The MuJoCo tasks NUNO is benchmarked on (hopper, halfcheetah, walker2d with
//! D4RL-v2 semantics, and NeoRL's variant that observes root x) and Gymnasium's
//! swimmer, inverted pendulum and ant, their normalised scores, and a parallel
//! evaluator that runs a policy in them;
//! and any other system described as data (`system.rs`: names, dt, the
//! action box, eq. 8's pairs, a reward expression, termination bounds).

mod evaluator;
mod modelled_system;
mod mujoco_table;
mod mujoco_task;
mod rules;
mod score;
mod system;
mod task;

pub use evaluator::{
    EpisodeController, EvaluationConfig, EvaluationReport, evaluate, evaluate_controlled,
    evaluate_or_cancel,
};
pub use modelled_system::{System, SystemShape};
pub use mujoco_task::{MujocoTask, TaskConfig, Transition};
pub use rules::{
    ForwardTerm, ForwardVelocity, ObservationClip, RootXReward, RuleTerms, Rules, TaskRules,
};
pub use score::ScoreReference;
pub use system::{ObservationBound, RewardExpression, SystemReward, SystemSpec};
pub use task::{
    FileTask, HealthRule, Joint, JointKind, ObservationLayout, ResetNoise, StateSplit, Task,
    TaskName, TaskSpec,
};

/// Everything that can go wrong in a task or an evaluation.
#[derive(Debug, thiserror::Error)]
pub enum EnvError {
    /// A system file that cannot be read or does not describe a system.
    #[error("{}: {message}", file.display())]
    System {
        file: std::path::PathBuf,
        message: String,
    },
    #[error(
        "unknown task `{0}` (expected one of: hopper, halfcheetah, walker2d, swimmer, invertedpendulum, ant)"
    )]
    UnknownTask(String),
    #[error("MuJoCo could not build the {task} model: {message}")]
    Model { task: String, message: String },
    #[error("{what} has {got} entries, the task expects {expected}")]
    Dimension {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("{what}[{index}] is not a finite number")]
    NonFinite { what: &'static str, index: usize },
    #[error("the policy expects {policy} {what}, the task has {task}")]
    PolicyMismatch {
        what: &'static str,
        policy: usize,
        task: usize,
    },
    #[error("the policy returned {got} action values for {batch} states, expected {expected}")]
    PolicyOutput {
        batch: usize,
        expected: usize,
        got: usize,
    },
    #[error("an evaluation needs at least one episode")]
    NoEpisodes,
    /// An [`EpisodeController`] that could not act (a planner's bad setting).
    #[error("the controller could not act: {0}")]
    Controller(String),
    #[error(transparent)]
    Cancelled(#[from] crate::shared::cancel::Cancelled),
}
