//! The models the server answers for: every subdirectory of the models
//! directory holding a valid neural SDE (`model.json` + `dynamics.safetensors`)
//! or, failing that, a Gaussian ensemble (`ensemble.json` +
//! `ensemble.safetensors`), and, when present, `policy.json` +
//! `policy.safetensors`. Both kinds answer the same routes through
//! [`BatchDynamics`]. Reloading builds a complete new set and swaps it in
//! atomically; a model that fails to load keeps its previous version, so a
//! half-written artifact is never served.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, RwLock};

use burn::tensor::Device;
use serde::Serialize;
use utoipa::ToSchema;

use crate::agent::FusedActor;
use crate::agent::{ActionMode, Actor, ActorPolicy};
use crate::artifact::{ArtifactError, ModelFolder, PolicyMetadata, load_model_policy};
use crate::envs::{Rules, System};
use crate::infer::Kernel;
use crate::sde::ThresholdTable;
use crate::shared::{BatchDynamics, BatchPolicy};

/// Which kind of dynamics model is served (`kind` in `/v1/models/{id}`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize, ToSchema)]
#[serde(rename_all = "kebab-case")]
pub enum ModelKind {
    /// NUNO's neural SDE (`fit-model`): η is the distance-aware uncertainty.
    NeuralSde,
    /// MOPO's Gaussian ensemble (`fit-ensemble`): η is MOPO's max ‖σᵢ‖, the
    /// state carries the reward (as NUNO^R's), one step per environment step.
    GaussianEnsemble,
}

/// One servable model.
pub struct LoadedModel {
    pub id: String,
    /// The folder's dynamics, as loaded.
    pub folder: ModelFolder,
    /// The same weights on the fused CPU path, when the server uses it.
    fused: Option<Box<dyn BatchDynamics + Send>>,
    /// The task or the file's system it models.
    pub system: System,
    pub rules: Rules,
    /// The action box, `(low, high)` per action: requests' actions are clipped into it.
    pub action_space: Vec<(f32, f32)>,
    pub policy: Option<(Actor, PolicyMetadata)>,
    /// Seconds of the task one model step covers.
    pub step_seconds: f64,
    /// The policy on the fused CPU path, when the server uses it.
    fused_actor: Option<FusedActor>,
}

impl LoadedModel {
    pub fn kind(&self) -> ModelKind {
        match self.folder {
            ModelFolder::NeuralSde { .. } => ModelKind::NeuralSde,
            ModelFolder::GaussianEnsemble { .. } => ModelKind::GaussianEnsemble,
        }
    }

    /// The dynamics as requests step them (the server's [`Kernel`]).
    pub fn batch_dynamics(&self) -> &dyn BatchDynamics {
        match &self.fused {
            Some(fused) => fused.as_ref(),
            None => self.folder.burn_dynamics(),
        }
    }

    pub fn obs_dim(&self) -> usize {
        self.batch_dynamics().obs_dim()
    }

    pub fn act_dim(&self) -> usize {
        self.batch_dynamics().act_dim()
    }

    /// Whether rewards come from the model (NUNO^R, the ensemble).
    pub fn reward_model(&self) -> bool {
        self.batch_dynamics().learns_reward()
    }

    /// ε(h, α) of the neural SDE; an ensemble has none.
    pub fn thresholds(&self) -> Option<&ThresholdTable> {
        self.folder.thresholds()
    }

    /// Each observation dimension's spread in the training data (what errors
    /// against the task are measured in).
    pub fn observation_std(&self) -> &[f32] {
        self.folder.observation_std()
    }

    /// The policy as requests run it, choosing actions by `mode`.
    pub fn batch_policy(&self, mode: ActionMode) -> Option<Box<dyn BatchPolicy>> {
        if let Some(actor) = &self.fused_actor {
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
            if !dir.is_dir() || !valid_model_id(&id) {
                continue;
            }
            match load_model(&id, &dir, self.kernel) {
                Ok(model) => {
                    next.insert(id, Arc::new(model));
                }
                // Not every folder beside the models is one.
                Err(LoadError::NotAModel) => {}
                Err(LoadError::Invalid(error)) => {
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

/// Why a folder is not served.
enum LoadError {
    NotAModel,
    Invalid(String),
}

/// The model in `dir` (through the one loader), with its policy when it has one.
fn load_model(id: &str, dir: &Path, kernel: Kernel) -> Result<LoadedModel, LoadError> {
    let device = Device::flex();
    let folder = match ModelFolder::load(dir, &device) {
        Ok(folder) => folder,
        Err(ArtifactError::NotAModel(_)) => return Err(LoadError::NotAModel),
        Err(e) => return Err(LoadError::Invalid(e.to_string())),
    };
    let invalid = |e: ArtifactError| LoadError::Invalid(e.to_string());
    let system = folder.system().map_err(invalid)?.ok_or_else(|| {
        LoadError::Invalid(
            "model.json names no task or system, so rewards and terminals are unknown".into(),
        )
    })?;
    let rules = folder.rules(&system).map_err(invalid)?;
    let action_space = system
        .shape()
        .map_err(|e| LoadError::Invalid(e.to_string()))?
        .action_space();
    let fused = kernel == Kernel::Fused;
    let dynamics = folder.burn_dynamics();
    let (obs_dim, act_dim, step_seconds) = (dynamics.obs_dim(), dynamics.act_dim(), rules.dt());
    let policy = load_model_policy(dir, obs_dim, act_dim, &device)
        .map_err(|e| LoadError::Invalid(format!("policy: {e}")))?;
    let fused_actor = policy.as_ref().filter(|_| fused).map(|(actor, _)| {
        FusedActor::new(&ActorPolicy {
            actor: actor.clone(),
            mode: ActionMode::default(),
        })
    });
    Ok(LoadedModel {
        id: id.to_string(),
        fused: fused.then(|| folder.fused_dynamics()),
        folder,
        system,
        rules,
        action_space,
        policy,
        step_seconds,
        fused_actor,
    })
}
