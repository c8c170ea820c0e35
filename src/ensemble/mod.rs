//! Gaussian-ensemble dynamics, the model of MOPO (Yu et al., 2020) and
//! TATU+MOPO that NUNO is compared with (Table 1, Figures 4–5): N MLPs, each
//! a diagonal Gaussian over (s' − s, r) given (s, a), fitted with OfflineRL-Kit's
//! defaults; the elites predict.

mod adversarial;
mod config;
mod dynamics;
mod fit;
mod fused_trainer;
mod model;
mod trainer;

pub use adversarial::{
    AdversarialConfig, AdversarialEnsemble, AdversarialLosses, AdversarialSample,
};
pub use config::EnsembleConfig;
pub use dynamics::{EnsembleDynamics, EnsembleUncertainty};
pub use fit::{EnsembleEpoch, EnsembleFit, EnsembleFitState, Scaler, fit_ensemble};
pub use model::GaussianEnsemble;

/// Everything that can go wrong building or fitting an ensemble.
#[derive(Debug, thiserror::Error)]
pub enum EnsembleError {
    #[error("ensemble: {0}")]
    Config(String),
    /// What the caller's per-epoch hook (a checkpoint's writer) reported.
    #[error("ensemble checkpoint: {0}")]
    Checkpoint(String),
}
