//! Planning next to the model: candidate action sequences scored in it (the
//! one number per candidate a sampling planner needs), with η's penalty, a
//! CVaR over particles and ε(H, α)'s truncation; and the sampling planners
//! (CEM, MPPI) that search over those scores.

mod plan;
mod score;

pub use plan::{
    CemConfig, MppiConfig, Optimizer, Plan, PlanConfig, PlanStart, objective, plan, shifted,
};
pub use score::{CandidateScore, Candidates, ScoreConfig, score_sequences};

/// What a planning request got wrong.
#[derive(Debug, thiserror::Error)]
pub enum PlanningError {
    #[error("{0}")]
    Invalid(String),
    #[error(transparent)]
    Cancelled(#[from] crate::shared::Cancelled),
}
