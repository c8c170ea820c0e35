//! What a model fit's checkpoint holds besides its own counters: the model now
//! and at its best, and Adam's moments by module path (`current.safetensors`,
//! `best.safetensors`, `adam.safetensors`), with their hashes and Adam's step
//! count flattened into the checkpoint's `state.json`. The SDE's and the
//! ensemble's checkpoints share it.

use std::path::Path;

use burn::module::Module;
use serde::{Deserialize, Serialize};

use super::json_file::read_checked_weights;
use super::sac_state::{put_moments, take_moments, write_synced};
use super::safetensors_file::safetensors_bytes;
use super::tensors::{NamedTensors, collect_tensors};
use super::{ArtifactError, sha256_hex};
use crate::nn::AdamState;

const CURRENT: &str = "current.safetensors";
const BEST: &str = "best.safetensors";
const ADAM: &str = "adam.safetensors";

/// The three files' hashes and Adam's step count.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct FitFiles {
    adam_time: u64,
    current_sha256: String,
    best_sha256: String,
    adam_sha256: String,
}

/// The tensors of a loaded checkpoint, checked against their hashes, and
/// Adam's state, every moment matching a parameter of the current model.
pub(crate) struct FitTensors {
    pub current: NamedTensors,
    pub best: NamedTensors,
    pub adam: AdamState,
}

/// Writes the three files into checkpoint directory `dir`.
pub(crate) fn write_fit_files<M: Module>(
    dir: &Path,
    current: &M,
    best: &M,
    adam: &AdamState,
) -> Result<FitFiles, ArtifactError> {
    let current = safetensors_bytes(&collect_tensors(current), None)?;
    let best = safetensors_bytes(&collect_tensors(best), None)?;
    let mut moments = NamedTensors::new();
    put_moments(&mut moments, "", adam);
    let moments = safetensors_bytes(&moments, None)?;
    for (file, bytes) in [(CURRENT, &current), (BEST, &best), (ADAM, &moments)] {
        write_synced(&dir.join(file), bytes)?;
    }
    Ok(FitFiles {
        adam_time: adam.time,
        current_sha256: sha256_hex(&current),
        best_sha256: sha256_hex(&best),
        adam_sha256: sha256_hex(&moments),
    })
}

/// Reads the three files from checkpoint directory `dir`.
pub(crate) fn read_fit_files(dir: &Path, files: &FitFiles) -> Result<FitTensors, ArtifactError> {
    let current = read_checked_weights(&dir.join(CURRENT), &files.current_sha256)?;
    let best = read_checked_weights(&dir.join(BEST), &files.best_sha256)?;
    let mut adam = read_checked_weights(&dir.join(ADAM), &files.adam_sha256)?;
    let moments = take_moments(&mut adam, "", |path| {
        current.get(path).map(|(_, values)| values.len())
    })?;
    if let Some(extra) = adam.keys().next() {
        return Err(ArtifactError::UnexpectedTensor(format!("{ADAM}: {extra}")));
    }
    Ok(FitTensors {
        current,
        best,
        adam: AdamState {
            time: files.adam_time,
            moments,
        },
    })
}
