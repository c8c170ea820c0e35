//! MOBILE (Sun et al., 2023, OfflineRL-Kit's `mobile.py`): MOPO's ensemble
//! and SAC loop with no reward penalty at rollout time; instead every critic
//! update lowers the model rows' rewards by the Bellman inconsistency over the
//! ensemble's elites, measured with the current target critics:
//!
//! ```text
//! u(s, a) = Std_e[(1/M)·Σ_k min_j Q̄_j(s'_{e,k}, ã'_{e,k})],  s'_{e,k} ~ N(μ_e, σ_e), ã' ~ π(·|s')
//! y = max(0, r − β·u(s, a) + γ(1 − d)·min_j Q̄_j(s', ã'))     (real rows: u = 0)
//! ```
//!
//! Std is the unbiased one over the elites (torch's default); the target's
//! deterministic backup and floor are [`super::SacConfig`]'s.

use burn::config::Config;
use rand_chacha::ChaCha8Rng;

use crate::ensemble::EnsembleDynamics;
use crate::shared::{BatchDynamics, TransitionBatch};

/// MOBILE's penalty term (OfflineRL-Kit's `penalty_coef`, `num_samples`).
#[derive(Config, Debug, PartialEq)]
pub struct BellmanPenalty {
    /// β, the penalty's weight (per task: `MOBILE_PRESETS`).
    pub beta: f64,
    /// M, next states sampled from each elite.
    #[config(default = 10)]
    pub samples: usize,
}

impl BellmanPenalty {
    /// Lowers the rewards of `batch`'s rows from `first_model_row` on (the
    /// model's; the real rows before them keep theirs) by β·u(s, a), where
    /// `target_values` gives min_j Q̄_j(s', ã') at sampled ã' for a block of
    /// next observations. Returns the mean u over the model rows.
    pub fn penalize(
        &self,
        batch: &mut TransitionBatch,
        first_model_row: usize,
        ensemble: &EnsembleDynamics,
        target_values: &mut dyn FnMut(&[f32], &mut ChaCha8Rng) -> Vec<f32>,
        rng: &mut ChaCha8Rng,
    ) -> f32 {
        let rows = batch.rewards.len() - first_model_row;
        if rows == 0 {
            return 0.0;
        }
        let (o, a) = (ensemble.obs_dim(), ensemble.act_dim());
        let next = ensemble.elite_next_observations(
            &batch.observations[first_model_row * o..],
            &batch.actions[first_model_row * a..],
            self.samples,
            rng,
        );
        let values = target_values(&next, rng);
        let u = bellman_inconsistency(&values, ensemble.elite_count(), self.samples);
        for (reward, u) in batch.rewards[first_model_row..].iter_mut().zip(&u) {
            *reward -= (self.beta as f32) * u;
        }
        u.iter().sum::<f32>() / rows as f32
    }
}

/// u per row from target values laid out `[elite][sample][row]`: the
/// unbiased standard deviation over elites of each elite's mean over samples
/// (0 with a single elite, where torch's would be NaN).
pub fn bellman_inconsistency(values: &[f32], elites: usize, samples: usize) -> Vec<f32> {
    let rows = values.len() / (elites * samples);
    let elite_means: Vec<Vec<f32>> = values
        .chunks_exact(samples * rows)
        .map(|elite| {
            (0..rows)
                .map(|r| (0..samples).map(|k| elite[k * rows + r]).sum::<f32>() / samples as f32)
                .collect()
        })
        .collect();
    (0..rows)
        .map(|r| {
            if elites < 2 {
                return 0.0;
            }
            let mean = elite_means.iter().map(|m| m[r]).sum::<f32>() / elites as f32;
            let squares: f32 = elite_means.iter().map(|m| (m[r] - mean).powi(2)).sum();
            (squares / (elites - 1) as f32).sqrt()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::bellman_inconsistency;

    #[test]
    fn the_inconsistency_is_the_unbiased_std_over_elites_of_sample_means() {
        // Two rows, three elites, two samples each, laid out [elite][sample][row].
        // Row 0: elite means 2, 4, 6 → mean 4, squares 4 + 0 + 4, /2 → std 2.
        // Row 1: elite means 1, 1, 1 → std 0.
        let values = [
            1.0, 0.0, 3.0, 2.0, // elite 0: sample 0 (rows 0, 1), sample 1
            4.0, 1.0, 4.0, 1.0, // elite 1
            5.0, 1.5, 7.0, 0.5, // elite 2
        ];
        let u = bellman_inconsistency(&values, 3, 2);
        assert!((u[0] - 2.0).abs() < 1e-6, "{u:?}");
        assert!(u[1].abs() < 1e-6, "{u:?}");
    }
}
