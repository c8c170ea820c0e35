//! Scoring candidate action sequences: each rolled open-loop from its start
//! state through the model with `particles` samples (mbrl-lib's
//! `evaluate_action_sequences`: particle p of candidate c is row c·P + p, a
//! particle's rewards stop where its task says it fell), then reduced to one
//! score per candidate. The rollout is the one the policy loop and the
//! server's `rollout` run (`agent::rollout_model`), without its trace, in
//! [`score_groups`](super::score_groups): several callers may share its steps.

use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use super::PlanningError;
use super::score_groups::{ScoreGroup, Tally, score_groups};
use crate::agent::StepOutcome;
use crate::envs::Rules;
use crate::shared::{BatchDynamics, Cancel};

/// How candidates are rolled and scored.
#[derive(Debug, Clone, PartialEq)]
pub struct ScoreConfig {
    /// H, the steps of every candidate.
    pub horizon: usize,
    /// Samples of each candidate's trajectory.
    pub particles: usize,
    /// γ of the returns: step t's reward weighs γ^t.
    pub discount: f64,
    /// λ of the penalised return, Σ γ^t (r_t − λ·η_t).
    pub penalty: f64,
    /// The share α of a candidate's particles whose returns the CVaR averages:
    /// its worst ⌈α·P⌉ (risk-averse); `None` leaves the CVaR out.
    pub cvar_alpha: Option<f64>,
    /// ε(H, α): a particle stops before the step that takes its accumulated η
    /// above this; its return is what it earned before. `None` never truncates.
    pub threshold: Option<f32>,
    /// Multiplies the model's noise (1 samples Σ, 0 follows the drift).
    pub noise_scale: f32,
    /// The caller's own terms in each step's reward (none: the model's reward).
    pub cost: Cost,
}

/// A caller's quadratic costs on the observations a candidate reaches, added
/// to the model's reward or replacing it: each kept step t is rewarded
/// r_t − Σ_k w_k (s'_{t,k} − target_k)², or without the reward only the sum's
/// negative (the parametrised reward mbrl-lib users write a function for).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Cost {
    pub terms: Vec<CostTerm>,
    /// Score on the costs alone, leaving the model's reward out.
    pub replace_reward: bool,
}

/// weight · (s'_dimension − target)².
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CostTerm {
    /// Which observation, 0-based.
    pub dimension: usize,
    pub target: f32,
    pub weight: f32,
}

impl Cost {
    /// A kept step's reward: the model's `reward` less the costs at its next
    /// observation `next`.
    pub(super) fn reward(&self, reward: f32, next: &[f32]) -> f64 {
        let cost: f64 = (self.terms.iter())
            .map(|t| {
                let miss = f64::from(next[t.dimension]) - f64::from(t.target);
                f64::from(t.weight) * miss * miss
            })
            .sum();
        if self.replace_reward {
            -cost
        } else {
            f64::from(reward) - cost
        }
    }
}

/// One candidate's score, over its particles.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct CandidateScore {
    /// Mean over particles of Σ γ^t r_t.
    pub mean_return: f64,
    /// Mean over particles of Σ γ^t (r_t − λ·η_t).
    pub penalized_return: f64,
    /// Mean of the worst ⌈α·P⌉ particles' returns, when α was asked for.
    pub cvar_return: Option<f64>,
    /// Mean over particles of Σ η_t along the steps kept.
    pub accumulated_eta: f64,
    /// The largest η any particle met at a step it took.
    pub max_eta: f64,
    /// The first step (0-based) at which a particle's accumulated η passed
    /// ε(H, α) and the step was dropped; `None` if none did.
    pub truncated_at: Option<usize>,
    /// The share of particles whose task rules ended them (the robot fell).
    pub terminated: f64,
    /// The share of particles whose model state stopped being finite.
    pub diverged: f64,
}

/// The sequences to score and where they start.
#[derive(Debug, Clone, Copy)]
pub struct Candidates<'a> {
    /// Start states, `[B, obs_dim]`.
    pub starts: &'a [f32],
    /// `[B, per_start, H, act_dim]`: each start's candidates.
    pub sequences: &'a [f32],
    pub per_start: usize,
}

