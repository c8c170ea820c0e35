//! Checkpoints of policy optimisation, one per finished epoch, so `--resume`
//! loses nothing but the epoch in progress: every network, the three Adam
//! states (moments by module path, so either SAC kernel resumes either's run),
//! the model buffer, the random generator's position, the counters and the history.
//!
//! Each checkpoint is a directory `checkpoints/epoch-NNNNNN/` written under a
//! temporary name, fsynced and renamed; then `checkpoints/LATEST` is replaced
//! atomically to name it, and older checkpoints are removed. A crash at any
//! point leaves LATEST naming a complete checkpoint.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::json_file::{read_checked_weights, read_versioned_json_filled, write_json};
use super::sac_state::{
    RngState, SacFiles, put_moments, read_sac, save_checkpoint_dir, take_moments, write_sac,
    write_synced,
};
use super::safetensors_file::safetensors_bytes;
use super::tensors::{NamedTensors, collect_tensors, load_tensors};
use super::{ArtifactError, sha256_hex};
use crate::agent::{
    ActorLrDecay, EpochRecord, PolicyLoopConfig, PolicyTraining, ReplayBuffer, SacConfig,
    TruncatedStep,
};
use crate::envs::{ForwardVelocity, RootXReward};
use crate::nn::AdamState;
use crate::shared::TransitionBatch;

/// Version 2: Adam's moments by module path in `adam.safetensors` (version 1
/// kept burn's optimiser records keyed by parameter id).
pub const CHECKPOINT_SCHEMA_VERSION: u32 = 2;
const BUFFER: &str = "model_buffer.safetensors";
/// RAMBO's adversarially trained ensemble: `model.*` weights, `adam/*` moments.
const ADVERSARY: &str = "adversary.safetensors";
const STATE: &str = "state.json";

/// `state.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct CheckpointState {
    schema_version: u32,
    config: PolicyLoopConfig,
    step: usize,
    epoch: usize,
    threshold: Option<f32>,
    rng: RngState,
    buffer: BufferShape,
    history: Vec<EpochRecord>,
    buffer_sha256: String,
    /// RAMBO's adversary, where the run has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    adversary: Option<AdversaryFiles>,
    #[serde(flatten)]
    sac: SacFiles,
}

/// What [`ADVERSARY`] holds: its hash and its Adam's step count.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct AdversaryFiles {
    sha256: String,
    adam_time: u64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
struct BufferShape {
    obs_dim: usize,
    act_dim: usize,
    capacity: usize,
    len: usize,
    next: usize,
}

/// Saves `training` as the newest checkpoint in `dir`.
pub fn save_checkpoint(dir: &Path, training: &PolicyTraining) -> Result<PathBuf, ArtifactError> {
    let name = format!("epoch-{:06}", training.epoch);
    save_checkpoint_dir(dir, &name, |tmp| write_contents(tmp, training))
}

fn write_contents(dir: &Path, training: &PolicyTraining) -> Result<(), ArtifactError> {
    let sac = write_sac(dir, &training.sac)?;
    let buffer = &training.model_buffer;
    let buffer_bytes = safetensors_bytes(&buffer_tensors(buffer), None)?;
    write_synced(&dir.join(BUFFER), &buffer_bytes)?;
    let state = CheckpointState {
        schema_version: CHECKPOINT_SCHEMA_VERSION,
        config: training.config.clone(),
        step: training.step,
        epoch: training.epoch,
        threshold: training.threshold,
        rng: RngState::of(&training.rng),
        buffer: BufferShape {
            obs_dim: buffer.obs_dim,
            act_dim: buffer.act_dim,
            capacity: buffer.capacity,
            len: buffer.len,
            next: buffer.next,
        },
        history: training.history.clone(),
        buffer_sha256: sha256_hex(&buffer_bytes),
        adversary: write_adversary(dir, training)?,
        sac,
    };
    write_json(&dir.join(STATE), &state)
}

