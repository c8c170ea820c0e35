//! Checkpoints of the neural SDE's fit, one at every validation, so that a
//! long fit (fit-model's default is 20 000 steps) survives being stopped: the
//! model now and at its best validation NLL (weights, and each one's
//! constants: spec, scales and config, whose h bias the fit recalibrates),
//! Adam's moments by module path, the generator's position, the early-stopping
//! counters and the records. Written like the policy's checkpoints
//! (`step-NNNNNNN/` under a temporary name, fsynced, renamed, then `LATEST`).

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use super::ArtifactError;
use super::dynamics::fill_older_sde_fields;
use super::fit_checkpoint::{FitFiles, read_fit_files, write_fit_files};
use super::json_file::{read_versioned_json_filled, write_json};
use super::sac_state::{RngState, save_checkpoint_dir};
use super::tensors::{NamedTensors, load_tensors};
use crate::infer::Kernel;
use crate::nn::seeded_init;
use crate::sde::{
    DynamicsSpec, FitConfig, FitRecord, NeuralSde, PhysicalScales, SdeConfig, SdeFitState,
};

pub const SDE_CHECKPOINT_SCHEMA_VERSION: u32 = 1;
const STATE: &str = "state.json";

/// `state.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct CheckpointState {
    schema_version: u32,
    fit: FitConfig,
    spec: DynamicsSpec,
    scales: PhysicalScales,
    current_config: SdeConfig,
    best_config: SdeConfig,
    step: usize,
    records: Vec<FitRecord>,
    best_nll: f32,
    best_step: usize,
    evals_without_improvement: usize,
    rng: RngState,
    #[serde(flatten)]
    files: FitFiles,
}

/// Saves `state` of a fit with `fit` as the newest checkpoint in `dir`.
pub fn save_sde_checkpoint(
    dir: &Path,
    fit: &FitConfig,
    state: &SdeFitState,
) -> Result<PathBuf, ArtifactError> {
    let name = format!("step-{:07}", state.step);
    save_checkpoint_dir(dir, &name, |tmp| {
        let files = write_fit_files(tmp, &state.current, &state.best, &state.adam)?;
        let c = &state.current.constants;
        write_json(
            &tmp.join(STATE),
            &CheckpointState {
                schema_version: SDE_CHECKPOINT_SCHEMA_VERSION,
                fit: fit.clone(),
                spec: c.spec.clone(),
                scales: c.scales.clone(),
                current_config: c.config.clone(),
                best_config: state.best.constants.config.clone(),
                step: state.step,
                records: state.records.clone(),
                best_nll: state.best_nll,
                best_step: state.best_step,
                evals_without_improvement: state.evals_without_improvement,
                rng: RngState::of(&state.rng),
                files,
            },
        )
    })
}

/// Loads checkpoint directory `checkpoint`, refusing one written by a fit
/// with other settings (its step cap aside, which a resume may raise).
pub fn load_sde_checkpoint(
    checkpoint: &Path,
    fit: &FitConfig,
    device: &Device,
) -> Result<SdeFitState, ArtifactError> {
    let state: CheckpointState = read_versioned_json_filled(
        &checkpoint.join(STATE),
        SDE_CHECKPOINT_SCHEMA_VERSION,
        |value| fill_older_sde_fields(value, &["/current_config", "/best_config"], &["/fit"]),
    )?;
    // Either kernel continues the other's fit: the same loss, draws and Adam.
    let uncapped = |c: &FitConfig| FitConfig {
        max_steps: 0,
        kernel: Kernel::Fused,
        ..c.clone()
    };
    if uncapped(&state.fit) != uncapped(fit) {
        return Err(ArtifactError::Invalid(format!(
            "{}: written by a fit with other settings; start afresh or fit with those",
            checkpoint.display()
        )));
    }
    let tensors = read_fit_files(checkpoint, &state.files)?;
    let model = |weights: &NamedTensors, config: &SdeConfig| -> Result<NeuralSde, ArtifactError> {
        let skeleton = seeded_init(device, 0, || {
            NeuralSde::init(
                state.spec.clone(),
                state.scales.clone(),
                config.clone(),
                device,
            )
        });
        load_tensors(skeleton, weights, device)
    };
    let current = model(&tensors.current, &state.current_config)?;
    let best = model(&tensors.best, &state.best_config)?;
    Ok(SdeFitState {
        step: state.step,
        records: state.records,
        current,
        best,
        best_nll: state.best_nll,
        best_step: state.best_step,
        evals_without_improvement: state.evals_without_improvement,
        adam: tensors.adam,
        rng: state.rng.restore(),
    })
}
