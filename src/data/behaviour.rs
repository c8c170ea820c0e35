//! Behaviour levels of the benchmarks' datasets (Appendix C.1) and how a
//! level's checkpoint is picked from an online SAC run's evaluations:
//!
//! - D4RL: `expert` is the converged policy (here the run's best evaluation),
//!   `medium` an early-stopped one at about a third of the expert's return;
//! - NeoRL: `low`, `medium`, `high` at about 25 %, 50 % and 75 % of the
//!   expert's return.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::DataError;

/// A behaviour policy's level.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum BehaviourLevel {
    /// D4RL's medium: about 1/3 of the expert's return.
    Medium,
    /// D4RL's expert: the run's best evaluation.
    Expert,
    /// NeoRL's low: about 25 % of the expert's return.
    NeorlLow,
    /// NeoRL's medium: about 50 %.
    NeorlMedium,
    /// NeoRL's high: about 75 %.
    NeorlHigh,
}

impl BehaviourLevel {
    pub const ALL: [BehaviourLevel; 5] = [
        Self::Medium,
        Self::Expert,
        Self::NeorlLow,
        Self::NeorlMedium,
        Self::NeorlHigh,
    ];

    /// The fraction of the expert's return the level aims at.
    pub fn fraction(self) -> f64 {
        match self {
            Self::Medium => 1.0 / 3.0,
            Self::Expert => 1.0,
            Self::NeorlLow => 0.25,
            Self::NeorlMedium => 0.5,
            Self::NeorlHigh => 0.75,
        }
    }

    pub fn as_str(self) -> &'static str {
        match self {
            Self::Medium => "medium",
            Self::Expert => "expert",
            Self::NeorlLow => "neorl-low",
            Self::NeorlMedium => "neorl-medium",
            Self::NeorlHigh => "neorl-high",
        }
    }
}

impl fmt::Display for BehaviourLevel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for BehaviourLevel {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|l| l.as_str() == s)
            .ok_or_else(|| {
                let known: Vec<&str> = Self::ALL.iter().map(|l| l.as_str()).collect();
                format!(
                    "unknown behaviour level `{s}` (known: {})",
                    known.join(", ")
                )
            })
    }
}

/// The checkpoint picked for a level.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BehaviourPick {
    pub step: usize,
    /// Its evaluation's mean return.
    pub mean_return: f64,
    /// The level's fraction of the expert's return.
    pub target_return: f64,
    /// The expert's return the target is a fraction of.
    pub expert_return: f64,
    /// The episodes of the evaluations picked on, where the policies were
    /// evaluated again (`collect select --episodes`); none: the run's own.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub evaluation_episodes: Option<usize>,
}

/// How far from its target a level's checkpoint may be by default, as a
/// fraction of the expert's return.
pub const LEVEL_TOLERANCE: f64 = 0.1;

/// Picks `level`'s checkpoint from a run's `(step, evaluation return)` pairs:
/// the expert is the best return; a lower level is the checkpoint up to the
/// expert's whose return is nearest its target, within `tolerance` × the
/// expert's return, the earliest among equals (early stopping).
pub fn select_behaviour(
    returns: &[(usize, f64)],
    level: BehaviourLevel,
    tolerance: f64,
) -> Result<BehaviourPick, DataError> {
    let evaluated = returns.iter().filter(|(_, r)| r.is_finite());
    let Some(&(expert_step, expert_return)) =
        evaluated
            .clone()
            .fold(None, |best: Option<&(usize, f64)>, p| match best {
                Some(b) if b.1 >= p.1 => Some(b),
                _ => Some(p),
            })
    else {
        return Err(DataError::Behaviour(
            "the run has no evaluated checkpoint".into(),
        ));
    };
    if expert_return <= 0.0 {
        return Err(DataError::Behaviour(format!(
            "the run's best evaluation return is {expert_return:.1}; levels are fractions of a positive expert return"
        )));
    }
    let target_return = level.fraction() * expert_return;
    let pick = |step, mean_return| BehaviourPick {
        step,
        mean_return,
        target_return,
        expert_return,
        evaluation_episodes: None,
    };
    if level == BehaviourLevel::Expert {
        return Ok(pick(expert_step, expert_return));
    }
    let nearest = evaluated.filter(|(step, _)| *step <= expert_step).fold(
        None,
        |best: Option<&(usize, f64)>, p| match best {
            Some(b) if (b.1 - target_return).abs() <= (p.1 - target_return).abs() => Some(b),
            _ => Some(p),
        },
    );
    match nearest {
        Some(&(step, r)) if (r - target_return).abs() <= tolerance * expert_return => {
            Ok(pick(step, r))
        }
        Some(&(step, r)) => Err(DataError::Behaviour(format!(
            "the run never reached level {level} ({:.0} % of the expert's return {expert_return:.1} = {target_return:.1}, \
             ± {:.0} %): its nearest checkpoint is step {step} at {r:.1}",
            100.0 * level.fraction(),
            100.0 * tolerance
        ))),
        None => Err(DataError::Behaviour(format!(
            "the run has no checkpoint for level {level}"
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_are_picked_against_the_best_return_and_early_stopped() {
        // Returns climb to 3000 at step 60, dip, and pass 1000 again later.
        let run = [
            (10, 100.0),
            (20, 700.0),
            (30, 1020.0),
            (40, 1600.0),
            (50, 2200.0),
            (60, 3000.0),
            (70, 1000.0),
        ];
        let expert = select_behaviour(&run, BehaviourLevel::Expert, LEVEL_TOLERANCE).unwrap();
        assert_eq!((expert.step, expert.mean_return), (60, 3000.0));
        // A third of 3000 is 1000: step 30 (1020) is nearer than 20 (700); the
        // later 1000 at step 70 comes after the expert and is not a candidate.
        let medium = select_behaviour(&run, BehaviourLevel::Medium, LEVEL_TOLERANCE).unwrap();
        assert_eq!(medium.step, 30);
        assert!((medium.target_return - 1000.0).abs() < 1e-9);
        assert_eq!(
            select_behaviour(&run, BehaviourLevel::NeorlMedium, LEVEL_TOLERANCE)
                .unwrap()
                .step,
            40
        );
        assert_eq!(
            select_behaviour(&run, BehaviourLevel::NeorlHigh, LEVEL_TOLERANCE)
                .unwrap()
                .step,
            50
        );
    }

    #[test]
    fn a_level_the_run_never_reached_is_refused_by_name() {
        // From 100 straight to 3000: nothing near 750 (25 %) within ±300.
        let run = [(10, 100.0), (20, 3000.0)];
        let error = select_behaviour(&run, BehaviourLevel::NeorlLow, LEVEL_TOLERANCE)
            .unwrap_err()
            .to_string();
        assert!(error.contains("never reached level neorl-low"), "{error}");
        assert!(error.contains("step 10"), "{error}");
        let none = select_behaviour(&[(10, f64::NAN)], BehaviourLevel::Expert, LEVEL_TOLERANCE)
            .unwrap_err();
        assert!(none.to_string().contains("no evaluated checkpoint"));
        assert!(
            "mediocre"
                .parse::<BehaviourLevel>()
                .unwrap_err()
                .contains("unknown behaviour level `mediocre`")
        );
    }
}
