//! Policies and NUNO's offline policy optimisation (Section 4.3, Appendix
//! C.2–C.3): SAC trained on penalised, truncated neural-SDE rollouts mixed
//! with real data. Everything that runs a policy goes through [`BatchPolicy`];
//! model rollouts step the dynamics through [`crate::shared::BatchDynamics`].

mod actor;
mod bc;
mod buffer;
mod cql;
mod critic;
mod edac;
mod fused_actor;
mod fused_sac;
mod method;
mod mobile;
mod model_free_loop;
mod model_rollout;
mod model_step;
mod online_sac;
mod policy;
mod policy_loop;
mod portable_actor;
mod presets;
mod rambo;
mod sac;
mod td3_bc;
mod uncertainty;

pub(crate) use actor::action_noise;
pub use actor::{ActionMode, Actor, ActorConfig, ActorPolicy, ActorSample};
pub use bc::{Bc, BcConfig};
pub use buffer::ReplayBuffer;
pub use cql::{ConservativeTerm, Cql, CqlConfig, CqlSamples};
pub use critic::{Temperature, TwinCritic};
pub use edac::{CriticEnsemble, Edac, EdacConfig};
pub use fused_actor::FusedActor;
pub use fused_sac::{FusedGradients, FusedSac};
pub use method::{Method, Truncation};
pub use mobile::{BellmanPenalty, bellman_inconsistency};
pub use model_free_loop::{
    Learner, LearnerConfig, ModelFreeConfig, ModelFreeTraining, fold_input_normalization,
    state_stats,
};
pub use model_rollout::{
    Halt, JudgedRow, ModelRollout, RolloutActions, RolloutConfig, RolloutStats, RolloutTrace,
    StateBox, StepOutcome, TruncatedStep, judge_row, rollout_model, rollout_model_or_cancel,
};
pub use model_step::{
    ParticleConfig, ParticleStep, particle_terms, penalized_reward, sample_particles,
    step_particles,
};
pub use online_sac::{OnlineRecord, OnlineSac, OnlineSacConfig, OnlineSeconds};
pub use policy::RandomPolicy;
pub use policy_loop::{
    ActorLrDecay, Adversary, EpochRecord, EtaProbe, EvalSummary, LoopContext, MopoSettings,
    PhaseSeconds, PolicyLoopConfig, PolicyTraining,
};
pub use portable_actor::PortableActor;
pub use presets::{
    COMBO_PRESETS, EDAC_PRESETS, MOBILE_PRESETS, MOPO_PRESETS, MOREL_PESSIMISM, PRESETS, Preset,
    RAMBO_PRESETS, TATU_DEFAULT_PESSIMISM, TATU_PESSIMISM, combo_preset, edac_preset,
    mobile_preset, mopo_preset, preset, rambo_preset, tatu_pessimism,
};
pub use rambo::{RamboConfig, advantages, adversarial_phase, behaviour_clone, standardise};
pub use sac::{
    CriticBackup, PolicyHalf, PolicyLosses, Sac, SacAdam, SacConfig, SacLosses, actor_loss,
    alpha_loss,
};
pub use td3_bc::{Td3Bc, Td3BcAdam, Td3BcConfig};
pub use uncertainty::{
    AleatoricAsEta, RunThreshold, dataset_max_threshold, rollout_threshold, run_threshold,
};

/// Everything that can go wrong setting up or running policy optimisation.
#[derive(Debug, thiserror::Error)]
pub enum AgentError {
    #[error("unknown preset `{name}` (known: {known})")]
    UnknownPreset { name: String, known: String },
    #[error("{0}")]
    Mismatch(String),
    #[error("truncation threshold: {0}")]
    Threshold(String),
    #[error(transparent)]
    Env(#[from] crate::envs::EnvError),
}
