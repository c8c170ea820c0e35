//! Checkpoints of policy optimisation, one per finished epoch, so `--resume`
//! loses nothing but the epoch in progress: every network, the three Adam
//! states (moments by module path, so either SAC kernel resumes either's run),
//! the model buffer, the random generator's position, the counters and the history.
//!
//! Each checkpoint is a directory `checkpoints/epoch-NNNNNN/` written under a
//! temporary name, fsynced and renamed; then `checkpoints/LATEST` is replaced
//! atomically to name it, and older checkpoints are removed. A crash at any
//! point leaves LATEST naming a complete checkpoint.

use std::collections::BTreeMap;
use std::fs::File;
use std::path::{Path, PathBuf};

use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::json_file::{read_checked_weights, read_versioned_json, write_json};
use super::safetensors_file::safetensors_bytes;
use super::tensors::{NamedTensors, collect_tensors, load_tensors};
use super::{ArtifactError, sha256_hex, write_atomically};
use crate::agent::{EpochRecord, PolicyLoopConfig, PolicyTraining, ReplayBuffer};
use crate::data::TransitionBatch;
use crate::nn::{AdamState, Moments};

/// Version 2: Adam's moments by module path in `adam.safetensors` (version 1
/// kept burn's optimiser records keyed by parameter id).
pub const CHECKPOINT_SCHEMA_VERSION: u32 = 2;
const LATEST: &str = "LATEST";
const NETWORKS: &str = "networks.safetensors";
const BUFFER: &str = "model_buffer.safetensors";
const STATE: &str = "state.json";
const ADAM: &str = "adam.safetensors";
const OPTIMIZERS: [&str; 3] = ["actor", "critic", "alpha"];

/// Where the generator stands: enough to continue its exact stream.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct RngState {
    seed: [u8; 32],
    stream: u64,
    word_pos: u128,
}

/// `state.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct CheckpointState {
    schema_version: u32,
    config: PolicyLoopConfig,
    step: usize,
    epoch: usize,
    threshold: Option<f32>,
    rng: RngState,
    /// Adam steps taken, per optimiser.
    adam_time: BTreeMap<String, u64>,
    buffer: BufferShape,
    history: Vec<EpochRecord>,
    networks_sha256: String,
    buffer_sha256: String,
    adam_sha256: String,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
struct BufferShape {
    obs_dim: usize,
    act_dim: usize,
    capacity: usize,
    len: usize,
    next: usize,
}

/// The checkpoint directory `LATEST` names in `dir`, if any.
pub fn latest_checkpoint(dir: &Path) -> Result<Option<PathBuf>, ArtifactError> {
    let pointer = dir.join(LATEST);
    if !pointer.exists() {
        return Ok(None);
    }
    let name = std::fs::read_to_string(&pointer).map_err(|e| ArtifactError::io(&pointer, e))?;
    let name = name.trim();
    if name.is_empty() || name.contains('/') || name.contains("..") {
        return Err(ArtifactError::Invalid(format!(
            "{}: `{name}` is not a checkpoint name",
            pointer.display()
        )));
    }
    Ok(Some(dir.join(name)))
}

