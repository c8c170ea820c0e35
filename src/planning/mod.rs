//! Planning next to the model: candidate action sequences scored in it (the
//! one number per candidate a sampling planner needs), with η's penalty, a
//! CVaR over particles and ε(H, α)'s truncation; and the sampling planners
//! (CEM, iCEM, MPPI) that search over those scores; model-predictive control with
//! them in the real task.

mod colored_noise;
mod mpc;
mod plan;
mod score;
mod score_groups;

pub use mpc::evaluate_mpc;
pub use plan::{
    CemConfig, IcemConfig, MppiConfig, Optimizer, Plan, PlanBudget, PlanConfig, PlanStart, Planner,
    PlannerSettings, objective, plan, shifted,
};
pub use score::{CandidateScore, Candidates, Cost, CostTerm, ScoreConfig, score_sequences};
pub use score_groups::{ScoreGroup, score_groups};

/// What a planning request got wrong.
#[derive(Debug, thiserror::Error)]
pub enum PlanningError {
    #[error("{0}")]
    Invalid(String),
    #[error(transparent)]
    Cancelled(#[from] crate::shared::Cancelled),
    /// The real task MPC runs in.
    #[error(transparent)]
    Env(#[from] crate::envs::EnvError),
}
