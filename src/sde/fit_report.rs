//! What `fit-model` measures on a fitted model before saving it: Section
//! 4.3's truncation thresholds ε(h, α) over the whole dataset, how Σ and
//! truncation behave on the held-out trajectories, and the open-loop error
//! by horizon next to the constant-velocity baseline.

use burn::config::Config;
use burn::tensor::Device;

use super::SdeError;
use super::calibration::{CalibrationConfig, CalibrationReport, calibration_report};
use super::evaluation::{HorizonError, prediction_error};
use super::model::NeuralSde;
use super::threshold::{ThresholdConfig, ThresholdTable, compute_thresholds};
use crate::data::Dataset;

/// The post-fit report's settings; each part draws from the fit's seed.
#[derive(Config, Debug, PartialEq)]
pub struct FitReportConfig {
    pub thresholds: ThresholdConfig,
    pub calibration: CalibrationConfig,
    /// Open-loop error for horizons 1..=this on the held-out trajectories.
    #[config(default = 50)]
    pub error_horizon: usize,
    /// Held-out windows per horizon of the open-loop error.
    #[config(default = 256)]
    pub error_windows: usize,
    #[config(default = 0)]
    pub seed: u64,
}

impl FitReportConfig {
    /// The report of a fit seeded `seed`: every part draws from it.
    pub fn seeded(thresholds: ThresholdConfig, seed: u64) -> Self {
        Self::new(
            thresholds.with_seed(seed),
            CalibrationConfig::new().with_seed(seed),
        )
        .with_seed(seed)
    }

    /// Refuses settings no report can be made from, naming the field.
    pub fn validate(&self) -> Result<(), SdeError> {
        self.thresholds.validate()?;
        self.calibration.validate()?;
        if self.error_horizon == 0 || self.error_windows == 0 {
            return Err(SdeError::Config(format!(
                "fit report: error_horizon ({}) and error_windows ({}) must be at least 1",
                self.error_horizon, self.error_windows
            )));
        }
        Ok(())
    }
}

/// The post-fit measurements a model artifact records and plots.
#[derive(Debug, Clone)]
pub struct FitReport {
    /// ε(h, α) over the whole dataset (Section 4.3).
    pub thresholds: ThresholdTable,
    /// Σ's calibration and the truncation rates on the held-out trajectories.
    pub calibration: CalibrationReport,
    /// Open-loop RMSE by horizon on the held-out trajectories.
    pub horizon_errors: Vec<HorizonError>,
}

/// Measures `model`, fitted with L_sc's ball radius `radius`, on the whole
/// `dataset` and its `held_out` trajectories; `action_space` is the task's
/// action box (the calibration's random actions).
pub fn fit_report(
    model: &NeuralSde,
    dataset: &Dataset,
    held_out: &Dataset,
    radius: f32,
    action_space: &[(f32, f32)],
    config: &FitReportConfig,
    device: &Device,
) -> Result<FitReport, SdeError> {
    config.validate()?;
    let thresholds = compute_thresholds(model, dataset, &config.thresholds, device)?;
    let calibration = calibration_report(
        model,
        held_out,
        Some(&thresholds),
        radius,
        action_space,
        &config.calibration,
        device,
    )?;
    let horizon_errors = prediction_error(
        model,
        held_out,
        config.error_horizon,
        config.error_windows,
        config.seed,
        device,
    );
    Ok(FitReport {
        thresholds,
        calibration,
        horizon_errors,
    })
}
