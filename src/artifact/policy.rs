//! A trained policy on disk, next to the dynamics it was trained in:
//! `{stem}.safetensors` (the actor's parameters by module path) and
//! `{stem}.json` (schema version, actor sizes and action box, task, training
//! provenance, the weights' hash). The best policy is `policy`, the last
//! `policy-last`.

use std::collections::BTreeMap;
use std::path::Path;

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use super::checkpoint::fill_older_loop_fields;
use super::json_file::{read_checked_weights, read_versioned_json_filled, write_json};
use super::safetensors_file::{safetensors_bytes, write_bytes};
use super::tensors::{collect_tensors, load_tensors};
use super::{ArtifactError, sha256_hex};
use crate::agent::{Actor, ActorConfig, ModelFreeConfig, OnlineSacConfig, PolicyLoopConfig};
use crate::envs::{System, TaskConfig};
use crate::nn::seeded_init;

pub const POLICY_SCHEMA_VERSION: u32 = 1;
/// File stem of the best policy (by evaluation score).
pub const BEST_POLICY: &str = "policy";
/// File stem of the policy after the last finished epoch.
pub const LAST_POLICY: &str = "policy-last";

/// Where a policy came from.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PolicyProvenance {
    pub preset: Option<String>,
    /// SHA-256 of the `dynamics.safetensors` it was trained in.
    pub dynamics_sha256: Option<String>,
    pub dataset_sha256: Option<String>,
    pub training: Option<PolicyLoopConfig>,
    pub epoch: usize,
    pub step: usize,
    /// D4RL normalised score at that epoch's evaluation.
    pub normalized_score: Option<f64>,
    /// Mean undiscounted return of that evaluation (absent in policies written before it was kept).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean_return: Option<f64>,
    /// The online SAC run that trained it (a behaviour policy), if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub online_training: Option<OnlineSacConfig>,
    /// A model-free method's settings (bc, td3-bc), in place of `training`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_free_training: Option<ModelFreeConfig>,
    /// The offline method (`fit-policy --algo`: nuno, nuno-r, nuno-al, mopo, tatu-mopo, bc, td3-bc).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub algorithm: Option<String>,
    /// The threshold its model rollouts truncated at, if they did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub truncation_threshold: Option<f32>,
}

/// The contents of `{stem}.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PolicyMetadata {
    pub schema_version: u32,
    pub actor: ActorConfig,
    /// The built-in task it acts in; none for a system described in a file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub task: Option<TaskConfig>,
    /// The name of the file's system it acts in.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub system: Option<String>,
    #[serde(flatten)]
    pub provenance: PolicyProvenance,
    pub weights_sha256: String,
    pub tensors: BTreeMap<String, Vec<usize>>,
}

/// Writes `actor` as `{stem}.safetensors` + `{stem}.json` in `dir`, weights first.
pub fn save_policy(
    dir: &Path,
    stem: &str,
    actor: &Actor,
    system: &System,
    provenance: PolicyProvenance,
) -> Result<PolicyMetadata, ArtifactError> {
    let tensors = collect_tensors(actor);
    let weights = safetensors_bytes(&tensors, None)?;
    let metadata = PolicyMetadata {
        schema_version: POLICY_SCHEMA_VERSION,
        actor: actor.config.clone(),
        task: system.task(),
        system: system.task().is_none().then(|| system.name()),
        provenance,
        weights_sha256: sha256_hex(&weights),
        tensors: tensors
            .iter()
            .map(|(k, (shape, _))| (k.clone(), shape.clone()))
            .collect(),
    };
    write_bytes(&dir.join(format!("{stem}.safetensors")), &weights)?;
    write_json(&dir.join(format!("{stem}.json")), &metadata)?;
    Ok(metadata)
}

impl PolicyMetadata {
    /// The task the policy acts in; an error naming `file` for a policy of a
    /// system described in a file, which has no simulator.
    pub fn simulated_task(&self, file: &Path) -> Result<TaskConfig, ArtifactError> {
        self.task.clone().ok_or_else(|| {
            ArtifactError::Invalid(format!(
                "{}: a policy for `{}`, a system described in a file: give the file (--system) to simulate it",
                file.display(),
                self.system.as_deref().unwrap_or("a system")
            ))
        })
    }
}

/// Whether `dir` holds a policy under `stem`.
pub fn has_policy(dir: &Path, stem: &str) -> bool {
    dir.join(format!("{stem}.json")).is_file()
}

/// The policy saved beside the model in `dir` (`policy.safetensors`, where
/// there is one), checked to act on the model's `obs_dim` → `act_dim`.
pub fn load_model_policy(
    dir: &Path,
    obs_dim: usize,
    act_dim: usize,
    device: &Device,
) -> Result<Option<(Actor, PolicyMetadata)>, ArtifactError> {
    if !has_policy(dir, BEST_POLICY) {
        return Ok(None);
    }
    let (actor, metadata) = load_policy(dir, BEST_POLICY, device)?;
    if actor.config.obs_dim != obs_dim || actor.config.act_dim != act_dim {
        return Err(ArtifactError::Invalid(format!(
            "{BEST_POLICY}.json: the policy acts on {}→{}, the model beside it on {obs_dim}→{act_dim}",
            actor.config.obs_dim, actor.config.act_dim
        )));
    }
    Ok(Some((actor, metadata)))
}

/// Loads the policy `{stem}` in `dir` onto `device`, validating everything.
pub fn load_policy(
    dir: &Path,
    stem: &str,
    device: &Device,
) -> Result<(Actor, PolicyMetadata), ArtifactError> {
    let metadata: PolicyMetadata = read_versioned_json_filled(
        &dir.join(format!("{stem}.json")),
        POLICY_SCHEMA_VERSION,
        |value| fill_older_loop_fields(value, "/training"),
    )?;
    let a = &metadata.actor;
    if a.action_low.len() != a.act_dim || a.action_high.len() != a.act_dim {
        return Err(ArtifactError::Invalid(format!(
            "{stem}.json: the action box has {} / {} bounds for {} actions",
            a.action_low.len(),
            a.action_high.len(),
            a.act_dim
        )));
    }
    let tensors = read_checked_weights(
        &dir.join(format!("{stem}.safetensors")),
        &metadata.weights_sha256,
    )?;
    // As for dynamics: the skeleton's draws stay out of concurrent fits' seeds.
    let skeleton = seeded_init(device, 0, || a.init(device));
    let actor = load_tensors(skeleton, &tensors, device)?;
    Ok((actor, metadata))
}
