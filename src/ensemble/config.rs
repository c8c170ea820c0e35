//! Every knob of the ensemble and its fit; defaults are MOPO's as
//! OfflineRL-Kit sets them (`EnsembleDynamicsModel`, `EnsembleDynamics.train`).

use burn::config::Config;

use super::EnsembleError;

#[derive(Config, Debug, PartialEq)]
pub struct EnsembleConfig {
    /// Members trained (MOPO: 7).
    #[config(default = 7)]
    pub members: usize,
    /// Members kept for prediction, those with the lowest holdout error (MOPO: 5).
    #[config(default = 5)]
    pub elites: usize,
    /// Hidden layers of each member (swish; MOPO: 4×200).
    #[config(default = "vec![200, 200, 200, 200]")]
    pub hidden: Vec<usize>,
    /// L2 coefficient of each layer's weights, hidden layers then the output
    /// (OfflineRL-Kit: 2.5e-5, 5e-5, 7.5e-5, 7.5e-5, 1e-4), as `coef·‖W‖²/2`.
    #[config(default = "vec![2.5e-5, 5e-5, 7.5e-5, 7.5e-5, 1e-4]")]
    pub weight_decay: Vec<f64>,
    #[config(default = 1e-3)]
    pub learning_rate: f64,
    #[config(default = 256)]
    pub batch_size: usize,
    /// The holdout is min(fraction·n, max_holdout) transitions (20 %, 1000).
    #[config(default = 0.2)]
    pub holdout_fraction: f64,
    #[config(default = 1000)]
    pub max_holdout: usize,
    /// Stop after this many epochs in which no member's holdout error improved.
    #[config(default = 5)]
    pub max_epochs_since_update: usize,
    /// The relative holdout improvement that counts (OfflineRL-Kit: 1 %).
    #[config(default = 0.01)]
    pub min_improvement: f64,
    /// Weight of the learned log-variance bounds' loss, coef·(Σ max − Σ min).
    #[config(default = 0.01)]
    pub logvar_loss_coef: f64,
    /// Initial upper and lower log-variance bounds (OfflineRL-Kit: 0.5, −10).
    #[config(default = 0.5)]
    pub max_logvar_init: f32,
    #[config(default = -10.0)]
    pub min_logvar_init: f32,
    /// A cap on epochs (None: until the holdout stops improving).
    pub max_epochs: Option<usize>,
    #[config(default = 0)]
    pub seed: u64,
}

impl EnsembleConfig {
    /// Checks every knob before any work starts.
    pub fn validate(&self) -> Result<(), EnsembleError> {
        let fail = |m: String| Err(EnsembleError::Config(m));
        if self.members == 0 || self.elites == 0 || self.elites > self.members {
            return fail(format!(
                "elites must be between 1 and the {} members, got {}",
                self.members, self.elites
            ));
        }
        if self.weight_decay.len() != self.hidden.len() + 1 {
            return fail(format!(
                "weight_decay needs one coefficient per layer ({} hidden + output), got {}",
                self.hidden.len(),
                self.weight_decay.len()
            ));
        }
        if self.hidden.contains(&0) || self.batch_size == 0 {
            return fail("hidden sizes and batch_size must be at least 1".into());
        }
        if !(self.holdout_fraction > 0.0 && self.holdout_fraction < 1.0) || self.max_holdout == 0 {
            return fail(format!(
                "holdout_fraction must lie in (0, 1) and max_holdout be at least 1, got {} and {}",
                self.holdout_fraction, self.max_holdout
            ));
        }
        if self.max_logvar_init <= self.min_logvar_init {
            return fail("max_logvar_init must exceed min_logvar_init".into());
        }
        Ok(())
    }
}
