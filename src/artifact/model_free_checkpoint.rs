//! Checkpoints of a model-free run (BC, TD3+BC, CQL, EDAC), one per finished epoch, laid
//! out as policy optimisation's (`checkpoints/epoch-NNNNNN/` named by
//! `LATEST`, written under a temporary name, fsynced, renamed): the learner's
//! networks and Adam moments by module path, the generator's position, the
//! counters and the history. The state statistics are the dataset's and are
//! computed again on resume.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::json_file::{read_checked_weights, read_versioned_json, write_json};
use super::sac_state::{RngState, put_moments, save_checkpoint_dir, take_moments, write_synced};
use super::safetensors_file::safetensors_bytes;
use super::tensors::{NamedTensors, collect_tensors, load_tensors};
use super::{ArtifactError, sha256_hex};
use crate::agent::{EpochRecord, Learner, ModelFreeConfig, ModelFreeTraining};
use crate::nn::AdamState;

pub const MODEL_FREE_CHECKPOINT_SCHEMA_VERSION: u32 = 1;
const NETWORKS: &str = "networks.safetensors";
const ADAM: &str = "adam.safetensors";
const STATE: &str = "state.json";

/// `state.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct ModelFreeState {
    schema_version: u32,
    config: ModelFreeConfig,
    step: usize,
    epoch: usize,
    rng: RngState,
    history: Vec<EpochRecord>,
    /// TD3+BC's critic updates and the last actor loss it reports.
    learner_updates: usize,
    last_actor_loss: f32,
    /// Adam steps taken, per optimiser.
    adam_time: BTreeMap<String, u64>,
    networks_sha256: String,
    adam_sha256: String,
}

/// The learner's networks by name (`actor`, `critic`, …) and its optimisers
/// by the network each steps.
fn networks(learner: &Learner) -> Vec<(&'static str, NamedTensors)> {
    match learner {
        Learner::Bc(bc) => vec![("actor", collect_tensors(&bc.actor))],
        Learner::Td3Bc(td3) => vec![
            ("actor", collect_tensors(&td3.actor)),
            ("target_actor", collect_tensors(&td3.target_actor)),
            ("critic", collect_tensors(&td3.critic)),
            ("target_critic", collect_tensors(&td3.target_critic)),
        ],
        Learner::Cql(cql) => vec![
            ("actor", collect_tensors(&cql.sac.actor)),
            ("critic", collect_tensors(&cql.sac.critic)),
            ("target_critic", collect_tensors(&cql.sac.target_critic)),
            ("temperature", collect_tensors(&cql.sac.temperature)),
        ],
        Learner::Edac(edac) => vec![
            ("actor", collect_tensors(&edac.actor)),
            ("critic", collect_tensors(&edac.critics)),
            ("target_critic", collect_tensors(&edac.target_critics)),
            ("temperature", collect_tensors(&edac.temperature)),
        ],
    }
}

fn optimizers(learner: &Learner) -> Vec<(&'static str, &AdamState)> {
    match learner {
        Learner::Bc(bc) => vec![("actor", &bc.adam)],
        Learner::Td3Bc(td3) => vec![("actor", &td3.adam.actor), ("critic", &td3.adam.critic)],
        Learner::Cql(cql) => vec![
            ("actor", &cql.sac.adam.actor),
            ("critic", &cql.sac.adam.critic),
            ("temperature", &cql.sac.adam.alpha),
        ],
        Learner::Edac(edac) => vec![
            ("actor", &edac.adam.actor),
            ("critic", &edac.adam.critic),
            ("temperature", &edac.adam.alpha),
        ],
    }
}

/// Saves `training` as the newest checkpoint in `dir`.
pub fn save_model_free_checkpoint(
    dir: &Path,
    training: &ModelFreeTraining,
) -> Result<PathBuf, ArtifactError> {
    let name = format!("epoch-{:06}", training.epoch);
    save_checkpoint_dir(dir, &name, |tmp| write_contents(tmp, training))
}

fn write_contents(dir: &Path, training: &ModelFreeTraining) -> Result<(), ArtifactError> {
    let mut tensors = NamedTensors::new();
    for (prefix, network) in networks(&training.learner) {
        for (k, v) in network {
            tensors.insert(format!("{prefix}.{k}"), v);
        }
    }
    let networks = safetensors_bytes(&tensors, None)?;
    write_synced(&dir.join(NETWORKS), &networks)?;
    let mut adam = NamedTensors::new();
    let mut adam_time = BTreeMap::new();
    for (name, state) in optimizers(&training.learner) {
        adam_time.insert(name.to_string(), state.time);
        put_moments(&mut adam, &format!("{name}/"), state);
    }
    let adam = safetensors_bytes(&adam, None)?;
    write_synced(&dir.join(ADAM), &adam)?;
    let (learner_updates, last_actor_loss) = match &training.learner {
        Learner::Bc(_) | Learner::Cql(_) | Learner::Edac(_) => (0, 0.0),
        Learner::Td3Bc(td3) => (td3.updates, td3.last_actor_loss),
    };
    let state = ModelFreeState {
        schema_version: MODEL_FREE_CHECKPOINT_SCHEMA_VERSION,
        config: training.config.clone(),
        step: training.step,
        epoch: training.epoch,
        rng: RngState::of(&training.rng),
        history: training.history.clone(),
        learner_updates,
        last_actor_loss,
        adam_time,
        networks_sha256: sha256_hex(&networks),
        adam_sha256: sha256_hex(&adam),
    };
    write_json(&dir.join(STATE), &state)
}

