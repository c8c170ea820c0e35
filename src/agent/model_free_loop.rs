//! The model-free offline methods' loop (BC, TD3+BC, CQL, EDAC), one epoch at a time so
//! a caller can checkpoint between epochs, as the model-based loop
//! ([`super::PolicyTraining`]) runs but with no model and no rollouts:
//!
//! ```text
//! every step: one update on a batch of dataset transitions (states normalised
//!     by the dataset's mean and std + 1e-3 where the method asks for it)
//! every epoch: evaluate the deterministic policy in the simulator
//! ```
//!
//! Its epochs are [`EpochRecord`]s (rollout and η fields empty), so metrics,
//! the experiment runner and the reports read them as any other run's.

use std::time::Instant;

use burn::module::{Module, Param};
use burn::nn::Linear;
use burn::tensor::{Device, Tensor, TensorData};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::AgentError;
use super::actor::{ActionMode, Actor, ActorConfig, ActorPolicy};
use super::bc::{Bc, BcConfig};
use super::cql::{Cql, CqlConfig};
use super::edac::{Edac, EdacConfig};
use super::fused_sac::FusedSac;
use super::method::Method;
use super::policy_loop::{EpochRecord, EvalSummary, PhaseSeconds};
use super::presets::edac_preset;
use super::sac::SacLosses;
use super::td3_bc::{Td3Bc, Td3BcConfig};
use crate::data::{Dataset, NormalizerConfig, Stats, TransitionSampler};
use crate::envs::{EvaluationConfig, System, TaskConfig, evaluate};
use crate::infer::Kernel;
use crate::shared::{SeedStream, derive_seed};

/// TD3+BC's (and the authors' `utils.py`'s) ε added to each state std.
const STATE_STD_EPSILON: f32 = 1e-3;

/// A model-free method and its settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "method")]
pub enum LearnerConfig {
    Bc(BcConfig),
    Td3Bc(Td3BcConfig),
    Cql(CqlConfig),
    Edac(EdacConfig),
}

impl LearnerConfig {
    /// The reference implementation's settings for a model-free `method`
    /// (EDAC's N and η at its defaults: [`LearnerConfig::for_dataset`] reads
    /// its per-task table).
    pub fn for_method(method: Method) -> Result<Self, AgentError> {
        match method {
            Method::Bc => Ok(Self::Bc(BcConfig::new())),
            Method::Td3Bc => Ok(Self::Td3Bc(Td3BcConfig::new())),
            Method::Cql => Ok(Self::Cql(CqlConfig::new())),
            Method::Edac => Ok(Self::Edac(EdacConfig::new())),
            other => Err(AgentError::Mismatch(format!(
                "{other} trains in a model, not on the dataset alone"
            ))),
        }
    }

    /// The reference's settings for `method` on the dataset of Table 3's row
    /// `preset`: EDAC's N and η from its per-task table (an error for a
    /// dataset it has none for).
    pub fn for_dataset(method: Method, preset: &str) -> Result<Self, AgentError> {
        let mut config = Self::for_method(method)?;
        if let Self::Edac(c) = &mut config {
            (c.num_critics, c.eta) = edac_preset(preset)?;
        }
        Ok(config)
    }

    pub fn method(&self) -> Method {
        match self {
            Self::Bc(_) => Method::Bc,
            Self::Td3Bc(_) => Method::Td3Bc,
            Self::Cql(_) => Method::Cql,
            Self::Edac(_) => Method::Edac,
        }
    }

    /// Transitions per update.
    pub fn batch_size(&self) -> usize {
        match self {
            Self::Bc(c) => c.batch_size,
            Self::Td3Bc(c) => c.batch_size,
            Self::Cql(c) => c.sac.batch_size,
            Self::Edac(c) => c.sac.batch_size,
        }
    }

