//! NUNO's policy optimisation loop (Section 4.3; MOPO + TATU + NUNO), one epoch
//! at a time so a caller can checkpoint between epochs:
//!
//! ```text
//! every rollout_freq steps: B starts ~ D; roll π through the SDE for h steps,
//!     r̃ = r − λ_pen·η, stop once Σ η > ε(h, α); push into D_model (last 5 rollouts)
//! every step: batch = β·256 from D ∪ (1 − β)·256 from D_model; one SAC update
//! every epoch: evaluate π in MuJoCo; η of policy/dataset/random actions on dataset states
//! ```

use std::time::Instant;

use burn::config::Config;
use burn::module::Module;
use burn::tensor::Device;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::AgentError;
use super::actor::{ActionMode, ActorConfig, ActorPolicy};
use super::buffer::ReplayBuffer;
use super::cql::ConservativeTerm;
use super::fused_sac::FusedSac;
use super::mobile::BellmanPenalty;
use super::model_rollout::{
    Halt, RolloutActions, RolloutConfig, RolloutStats, StateBox, TruncatedStep, rollout_model,
};
use super::presets::Preset;
use super::rambo::{RamboConfig, adversarial_phase, behaviour_clone};
use super::sac::{CriticBackup, Sac, SacConfig, SacLosses};
use crate::data::{Dataset, StartStateSampler, TransitionSampler};
use crate::ensemble::{
    AdversarialConfig, AdversarialEnsemble, AdversarialLosses, EnsembleDynamics,
};
use crate::envs::{
    EvaluationConfig, EvaluationReport, ForwardVelocity, RootXReward, Rules, System, evaluate,
};
use crate::infer::Kernel;
use crate::sde::{CODE_MODEL_BUFFER_FACTOR, Recipe, ThresholdTable};
use crate::shared::{
    BatchDynamics, BatchPolicy, SeedStream, TransitionBatch, derive_seed, mean_std_population,
};

/// How the actor's learning rate moves over a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ActorLrDecay {
    /// NUNO's code and its SAC.
    Constant,
    /// lr·(1 + cos(π·e/epochs))/2 in epoch e, stepped once per epoch: OfflineRL-Kit's
    /// `CosineAnnealingLR(T_max = epochs)` for MOPO's actor. A run extended on
    /// resume anneals over its new length from there on.
    Cosine,
}

crate::shared::named_enum!(ActorLrDecay, "actor learning-rate decay", ActorLrDecay::Constant => "constant", ActorLrDecay::Cosine => "cosine");

/// Which SAC settings MOPO's (and TATU+MOPO's) policy step runs with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MopoSettings {
    /// OfflineRL-Kit's `run_mopo.py`, the published baseline: actor lr 1e-4 with
    /// cosine decay, α lr 1e-4, rollouts of 50 000 starts (`KIT_MOPO`). The default.
    #[default]
    OfflinerlKit,
    /// NUNO's SAC settings (3e-4 everywhere, constant, 5000 starts): what nuno's
    /// MOPO ran before it followed OfflineRL-Kit, kept for ablations.
    Nuno,
}

crate::shared::named_enum!(MopoSettings, "MOPO settings", MopoSettings::OfflinerlKit => "offlinerl-kit", MopoSettings::Nuno => "nuno");

/// OfflineRL-Kit's MOPO (`run_mopo.py`): actor lr, α lr, the actor's decay, rollout starts.
const KIT_MOPO: (f64, f64, ActorLrDecay, usize) = (1e-4, 1e-4, ActorLrDecay::Cosine, 50_000);

/// COMBO's real fraction of each batch (`run_combo.py`'s `real-ratio`).
const COMBO_REAL_RATIO: f64 = 0.5;

/// RAMBO's real fraction of each batch and steps between rollouts (`run_rambo.py`).
const RAMBO_REAL_RATIO: f64 = 0.5;
const RAMBO_ROLLOUT_FREQ: usize = 250;