/// RAMBO's adversary's weights and Adam moments, where the run has one.
fn write_adversary(
    dir: &Path,
    training: &PolicyTraining,
) -> Result<Option<AdversaryFiles>, ArtifactError> {
    let Some(adversary) = &training.adversary else {
        return Ok(None);
    };
    let ensemble = &adversary.ensemble;
    let mut tensors: NamedTensors = collect_tensors(&ensemble.model())
        .into_iter()
        .map(|(k, v)| (format!("model.{k}"), v))
        .collect();
    let state = ensemble.optimizer_state();
    put_moments(&mut tensors, "adam/", &state);
    let bytes = safetensors_bytes(&tensors, None)?;
    write_synced(&dir.join(ADVERSARY), &bytes)?;
    Ok(Some(AdversaryFiles {
        sha256: sha256_hex(&bytes),
        adam_time: state.time,
    }))
}

/// Restores RAMBO's adversary from `checkpoint` into `training`'s, and the
/// dynamics its rollouts step.
fn read_adversary(
    checkpoint: &Path,
    files: Option<&AdversaryFiles>,
    training: &mut PolicyTraining,
) -> Result<(), ArtifactError> {
    let (Some(files), Some(adversary)) = (files, training.adversary.as_mut()) else {
        return match (files.is_some(), training.adversary.is_some()) {
            (false, false) => Ok(()),
            _ => Err(ArtifactError::Invalid(format!(
                "{}: the checkpoint and the run disagree on RAMBO's adversary",
                checkpoint.display()
            ))),
        };
    };
    let path = checkpoint.join(ADVERSARY);
    let mut tensors = read_checked_weights(&path, &files.sha256)?;
    let weights: NamedTensors = tensors
        .iter()
        .filter_map(|(k, v)| Some((k.strip_prefix("model.")?.to_string(), v.clone())))
        .collect();
    tensors.retain(|k, _| !k.starts_with("model."));
    let model = adversary.ensemble.model();
    let device = model.max_logvar.val().device();
    let model = load_tensors(model, &weights, &device)?;
    let moments = take_moments(&mut tensors, "adam/", |p| {
        weights.get(p).map(|(_, v)| v.len())
    })?;
    if let Some(extra) = tensors.keys().next() {
        return Err(ArtifactError::UnexpectedTensor(format!(
            "{ADVERSARY}: {extra}"
        )));
    }
    let state = AdamState {
        time: files.adam_time,
        moments,
    };
    adversary.ensemble.restore(&model, state);
    adversary.dynamics = adversary.ensemble.dynamics(&adversary.dynamics);
    Ok(())
}

fn buffer_tensors(buffer: &ReplayBuffer) -> NamedTensors {
    let d = &buffer.data;
    let (n, o, a) = (buffer.len, buffer.obs_dim, buffer.act_dim);
    NamedTensors::from([
        ("observations".into(), (vec![n, o], d.observations.clone())),
        ("actions".into(), (vec![n, a], d.actions.clone())),
        ("rewards".into(), (vec![n], d.rewards.clone())),
        (
            "next_observations".into(),
            (vec![n, o], d.next_observations.clone()),
        ),
        ("terminals".into(), (vec![n], d.terminals.clone())),
    ])
}

