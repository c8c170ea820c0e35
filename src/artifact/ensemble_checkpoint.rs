//! Checkpoints of the ensemble's fit, one per finished epoch, so that a fit to
//! convergence (MOPO's rule can take hundreds of epochs) survives being
//! stopped: the members now and at their best epochs, Adam's moments by module
//! path (either trainer resumes either's checkpoint), the history and the
//! early-stopping counters. Written like the policy's checkpoints
//! (`epoch-NNNNNN/` under a temporary name, fsynced, renamed, then `LATEST`).

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use super::json_file::{read_checked_weights, read_versioned_json, write_json};
use super::sac_state::{put_moments, save_checkpoint_dir, take_moments, write_synced};
use super::safetensors_file::safetensors_bytes;
use super::tensors::{NamedTensors, collect_tensors, load_tensors};
use super::{ArtifactError, sha256_hex};
use crate::ensemble::{EnsembleConfig, EnsembleEpoch, EnsembleFitState, GaussianEnsemble};
use crate::nn::{AdamState, seeded_init};

pub const ENSEMBLE_CHECKPOINT_SCHEMA_VERSION: u32 = 1;
const CURRENT: &str = "current.safetensors";
const BEST: &str = "best.safetensors";
const ADAM: &str = "adam.safetensors";
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
    adam_time: u64,
    current_sha256: String,
    best_sha256: String,
    adam_sha256: String,
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
        let current = safetensors_bytes(&collect_tensors(&state.current), None)?;
        let best = safetensors_bytes(&collect_tensors(&state.best), None)?;
        let mut moments = NamedTensors::new();
        put_moments(&mut moments, "", &state.adam);
        let adam = safetensors_bytes(&moments, None)?;
        for (file, bytes) in [(CURRENT, &current), (BEST, &best), (ADAM, &adam)] {
            write_synced(&tmp.join(file), bytes)?;
        }
        write_json(
            &tmp.join(STATE),
            &CheckpointState {
                schema_version: ENSEMBLE_CHECKPOINT_SCHEMA_VERSION,
                config: config.clone(),
                shape: shape.clone(),
                history: state.history.clone(),
                since_update: state.since_update,
                best_mse: state.best_mse.clone(),
                adam_time: state.adam.time,
                current_sha256: sha256_hex(&current),
                best_sha256: sha256_hex(&best),
                adam_sha256: sha256_hex(&adam),
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
    let current = read_checked_weights(&checkpoint.join(CURRENT), &state.current_sha256)?;
    let best = read_checked_weights(&checkpoint.join(BEST), &state.best_sha256)?;
    let mut adam = read_checked_weights(&checkpoint.join(ADAM), &state.adam_sha256)?;
    let moments = take_moments(&mut adam, "", |path| {
        current.get(path).map(|(_, values)| values.len())
    })?;
    if let Some(extra) = adam.keys().next() {
        return Err(ArtifactError::UnexpectedTensor(format!("{ADAM}: {extra}")));
    }
    Ok(EnsembleFitState {
        current: load_tensors(skeleton(), &current, device)?,
        best: load_tensors(skeleton(), &best, device)?,
        adam: AdamState {
            time: state.adam_time,
            moments,
        },
        history: state.history,
        since_update: state.since_update,
        best_mse: state.best_mse,
    })
}