/// Saves `training` as the newest checkpoint in `dir`.
pub fn save_checkpoint(dir: &Path, training: &PolicyTraining) -> Result<PathBuf, ArtifactError> {
    std::fs::create_dir_all(dir).map_err(|e| ArtifactError::io(dir, e))?;
    let name = format!("epoch-{:06}", training.epoch);
    let final_dir = dir.join(&name);
    let tmp = dir.join(format!(".{name}.tmp-{}", std::process::id()));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(|e| ArtifactError::io(&tmp, e))?;
    }
    std::fs::create_dir_all(&tmp).map_err(|e| ArtifactError::io(&tmp, e))?;
    let written = write_contents(&tmp, training).and_then(|()| {
        if final_dir.exists() {
            std::fs::remove_dir_all(&final_dir).map_err(|e| ArtifactError::io(&final_dir, e))?;
        }
        std::fs::rename(&tmp, &final_dir).map_err(|e| ArtifactError::io(&final_dir, e))?;
        File::open(dir)
            .and_then(|d| d.sync_all())
            .map_err(|e| ArtifactError::io(dir, e))
    });
    if let Err(e) = written {
        let _ = std::fs::remove_dir_all(&tmp);
        return Err(e);
    }
    let pointer = dir.join(LATEST);
    write_atomically(
        &pointer,
        |p| std::fs::write(p, &name).map_err(|e| ArtifactError::io(p, e)),
        |e| ArtifactError::io(&pointer, e),
    )?;
    // Older checkpoints are no longer needed once LATEST names the new one.
    for entry in std::fs::read_dir(dir).map_err(|e| ArtifactError::io(dir, e))? {
        let path = entry.map_err(|e| ArtifactError::io(dir, e))?.path();
        let file_name = path.file_name().map(|n| n.to_string_lossy().into_owned());
        if let Some(other) = file_name
            && other.starts_with("epoch-")
            && other != name
        {
            std::fs::remove_dir_all(&path).map_err(|e| ArtifactError::io(&path, e))?;
        }
    }
    Ok(final_dir)
}

fn write_contents(dir: &Path, training: &PolicyTraining) -> Result<(), ArtifactError> {
    let sac = &training.sac;
    let mut networks = NamedTensors::new();
    let mut add = |prefix: &str, tensors: NamedTensors| {
        for (k, v) in tensors {
            networks.insert(format!("{prefix}.{k}"), v);
        }
    };
    add("actor", collect_tensors(&sac.actor));
    add("critic", collect_tensors(&sac.critic));
    add("target_critic", collect_tensors(&sac.target_critic));
    add("temperature", collect_tensors(&sac.temperature));
    let networks = safetensors_bytes(&networks, None)?;
    write_synced(&dir.join(NETWORKS), &networks)?;

    let buffer = &training.model_buffer;
    let buffer_bytes = safetensors_bytes(&buffer_tensors(buffer), None)?;
    write_synced(&dir.join(BUFFER), &buffer_bytes)?;

    let a = &sac.adam;
    let mut adam = NamedTensors::new();
    let mut adam_time = BTreeMap::new();
    for (name, state) in OPTIMIZERS.iter().zip([&a.actor, &a.critic, &a.alpha]) {
        adam_time.insert(name.to_string(), state.time);
        for (path, moments) in &state.moments {
            let n = moments.first.len();
            adam.insert(
                format!("{name}/{path}/first"),
                (vec![n], moments.first.clone()),
            );
            adam.insert(
                format!("{name}/{path}/second"),
                (vec![n], moments.second.clone()),
            );
        }
    }
    let adam = safetensors_bytes(&adam, None)?;
    write_synced(&dir.join(ADAM), &adam)?;

    let rng = &training.rng;
    let state = CheckpointState {
        schema_version: CHECKPOINT_SCHEMA_VERSION,
        config: training.config.clone(),
        step: training.step,
        epoch: training.epoch,
        threshold: training.threshold,
        rng: RngState {
            seed: rng.get_seed(),
            stream: rng.get_stream(),
            word_pos: rng.get_word_pos(),
        },
        adam_time,
        buffer: BufferShape {
            obs_dim: buffer.obs_dim,
            act_dim: buffer.act_dim,
            capacity: buffer.capacity,
            len: buffer.len,
            next: buffer.next,
        },
        history: training.history.clone(),
        networks_sha256: sha256_hex(&networks),
        buffer_sha256: sha256_hex(&buffer_bytes),
        adam_sha256: sha256_hex(&adam),
    };
    write_json(&dir.join(STATE), &state)
}

