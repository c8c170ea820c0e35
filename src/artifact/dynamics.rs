//! A fitted neural SDE on disk: one directory holding `dynamics.safetensors`
//! (every parameter under its module path) and `model.json` (schema version,
//! task, dims, state split, dt, normaliser and scales, every hyperparameter,
//! the threshold table, the training summary, the dataset's hash, and the
//! hash of the weights it belongs to).
//!
//! Both files are written atomically, weights first. Loading checks the schema
//! version, that the weights are the ones `model.json` was written for, and
//! every tensor's name, shape and dtype, so a half-written or mixed artifact is
//! refused with an error that says what is wrong.

use std::collections::BTreeMap;
use std::path::Path;

use burn::tensor::Device;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::ArtifactError;
use super::json_file::{read_checked_weights, read_versioned_json_filled, write_json};
use super::safetensors_file::{safetensors_bytes, write_bytes};
use super::tensors::{collect_tensors, load_tensors};
use crate::envs::TaskConfig;
use crate::infer::Kernel;
use crate::nn::seeded_init;
use crate::sde::{
    CalibrationReport, DriftInputs, DynamicsSpec, EtaLossForm, FitConfig, FitSummary,
    LikelihoodPath, LossConfig, MuForm, NeuralSde, PhysicalScales, SdeConfig, ThresholdTable,
};

/// Version of the `model.json` layout this build reads and writes. Version 2:
/// h(η) reads η's logit and W^max is per dimension (`w_max`); version-1 models
/// (h on the bounded η) are refused with a hint to refit, never reinterpreted.
pub const DYNAMICS_SCHEMA_VERSION: u32 = 2;
/// File names inside a model directory.
pub const DYNAMICS_WEIGHTS: &str = "dynamics.safetensors";
pub const DYNAMICS_METADATA: &str = "model.json";

/// Which data a model was fitted on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DatasetInfo {
    pub path: String,
    pub sha256: String,
    pub transitions: usize,
    pub trajectories: usize,
}

/// Provenance saved alongside the weights.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct DynamicsProvenance {
    /// The built-in task it models, or none for a system described in a file.
    pub task: Option<TaskConfig>,
    /// The system file's text, for a model of a system described as data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub system: Option<String>,
    pub fit: Option<FitConfig>,
    pub thresholds: Option<ThresholdTable>,
    pub training: Option<FitSummary>,
    pub dataset: Option<DatasetInfo>,
    /// How Σ and the truncation behave on the fit's held-out trajectories.
    #[serde(default)]
    pub calibration: Option<CalibrationReport>,
}

/// The contents of `model.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DynamicsMetadata {
    pub schema_version: u32,
    pub spec: DynamicsSpec,
    pub scales: PhysicalScales,
    pub model: SdeConfig,
    #[serde(flatten)]
    pub provenance: DynamicsProvenance,
    /// SHA-256 of `dynamics.safetensors`.
    pub weights_sha256: String,
    /// Every tensor's name and shape.
    pub tensors: BTreeMap<String, Vec<usize>>,
}

/// Lower-case hex SHA-256 of `bytes`.
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Lower-case hex SHA-256 of a file's contents, streamed.
pub fn sha256_file(path: &Path) -> Result<String, ArtifactError> {
    use std::io::Read;
    let mut file = std::fs::File::open(path).map_err(|e| ArtifactError::io(path, e))?;
    let mut hasher = Sha256::new();
    let mut buffer = vec![0u8; 1 << 20];
    loop {
        let n = file
            .read(&mut buffer)
            .map_err(|e| ArtifactError::io(path, e))?;
        if n == 0 {
            break;
        }
        hasher.update(&buffer[..n]);
    }
    Ok(hasher
        .finalize()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect())
}

/// Writes `model` and its metadata into `dir` (created if missing).
pub fn save_dynamics(
    dir: &Path,
    model: &NeuralSde,
    provenance: DynamicsProvenance,
) -> Result<DynamicsMetadata, ArtifactError> {
    let tensors = collect_tensors(model);
    let weights = safetensors_bytes(&tensors, None)?;
    let c = &model.constants;
    let metadata = DynamicsMetadata {
        schema_version: DYNAMICS_SCHEMA_VERSION,
        spec: c.spec.clone(),
        scales: c.scales.clone(),
        model: c.config.clone(),
        provenance,
        weights_sha256: sha256_hex(&weights),
        tensors: tensors
            .iter()
            .map(|(k, (shape, _))| (k.clone(), shape.clone()))
            .collect(),
    };
    write_bytes(&dir.join(DYNAMICS_WEIGHTS), &weights)?;
    write_json(&dir.join(DYNAMICS_METADATA), &metadata)?;
    Ok(metadata)
}