/// Every knob of the loop; defaults are Appendix C.2–C.3's.
#[derive(Config, Debug, PartialEq)]
pub struct PolicyLoopConfig {
    pub sac: SacConfig,
    /// h, the model rollout length (Table 3).
    pub horizon: usize,
    /// α, the CVaR level of the truncation threshold ε(h, α) (Table 3).
    pub cvar_alpha: f64,
    /// λ_pen, the η penalty weight (Table 3).
    pub penalty: f64,
    /// Truncate rollouts at ε(h, α) (NUNO); off keeps the penalty alone.
    #[config(default = true)]
    pub truncate: bool,
    /// Gradient steps between model rollouts.
    #[config(default = 1000)]
    pub rollout_freq: usize,
    /// Start states per model rollout: NUNO's scripts' 5000 (the TATU+MOPO base uses 50000).
    #[config(default = 5000)]
    pub rollout_batch: usize,
    /// SDE trajectories per start state.
    #[config(default = 1)]
    pub particles: usize,
    /// Rollouts the model buffer retains.
    #[config(default = 5)]
    pub retain_epochs: usize,
    /// The model buffer holds this many times `rollout_batch · horizon ·
    /// particles · retain_epochs` transitions: 1 in nuno's paper recipe, 10 in
    /// NUNO's code (`train_tatu_modelbased.py`), where it keeps 10 × as much history.
    /// Runs saved before this field used 1, and load so.
    #[config(default = 1)]
    pub model_buffer_factor: usize,
    /// The velocity the known reward reads on D4RL observations: after the step
    /// (nuno's paper recipe) or the mean over the step (NUNO's code). Runs saved
    /// before this field used the one after, and load so.
    #[config(default = "ForwardVelocity::Next")]
    pub forward_velocity: ForwardVelocity,
    /// What the known reward reads on NeoRL's observations, which hold root x:
    /// its difference (the data's own, NUNO's code's) or the velocity
    /// `forward_velocity` picks, an ablation of the 1/dt the difference puts
    /// on the SDE's noise in x. Runs saved before this field read the
    /// difference, and load so.
    #[config(default = "RootXReward::Difference")]
    pub root_x_reward: RootXReward,
    /// How the actor's learning rate moves over the run (`sac.actor_lr` at the
    /// first epoch). Runs saved before this field kept it constant, and load so.
    #[config(default = "ActorLrDecay::Constant")]
    pub actor_lr_decay: ActorLrDecay,
    /// β, the fraction of each SAC batch drawn from the real data.
    #[config(default = 0.05)]
    pub real_ratio: f64,
    /// COMBO: CQL's conservative term in each critic update, its log-sum-exp
    /// over the mixed batch and its data term over the batch's real rows (no
    /// reward penalty); `None` for every other method. Runs saved before this
    /// field had none, and load so.
    #[config(default = "None")]
    pub conservative: Option<ConservativeTerm>,
    /// MOReL: the run's threshold is a HALT's (each step's ensemble
    /// disagreement against it, a halting step kept as terminal with its
    /// reward less this κ), not an accumulated truncation's; `None` for every
    /// other method. Runs saved before this field had none, and load so.
    #[config(default = "None")]
    pub halt_penalty: Option<f64>,
    /// MOBILE: each update's model rows rewarded r − β·u(s, a), u the Bellman
    /// inconsistency over the ensemble's elites (needs
    /// [`LoopContext::ensemble`]); `None` for every other method. Runs saved
    /// before this field had none, and load so.
    #[config(default = "None")]
    pub bellman_penalty: Option<BellmanPenalty>,
    /// RAMBO: the actor cloned on the data first, then the ensemble trained
    /// against the policy every `adversary_every` steps (needs
    /// [`LoopContext::ensemble`]); `None` for every other method. Runs saved
    /// before this field had none, and load so.
    #[config(default = "None")]
    pub rambo: Option<RamboConfig>,
    /// A model step whose next observation leaves the dataset's range widened by
    /// this many times that range on each side ends its rollout as diverged
    /// ([`StateBox`]); `None` (the paper's and NUNO's code's rollouts) ends
    /// only non-finite ones. Runs saved before this field had none, and load so.
    #[config(default = "None")]
    pub state_box_margin: Option<f64>,
    /// Model next observations are clipped as the task clips its own
    /// ([`Rules::observation_clip`]: Hopper's and Walker2d's joint velocities to
    /// ±10; nothing on a task that observes them unclipped); off (the paper's
    /// and NUNO's code's rollouts) leaves them as the model gives them. Runs
    /// saved before this field clipped nothing, and load so.
    #[config(default = false)]
    pub clip_observations: bool,
    /// What the rollouts keep of the step that takes the accumulated signal
    /// past ε: dropped (the paper's Section 4.3, the default) or kept as
    /// terminal (NUNO's code). Runs saved before this field dropped it, and
    /// load so.
    #[config(default = "TruncatedStep::Drop")]
    pub truncated_step: TruncatedStep,
    /// The scale of the model's noise in the policy's rollouts; `None` (the
    /// paper's and NUNO's code's rollouts) samples at the model's own scale, 0
    /// rolls its drift (the ensemble's mean) alone, to separate the diffusion's
    /// noise from the drift's extrapolation. Runs saved before this field
    /// sampled at the model's scale, and load so.
    #[config(default = "None")]
    pub rollout_noise_scale: Option<f32>,
    /// Gradient steps per epoch.
    #[config(default = 1000)]
    pub steps_per_epoch: usize,
    /// Epochs (1000 × 1000 steps = the paper's 1M).
    #[config(default = 1000)]
    pub epochs: usize,
    /// MuJoCo evaluation episodes per epoch (for a system without a
    /// simulator: the policy's rollouts in the model).
    #[config(default = 10)]
    pub eval_episodes: usize,
    /// Steps of each in-model evaluation rollout, where the system has no
    /// simulator (D4RL's episode limit).
    #[config(default = 1000)]
    pub model_eval_horizon: usize,
    /// Dataset states on which η of policy, dataset and random actions is compared.
    #[config(default = 1000)]
    pub eta_probe_states: usize,
    #[config(default = 0)]
    pub seed: u64,
}

