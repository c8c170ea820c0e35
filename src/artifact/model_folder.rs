//! The one loader of a model folder: whichever dynamics it holds (NUNO's
//! neural SDE, `model.json` from `fit-model`; MOPO's Gaussian ensemble,
//! `ensemble.json` from `fit-ensemble`), validated, with the task it models.
//! The server, `fit-policy` and `analyze` all read model folders through it.

use std::path::Path;

use burn::tensor::Device;

use super::ArtifactError;
use super::dynamics::{DYNAMICS_METADATA, DynamicsMetadata, load_dynamics, read_dynamics_metadata};
use super::ensemble::{ENSEMBLE_METADATA, EnsembleMetadata, load_ensemble, read_ensemble_metadata};
use crate::ensemble::{EnsembleDynamics, EnsembleUncertainty};
use crate::envs::{Rules, System};
use crate::infer::Kernel;
use crate::sde::{FusedSde, NeuralSde, ThresholdTable};
use crate::shared::BatchDynamics;

/// The system a model's metadata `record` names: its file's text, else its task.
fn recorded(
    task: Option<crate::envs::TaskConfig>,
    file: Option<&str>,
    record: &str,
) -> Result<Option<System>, ArtifactError> {
    System::recorded(task, file, Path::new(record))
        .map_err(|e| ArtifactError::Invalid(e.to_string()))
}

/// A model folder's dynamics, by kind.
pub enum ModelFolder {
    NeuralSde {
        model: Box<NeuralSde>,
        metadata: Box<DynamicsMetadata>,
    },
    /// Stepped with MOPO's uncertainty (the largest member σ) as η.
    GaussianEnsemble {
        model: Box<EnsembleDynamics>,
        metadata: Box<EnsembleMetadata>,
    },
}

impl ModelFolder {
    /// The model in `dir`: its neural SDE when it holds `model.json`, its
    /// ensemble when it holds `ensemble.json`, an error naming both otherwise.
    pub fn load(dir: &Path, device: &Device) -> Result<Self, ArtifactError> {
        if dir.join(DYNAMICS_METADATA).is_file() {
            let (model, metadata) = load_dynamics(dir, device)?;
            return Ok(Self::NeuralSde {
                model: Box::new(model),
                metadata: Box::new(metadata),
            });
        }
        if dir.join(ENSEMBLE_METADATA).is_file() {
            let (fit, metadata) = load_ensemble(dir, device)?;
            let model = EnsembleDynamics::new(
                &fit,
                metadata.obs_dim,
                metadata.act_dim,
                EnsembleUncertainty::MaxAleatoric,
            );
            return Ok(Self::GaussianEnsemble {
                model: Box::new(model),
                metadata: Box::new(metadata),
            });
        }
        Err(ArtifactError::NotAModel(dir.to_path_buf()))
    }

    /// The system the folder was fitted on, where its metadata records one:
    /// a system file's text (checked again here) or a built-in task.
    pub fn system(&self) -> Result<Option<System>, ArtifactError> {
        match self {
            Self::NeuralSde { metadata, .. } => recorded(
                metadata.provenance.task.clone(),
                metadata.provenance.system.as_deref(),
                DYNAMICS_METADATA,
            ),
            Self::GaussianEnsemble { metadata, .. } => recorded(
                metadata.task.clone(),
                metadata.system.as_deref(),
                ENSEMBLE_METADATA,
            ),
        }
    }

    /// [`system`](Self::system) of the folder in `dir`, from its metadata
    /// alone (no weights read): what a policy saved there acts in.
    pub fn recorded_system(dir: &Path) -> Result<Option<System>, ArtifactError> {
        if dir.join(DYNAMICS_METADATA).is_file() {
            let metadata = read_dynamics_metadata(dir)?;
            let provenance = metadata.provenance;
            return recorded(
                provenance.task,
                provenance.system.as_deref(),
                DYNAMICS_METADATA,
            );
        }
        if dir.join(ENSEMBLE_METADATA).is_file() {
            let metadata = read_ensemble_metadata(dir)?;
            return recorded(metadata.task, metadata.system.as_deref(), ENSEMBLE_METADATA);
        }
        Err(ArtifactError::NotAModel(dir.to_path_buf()))
    }

