//! Shipped behaviour policies, the checkpoints each dataset recipe runs:
//! `<root>/<task>/<level>.{safetensors,json}` (a policy artifact, copied
//! byte for byte from the online run's checkpoint, its provenance naming the
//! run's settings and seed, the step and the evaluation) and
//! `<root>/<task>/levels.json`, each level's pick against the expert's return.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use super::ArtifactError;
use super::json_file::{read_versioned_json, write_json};
use super::online_run::RunPolicy;
use super::policy::{PolicyMetadata, load_policy};
use super::safetensors_file::write_bytes;
use crate::agent::Actor;
use crate::data::{BehaviourLevel, BehaviourPick};
use crate::envs::{MujocoTask, TaskConfig, TaskName};

pub const BEHAVIOUR_SCHEMA_VERSION: u32 = 1;
const LEVELS: &str = "levels.json";

/// `levels.json`: what each shipped level is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BehaviourIndex {
    pub schema_version: u32,
    pub task: TaskName,
    pub levels: BTreeMap<String, BehaviourEntry>,
}

/// One shipped level.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BehaviourEntry {
    pub pick: BehaviourPick,
    /// The run it came from, as given to `collect select`.
    pub run: String,
    pub weights_sha256: String,
}

/// A behaviour policy loaded for a recipe.
pub struct Behaviour {
    pub actor: Actor,
    pub metadata: PolicyMetadata,
    pub entry: BehaviourEntry,
    /// The policy's files, for the dataset's metadata.
    pub path: PathBuf,
}

/// The directory of `task`'s behaviour policies under `root`.
pub fn behaviour_dir(root: &Path, task: TaskName) -> PathBuf {
    root.join(task.as_str())
}

/// The built-in task a behaviour policy acts in (behaviour policies are
/// D4RL's and NeoRL's recipes, which only the built-in tasks have).
fn built_in(task: TaskConfig, run: &Path) -> Result<TaskName, ArtifactError> {
    task.task.built_in().ok_or_else(|| {
        ArtifactError::Invalid(format!(
            "{}: behaviour policies are picked for the built-in tasks, not for `{}`",
            run.display(),
            task.task
        ))
    })
}

/// Copies `policy` (from `run`) into `root` as `level`, and records the pick.
pub fn save_behaviour(
    root: &Path,
    run: &Path,
    policy: &RunPolicy,
    level: BehaviourLevel,
    pick: &BehaviourPick,
) -> Result<PathBuf, ArtifactError> {
    let task = built_in(policy.metadata.simulated_task(run)?, run)?;
    let dir = behaviour_dir(root, task);
    std::fs::create_dir_all(&dir).map_err(|e| ArtifactError::io(&dir, e))?;
    let index_path = dir.join(LEVELS);
    let mut index = if index_path.exists() {
        read_index(&dir)?
    } else {
        BehaviourIndex {
            schema_version: BEHAVIOUR_SCHEMA_VERSION,
            task,
            levels: BTreeMap::new(),
        }
    };
    if index.task != task {
        return Err(ArtifactError::Invalid(format!(
            "{}: the behaviour policies there are for {}, this run is {task}",
            index_path.display(),
            index.task
        )));
    }
    for ext in ["safetensors", "json"] {
        let from = policy.dir.join(format!("{}.{ext}", policy.stem));
        let bytes = std::fs::read(&from).map_err(|e| ArtifactError::io(&from, e))?;
        write_bytes(&dir.join(format!("{level}.{ext}")), &bytes)?;
    }
    index.levels.insert(
        level.to_string(),
        BehaviourEntry {
            pick: *pick,
            run: run.display().to_string(),
            weights_sha256: policy.metadata.weights_sha256.clone(),
        },
    );
    write_json(&index_path, &index)?;
    Ok(dir.join(format!("{level}.safetensors")))
}

/// Loads `task`'s `level` from `root`, checking it is a policy for that task
/// with the task's widths.
pub fn load_behaviour(
    root: &Path,
    task: TaskName,
    level: BehaviourLevel,
    device: &Device,
) -> Result<Behaviour, ArtifactError> {
    let dir = behaviour_dir(root, task);
    if !dir.join(LEVELS).exists() {
        return Err(ArtifactError::Invalid(format!(
            "{}: no behaviour policies for {task} (make them with `nuno-trainer collect online-sac` \
             and `collect select`)",
            dir.display()
        )));
    }
    let index = read_index(&dir)?;
    let entry = index.levels.get(level.as_str()).cloned().ok_or_else(|| {
        let known: Vec<&String> = index.levels.keys().collect();
        ArtifactError::Invalid(format!(
            "{}: no `{level}` behaviour policy for {task} (shipped: {known:?})",
            dir.display()
        ))
    })?;
    let (actor, metadata) = load_policy(&dir, level.as_str(), device)?;
    let policy_task = metadata.simulated_task(&dir)?;
    if policy_task.task != task || index.task != task {
        return Err(ArtifactError::Invalid(format!(
            "{}: `{level}` is a policy for {}, not {task}",
            dir.display(),
            policy_task.task
        )));
    }
    let probe = MujocoTask::new(&policy_task).map_err(|e| ArtifactError::Invalid(e.to_string()))?;
    let c = &actor.config;
    if (c.obs_dim, c.act_dim) != (probe.obs_dim(), probe.act_dim()) {
        return Err(ArtifactError::Invalid(format!(
            "{}: `{level}` takes observations of width {} and gives actions of width {}; {task} ({:?} layout) has {} and {}",
            dir.display(),
            c.obs_dim,
            c.act_dim,
            policy_task.layout,
            probe.obs_dim(),
            probe.act_dim()
        )));
    }
    if entry.weights_sha256 != metadata.weights_sha256 {
        return Err(ArtifactError::Invalid(format!(
            "{}: `{level}`'s weights are not the ones {LEVELS} records",
            dir.display()
        )));
    }
    Ok(Behaviour {
        actor,
        metadata,
        entry,
        path: dir.join(format!("{level}.safetensors")),
    })
}

fn read_index(dir: &Path) -> Result<BehaviourIndex, ArtifactError> {
    read_versioned_json(&dir.join(LEVELS), BEHAVIOUR_SCHEMA_VERSION)
}