    /// The hidden sizes of its networks (actor and critics alike).
    pub fn hidden(&self) -> Vec<usize> {
        match self {
            Self::Bc(c) => c.hidden.clone(),
            Self::Td3Bc(c) => c.actor_hidden.clone(),
            Self::Cql(c) => c.sac.actor_hidden.clone(),
            Self::Edac(c) => c.sac.actor_hidden.clone(),
        }
    }

    /// Sets every network's hidden sizes.
    pub fn set_hidden(&mut self, hidden: &[usize]) {
        match self {
            Self::Bc(c) => c.hidden = hidden.to_vec(),
            Self::Td3Bc(c) => {
                (c.actor_hidden, c.critic_hidden) = (hidden.to_vec(), hidden.to_vec());
            }
            Self::Cql(CqlConfig { sac, .. }) | Self::Edac(EdacConfig { sac, .. }) => {
                (sac.actor_hidden, sac.critic_hidden) = (hidden.to_vec(), hidden.to_vec());
            }
        }
    }

    /// Sets the transitions per update.
    pub fn set_batch_size(&mut self, batch_size: usize) {
        match self {
            Self::Bc(c) => c.batch_size = batch_size,
            Self::Td3Bc(c) => c.batch_size = batch_size,
            Self::Cql(CqlConfig { sac, .. }) | Self::Edac(EdacConfig { sac, .. }) => {
                sac.batch_size = batch_size;
            }
        }
    }

    /// Whether the method trains on normalised states (TD3+BC does; BC, CQL
    /// and EDAC do not, as OfflineRL-Kit runs them).
    pub fn normalizes_states(&self) -> bool {
        matches!(self, Self::Td3Bc(_))
    }
}

/// Every knob of a model-free run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelFreeConfig {
    pub learner: LearnerConfig,
    /// Updates per epoch (evaluation and checkpoint after each).
    pub steps_per_epoch: usize,
    pub epochs: usize,
    /// Simulator evaluation episodes per epoch (0: none).
    pub eval_episodes: usize,
    pub seed: u64,
}

/// The learner of a model-free run.
pub enum Learner {
    Bc(Box<Bc>),
    Td3Bc(Box<Td3Bc>),
    Cql(Box<Cql>),
    Edac(Box<Edac>),
}

impl crate::nn::Initialised for Learner {
    fn draw_parameters(&self) {
        match self {
            Self::Bc(bc) => bc.draw_parameters(),
            Self::Td3Bc(td3) => td3.draw_parameters(),
            Self::Cql(cql) => cql.draw_parameters(),
            Self::Edac(edac) => edac.draw_parameters(),
        }
    }
}

impl Learner {
    /// The actor as it trains (on normalised states where the method normalises).
    pub fn actor(&self) -> &Actor {
        match self {
            Self::Bc(bc) => &bc.actor,
            Self::Td3Bc(td3) => &td3.actor,
            Self::Cql(cql) => &cql.sac.actor,
            Self::Edac(edac) => &edac.actor,
        }
    }

    /// A fresh learner for `actor`'s state and action box (call it inside
    /// [`crate::nn::seeded_init`] for seeded weights).
    pub fn new(actor: ActorConfig, config: &LearnerConfig, device: &Device) -> Self {
        match config {
            LearnerConfig::Bc(c) => Self::Bc(Box::new(Bc::new(actor, c.clone(), device))),
            LearnerConfig::Td3Bc(c) => Self::Td3Bc(Box::new(Td3Bc::new(actor, c.clone(), device))),
            LearnerConfig::Cql(c) => Self::Cql(Box::new(Cql::new(actor, c.clone(), device))),
            LearnerConfig::Edac(c) => Self::Edac(Box::new(Edac::new(actor, c.clone(), device))),
        }
    }