impl PolicyLoopConfig {
    /// These settings with `recipe`'s choices for the loop: NUNO's code keeps a
    /// 10× model buffer and rewards the mean forward velocity over a step.
    pub fn apply_recipe(&mut self, recipe: Recipe) {
        let code = recipe == Recipe::Code;
        self.model_buffer_factor = if code { CODE_MODEL_BUFFER_FACTOR } else { 1 };
        self.forward_velocity = if code {
            ForwardVelocity::Mean
        } else {
            ForwardVelocity::Next
        };
    }

    /// The settings MOPO's policy step runs with (`--algo mopo|tatu-mopo`).
    pub fn apply_mopo_settings(&mut self, settings: MopoSettings) {
        let (actor_lr, alpha_lr, decay, rollout_batch) = match settings {
            MopoSettings::OfflinerlKit => KIT_MOPO,
            MopoSettings::Nuno => {
                let nuno = Self::new(SacConfig::new(), 0, 0.0, 0.0);
                (
                    nuno.sac.actor_lr,
                    nuno.sac.alpha_lr,
                    nuno.actor_lr_decay,
                    nuno.rollout_batch,
                )
            }
        };
        self.sac.actor_lr = actor_lr;
        self.sac.alpha_lr = alpha_lr;
        self.actor_lr_decay = decay;
        self.rollout_batch = rollout_batch;
    }

    /// COMBO's policy step as OfflineRL-Kit's `run_combo.py` runs it:
    /// MOPO's SAC settings (actor lr 1e-4 cosine, α lr 1e-4, 50 000 rollout
    /// starts), no reward penalty and no truncation, half of each batch real,
    /// and the conservative term of weight β on every critic update.
    pub fn apply_combo_settings(&mut self, beta: f64) {
        self.apply_mopo_settings(MopoSettings::OfflinerlKit);
        self.penalty = 0.0;
        self.truncate = false;
        self.real_ratio = COMBO_REAL_RATIO;
        self.conservative = Some(ConservativeTerm::new().with_cql_weight(beta));
    }

    /// MOReL's pessimistic MDP in the SAC loop (OfflineRL-Kit has no MOReL; its
    /// NPG planner is replaced by MOPO's policy step): MOPO's SAC settings, no
    /// reward penalty, each step halted where the ensemble's pairwise
    /// disagreement passes the run's threshold, κ off its reward.
    pub fn apply_morel_settings(&mut self, kappa: f64) {
        self.apply_mopo_settings(MopoSettings::OfflinerlKit);
        self.penalty = 0.0;
        self.truncate = true;
        self.halt_penalty = Some(kappa);
    }

    /// MOBILE's policy step as OfflineRL-Kit's `run_mobile.py` runs it:
    /// MOPO's SAC settings, no reward penalty at rollout time and no
    /// truncation, the Bellman penalty of weight β on every update's model
    /// rows, a deterministic backup floored at 0, and α fixed where the
    /// dataset's row turns its tuning off.
    pub fn apply_mobile_settings(&mut self, beta: f64, fixed_alpha: Option<f64>) {
        self.apply_mopo_settings(MopoSettings::OfflinerlKit);
        self.penalty = 0.0;
        self.truncate = false;
        self.sac.backup = Some(CriticBackup {
            deterministic: true,
            floor: Some(0.0),
        });
        if let Some(alpha) = fixed_alpha {
            self.sac.initial_alpha = alpha;
            self.sac.alpha_lr = 0.0;
        }
        self.bellman_penalty = Some(BellmanPenalty::new(beta));
    }

    /// RAMBO's policy step as OfflineRL-Kit's `run_rambo.py` runs it: MOPO's
    /// SAC settings without the actor's decay, no reward penalty and no
    /// truncation, half of each batch real, rollouts every 250 steps, and the
    /// adversarial model update of weight `adv_weight`.
    pub fn apply_rambo_settings(&mut self, adv_weight: f64) {
        self.apply_mopo_settings(MopoSettings::OfflinerlKit);
        self.actor_lr_decay = ActorLrDecay::Constant;
        self.penalty = 0.0;
        self.truncate = false;
        self.real_ratio = RAMBO_REAL_RATIO;
        self.rollout_freq = RAMBO_ROLLOUT_FREQ;
        self.rambo = Some(RamboConfig::new(AdversarialConfig::new(adv_weight)));
    }

