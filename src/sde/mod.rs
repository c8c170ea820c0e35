//! The neural SDE of NUNO (Section 4.1–4.2, Appendix B–C): physics-structured
//! drift, aleatoric plus distance-aware diffusion, the η losses, fitting by the
//! NLL of Euler–Maruyama rollouts, and the CVaR truncation thresholds.

mod batch;
mod calibration;
mod config;
mod device;
mod drift_inputs;
mod eta;
mod eta_report;
mod evaluation;
mod fit;
mod fit_report;
mod fit_step;
mod fused;
mod fused_fit;
mod losses;
mod model;
mod recipe;
mod rollout;
mod spec;
mod threshold;

pub use calibration::{
    CalibrationConfig, CalibrationReport, DiffusionAt, DimensionCalibration, HorizonCalibration,
    TruncationRate, Z_STD_BAND, calibration_report,
};
pub use config::{
    EtaLossForm, FitConfig, LikelihoodPath, LossConfig, MuForm, SCALAR_MU_FACTOR, SdeConfig,
};
pub use device::ComputeDevice;
pub(crate) use drift_inputs::DriftFeatures;
pub use drift_inputs::DriftInputs;
pub use eta::{DistanceAware, EtaLosses, FarField};
pub use eta_report::{EtaComparison, EtaReport, EtaReportConfig, auroc, eta_report};
pub use evaluation::{
    HorizonError, TaskComparison, TaskComparisonConfig, compare_with_task, prediction_error,
};
pub use fit::{
    FitRecord, FitSummary, SdeFitState, fit, fit_eta, fit_from, validation_nll, window_tensors,
};
pub use fit_report::{FitReport, FitReportConfig, fit_report};
pub use fit_step::{Gradients, StepDraws, StepLosses};
pub use fused::FusedSde;
pub use losses::{LossTerms, WindowTensors};
pub use model::{NeuralSde, SdeConstants, SdeTerms};
pub use recipe::{
    CODE_MAX_MARGIN, CODE_MODEL_BUFFER_FACTOR, CODE_STEP_DISCOUNT, Recipe, SampleNoise,
};
pub use rollout::{OpenLoop, OpenLoopRollout};
pub use spec::{DynamicsSpec, PhysicalScales};
pub use threshold::{
    ThresholdConfig, ThresholdTable, accumulated_eta, accumulated_eta_along, compute_thresholds,
    cvar, requested_threshold, window_starts_and_actions,
};

/// Everything that can go wrong building, fitting, saving or loading a model.
#[derive(Debug, thiserror::Error)]
pub enum SdeError {
    #[error("invalid dynamics spec: {0}")]
    Spec(String),
    #[error("invalid {0}")]
    Config(String),
    #[error(transparent)]
    Data(#[from] crate::data::DataError),
    /// What the caller's per-evaluation hook (a checkpoint's writer) reported.
    #[error("SDE fit checkpoint: {0}")]
    Checkpoint(String),
    /// A truncation threshold asked for that the model's table cannot give.
    #[error("{0}")]
    Threshold(String),
}
