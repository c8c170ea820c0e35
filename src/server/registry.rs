//! The models the server answers for: every subdirectory of the models
//! directory holding a valid `model.json` + `dynamics.safetensors` (and, when
//! present, `policy.json` + `policy.safetensors`). Reloading builds a complete
//! new set and swaps it in atomically; a model that fails to load keeps its
//! previous version, so a half-written artifact is never served.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, RwLock};

use burn::tensor::Device;
use serde::Serialize;
use utoipa::ToSchema;

use crate::agent::FusedActor;
use crate::agent::{ActionMode, Actor, ActorPolicy, BatchPolicy};
use crate::artifact::{
    BEST_POLICY, DynamicsMetadata, PolicyMetadata, has_policy, load_dynamics, load_policy,
};
use crate::envs::{TaskConfig, TaskRules};
use crate::infer::Kernel;
use crate::sde::FusedSde;
use crate::sde::{BatchDynamics, NeuralSde};

/// One servable model.
pub struct LoadedModel {
    pub id: String,
    pub dynamics: NeuralSde,
    pub metadata: DynamicsMetadata,
    pub task: TaskConfig,
    pub rules: TaskRules,
    pub policy: Option<(Actor, PolicyMetadata)>,
    /// The same weights on the fused CPU path, when the server uses it.
    fused: Option<(FusedSde, Option<FusedActor>)>,
}

impl LoadedModel {
    /// The dynamics as requests step them (the server's [`Kernel`]).
    pub fn batch_dynamics(&self) -> &dyn BatchDynamics {
        match &self.fused {
            Some((fused, _)) => fused,
            None => &self.dynamics,
        }
    }

    /// The policy as requests run it, choosing actions by `mode`.
    pub fn batch_policy(&self, mode: ActionMode) -> Option<Box<dyn BatchPolicy>> {
        if let Some((_, Some(actor))) = &self.fused {
            return Some(Box::new(actor.with_mode(mode)));
        }
        let (actor, _) = self.policy.as_ref()?;
        Some(Box::new(ActorPolicy {
            actor: actor.clone(),
            mode,
        }))
    }
}

/// A model that could not be (re)loaded, and why.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct LoadFailure {
    pub id: String,
    pub error: String,
}

/// What a (re)load did.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct ReloadReport {
    /// Ids served after the reload.
    pub loaded: Vec<String>,
    /// Models that failed; a previous version, if any, is still served.
    pub failed: Vec<LoadFailure>,
}

type ModelMap = BTreeMap<String, Arc<LoadedModel>>;

/// The loaded models, swapped as a whole on reload.
pub struct ModelRegistry {
    dir: PathBuf,
    kernel: Kernel,
    models: RwLock<Arc<ModelMap>>,
    /// Serialises reloads (SIGHUP and the admin endpoint).
    reloading: std::sync::Mutex<()>,
}

/// Whether `name` may be a model id: it never reaches the filesystem from a
/// request, but directory names outside this alphabet are not served either.
pub fn valid_model_id(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 128
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
}

impl ModelRegistry {
    /// Loads every model in `dir`, to be evaluated by `kernel`.
    pub fn open(dir: &Path, kernel: Kernel) -> (Self, ReloadReport) {
        let registry = Self {
            dir: dir.to_path_buf(),
            kernel,
            models: RwLock::new(Arc::new(ModelMap::new())),
            reloading: std::sync::Mutex::new(()),
        };
        let report = registry.reload();
        (registry, report)
    }

    /// The current set of models.
    pub fn snapshot(&self) -> Arc<ModelMap> {
        match self.models.read() {
            Ok(guard) => guard.clone(),
            Err(poisoned) => poisoned.into_inner().clone(),
        }
    }

    pub fn get(&self, id: &str) -> Option<Arc<LoadedModel>> {
        self.snapshot().get(id).cloned()
    }

    /// Re-reads the models directory and swaps the new set in.
    pub fn reload(&self) -> ReloadReport {
        let _one_at_a_time = self.reloading.lock();
        let previous = self.snapshot();
        let mut next = ModelMap::new();
        let mut failed = Vec::new();
        let entries = match std::fs::read_dir(&self.dir) {
            Ok(entries) => entries.filter_map(Result::ok).map(|e| e.path()).collect(),
            Err(e) => {
                failed.push(LoadFailure {
                    id: self.dir.display().to_string(),
                    error: e.to_string(),
                });
                Vec::new()
            }
        };
        let mut dirs: Vec<PathBuf> = entries;
        dirs.sort();
        for dir in dirs {
            let Some(id) = dir.file_name().and_then(|n| n.to_str()).map(String::from) else {
                continue;
            };
            if !dir.is_dir() || !valid_model_id(&id) || !dir.join("model.json").is_file() {
                continue;
            }
            match load_model(&id, &dir, self.kernel) {
                Ok(model) => {
                    next.insert(id, Arc::new(model));
                }
                Err(error) => {
                    if let Some(old) = previous.get(&id) {
                        next.insert(id.clone(), old.clone());
                    }
                    failed.push(LoadFailure { id, error });
                }
            }
        }
        let report = ReloadReport {
            loaded: next.keys().cloned().collect(),
            failed,
        };
        let next = Arc::new(next);
        match self.models.write() {
            Ok(mut guard) => *guard = next,
            Err(poisoned) => *poisoned.into_inner() = next,
        }
        report
    }
}

fn load_model(id: &str, dir: &Path, kernel: Kernel) -> Result<LoadedModel, String> {
    let device = Device::flex();
    let (dynamics, metadata) = load_dynamics(dir, &device).map_err(|e| e.to_string())?;
    let task = metadata
        .provenance
        .task
        .ok_or("model.json names no task, so rewards and terminals are unknown")?;
    let policy = if has_policy(dir, BEST_POLICY) {
        let (actor, policy_metadata) =
            load_policy(dir, BEST_POLICY, &device).map_err(|e| format!("policy: {e}"))?;
        let spec = &metadata.spec;
        if actor.config.obs_dim != spec.obs_dim || actor.config.act_dim != spec.act_dim {
            return Err(format!(
                "policy: acts on {}→{}, the dynamics on {}→{}",
                actor.config.obs_dim, actor.config.act_dim, spec.obs_dim, spec.act_dim
            ));
        }
        Some((actor, policy_metadata))
    } else {
        None
    };
    let fused = (kernel == Kernel::Fused).then(|| {
        let actor = policy.as_ref().map(|(actor, _)| {
            FusedActor::new(&ActorPolicy {
                actor: actor.clone(),
                mode: ActionMode::default(),
            })
        });
        (FusedSde::new(&dynamics), actor)
    });
    Ok(LoadedModel {
        id: id.to_string(),
        rules: TaskRules::new(task, &metadata.spec.split, metadata.spec.dt),
        task,
        dynamics,
        metadata,
        policy,
        fused,
    })
}