    /// `system`'s reward and termination rules on this model's state; refused
    /// where the system's reward is learned and the model does not learn it.
    pub fn rules(&self, system: &System) -> Result<Rules, ArtifactError> {
        let rules = match self {
            Self::NeuralSde { metadata, .. } => system.rules_on(metadata.spec.dt),
            Self::GaussianEnsemble { .. } => system
                .rules()
                .map_err(|e| ArtifactError::Invalid(e.to_string()))?,
        };
        if rules.learned_reward() && !self.burn_dynamics().learns_reward() {
            return Err(ArtifactError::Invalid(format!(
                "{} learns its reward (reward.learned), but the model does not: refit it with --reward-model",
                system.name()
            )));
        }
        Ok(rules)
    }

    /// ε(h, α) computed at the fit (a neural SDE's; an ensemble has none).
    pub fn thresholds(&self) -> Option<&ThresholdTable> {
        match self {
            Self::NeuralSde { metadata, .. } => metadata.provenance.thresholds.as_ref(),
            Self::GaussianEnsemble { .. } => None,
        }
    }

    /// SHA-256 of the weights file.
    pub fn weights_sha256(&self) -> &str {
        match self {
            Self::NeuralSde { metadata, .. } => &metadata.weights_sha256,
            Self::GaussianEnsemble { metadata, .. } => &metadata.weights_sha256,
        }
    }

    /// SHA-256 of the dataset it was fitted on, when recorded.
    pub fn dataset_sha256(&self) -> Option<&str> {
        let dataset = match self {
            Self::NeuralSde { metadata, .. } => metadata.provenance.dataset.as_ref(),
            Self::GaussianEnsemble { metadata, .. } => metadata.dataset.as_ref(),
        };
        dataset.map(|d| d.sha256.as_str())
    }

    /// Each observation dimension's spread in the training data.
    pub fn observation_std(&self) -> &[f32] {
        match self {
            Self::NeuralSde { metadata, .. } => &metadata.scales.normalizer.state.std,
            Self::GaussianEnsemble { metadata, .. } => &metadata.scaler.std[..metadata.obs_dim],
        }
    }

    /// The model on burn's tensors, behind the batch interface.
    pub fn burn_dynamics(&self) -> &dyn BatchDynamics {
        match self {
            Self::NeuralSde { model, .. } => model.as_ref(),
            Self::GaussianEnsemble { model, .. } => model.as_ref(),
        }
    }

    /// The same weights on the fused CPU path, owned (a server keeps it beside
    /// the folder rather than copy the weights per request).
    pub fn fused_dynamics(&self) -> Box<dyn BatchDynamics + Send> {
        match self {
            Self::NeuralSde { model, .. } => Box::new(FusedSde::new(model)),
            Self::GaussianEnsemble { model, .. } => Box::new(model.on_fused_path()),
        }
    }

    /// The Gaussian ensemble itself (MOBILE samples its elites one by one),
    /// its networks run by `kernel`; `None` for a neural SDE.
    pub fn ensemble(&self, kernel: Kernel) -> Option<EnsembleDynamics> {
        match self {
            Self::NeuralSde { .. } => None,
            Self::GaussianEnsemble { model, .. } => Some(match kernel {
                Kernel::Fused => model.on_fused_path(),
                Kernel::Burn => model.as_ref().clone(),
            }),
        }
    }

    /// The model behind the batch interface, its networks run by `kernel`.
    pub fn dynamics(&self, kernel: Kernel) -> Box<dyn BatchDynamics + '_> {
        match kernel {
            Kernel::Fused => self.fused_dynamics(),
            Kernel::Burn => Box::new(self.burn_dynamics()),
        }
    }
}