    /// The actor's learning rate during epoch `epoch` (from 0).
    pub fn actor_lr_at(&self, epoch: usize) -> f64 {
        match self.actor_lr_decay {
            ActorLrDecay::Constant => self.sac.actor_lr,
            ActorLrDecay::Cosine => {
                let progress = epoch as f64 / self.epochs.max(1) as f64;
                self.sac.actor_lr * 0.5 * (1.0 + (std::f64::consts::PI * progress).cos())
            }
        }
    }

    /// The loop with a preset's h, α and λ_pen.
    pub fn from_preset(preset: &Preset, sac: SacConfig) -> Self {
        Self::new(sac, preset.horizon, preset.cvar_alpha, preset.penalty)
    }

    /// ε(h, α) from a model's table when truncating, `None` otherwise.
    pub fn threshold_from(
        &self,
        table: Option<&ThresholdTable>,
    ) -> Result<Option<f32>, AgentError> {
        if !self.truncate {
            return Ok(None);
        }
        let table = table.ok_or_else(|| {
            AgentError::Threshold("the dynamics artifact has no threshold table".into())
        })?;
        let threshold = table.get(self.horizon, self.cvar_alpha).ok_or_else(|| {
            AgentError::Threshold(format!(
                "ε(h = {}, α = {}) is not in the model's table (h ∈ {:?}, α ∈ {:?})",
                self.horizon, self.cvar_alpha, table.horizons, table.alphas
            ))
        })?;
        Ok(Some(threshold))
    }

    /// The rollouts' settings, sampling at the model's own `model_noise_scale`
    /// unless the run sets its own: the run's threshold truncates on the
    /// accumulated signal, or (MOReL) halts on each step's.
    fn rollout(
        &self,
        threshold: Option<f32>,
        model_noise_scale: f32,
        (state_box, rules): (Option<&StateBox>, &Rules),
    ) -> RolloutConfig {
        let halt = (self.halt_penalty).and_then(|penalty| {
            threshold.map(|threshold| Halt {
                threshold,
                penalty: penalty as f32,
            })
        });
        RolloutConfig {
            horizon: self.horizon,
            particles: self.particles,
            penalty: self.penalty,
            threshold: threshold.filter(|_| halt.is_none()),
            noise_scale: self.rollout_noise_scale.unwrap_or(model_noise_scale),
            halt,
            state_box: state_box.cloned(),
            observation_clip: rules.observation_clip().filter(|_| self.clip_observations),
            truncated_step: self.truncated_step,
        }
    }
}

/// Mean η of three kinds of actions on the same dataset states (Figure 3).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct EtaProbe {
    pub policy: f32,
    pub dataset: f32,
    pub random: f32,
}

/// The MuJoCo evaluation of one epoch.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct EvalSummary {
    pub mean_return: f64,
    pub std_return: f64,
    /// `charts/normalized_score` (D4RL × 100; 0 in the model, which has no references).
    pub normalized_score: f64,
    pub std_normalized_score: f64,
    /// The returns are the model's own estimate: the deterministic policy
    /// rolled in the model from dataset episode starts (a system without a
    /// simulator). Absent from records written before systems.
    #[serde(default)]
    pub in_model: bool,
}

impl EvalSummary {
    /// What [`EvalSummary::score`] is, for messages and charts.
    pub fn score_name(&self) -> &'static str {
        if self.in_model {
            "return in the model"
        } else {
            "normalised score"
        }
    }

    /// What the best policy is chosen by: the normalised score in the real
    /// task, the mean return in the model.
    pub fn score(&self) -> f64 {
        if self.in_model {
            self.mean_return
        } else {
            self.normalized_score
        }
    }
}

impl From<&EvaluationReport> for EvalSummary {
    fn from(report: &EvaluationReport) -> Self {
        Self {
            mean_return: report.mean_return,
            std_return: report.std_return,
            normalized_score: report.mean_normalized_score,
            std_normalized_score: report.std_normalized_score,
            in_model: false,
        }
    }
}

/// Wall-clock seconds each phase of one epoch took.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct PhaseSeconds {
    /// SAC updates, their batches included.
    pub updates: f64,
    /// Model rollouts into the model buffer.
    pub rollouts: f64,
    /// Evaluation episodes in the real task.
    pub evaluation: f64,
    pub eta_probe: f64,
}

impl PhaseSeconds {
    /// The epoch's wall-clock seconds, all phases.
    pub fn total(&self) -> f64 {
        self.updates + self.rollouts + self.evaluation + self.eta_probe
    }
}