/// Writes and fsyncs a file inside the temporary checkpoint directory.
fn write_synced(path: &Path, bytes: &[u8]) -> Result<(), ArtifactError> {
    std::fs::write(path, bytes)
        .and_then(|()| File::open(path)?.sync_all())
        .map_err(|e| ArtifactError::io(path, e))
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

/// Restores the state saved in checkpoint directory `checkpoint` into
/// `training`, a fresh run built with the same configuration.
pub fn load_checkpoint(
    checkpoint: &Path,
    training: &mut PolicyTraining,
) -> Result<(), ArtifactError> {
    let state: CheckpointState =
        read_versioned_json(&checkpoint.join(STATE), CHECKPOINT_SCHEMA_VERSION)?;
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
    let networks = read_checked_weights(&checkpoint.join(NETWORKS), &state.networks_sha256)?;
    let part = |prefix: &str| -> NamedTensors {
        let dotted = format!("{prefix}.");
        networks
            .iter()
            .filter_map(|(k, v)| {
                k.strip_prefix(&dotted)
                    .map(|rest| (rest.to_string(), v.clone()))
            })
            .collect()
    };
    let sac = &mut training.sac;
    let device = sac.device().clone();
    let plain = device.clone().inner();
    sac.actor = load_tensors(sac.actor.clone(), &part("actor"), &device)?;
    sac.critic = load_tensors(sac.critic.clone(), &part("critic"), &device)?;
    sac.target_critic = load_tensors(sac.target_critic.clone(), &part("target_critic"), &plain)?;
    sac.temperature = load_tensors(sac.temperature.clone(), &part("temperature"), &device)?;
    let mut adam = read_checked_weights(&checkpoint.join(ADAM), &state.adam_sha256)?;
    let a = &mut sac.adam;
    for (name, optimizer) in OPTIMIZERS
        .iter()
        .zip([&mut a.actor, &mut a.critic, &mut a.alpha])
    {
        *optimizer = read_adam(name, &mut adam, &state, &networks)?;
    }
    if let Some(extra) = adam.keys().next() {
        return Err(ArtifactError::UnexpectedTensor(format!("{ADAM}: {extra}")));
    }

    training.model_buffer = read_buffer(checkpoint, &state)?;
    let mut rng = <ChaCha8Rng as rand::SeedableRng>::from_seed(state.rng.seed);
    rng.set_stream(state.rng.stream);
    rng.set_word_pos(state.rng.word_pos);
    training.rng = rng;
    training.step = state.step;
    training.epoch = state.epoch;
    training.threshold = state.threshold;
    training.history = state.history;
    Ok(())
}

/// Optimiser `name`'s state, taking its moments out of `adam`: every moment
/// belongs to a saved parameter of the network `name` steps and has its size.
fn read_adam(
    name: &str,
    adam: &mut NamedTensors,
    state: &CheckpointState,
    networks: &NamedTensors,
) -> Result<AdamState, ArtifactError> {
    let network = if name == "alpha" { "temperature" } else { name };
    let prefix = format!("{name}/");
    let paths: Vec<String> = adam
        .keys()
        .filter_map(|k| k.strip_prefix(&prefix)?.strip_suffix("/first"))
        .map(str::to_string)
        .collect();
    let mut moments = BTreeMap::new();
    for path in paths {
        let first = adam.remove(&format!("{prefix}{path}/first"));
        let second = adam.remove(&format!("{prefix}{path}/second"));
        let size = networks
            .get(&format!("{network}.{path}"))
            .map(|(_, values)| values.len());
        match (first, second, size) {
            (Some((_, first)), Some((_, second)), Some(n))
                if first.len() == n && second.len() == n =>
            {
                moments.insert(path, Moments { first, second });
            }
            _ => {
                return Err(ArtifactError::Invalid(format!(
                    "{ADAM}: the moments of `{name}/{path}` do not match a parameter of `{network}`"
                )));
            }
        }
    }
    Ok(AdamState {
        time: state.adam_time.get(name).copied().unwrap_or(0),
        moments,
    })
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