/// Scores every candidate from its start state; the answer is
/// `[B, per_start]`, row-major.
pub fn score_sequences(
    dynamics: &dyn BatchDynamics,
    rules: &Rules,
    candidates: &Candidates,
    config: &ScoreConfig,
    rng: &mut ChaCha8Rng,
    cancel: &Cancel,
) -> Result<Vec<CandidateScore>, PlanningError> {
    let group = ScoreGroup {
        candidates: *candidates,
        config,
        rng,
        cancel,
    };
    let mut scores = score_groups(dynamics, rules, vec![group]);
    scores.pop().expect("one group, one answer")
}

/// One candidate's score from its particles' tallies.
pub(super) fn score_particles(particles: &[Tally], config: &ScoreConfig) -> CandidateScore {
    let n = particles.len() as f64;
    let mean = |value: fn(&Tally) -> f64| particles.iter().map(value).sum::<f64>() / n;
    let share = |o: StepOutcome| particles.iter().filter(|p| p.outcome == o).count() as f64 / n;
    let returns: Vec<f64> = particles.iter().map(|p| p.discounted_return).collect();
    CandidateScore {
        mean_return: mean(|p| p.discounted_return),
        penalized_return: mean(|p| p.penalized_return),
        cvar_return: config.cvar_alpha.map(|alpha| lower_cvar(&returns, alpha)),
        accumulated_eta: mean(|p| p.eta_sum),
        max_eta: particles.iter().map(|p| p.max_eta).fold(0.0, f64::max),
        truncated_at: (particles.iter())
            .filter(|p| p.outcome == StepOutcome::Truncated)
            .map(|p| p.kept)
            .min(),
        terminated: share(StepOutcome::Terminal),
        diverged: share(StepOutcome::Diverged),
    }
}

/// The mean of the lowest ⌈α·n⌉ of `values` (α in (0, 1]).
fn lower_cvar(values: &[f64], alpha: f64) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let k = ((alpha * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[..k].iter().sum::<f64>() / k as f64
}

pub(super) fn check(
    starts: &[f32],
    sequences: &[f32],
    candidates: usize,
    config: &ScoreConfig,
    (obs_dim, act_dim): (usize, usize),
) -> Result<(), PlanningError> {
    let invalid = |message: String| Err(PlanningError::Invalid(message));
    if config.horizon == 0 || config.particles == 0 || candidates == 0 {
        return invalid("horizon, particles and candidates must each be at least 1".into());
    }
    if starts.is_empty() || !starts.len().is_multiple_of(obs_dim) {
        return invalid(format!(
            "starts hold {} values, not rows of {obs_dim}",
            starts.len()
        ));
    }
    let expected = starts.len() / obs_dim * candidates * config.horizon * act_dim;
    if sequences.len() != expected {
        return invalid(format!(
            "sequences hold {} values; {} starts × {candidates} candidates × {} steps × {act_dim} \
             actions are {expected}",
            sequences.len(),
            starts.len() / obs_dim,
            config.horizon
        ));
    }
    if !(config.discount > 0.0 && config.discount <= 1.0) {
        return invalid(format!("discount {} is not in (0, 1]", config.discount));
    }
    if !(config.penalty.is_finite() && config.penalty >= 0.0) {
        return invalid(format!("penalty {} is not a number ≥ 0", config.penalty));
    }
    if config.cvar_alpha.is_some_and(|a| !(a > 0.0 && a <= 1.0)) {
        return invalid(format!(
            "cvar_alpha {:?} is not in (0, 1]",
            config.cvar_alpha
        ));
    }
    if !(config.noise_scale.is_finite() && config.noise_scale >= 0.0) {
        return invalid(format!(
            "noise_scale {} is not a number ≥ 0",
            config.noise_scale
        ));
    }
    for (i, term) in config.cost.terms.iter().enumerate() {
        if term.dimension >= obs_dim {
            return invalid(format!(
                "cost term {i}: observation {} is past the model's {obs_dim}",
                term.dimension
            ));
        }
        if !(term.target.is_finite() && term.weight.is_finite() && term.weight >= 0.0) {
            return invalid(format!(
                "cost term {i}: target {} and weight {} must be finite, the weight ≥ 0",
                term.target, term.weight
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lower_cvar_averages_the_worst_share() {
        let returns = [4.0, -1.0, 2.0, 10.0, 0.0];
        // ⌈0.4·5⌉ = 2 worst: −1 and 0.
        assert_eq!(lower_cvar(&returns, 0.4), -0.5);
        assert_eq!(lower_cvar(&returns, 0.01), -1.0);
        assert_eq!(lower_cvar(&returns, 1.0), 3.0);
    }
}