/// What one epoch did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpochRecord {
    pub epoch: usize,
    pub step: usize,
    /// Mean SAC losses over the epoch.
    pub losses: SacLosses,
    /// The last model rollout of the epoch.
    pub rollout: RolloutStats,
    pub model_buffer: usize,
    /// `charts/SPS`: gradient steps per second (rollouts included, evaluation not).
    pub sps: f64,
    pub eval: EvalSummary,
    pub eta: EtaProbe,
    /// Absent from records written before phases were timed.
    #[serde(default)]
    pub seconds: PhaseSeconds,
    /// MOBILE: the mean Bellman inconsistency u(s, a) over the epoch's model
    /// rows (before β); absent for every other method.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bellman_penalty: Option<f32>,
    /// RAMBO: the mean losses of the epoch's adversarial steps; absent for
    /// every other method and epochs without a phase.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adversary: Option<AdversarialLosses>,
}

/// What the loop reads but does not own.
pub struct LoopContext<'a> {
    pub dataset: &'a Dataset,
    /// The model as rollouts step it (see [`Kernel::dynamics`]).
    pub dynamics: &'a dyn BatchDynamics,
    /// The task evaluation episodes run in, or a system without a simulator.
    pub system: System,
    pub rules: Rules,
    /// What runs SAC's updates, and the policy in rollouts and evaluation episodes.
    pub kernel: Kernel,
    /// The Gaussian ensemble itself, where the method samples its elites one
    /// by one (MOBILE's penalty); `None` otherwise.
    pub ensemble: Option<&'a EnsembleDynamics>,
}

/// The loop's whole state: what a checkpoint saves.
pub struct PolicyTraining {
    pub config: PolicyLoopConfig,
    pub sac: Sac,
    pub model_buffer: ReplayBuffer,
    pub rng: ChaCha8Rng,
    /// Gradient steps taken.
    pub step: usize,
    /// Epochs finished.
    pub epoch: usize,
    /// ε(h, α), when truncating.
    pub threshold: Option<f32>,
    /// The box model rollouts stay in, where the config has a margin.
    pub state_box: Option<StateBox>,
    pub history: Vec<EpochRecord>,
    /// RAMBO: the ensemble as the adversary trains it, and as rollouts step
    /// it (in place of [`LoopContext::dynamics`]).
    pub adversary: Option<Adversary>,
}

/// RAMBO's adversarially trained ensemble and its current dynamics.
pub struct Adversary {
    pub ensemble: AdversarialEnsemble,
    pub dynamics: EnsembleDynamics,
}

impl PolicyTraining {
    /// A fresh run: checks the dataset, dynamics and task agree. `threshold`
    /// is ε, what rollouts truncate at (`None`: never); NUNO's comes from the
    /// model's table ([`PolicyLoopConfig::threshold_from`]), the baselines'
    /// from [`crate::agent::uncertainty`].
    pub fn new(
        config: PolicyLoopConfig,
        ctx: &LoopContext,
        threshold: Option<f32>,
        device: &Device,
    ) -> Result<Self, AgentError> {
        if config.truncate && threshold.is_none() {
            return Err(AgentError::Threshold(
                "the loop truncates but was given no threshold".into(),
            ));
        }
        if (config.bellman_penalty.is_some() || config.rambo.is_some()) && ctx.ensemble.is_none() {
            return Err(AgentError::Mismatch(
                "MOBILE's penalty and RAMBO's adversary work on a Gaussian ensemble's members: \
                 train them in an ensemble folder (fit-ensemble)"
                    .into(),
            ));
        }
        let adversary = (config.rambo.as_ref())
            .zip(ctx.ensemble)
            .map(|(rambo, ensemble)| Adversary {
                ensemble: AdversarialEnsemble::new(
                    ensemble,
                    rambo.adversary.clone(),
                    ctx.kernel,
                    device,
                ),
                dynamics: ensemble.clone(),
            });
        let (obs_dim, act_dim) = (ctx.dynamics.obs_dim(), ctx.dynamics.act_dim());
        if ctx.dataset.obs_dim() != obs_dim || ctx.dataset.act_dim() != act_dim {
            return Err(AgentError::Mismatch(format!(
                "the dataset has observations of width {} and actions of width {}, \
                 the dynamics model expects {} and {}",
                ctx.dataset.obs_dim(),
                ctx.dataset.act_dim(),
                obs_dim,
                act_dim
            )));
        }
        let (low, high) = ctx.system.shape()?.action_space().into_iter().unzip();
        let actor = ActorConfig::new(obs_dim, act_dim, low, high);
        let sac = crate::nn::seeded_init(device, config.seed, || {
            Sac::new(actor, config.sac.clone(), device)
        });
        let capacity = config.rollout_batch
            * config.horizon
            * config.particles
            * config.retain_epochs
            * config.model_buffer_factor;
        let state_box = (config.state_box_margin)
            .map(|margin| StateBox::around(&ctx.dataset.observation_bounds(), margin as f32));
        Ok(Self {
            model_buffer: ReplayBuffer::new(capacity, obs_dim, act_dim),
            rng: ChaCha8Rng::seed_from_u64(config.seed),
            step: 0,
            epoch: 0,
            threshold,
            state_box,
            history: Vec::new(),
            adversary,
            sac,
            config,
        })
    }

