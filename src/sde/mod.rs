//! The neural SDE of NUNO (Section 4.1–4.2, Appendix B–C): physics-structured
//! drift, aleatoric plus distance-aware diffusion, the η losses, fitting by the
//! NLL of Euler–Maruyama rollouts, and the CVaR truncation thresholds.

mod batch;
mod config;
mod device;
mod eta;
mod eta_report;
mod evaluation;
mod fit;
mod losses;
mod model;
mod rollout;
mod spec;
mod threshold;

pub use batch::{BatchDynamics, ModelStep};
pub use config::{FitConfig, LossConfig, SdeConfig};
pub use device::ComputeDevice;
pub use eta::{DistanceAware, EtaLosses, FarField};
pub use eta_report::{EtaComparison, EtaReport, EtaReportConfig, auroc, eta_report};
pub use evaluation::{HorizonError, prediction_error};
pub use fit::{FitRecord, FitSummary, fit, fit_eta, validation_nll, window_tensors};
pub use losses::{LossTerms, WindowTensors};
pub use model::{NeuralSde, SdeConstants, SdeTerms};
pub use rollout::{OpenLoop, OpenLoopRollout};
pub use spec::{DynamicsSpec, PhysicalScales};
pub use threshold::{ThresholdConfig, ThresholdTable, accumulated_eta, compute_thresholds, cvar};

/// Everything that can go wrong building, fitting, saving or loading a model.
#[derive(Debug, thiserror::Error)]
pub enum SdeError {
    #[error("invalid dynamics spec: {0}")]
    Spec(String),
    #[error("invalid {0}")]
    Config(String),
    #[error(transparent)]
    Data(#[from] crate::data::DataError),
}
