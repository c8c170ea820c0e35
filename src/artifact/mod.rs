//! Files nuno writes and reads back: model artifacts as safetensors plus JSON
//! metadata, validated on load, and the atomic write every file goes through,
//! so a reader never sees a half-written file.

mod behaviour;
mod checkpoint;
mod dynamics;
mod ensemble;
mod ensemble_checkpoint;
mod fit_checkpoint;
mod json_file;
mod model_folder;
mod model_free_checkpoint;
mod online_run;
mod policy;
mod sac_state;
mod safetensors_file;
mod sde_checkpoint;
mod tensors;

use std::path::{Path, PathBuf};

pub use behaviour::{
    BEHAVIOUR_SCHEMA_VERSION, Behaviour, BehaviourEntry, BehaviourIndex, behaviour_dir,
    load_behaviour, save_behaviour,
};
pub use checkpoint::{CHECKPOINT_SCHEMA_VERSION, load_checkpoint, save_checkpoint};
pub use dynamics::{
    DYNAMICS_METADATA, DYNAMICS_SCHEMA_VERSION, DYNAMICS_WEIGHTS, DatasetInfo, DynamicsMetadata,
    DynamicsProvenance, load_dynamics, read_dynamics_metadata, save_dynamics, sha256_file,
    sha256_hex,
};
pub use ensemble::{
    ENSEMBLE_METADATA, ENSEMBLE_SCHEMA_VERSION, ENSEMBLE_WEIGHTS, EnsembleMetadata, load_ensemble,
    save_ensemble,
};
pub use ensemble_checkpoint::{
    ENSEMBLE_CHECKPOINT_SCHEMA_VERSION, EnsembleFitShape, load_ensemble_checkpoint,
    save_ensemble_checkpoint,
};
pub use json_file::{
    read_checked_weights, read_versioned_json, read_versioned_json_filled, write_json,
};
pub use model_folder::ModelFolder;
pub use model_free_checkpoint::{
    MODEL_FREE_CHECKPOINT_SCHEMA_VERSION, load_model_free_checkpoint, save_model_free_checkpoint,
};
pub use online_run::{
    ONLINE_RUN_SCHEMA_VERSION, OnlineRunInfo, RunPolicy, RunSnapshot, load_online_checkpoint,
    read_online_run, read_run_transitions, run_policies, save_online_checkpoint,
    snapshot_online_run, start_online_run,
};
pub use policy::{
    BEST_POLICY, LAST_POLICY, POLICY_SCHEMA_VERSION, PolicyMetadata, PolicyProvenance, has_policy,
    load_model_policy, load_policy, save_policy,
};
pub use sac_state::latest_checkpoint;
pub use safetensors_file::{parse_safetensors, parse_safetensors_with_metadata, safetensors_bytes};
pub use sde_checkpoint::{SDE_CHECKPOINT_SCHEMA_VERSION, load_sde_checkpoint, save_sde_checkpoint};
pub use tensors::{NamedTensors, collect_tensors, load_tensors};

/// Everything that can be wrong with an artifact.
#[derive(Debug, thiserror::Error)]
pub enum ArtifactError {
    #[error("{file}: {source}")]
    Io {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{file}: invalid JSON metadata: {message}")]
    Json { file: PathBuf, message: String },
    #[error(
        "{file}: schema version {found}, this build reads version {expected}; \
         re-create it with this build (`nuno-trainer fit-model` for a model, \
         `nuno-trainer fit-policy` for a policy)"
    )]
    Schema {
        file: PathBuf,
        found: String,
        expected: u32,
    },
    #[error("{file}: corrupt or truncated safetensors file: {message}")]
    Corrupt { file: PathBuf, message: String },
    #[error(
        "{file}: the weights are not the ones model.json was written for (half-written or mixed artifact)"
    )]
    HashMismatch { file: PathBuf },
    #[error("tensor `{0}` is missing from the weights")]
    MissingTensor(String),
    #[error("tensor `{0}` is not a parameter of this model")]
    UnexpectedTensor(String),
    #[error("tensor `{name}` has shape {got:?}, the model expects {expected:?}")]
    TensorShape {
        name: String,
        expected: Vec<usize>,
        got: Vec<usize>,
    },
    #[error("tensor `{name}` is {got}, expected F32")]
    TensorDtype { name: String, got: String },
    #[error("cannot serialise tensors: {0}")]
    Safetensors(String),
    #[error("invalid artifact: {0}")]
    Invalid(String),
    #[error(
        "{}: not a model folder: it holds neither model.json (a neural SDE, from \
         `nuno-trainer fit-model`) nor ensemble.json (a Gaussian ensemble, from \
         `nuno-trainer fit-ensemble`)",
        .0.display()
    )]
    NotAModel(PathBuf),
}

impl ArtifactError {
    pub(crate) fn io(file: &Path, source: std::io::Error) -> Self {
        Self::Io {
            file: file.to_path_buf(),
            source,
        }
    }
}