    /// The current actor as a policy on the plain device.
    pub fn policy(&self, mode: ActionMode) -> ActorPolicy {
        ActorPolicy {
            actor: self.sac.actor.valid(),
            mode,
        }
    }

    /// One epoch: `steps_per_epoch` SAC updates with model rollouts every
    /// `rollout_freq` steps, then evaluation and the η probe.
    pub fn run_epoch(&mut self, ctx: &LoopContext) -> Result<EpochRecord, AgentError> {
        let started = Instant::now();
        let mut seconds = PhaseSeconds::default();
        let mut losses = Vec::with_capacity(self.config.steps_per_epoch);
        let mut rollout = RolloutStats::default();
        let mut penalties = Vec::new();
        // The fused kernel trains on host buffers for the epoch and hands the
        // agent back to `self.sac` for rollouts, evaluation and checkpoints.
        self.sac.config.actor_lr = self.config.actor_lr_at(self.epoch);
        let mut adversarial = Vec::new();
        if let (Some(rambo), 0) = (&self.config.rambo, self.step) {
            behaviour_clone(&mut self.sac, ctx.dataset, rambo, &mut self.rng);
        }
        let fused_updates = ctx.kernel == Kernel::Fused;
        let mut fused = fused_updates.then(|| FusedSac::from_sac(&self.sac));
        for _ in 0..self.config.steps_per_epoch {
            if let Some(losses) = self.adversary_turn(ctx, fused.as_ref()) {
                adversarial.push(losses);
            }
            if self.step.is_multiple_of(self.config.rollout_freq.max(1)) {
                if let Some(fused) = &fused {
                    fused.write_actor_to(&mut self.sac);
                }
                let rolling = Instant::now();
                rollout = self.model_rollout(ctx);
                seconds.rollouts += rolling.elapsed().as_secs_f64();
            }
            let mut batch = self.mixed_batch(ctx.dataset);
            let real_rows = self.real_rows();
            if let Some(u) = self.penalize_model_rows(ctx, (&mut batch, real_rows), fused.as_mut())
            {
                penalties.push(u);
            }
            losses.push(match (fused.as_mut(), &self.config.conservative) {
                (Some(fused), Some(term)) => {
                    fused.update_conservative(term, &batch, real_rows, &mut self.rng)
                }
                (Some(fused), None) => fused.update(&batch, &mut self.rng),
                (None, Some(term)) => term.update(&mut self.sac, &batch, real_rows, &mut self.rng),
                (None, None) => self.sac.update(&batch, &mut self.rng),
            });
            self.step += 1;
        }
        if let Some(fused) = fused {
            fused.write_to(&mut self.sac);
        }
        let elapsed = started.elapsed().as_secs_f64();
        let sps = losses.len() as f64 / elapsed;
        seconds.updates = elapsed - seconds.rollouts;
        self.epoch += 1;

        let evaluating = Instant::now();
        let eval = self.evaluate(ctx)?;
        seconds.evaluation = evaluating.elapsed().as_secs_f64();
        let probing = Instant::now();
        let eta = self.eta_probe(ctx);
        seconds.eta_probe = probing.elapsed().as_secs_f64();
        let record = EpochRecord {
            epoch: self.epoch,
            step: self.step,
            losses: SacLosses::mean(&losses),
            rollout,
            model_buffer: self.model_buffer.len(),
            sps,
            eval,
            eta,
            seconds,
            bellman_penalty: (!penalties.is_empty())
                .then(|| penalties.iter().sum::<f32>() / penalties.len() as f32),
            adversary: AdversarialLosses::mean(&adversarial),
        };
        self.history.push(record.clone());
        Ok(record)
    }

    /// MOBILE: the batch's model rows (from `first_model_row` on) rewarded
    /// r − β·u(s, a), u from the target critics of the kernel that trains;
    /// returns the mean u where the batch has model rows (nothing for other methods).
    fn penalize_model_rows(
        &mut self,
        ctx: &LoopContext,
        (batch, first_model_row): (&mut TransitionBatch, usize),
        mut fused: Option<&mut FusedSac>,
    ) -> Option<f32> {
        let (Some(term), Some(ensemble)) = (&self.config.bellman_penalty, ctx.ensemble) else {
            return None;
        };
        let sac = &self.sac;
        let mut target_values = |obs: &[f32], rng: &mut ChaCha8Rng| match fused.as_deref_mut() {
            Some(fused) => fused.target_values(obs, rng),
            None => sac.target_values(obs, rng),
        };
        (first_model_row < batch.rewards.len()).then(|| {
            term.penalize(
                batch,
                first_model_row,
                ensemble,
                &mut target_values,
                &mut self.rng,
            )
        })
    }

