//! Normalised scores: `100 · (R − R_random) / (R_expert − R_random)`, D4RL's
//! `get_normalized_score`, with D4RL's reference returns (and NUNO's for NeoRL).

use serde::{Deserialize, Serialize};

/// The returns that map to a score of 0 (random) and 100 (expert).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ScoreReference {
    pub random: f64,
    pub expert: f64,
}

impl ScoreReference {
    /// The normalised score of an episode return, in percent.
    pub fn normalize(&self, episode_return: f64) -> f64 {
        100.0 * (episode_return - self.random) / (self.expert - self.random)
    }
}
