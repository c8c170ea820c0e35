//! A fitted Gaussian ensemble on disk, beside (or instead of) a neural SDE in
//! a model directory: `ensemble.safetensors` (every member's parameters and
//! the log-variance bounds, by module path) and `ensemble.json` (schema
//! version, task, widths, the fit's settings, the input scaler, the elites and
//! holdout errors, the dataset's hash, the weights' hash). Written weights
//! first, both atomically; loading checks the version, the hash and every
//! tensor's name and shape.

use std::collections::BTreeMap;
use std::path::Path;

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use super::ArtifactError;
use super::dynamics::{DatasetInfo, sha256_hex};
use super::json_file::{read_checked_weights, read_versioned_json, write_json};
use super::safetensors_file::{safetensors_bytes, write_bytes};
use super::tensors::{collect_tensors, load_tensors};
use crate::ensemble::{EnsembleConfig, EnsembleFit, GaussianEnsemble, Scaler};
use crate::envs::{System, TaskConfig};
use crate::nn::seeded_init;

pub const ENSEMBLE_SCHEMA_VERSION: u32 = 1;
pub const ENSEMBLE_WEIGHTS: &str = "ensemble.safetensors";
pub const ENSEMBLE_METADATA: &str = "ensemble.json";

/// The contents of `ensemble.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EnsembleMetadata {
    pub schema_version: u32,
    /// Always `gaussian-ensemble` (what `/v1/models/{id}` will call its kind).
    pub kind: String,
    /// The built-in task it models, or none for a system described in a file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub task: Option<TaskConfig>,
    /// The system file's text, for a model of a system described as data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub system: Option<String>,
    pub obs_dim: usize,
    pub act_dim: usize,
    pub config: EnsembleConfig,
    pub scaler: Scaler,
    pub elites: Vec<usize>,
    /// Each member's best holdout MSE.
    pub holdout_mse: Vec<f32>,
    /// Epochs the fit ran.
    pub epochs: usize,
    pub dataset: Option<DatasetInfo>,
    pub weights_sha256: String,
    pub tensors: BTreeMap<String, Vec<usize>>,
}

/// Writes `fit` into `dir` (created if missing).
pub fn save_ensemble(
    dir: &Path,
    fit: &EnsembleFit,
    config: &EnsembleConfig,
    system: &System,
    dataset: Option<DatasetInfo>,
) -> Result<EnsembleMetadata, ArtifactError> {
    let shape = system
        .shape()
        .map_err(|e| ArtifactError::Invalid(e.to_string()))?;
    let (obs_dim, act_dim) = (shape.obs_dim, shape.act_dim);
    if fit.scaler.mean.len() != obs_dim + act_dim {
        return Err(ArtifactError::Invalid(format!(
            "the ensemble takes {} inputs, {} has {obs_dim} observations and {act_dim} actions",
            fit.scaler.mean.len(),
            system.name()
        )));
    }
    let tensors = collect_tensors(&fit.model);
    let weights = safetensors_bytes(&tensors, None)?;
    let metadata = EnsembleMetadata {
        schema_version: ENSEMBLE_SCHEMA_VERSION,
        kind: "gaussian-ensemble".into(),
        task: system.task(),
        system: system.file_text(),
        obs_dim,
        act_dim,
        config: config.clone(),
        scaler: fit.scaler.clone(),
        elites: fit.elites.clone(),
        holdout_mse: fit.holdout_mse.clone(),
        epochs: fit.history.len(),
        dataset,
        weights_sha256: sha256_hex(&weights),
        tensors: tensors
            .iter()
            .map(|(k, (shape, _))| (k.clone(), shape.clone()))
            .collect(),
    };
    std::fs::create_dir_all(dir).map_err(|e| ArtifactError::io(dir, e))?;
    write_bytes(&dir.join(ENSEMBLE_WEIGHTS), &weights)?;
    write_json(&dir.join(ENSEMBLE_METADATA), &metadata)?;
    Ok(metadata)
}

/// `ensemble.json` in `dir`, without its weights.
pub fn read_ensemble_metadata(dir: &Path) -> Result<EnsembleMetadata, ArtifactError> {
    read_versioned_json(&dir.join(ENSEMBLE_METADATA), ENSEMBLE_SCHEMA_VERSION)
}

/// Loads the ensemble in `dir`, validated, as an [`EnsembleFit`] (without its history).
pub fn load_ensemble(
    dir: &Path,
    device: &Device,
) -> Result<(EnsembleFit, EnsembleMetadata), ArtifactError> {
    let metadata = read_ensemble_metadata(dir)?;
    let m = &metadata;
    let d_in = m.obs_dim + m.act_dim;
    let members = m.config.members;
    if m.scaler.mean.len() != d_in
        || m.scaler.std.len() != d_in
        || m.elites.is_empty()
        || m.elites.iter().any(|&e| e >= members)
        || m.holdout_mse.len() != members
    {
        return Err(ArtifactError::Invalid(format!(
            "{ENSEMBLE_METADATA}: the scaler, elites or holdout errors do not fit {members} members on {d_in} inputs"
        )));
    }
    let tensors = read_checked_weights(&dir.join(ENSEMBLE_WEIGHTS), &m.weights_sha256)?;
    let config = &m.config;
    let skeleton = seeded_init(device, 0, || {
        GaussianEnsemble::init(
            d_in,
            m.obs_dim + 1,
            &config.hidden,
            members,
            (config.max_logvar_init, config.min_logvar_init),
            device,
        )
    });
    let model = load_tensors(skeleton, &tensors, device)?;
    Ok((
        EnsembleFit {
            model,
            scaler: m.scaler.clone(),
            elites: m.elites.clone(),
            holdout_mse: m.holdout_mse.clone(),
            history: Vec::new(),
        },
        metadata,
    ))
}