    /// RAMBO: at every `adversary_every`-th step, one adversarial phase
    /// against the current agent (the fused kernel's, written back first),
    /// then rollouts step the ensemble it left; nothing for other methods.
    fn adversary_turn(
        &mut self,
        ctx: &LoopContext,
        fused: Option<&FusedSac>,
    ) -> Option<AdversarialLosses> {
        let rambo = self.config.rambo.as_ref()?;
        let (adversary, like) = (self.adversary.as_mut()?, ctx.ensemble?);
        if !self.step.is_multiple_of(rambo.adversary_every.max(1)) {
            return None;
        }
        if let Some(fused) = fused {
            fused.write_to(&mut self.sac);
        }
        let losses = adversarial_phase(
            &mut adversary.ensemble,
            &self.sac,
            (ctx.dataset, &ctx.rules),
            (rambo, self.config.horizon),
            &mut self.rng,
        );
        adversary.dynamics = adversary.ensemble.dynamics(like);
        Some(losses)
    }

    /// Rolls the sampled policy through the model from dataset states into the model buffer.
    fn model_rollout(&mut self, ctx: &LoopContext) -> RolloutStats {
        let starts =
            StartStateSampler::new(ctx.dataset).sample(self.config.rollout_batch, &mut self.rng);
        let policy = ctx.kernel.policy(self.policy(ActionMode::Sampled));
        let dynamics: &dyn BatchDynamics = match &self.adversary {
            Some(adversary) => &adversary.dynamics,
            None => ctx.dynamics,
        };
        let config = self.config.rollout(
            self.threshold,
            dynamics.sample_noise_scale(),
            (self.state_box.as_ref(), &ctx.rules),
        );
        let result = rollout_model(
            dynamics,
            RolloutActions::Policy(policy.as_ref()),
            &ctx.rules
                .with_forward_reward(self.config.forward_velocity, self.config.root_x_reward),
            &starts,
            &config,
            &mut self.rng,
        );
        self.model_buffer.push(&result.transitions);
        result.stats
    }

    /// A SAC batch: ⌊β·batch⌋ real transitions first (NUNO's `int(256·0.05)` = 12),
    /// then the rest from the model buffer (all real while the model buffer is empty).
    pub fn mixed_batch(&mut self, dataset: &Dataset) -> TransitionBatch {
        let batch_size = self.config.sac.batch_size;
        let real_count = self.real_rows();
        let mut batch = TransitionSampler::new(dataset).sample(real_count, &mut self.rng);
        batch.append(
            &self
                .model_buffer
                .sample(batch_size - real_count, &mut self.rng),
        );
        batch
    }

    /// How many of a batch's first rows [`Self::mixed_batch`] draws from the real data.
    pub fn real_rows(&self) -> usize {
        let batch_size = self.config.sac.batch_size;
        if self.model_buffer.is_empty() {
            batch_size
        } else {
            ((self.config.real_ratio * batch_size as f64) as usize).min(batch_size)
        }
    }

    /// The deterministic policy in the real task, or in the model where the
    /// system has no simulator; episode seeds differ per epoch.
    fn evaluate(&self, ctx: &LoopContext) -> Result<EvalSummary, AgentError> {
        if self.config.eval_episodes == 0 {
            return Ok(EvalSummary::default());
        }
        let seed = derive_seed(self.config.seed, SeedStream::EvalEpoch(self.epoch as u64));
        let policy = ctx.kernel.policy(self.policy(ActionMode::Deterministic));
        let Some(task) = ctx.system.simulator() else {
            return Ok(self.evaluate_in_model(ctx, policy.as_ref(), seed));
        };
        let config = EvaluationConfig::new(task, self.config.eval_episodes, seed);
        Ok(EvalSummary::from(&evaluate(policy.as_ref(), &config)?))
    }