/// Fields of the `PolicyLoopConfig` at `pointer` that files written before
/// them lack, with the meaning those runs had: a model buffer of 1 × its
/// rollouts, the known reward on the velocity after the step (on root x's
/// difference where root x is observed), a constant actor
/// learning rate, and (never used by those runs, which had a simulator) the
/// in-model evaluation's default horizon; no state box, no observation clip.
pub(super) fn fill_older_loop_fields(value: &mut serde_json::Value, pointer: &str) {
    if let Some(fields) = value.pointer_mut(pointer).and_then(|v| v.as_object_mut()) {
        fields
            .entry("model_buffer_factor")
            .or_insert(serde_json::json!(1));
        fields
            .entry("forward_velocity")
            .or_insert(serde_json::json!(ForwardVelocity::Next));
        fields
            .entry("actor_lr_decay")
            .or_insert(serde_json::json!(ActorLrDecay::Constant));
        fields
            .entry("conservative")
            .or_insert(serde_json::Value::Null);
        fields
            .entry("halt_penalty")
            .or_insert(serde_json::Value::Null);
        fields
            .entry("bellman_penalty")
            .or_insert(serde_json::Value::Null);
        fields.entry("rambo").or_insert(serde_json::Value::Null);
        fields
            .entry("state_box_margin")
            .or_insert(serde_json::Value::Null);
        fields
            .entry("clip_observations")
            .or_insert(serde_json::json!(false));
        fields
            .entry("truncated_step")
            .or_insert(serde_json::json!(TruncatedStep::Drop));
        fields
            .entry("rollout_noise_scale")
            .or_insert(serde_json::Value::Null);
        fields
            .entry("root_x_reward")
            .or_insert(serde_json::json!(RootXReward::Difference));
        fields
            .entry("model_eval_horizon")
            .or_insert(serde_json::json!(
                PolicyLoopConfig::new(SacConfig::new(), 0, 0.0, 0.0).model_eval_horizon
            ));
    }
}

/// Restores the state saved in checkpoint directory `checkpoint` into
/// `training`, a fresh run built with the same configuration.
pub fn load_checkpoint(
    checkpoint: &Path,
    training: &mut PolicyTraining,
) -> Result<(), ArtifactError> {
    let state: CheckpointState = read_versioned_json_filled(
        &checkpoint.join(STATE),
        CHECKPOINT_SCHEMA_VERSION,
        |value| fill_older_loop_fields(value, "/config"),
    )?;
    // The run may be extended (more epochs); every other knob must match.
    let comparable = PolicyLoopConfig {
        epochs: training.config.epochs,
        ..state.config.clone()
    };
    if comparable != training.config {
        return Err(ArtifactError::Invalid(format!(
            "{}: the checkpoint was written with a different configuration; resume with the same flags",
            checkpoint.display()
        )));
    }
    read_sac(checkpoint, &state.sac, &mut training.sac)?;
    training.model_buffer = read_buffer(checkpoint, &state)?;
    training.rng = state.rng.restore();
    training.step = state.step;
    training.epoch = state.epoch;
    training.threshold = state.threshold;
    read_adversary(checkpoint, state.adversary.as_ref(), training)?;
    training.history = state.history;
    Ok(())
}

fn read_buffer(checkpoint: &Path, state: &CheckpointState) -> Result<ReplayBuffer, ArtifactError> {
    let path = checkpoint.join(BUFFER);
    let mut tensors = read_checked_weights(&path, &state.buffer_sha256)?;
    let shape = state.buffer;
    let mut take = |name: &str, width: Option<usize>| -> Result<Vec<f32>, ArtifactError> {
        let (dims, values) = tensors
            .remove(name)
            .ok_or_else(|| ArtifactError::MissingTensor(format!("{}: {name}", path.display())))?;
        let expected: Vec<usize> = std::iter::once(shape.len).chain(width).collect();
        if dims != expected {
            return Err(ArtifactError::TensorShape {
                name: name.to_string(),
                expected,
                got: dims,
            });
        }
        Ok(values)
    };
    let data = TransitionBatch {
        observations: take("observations", Some(shape.obs_dim))?,
        actions: take("actions", Some(shape.act_dim))?,
        rewards: take("rewards", None)?,
        next_observations: take("next_observations", Some(shape.obs_dim))?,
        terminals: take("terminals", None)?,
    };
    Ok(ReplayBuffer {
        obs_dim: shape.obs_dim,
        act_dim: shape.act_dim,
        capacity: shape.capacity,
        len: shape.len,
        next: shape.next,
        data,
    })
}