    /// One update on `batch` (states as the learner sees them), on `fused`
    /// where the epoch has the fused kernel's copy ([`Learner::fused`]).
    pub fn update(
        &mut self,
        fused: Option<&mut FusedSac>,
        batch: &crate::shared::TransitionBatch,
        rng: &mut ChaCha8Rng,
    ) -> SacLosses {
        match (self, fused) {
            (Self::Cql(cql), Some(fused)) => {
                fused.update_conservative(&cql.config.term, batch, batch.len(), rng)
            }
            (Self::Edac(edac), Some(fused)) => {
                fused.update_edac(edac.config.eta as f32, batch, rng)
            }
            (Self::Bc(bc), _) => bc.update(batch),
            (Self::Td3Bc(td3), _) => td3.update(batch, rng),
            (Self::Cql(cql), None) => cql.update(batch, rng),
            (Self::Edac(edac), None) => edac.update(batch, rng),
        }
    }

    /// The agent on the fused kernel's host buffers for an epoch of updates,
    /// where `kernel` is fused and the method has it there (CQL, EDAC).
    pub fn fused(&self, kernel: Kernel) -> Option<FusedSac> {
        match (self, kernel) {
            (Self::Cql(cql), Kernel::Fused) => Some(FusedSac::from_sac(&cql.sac)),
            (Self::Edac(edac), Kernel::Fused) => Some(FusedSac::from_edac(edac)),
            _ => None,
        }
    }

    /// Takes back the agent an epoch trained on the fused kernel.
    pub fn write_back(&mut self, fused: FusedSac) {
        match self {
            Self::Cql(cql) => fused.write_to(&mut cql.sac),
            Self::Edac(edac) => fused.write_to_edac(edac),
            Self::Bc(_) | Self::Td3Bc(_) => {}
        }
    }
}

/// The loop's whole state: what a checkpoint saves.
pub struct ModelFreeTraining {
    pub config: ModelFreeConfig,
    pub learner: Learner,
    /// The dataset's state statistics the learner sees states through (TD3+BC).
    pub state_stats: Option<Stats>,
    pub rng: ChaCha8Rng,
    /// Updates taken.
    pub step: usize,
    /// Epochs finished.
    pub epoch: usize,
    pub history: Vec<EpochRecord>,
    /// The simulator evaluations run in.
    task: Option<TaskConfig>,
}

impl ModelFreeTraining {
    /// A fresh run on `dataset` of `system`: the widths must agree, and a run
    /// that evaluates needs a simulator.
    pub fn new(
        config: ModelFreeConfig,
        dataset: &Dataset,
        system: &System,
        device: &Device,
    ) -> Result<Self, AgentError> {
        let shape = system.shape()?;
        if dataset.obs_dim() != shape.obs_dim || dataset.act_dim() != shape.act_dim {
            return Err(AgentError::Mismatch(format!(
                "the dataset has observations of width {} and actions of width {}, {} has {} and {}",
                dataset.obs_dim(),
                dataset.act_dim(),
                system.name(),
                shape.obs_dim,
                shape.act_dim
            )));
        }
        let task = system.simulator();
        if task.is_none() && config.eval_episodes > 0 {
            return Err(AgentError::Mismatch(format!(
                "{} learns from the dataset alone and is evaluated in a simulator, which {} has none of \
                 (train without evaluation with 0 evaluation episodes)",
                config.learner.method(),
                system.name()
            )));
        }
        let (low, high) = shape.action_space().into_iter().unzip();
        let actor = ActorConfig::new(shape.obs_dim, shape.act_dim, low, high);
        let learner = crate::nn::seeded_init(device, config.seed, || {
            Learner::new(actor, &config.learner, device)
        });
        let state_stats = config
            .learner
            .normalizes_states()
            .then(|| state_stats(dataset));
        Ok(Self {
            rng: ChaCha8Rng::seed_from_u64(config.seed),
            learner,
            state_stats,
            step: 0,
            epoch: 0,
            history: Vec::new(),
            task,
            config,
        })
    }

    /// The trained actor on raw observations (the state normalisation folded
    /// into its first layer), on the plain device.
    pub fn actor(&self) -> Actor {
        let actor = self.learner.actor().valid();
        match &self.state_stats {
            Some(stats) => fold_input_normalization(actor, stats),
            None => actor,
        }
    }

