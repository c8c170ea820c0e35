//! Checkpoints of the ensemble's fit, one per finished epoch, so that a fit to
//! convergence (MOPO's rule can take hundreds of epochs) survives being
//! stopped: the members now and at their best epochs, Adam's moments by module
//! path (either trainer resumes either's checkpoint), the history and the
//! early-stopping counters. Written like the policy's checkpoints
//! (`epoch-NNNNNN/` under a temporary name, fsynced, renamed, then `LATEST`).

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use super::ArtifactError;
use super::fit_checkpoint::{FitFiles, read_fit_files, write_fit_files};
use super::json_file::{read_versioned_json, write_json};
use super::sac_state::save_checkpoint_dir;
use super::tensors::load_tensors;
use crate::ensemble::{EnsembleConfig, EnsembleEpoch, EnsembleFitState, GaussianEnsemble};
use crate::nn::seeded_init;

pub const ENSEMBLE_CHECKPOINT_SCHEMA_VERSION: u32 = 1;
const STATE: &str = "state.json";

/// What the fit ran on: a checkpoint resumes only the same fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EnsembleFitShape {
    /// Transitions in the dataset.
    pub rows: usize,
    pub obs_dim: usize,
    pub act_dim: usize,
}

/// `state.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct CheckpointState {
    schema_version: u32,
    config: EnsembleConfig,
    shape: EnsembleFitShape,
    history: Vec<EnsembleEpoch>,
    since_update: usize,
    best_mse: Vec<f32>,
    #[serde(flatten)]
    files: FitFiles,
}

/// Saves `state` as the newest checkpoint in `dir`.
pub fn save_ensemble_checkpoint(
    dir: &Path,
    config: &EnsembleConfig,
    shape: &EnsembleFitShape,
    state: &EnsembleFitState,
) -> Result<PathBuf, ArtifactError> {
    let name = format!("epoch-{:06}", state.history.len());
    save_checkpoint_dir(dir, &name, |tmp| {
        let files = write_fit_files(tmp, &state.current, &state.best, &state.adam)?;
        write_json(
            &tmp.join(STATE),
            &CheckpointState {
                schema_version: ENSEMBLE_CHECKPOINT_SCHEMA_VERSION,
                config: config.clone(),
                shape: shape.clone(),
                history: state.history.clone(),
                since_update: state.since_update,
                best_mse: state.best_mse.clone(),
                files,
            },
        )
    })
}

/// Loads checkpoint directory `checkpoint`, refusing one written for another
/// dataset shape or config (its epoch cap aside, which a resume may change).
pub fn load_ensemble_checkpoint(
    checkpoint: &Path,
    config: &EnsembleConfig,
    shape: &EnsembleFitShape,
    device: &Device,
) -> Result<EnsembleFitState, ArtifactError> {
    let state: CheckpointState =
        read_versioned_json(&checkpoint.join(STATE), ENSEMBLE_CHECKPOINT_SCHEMA_VERSION)?;
    let uncapped = |c: &EnsembleConfig| c.clone().with_max_epochs(None);
    if uncapped(&state.config) != uncapped(config) || state.shape != *shape {
        return Err(ArtifactError::Invalid(format!(
            "{}: written by a fit with other settings or data ({:?} on {:?}); start afresh or fit with those",
            checkpoint.display(),
            state.config,
            state.shape
        )));
    }
    if state.best_mse.len() != config.members || state.history.is_empty() {
        return Err(ArtifactError::Invalid(format!(
            "{}: {} best errors for {} members, {} epochs",
            checkpoint.display(),
            state.best_mse.len(),
            config.members,
            state.history.len()
        )));
    }
    let skeleton = || {
        seeded_init(device, 0, || {
            GaussianEnsemble::init(
                shape.obs_dim + shape.act_dim,
                shape.obs_dim + 1,
                &config.hidden,
                config.members,
                (config.max_logvar_init, config.min_logvar_init),
                device,
            )
        })
    };
    let tensors = read_fit_files(checkpoint, &state.files)?;
    Ok(EnsembleFitState {
        current: load_tensors(skeleton(), &tensors.current, device)?,
        best: load_tensors(skeleton(), &tensors.best, device)?,
        adam: tensors.adam,
        history: state.history,
        since_update: state.since_update,
        best_mse: state.best_mse,
    })
}
