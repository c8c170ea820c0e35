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
use crate::artifact::{
    BEST_POLICY, DynamicsMetadata, ENSEMBLE_METADATA, EnsembleMetadata, PolicyMetadata, has_policy,
    load_dynamics, load_ensemble, load_policy,
};
use crate::ensemble::{EnsembleDynamics, EnsembleUncertainty};
use crate::envs::{TaskConfig, TaskRules};
use crate::infer::Kernel;
use crate::sde::{FusedSde, NeuralSde, ThresholdTable};
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

/// A served model's dynamics, by kind.
pub enum ServedDynamics {
    NeuralSde {
        model: NeuralSde,
        metadata: Box<DynamicsMetadata>,
        /// The same weights on the fused CPU path, when the server uses it.
        fused: Option<Box<FusedSde>>,
    },
    GaussianEnsemble {
        /// On the fused CPU path when the server uses it.
        model: EnsembleDynamics,
        metadata: EnsembleMetadata,
    },
}

impl ServedDynamics {
    /// The model behind the batch interface, on the fused path when loaded there.
    fn batch_dynamics(&self) -> &dyn BatchDynamics {
        match self {
            ServedDynamics::NeuralSde {
                fused: Some(fused), ..
            } => fused.as_ref(),
            ServedDynamics::NeuralSde { model, .. } => model,
            ServedDynamics::GaussianEnsemble { model, .. } => model,
        }
    }
}

/// One servable model.
pub struct LoadedModel {
    pub id: String,
    pub dynamics: ServedDynamics,
    pub task: TaskConfig,
    pub rules: TaskRules,
    pub policy: Option<(Actor, PolicyMetadata)>,
    /// Seconds of the task one model step covers.
    pub step_seconds: f64,
    /// The policy on the fused CPU path, when the server uses it.
    fused_actor: Option<FusedActor>,
}

impl LoadedModel {
    pub fn kind(&self) -> ModelKind {
        match self.dynamics {
            ServedDynamics::NeuralSde { .. } => ModelKind::NeuralSde,
            ServedDynamics::GaussianEnsemble { .. } => ModelKind::GaussianEnsemble,
        }
    }

    /// The dynamics as requests step them (the server's [`Kernel`]).
    pub fn batch_dynamics(&self) -> &dyn BatchDynamics {
        self.dynamics.batch_dynamics()
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
        match &self.dynamics {
            ServedDynamics::NeuralSde { metadata, .. } => metadata.provenance.thresholds.as_ref(),
            ServedDynamics::GaussianEnsemble { .. } => None,
        }
    }

    /// Each observation dimension's spread in the training data (what errors
    /// against the task are measured in).
    pub fn observation_std(&self) -> &[f32] {
        match &self.dynamics {
            ServedDynamics::NeuralSde { metadata, .. } => &metadata.scales.normalizer.state.std,
            ServedDynamics::GaussianEnsemble { metadata, .. } => {
                &metadata.scaler.std[..metadata.obs_dim]
            }
        }
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
            let holds_model = ["model.json", ENSEMBLE_METADATA]
                .iter()
                .any(|f| dir.join(f).is_file());
            if !dir.is_dir() || !valid_model_id(&id) || !holds_model {
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

/// The model in `dir`: its neural SDE when it holds one, else its ensemble.
fn load_model(id: &str, dir: &Path, kernel: Kernel) -> Result<LoadedModel, String> {
    let device = Device::flex();
    let fused = kernel == Kernel::Fused;
    let (dynamics, task, rules, step_seconds) = if dir.join("model.json").is_file() {
        let (model, metadata) = load_dynamics(dir, &device).map_err(|e| e.to_string())?;
        let task = metadata
            .provenance
            .task
            .ok_or("model.json names no task, so rewards and terminals are unknown")?;
        let spec = &metadata.spec;
        let rules = TaskRules::new(task, &spec.split, spec.dt);
        let dt = spec.dt;
        let fused = fused.then(|| Box::new(FusedSde::new(&model)));
        let dynamics = ServedDynamics::NeuralSde {
            model,
            metadata: Box::new(metadata),
            fused,
        };
        (dynamics, task, rules, dt)
    } else {
        let (fit, metadata) = load_ensemble(dir, &device).map_err(|e| e.to_string())?;
        let task = metadata.task;
        let rules = TaskRules::of_task(task).map_err(|e| e.to_string())?;
        let model = EnsembleDynamics::new(
            &fit,
            metadata.obs_dim,
            metadata.act_dim,
            EnsembleUncertainty::MaxAleatoric,
        );
        let model = if fused { model.on_fused_path() } else { model };
        let dynamics = ServedDynamics::GaussianEnsemble { model, metadata };
        let dt = rules.dt();
        (dynamics, task, rules, dt)
    };
    let (obs_dim, act_dim) = {
        let batch = dynamics.batch_dynamics();
        (batch.obs_dim(), batch.act_dim())
    };
    let policy = if has_policy(dir, BEST_POLICY) {
        let (actor, policy_metadata) =
            load_policy(dir, BEST_POLICY, &device).map_err(|e| format!("policy: {e}"))?;
        if actor.config.obs_dim != obs_dim || actor.config.act_dim != act_dim {
            return Err(format!(
                "policy: acts on {}→{}, the dynamics on {obs_dim}→{act_dim}",
                actor.config.obs_dim, actor.config.act_dim
            ));
        }
        Some((actor, policy_metadata))
    } else {
        None
    };
    let fused_actor = policy.as_ref().filter(|_| fused).map(|(actor, _)| {
        FusedActor::new(&ActorPolicy {
            actor: actor.clone(),
            mode: ActionMode::default(),
        })
    });
    Ok(LoadedModel {
        id: id.to_string(),
        dynamics,
        task,
        rules,
        policy,
        step_seconds,
        fused_actor,
    })
}