    /// One epoch of updates on dataset batches, then the evaluation.
    pub fn run_epoch(
        &mut self,
        dataset: &Dataset,
        kernel: Kernel,
    ) -> Result<EpochRecord, AgentError> {
        let started = Instant::now();
        let sampler = TransitionSampler::new(dataset);
        let batch_size = self.config.learner.batch_size();
        let mut losses = Vec::with_capacity(self.config.steps_per_epoch);
        let mut fused = self.learner.fused(kernel);
        for _ in 0..self.config.steps_per_epoch {
            let mut batch = sampler.sample(batch_size, &mut self.rng);
            if let Some(stats) = &self.state_stats {
                stats.normalize(&mut batch.observations);
                stats.normalize(&mut batch.next_observations);
            }
            losses.push(self.learner.update(fused.as_mut(), &batch, &mut self.rng));
            self.step += 1;
        }
        if let Some(fused) = fused {
            self.learner.write_back(fused);
        }
        let updates = started.elapsed().as_secs_f64();
        self.epoch += 1;
        let evaluating = Instant::now();
        let eval = self.evaluate(kernel)?;
        let record = EpochRecord {
            epoch: self.epoch,
            step: self.step,
            losses: SacLosses::mean(&losses),
            rollout: Default::default(),
            model_buffer: 0,
            sps: losses.len() as f64 / updates,
            eval,
            eta: Default::default(),
            seconds: PhaseSeconds {
                updates,
                evaluation: evaluating.elapsed().as_secs_f64(),
                ..PhaseSeconds::default()
            },
            bellman_penalty: None,
            adversary: None,
        };
        self.history.push(record.clone());
        Ok(record)
    }

    /// The deterministic policy in the simulator; episode seeds differ per
    /// epoch, as the model-based loop's.
    fn evaluate(&self, kernel: Kernel) -> Result<EvalSummary, AgentError> {
        let Some(task) = self.task.clone().filter(|_| self.config.eval_episodes > 0) else {
            return Ok(EvalSummary::default());
        };
        let seed = derive_seed(self.config.seed, SeedStream::EvalEpoch(self.epoch as u64));
        let policy = kernel.policy(ActorPolicy {
            actor: self.actor(),
            mode: ActionMode::Deterministic,
        });
        let config = EvaluationConfig::new(task, self.config.eval_episodes, seed);
        Ok(EvalSummary::from(&evaluate(policy.as_ref(), &config)?))
    }
}

/// The dataset's state mean and std + 1e-3 (TD3+BC's `normalize_states`).
pub fn state_stats(dataset: &Dataset) -> Stats {
    let mut stats = Stats::fit(
        dataset.observations.view(),
        &NormalizerConfig { std_floor: 0.0 },
    );
    for s in &mut stats.std {
        *s += STATE_STD_EPSILON;
    }
    stats
}

/// `actor` reading raw states where it was trained on (s − m) / σ: its first
/// layer's W ← W / σ (per input row), b ← b − m·(W / σ).
pub fn fold_input_normalization(mut actor: Actor, stats: &Stats) -> Actor {
    let first: &Linear = &actor.net.layers[0];
    let weight = first.weight.val();
    let device = weight.device();
    let [inputs, _] = weight.dims();
    let tensor =
        |v: Vec<f32>, shape: [usize; 2]| Tensor::<2>::from_data(TensorData::new(v, shape), &device);
    let inv_std = stats.std.iter().map(|s| 1.0 / s).collect();
    let weight = weight * tensor(inv_std, [inputs, 1]);
    let shift = tensor(stats.mean.clone(), [1, inputs]).matmul(weight.clone());
    let bias = first.bias.as_ref().map(|b| {
        let outputs = b.val().dims()[0];
        Param::initialized(b.id, b.val() - shift.reshape([outputs]))
    });
    actor.net.layers[0] = Linear {
        weight: Param::initialized(first.weight.id, weight),
        bias,
    };
    actor
}
