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

use super::json_file::{read_checked_weights, read_versioned_json, write_json};
use super::sac_state::{RngState, put_moments, save_checkpoint_dir, take_moments, write_synced};
use super::safetensors_file::safetensors_bytes;
use super::tensors::{NamedTensors, collect_tensors, load_tensors};
use super::{ArtifactError, sha256_hex};
use crate::nn::{AdamState, seeded_init};
use crate::sde::{
    DynamicsSpec, FitConfig, FitRecord, NeuralSde, PhysicalScales, SdeConfig, SdeFitState,
};

pub const SDE_CHECKPOINT_SCHEMA_VERSION: u32 = 1;
const CURRENT: &str = "current.safetensors";
const BEST: &str = "best.safetensors";
const ADAM: &str = "adam.safetensors";
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
    adam_time: u64,
    current_sha256: String,
    best_sha256: String,
    adam_sha256: String,
}

/// Saves `state` of a fit with `fit` as the newest checkpoint in `dir`.
pub fn save_sde_checkpoint(
    dir: &Path,
    fit: &FitConfig,
    state: &SdeFitState,
) -> Result<PathBuf, ArtifactError> {
    let name = format!("step-{:07}", state.step);
    save_checkpoint_dir(dir, &name, |tmp| {
        let current = safetensors_bytes(&collect_tensors(&state.current), None)?;
        let best = safetensors_bytes(&collect_tensors(&state.best), None)?;
        let mut moments = NamedTensors::new();
        put_moments(&mut moments, "", &state.adam);
        let adam = safetensors_bytes(&moments, None)?;
        for (file, bytes) in [(CURRENT, &current), (BEST, &best), (ADAM, &adam)] {
            write_synced(&tmp.join(file), bytes)?;
        }
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
                adam_time: state.adam.time,
                current_sha256: sha256_hex(&current),
                best_sha256: sha256_hex(&best),
                adam_sha256: sha256_hex(&adam),
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
    let state: CheckpointState =
        read_versioned_json(&checkpoint.join(STATE), SDE_CHECKPOINT_SCHEMA_VERSION)?;
    let uncapped = |c: &FitConfig| FitConfig {
        max_steps: 0,
        ..c.clone()
    };
    if uncapped(&state.fit) != uncapped(fit) {
        return Err(ArtifactError::Invalid(format!(
            "{}: written by a fit with other settings; start afresh or fit with those",
            checkpoint.display()
        )));
    }
    let model = |file: &str, sha: &str, config: &SdeConfig| -> Result<NeuralSde, ArtifactError> {
        let tensors = read_checked_weights(&checkpoint.join(file), sha)?;
        let skeleton = seeded_init(device, 0, || {
            NeuralSde::init(
                state.spec.clone(),
                state.scales.clone(),
                config.clone(),
                device,
            )
        });
        load_tensors(skeleton, &tensors, device)
    };
    let current = model(CURRENT, &state.current_sha256, &state.current_config)?;
    let best = model(BEST, &state.best_sha256, &state.best_config)?;
    let weights = collect_tensors(&current);
    let mut adam = read_checked_weights(&checkpoint.join(ADAM), &state.adam_sha256)?;
    let moments = take_moments(&mut adam, "", |path| {
        weights.get(path).map(|(_, values)| values.len())
    })?;
    if let Some(extra) = adam.keys().next() {
        return Err(ArtifactError::UnexpectedTensor(format!("{ADAM}: {extra}")));
    }
    Ok(SdeFitState {
        step: state.step,
        records: state.records,
        current,
        best,
        best_nll: state.best_nll,
        best_step: state.best_step,
        evals_without_improvement: state.evals_without_improvement,
        adam: AdamState {
            time: state.adam_time,
            moments,
        },
        rng: state.rng.restore(),
    })
}