    /// The model's estimate of the policy's return: `eval_episodes` rollouts
    /// of `model_eval_horizon` steps from dataset episode starts, sampled at
    /// the model's noise, unpenalised and never truncated by η.
    fn evaluate_in_model(
        &self,
        ctx: &LoopContext,
        policy: &dyn BatchPolicy,
        seed: u64,
    ) -> EvalSummary {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let episodes = ctx.dataset.trajectories();
        let obs_dim = ctx.dataset.obs_dim();
        let starts: Vec<f32> = (0..self.config.eval_episodes)
            .flat_map(|_| {
                let start = episodes[rng.random_range(0..episodes.len())].start;
                ctx.dataset.observations.row(start).to_vec()
            })
            .collect();
        debug_assert_eq!(starts.len(), self.config.eval_episodes * obs_dim);
        let config = RolloutConfig::unpenalised(self.config.model_eval_horizon, 1, ctx.dynamics);
        let rollout = rollout_model(
            ctx.dynamics,
            RolloutActions::Policy(policy),
            &ctx.rules,
            &starts,
            &config,
            &mut rng,
        );
        let returns: Vec<f64> = (rollout.trace.rewards.iter())
            .map(|r| r.iter().map(|&x| f64::from(x)).sum())
            .collect();
        let (mean_return, std_return) = mean_std_population(&returns);
        EvalSummary {
            mean_return,
            std_return,
            in_model: true,
            ..EvalSummary::default()
        }
    }

    /// η of policy, dataset and uniformly random actions on the same dataset
    /// states (fixed per run, so epochs compare).
    fn eta_probe(&self, ctx: &LoopContext) -> EtaProbe {
        let n = self.config.eta_probe_states.min(ctx.dataset.len());
        if n == 0 {
            return EtaProbe::default();
        }
        let mut rng =
            ChaCha8Rng::seed_from_u64(derive_seed(self.config.seed, SeedStream::EtaProbe));
        let d = ctx.dataset;
        let rows: Vec<usize> = (0..n).map(|_| rng.random_range(0..d.len())).collect();
        let obs: Vec<f32> = rows
            .iter()
            .flat_map(|&i| d.observations.row(i).to_vec())
            .collect();
        let dataset_actions: Vec<f32> = rows
            .iter()
            .flat_map(|&i| d.actions.row(i).to_vec())
            .collect();
        let policy = self.policy(ActionMode::Deterministic);
        let policy_actions = policy.act(&obs, &mut rng);
        let c = &policy.actor.config;
        let random_actions: Vec<f32> = (0..n)
            .flat_map(|_| {
                c.action_low
                    .iter()
                    .zip(&c.action_high)
                    .map(|(l, h)| l + (h - l) * rng.random::<f32>())
                    .collect::<Vec<_>>()
            })
            .collect();
        let mean_eta = |actions: &[f32]| mean_eta(ctx.dynamics, &obs, actions);
        EtaProbe {
            policy: mean_eta(&policy_actions),
            dataset: mean_eta(&dataset_actions),
            random: mean_eta(&random_actions),
        }
    }
}

/// Mean η(s, a) over rows.
fn mean_eta(dynamics: &dyn BatchDynamics, obs: &[f32], actions: &[f32]) -> f32 {
    let states = dynamics.states_from_observations(obs);
    let noise = vec![0.0; obs.len() / dynamics.obs_dim() * dynamics.noise_dim()];
    let eta = dynamics.step(&states, actions, &noise).eta;
    eta.iter().sum::<f32>() / eta.len().max(1) as f32
}

#[cfg(test)]
mod tests {
    use super::{PolicyLoopConfig, SacConfig};
    use crate::envs::{ObservationClip, Rules, TaskConfig, TaskName, TaskRules};

    /// The loop's switch hands its rollouts the task's own clip (hopper's
    /// qvel, observations 5.. of D4RL's layout, to ±10), none when off, and
    /// none on a task that observes its velocities unclipped.
    #[test]
    fn the_loops_rollouts_clip_observations_as_the_task_does_when_asked() {
        let rules = |name| Rules::from(TaskRules::new(&TaskConfig::d4rl(name), 0.008));
        let mut config = PolicyLoopConfig::new(SacConfig::new(), 5, 0.95, 1.0);
        let clip_of = |config: &PolicyLoopConfig, name| {
            (config.rollout(None, 1.0, (None, &rules(name)))).observation_clip
        };
        assert_eq!(clip_of(&config, TaskName::Hopper), None);
        config.clip_observations = true;
        assert_eq!(
            clip_of(&config, TaskName::Hopper),
            Some(ObservationClip {
                from: 5,
                limit: 10.0
            })
        );
        assert_eq!(clip_of(&config, TaskName::HalfCheetah), None);
    }

    /// Rollouts sample at the model's own noise scale unless the run sets one.
    #[test]
    fn the_loops_rollouts_sample_at_the_models_noise_unless_the_run_sets_its_own() {
        let rules = Rules::from(TaskRules::new(&TaskConfig::d4rl(TaskName::Hopper), 0.008));
        let mut config = PolicyLoopConfig::new(SacConfig::new(), 5, 0.95, 1.0);
        let scale =
            |config: &PolicyLoopConfig| config.rollout(None, 0.7, (None, &rules)).noise_scale;
        assert_eq!(scale(&config), 0.7);
        config.rollout_noise_scale = Some(0.0);
        assert_eq!(scale(&config), 0.0);
    }
}