/// Reads and validates `model.json` alone, filling what older files lack with
/// the meaning they were written under ([`fill_older_sde_fields`]).
pub fn read_dynamics_metadata(dir: &Path) -> Result<DynamicsMetadata, ArtifactError> {
    read_versioned_json_filled(
        &dir.join(DYNAMICS_METADATA),
        DYNAMICS_SCHEMA_VERSION,
        |value| fill_older_sde_fields(value, &["/model"], &["/fit"]),
    )
}

/// Fields of `SdeConfig` (at each of `models`) and `FitConfig` (at each of
/// `fits`) that files written before them lack, with the meaning those files
/// had: fitted on eq. 6's particle path, every window step weighed 1, samples
/// drawn at the full Σ, by burn, μ a network, η's losses the paper's on the
/// fit's learning rate. Never reinterpreted: a file that names a field keeps it.
pub(super) fn fill_older_sde_fields(value: &mut serde_json::Value, models: &[&str], fits: &[&str]) {
    let mut fill = |pointer: String, field: &str, default: serde_json::Value| {
        if let Some(fields) = value.pointer_mut(&pointer).and_then(|v| v.as_object_mut()) {
            fields.entry(field).or_insert(default);
        }
    };
    let fit_models = fits.iter().map(|fit| format!("{fit}/model"));
    for model in models.iter().map(|m| m.to_string()).chain(fit_models) {
        fill(model.clone(), "sample_noise_scale", serde_json::json!(1.0));
        fill(model.clone(), "mu_form", serde_json::json!(MuForm::Network));
        fill(
            model,
            "drift_inputs",
            serde_json::json!(DriftInputs::ZScores),
        );
    }
    for fit in fits {
        let loss = format!("{fit}/loss");
        fill(
            loss.clone(),
            "likelihood",
            serde_json::json!(LikelihoodPath::Particle),
        );
        fill(loss.clone(), "step_discount", serde_json::json!(1.0));
        fill(
            loss.clone(),
            "eta_losses",
            serde_json::json!(EtaLossForm::Paper),
        );
        // Weights of the code form's terms only, unread under the paper's.
        let code_form = LossConfig::new();
        for (field, value) in [
            ("lambda_value", code_form.lambda_value),
            ("lambda_one", code_form.lambda_one),
            ("grad_floor", code_form.grad_floor),
            ("grad_floor_weight", code_form.grad_floor_weight),
        ] {
            fill(loss.clone(), field, serde_json::json!(value));
        }
        fill(fit.to_string(), "kernel", serde_json::json!(Kernel::Burn));
        fill(fit.to_string(), "eta_lr", serde_json::Value::Null);
    }
}

/// Loads the model in `dir` onto `device` (no autodiff).
pub fn load_dynamics(
    dir: &Path,
    device: &Device,
) -> Result<(NeuralSde, DynamicsMetadata), ArtifactError> {
    let metadata = read_dynamics_metadata(dir)?;
    let tensors = read_checked_weights(&dir.join(DYNAMICS_WEIGHTS), &metadata.weights_sha256)?;
    metadata
        .spec
        .validate()
        .and_then(|()| {
            let state_dim = metadata.spec.obs_dim + usize::from(metadata.model.reward_model);
            metadata.model.validate(state_dim)
        })
        .map_err(|e| ArtifactError::Invalid(e.to_string()))?;
    // The skeleton's random weights are replaced at once; drawing them under the
    // initialiser's lock keeps a concurrent fit's initial weights its seed's.
    let skeleton = seeded_init(device, 0, || {
        NeuralSde::init(
            metadata.spec.clone(),
            metadata.scales.clone(),
            metadata.model.clone(),
            device,
        )
    });
    let model = load_tensors(skeleton, &tensors, device)?;
    Ok((model, metadata))
}
