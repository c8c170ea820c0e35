//! The narrow policy interface: actions for a batch of states.
//!
//! Everything that runs a policy (the MuJoCo evaluator, model rollouts, the
//! server) goes through [`BatchPolicy`], so the kernel behind it can change
//! without touching its callers.

use rand::{Rng, RngCore};

use crate::shared::{BatchPolicy, act_batch};

/// Actions drawn uniformly from the task's action box, ignoring the state: the
/// baseline behind D4RL's "random" datasets and the 0 of normalised scores.
#[derive(Debug, Clone)]
pub struct RandomPolicy {
    obs_dim: usize,
    low: Vec<f32>,
    high: Vec<f32>,
}

impl RandomPolicy {
    /// A uniform policy over `[low[i], high[i]]` for each action dimension `i`.
    pub fn new(obs_dim: usize, low: Vec<f32>, high: Vec<f32>) -> Self {
        debug_assert_eq!(low.len(), high.len());
        Self { obs_dim, low, high }
    }
}

impl BatchPolicy for RandomPolicy {
    fn obs_dim(&self) -> usize {
        self.obs_dim
    }

    fn act_dim(&self) -> usize {
        self.low.len()
    }

    fn act(&self, observations: &[f32], rng: &mut dyn RngCore) -> Vec<f32> {
        let batch = act_batch(self, observations);
        let mut actions = Vec::with_capacity(batch * self.act_dim());
        for _ in 0..batch {
            for (low, high) in self.low.iter().zip(&self.high) {
                actions.push(low + (high - low) * rng.random::<f32>());
            }
        }
        actions
    }
}