/// Restores checkpoint directory `checkpoint` into `training`, a fresh run
/// built with the same configuration (the number of epochs may differ).
pub fn load_model_free_checkpoint(
    checkpoint: &Path,
    training: &mut ModelFreeTraining,
) -> Result<(), ArtifactError> {
    let state: ModelFreeState = read_versioned_json(
        &checkpoint.join(STATE),
        MODEL_FREE_CHECKPOINT_SCHEMA_VERSION,
    )?;
    let comparable = ModelFreeConfig {
        epochs: training.config.epochs,
        ..state.config.clone()
    };
    if comparable != training.config {
        return Err(ArtifactError::Invalid(format!(
            "{}: the checkpoint was written with a different configuration; resume with the same flags",
            checkpoint.display()
        )));
    }
    let tensors = read_checked_weights(&checkpoint.join(NETWORKS), &state.networks_sha256)?;
    let part = |prefix: &str| -> NamedTensors {
        let dotted = format!("{prefix}.");
        (tensors.iter())
            .filter_map(|(k, v)| {
                k.strip_prefix(&dotted)
                    .map(|rest| (rest.to_string(), v.clone()))
            })
            .collect()
    };
    let mut adam = read_checked_weights(&checkpoint.join(ADAM), &state.adam_sha256)?;
    let mut moments = |name: &str| -> Result<AdamState, ArtifactError> {
        let moments = take_moments(&mut adam, &format!("{name}/"), |path| {
            tensors
                .get(&format!("{name}.{path}"))
                .map(|(_, values)| values.len())
        })?;
        Ok(AdamState {
            time: state.adam_time.get(name).copied().unwrap_or(0),
            moments,
        })
    };
    restore_learner(&mut training.learner, &state, &part, &mut moments)?;
    if let Some(extra) = adam.keys().next() {
        return Err(ArtifactError::UnexpectedTensor(format!("{ADAM}: {extra}")));
    }
    training.rng = state.rng.restore();
    training.step = state.step;
    training.epoch = state.epoch;
    training.history = state.history;
    Ok(())
}

/// The learner's networks from `part` (its saved tensors by network name),
/// its Adam states from `moments` (by optimiser name), its counters from `state`.
fn restore_learner(
    learner: &mut Learner,
    state: &ModelFreeState,
    part: &dyn Fn(&str) -> NamedTensors,
    moments: &mut dyn FnMut(&str) -> Result<AdamState, ArtifactError>,
) -> Result<(), ArtifactError> {
    match learner {
        Learner::Bc(bc) => {
            let device = bc.device().clone();
            bc.actor = load_tensors(bc.actor.clone(), &part("actor"), &device)?;
            bc.adam = moments("actor")?;
        }
        Learner::Td3Bc(td3) => {
            let device = td3.device().clone();
            let plain = device.clone().inner();
            td3.actor = load_tensors(td3.actor.clone(), &part("actor"), &device)?;
            td3.critic = load_tensors(td3.critic.clone(), &part("critic"), &device)?;
            td3.target_actor =
                load_tensors(td3.target_actor.clone(), &part("target_actor"), &plain)?;
            td3.target_critic =
                load_tensors(td3.target_critic.clone(), &part("target_critic"), &plain)?;
            td3.adam.actor = moments("actor")?;
            td3.adam.critic = moments("critic")?;
            td3.updates = state.learner_updates;
            td3.last_actor_loss = state.last_actor_loss;
        }
        Learner::Cql(cql) => {
            let sac = &mut cql.sac;
            let device = sac.device().clone();
            let plain = device.clone().inner();
            sac.actor = load_tensors(sac.actor.clone(), &part("actor"), &device)?;
            sac.critic = load_tensors(sac.critic.clone(), &part("critic"), &device)?;
            sac.target_critic =
                load_tensors(sac.target_critic.clone(), &part("target_critic"), &plain)?;
            sac.temperature = load_tensors(sac.temperature.clone(), &part("temperature"), &device)?;
            sac.adam.actor = moments("actor")?;
            sac.adam.critic = moments("critic")?;
            sac.adam.alpha = moments("temperature")?;
        }
        Learner::Edac(edac) => {
            let device = edac.device().clone();
            let plain = device.clone().inner();
            edac.actor = load_tensors(edac.actor.clone(), &part("actor"), &device)?;
            edac.critics = load_tensors(edac.critics.clone(), &part("critic"), &device)?;
            edac.target_critics =
                load_tensors(edac.target_critics.clone(), &part("target_critic"), &plain)?;
            edac.temperature =
                load_tensors(edac.temperature.clone(), &part("temperature"), &device)?;
            edac.adam.actor = moments("actor")?;
            edac.adam.critic = moments("critic")?;
            edac.adam.alpha = moments("temperature")?;
        }
    }
    Ok(())
}
