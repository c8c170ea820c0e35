//! Soft actor-critic (Haarnoja et al., 2018), one update read top to bottom:
//! critic target, critic step, actor step, temperature step, Polyak targets.
//! Defaults are NUNO's (Appendix C.2, from TATU+MOPO): learning rates 3e-4,
//! γ = 0.99, τ = 0.005, batch 256, 2×256 networks, automatic α.

use burn::config::Config;
use burn::module::Module;
use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor, TensorData};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::actor::{Actor, ActorConfig};
use super::critic::{Temperature, TwinCritic};
use crate::nn::{Adam, AdamState, Initialised, normal, polyak_update, rows_tensor};
use crate::shared::TransitionBatch;

/// SAC's hyperparameters.
#[derive(Config, Debug, PartialEq)]
pub struct SacConfig {
    /// Actor hidden layers (ReLU).
    #[config(default = "vec![256, 256]")]
    pub actor_hidden: Vec<usize>,
    /// Critic hidden layers (ReLU).
    #[config(default = "vec![256, 256]")]
    pub critic_hidden: Vec<usize>,
    /// γ, the discount.
    #[config(default = 0.99)]
    pub gamma: f64,
    /// τ, the Polyak rate of the target critics.
    #[config(default = 0.005)]
    pub tau: f64,
    #[config(default = 3e-4)]
    pub actor_lr: f64,
    #[config(default = 3e-4)]
    pub critic_lr: f64,
    /// Learning rate of log α.
    #[config(default = 3e-4)]
    pub alpha_lr: f64,
    /// Transitions per update.
    #[config(default = 256)]
    pub batch_size: usize,
    /// H̄, the target entropy; `None` gives −|A| (NUNO's code uses −3 for every
    /// task through an argparse quirk; −|A| is SAC's rule).
    pub target_entropy: Option<f64>,
    /// α before any update: 1 (log α = 0), as NUNO's and TATU's SAC start when α
    /// is learned (their 0.2 is the fixed α used only without auto-tuning).
    #[config(default = 1.0)]
    pub initial_alpha: f64,
    /// Adam's ε for actor, critics and α: PyTorch's and optax's 1e-8. Absent
    /// (`None`) in policies and checkpoints written before it was a setting, whose
    /// runs used burn's default 1e-5, so they resume with the ε they had.
    #[config(default = "Some(1e-8)")]
    pub adam_epsilon: Option<f32>,
    /// The critic target's form where it is not SAC's (MOBILE's); `None`:
    /// SAC's. Runs saved before this field had none, and load so.
    pub backup: Option<CriticBackup>,
    #[config(default = -5.0)]
    pub log_std_min: f32,
    #[config(default = 2.0)]
    pub log_std_max: f32,
}

/// A critic target other than SAC's soft one.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CriticBackup {
    /// Leave the entropy term out (OfflineRL-Kit's `deterministic_backup`).
    pub deterministic: bool,
    /// Clamp the target from below (MOBILE's `clamp(target_q, 0)`).
    pub floor: Option<f32>,
}

/// burn's default Adam ε, which runs used before [`SacConfig::adam_epsilon`] existed.
const BURN_ADAM_EPSILON: f32 = 1e-5;

/// One update's losses, under CleanRL's metric names.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct SacLosses {
    /// `losses/qf1_values`: mean Q₁(s, a).
    pub qf1_values: f32,
    /// `losses/qf1_loss`, `losses/qf2_loss`: mean (Q_i(s, a) − y)².
    pub qf1_loss: f32,
    pub qf2_loss: f32,
    /// `losses/actor_loss`: mean α·log π(ã|s) − min Q(s, ã).
    pub actor_loss: f32,
    /// `losses/alpha`
    pub alpha: f32,
    /// `losses/alpha_loss`
    pub alpha_loss: f32,
    /// Mean −log π(ã|s), the policy's entropy estimate.
    pub entropy: f32,
}

impl SacLosses {
    /// The mean of each loss over `losses` (zeros when there are none).
    pub fn mean(losses: &[SacLosses]) -> SacLosses {
        if losses.is_empty() {
            return SacLosses::default();
        }
        let n = losses.len().max(1) as f32;
        let sum = |f: fn(&SacLosses) -> f32| losses.iter().map(f).sum::<f32>() / n;
        SacLosses {
            qf1_values: sum(|l| l.qf1_values),
            qf1_loss: sum(|l| l.qf1_loss),
            qf2_loss: sum(|l| l.qf2_loss),
            actor_loss: sum(|l| l.actor_loss),
            alpha: sum(|l| l.alpha),
            alpha_loss: sum(|l| l.alpha_loss),
            entropy: sum(|l| l.entropy),
        }
    }
}

/// Adam's state for the actor, the critics and log α, by module path: what a
/// checkpoint saves, and what both kernels step (`crate::nn::Adam`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SacAdam {
    pub actor: AdamState,
    pub critic: AdamState,
    pub alpha: AdamState,
}

/// The agent: networks on the autodiff device, target critics off it.
pub struct Sac {
    pub config: SacConfig,
    pub actor: Actor,
    pub critic: TwinCritic,
    /// Q̄₁, Q̄₂: Polyak averages of the critics, never differentiated.
    pub target_critic: TwinCritic,
    pub temperature: Temperature,
    pub adam: SacAdam,
    /// H̄
    pub target_entropy: f64,
    device: Device,
}

impl Initialised for Sac {
    fn draw_parameters(&self) {
        self.actor.draw_parameters();
        self.critic.draw_parameters();
        self.target_critic.draw_parameters();
        self.temperature.draw_parameters();
    }
}

impl Sac {
    /// A new agent for `actor`'s state and action box; `device` is the plain
    /// device, the networks train on its autodiff version.
    pub fn new(actor: ActorConfig, config: SacConfig, device: &Device) -> Self {
        let device = device.clone().autodiff();
        let actor_config = ActorConfig {
            hidden: config.actor_hidden.clone(),
            log_std_min: config.log_std_min,
            log_std_max: config.log_std_max,
            ..actor
        };
        let (obs_dim, act_dim) = (actor_config.obs_dim, actor_config.act_dim);
        let critic = TwinCritic::init(obs_dim, act_dim, &config.critic_hidden, &device);
        Self {
            target_critic: critic.valid(),
            actor: actor_config.init(&device),
            critic,
            temperature: Temperature::init(config.initial_alpha, &device),
            adam: SacAdam::default(),
            target_entropy: config.target_entropy.unwrap_or(-(act_dim as f64)),
            config,
            device,
        }
    }

    pub fn device(&self) -> &Device {
        &self.device
    }

    /// Adam with this agent's ε (burn's old default for runs that predate it).
    pub fn optimizer(&self) -> Adam {
        Adam::new(self.config.adam_epsilon.unwrap_or(BURN_ADAM_EPSILON))
    }

    /// The critic target, off the graph:
    /// y = r + γ(1 − d)(min_i Q̄_i(s', ã') − α·log π(ã'|s')),  ã' ~ π(·|s') drawn with `noise`
    /// (without the entropy term and at least the floor under a [`CriticBackup`]).
    ///
    /// # Shapes
    /// - `next_obs`: `[batch, obs_dim]`, `rewards`, `terminals`: `[batch, 1]`,
    ///   `noise`: `[batch, act_dim]` → `[batch, 1]`
    pub fn critic_target(
        &self,
        next_obs: Tensor<2>,
        rewards: Tensor<2>,
        terminals: Tensor<2>,
        noise: Tensor<2>,
    ) -> Tensor<2> {
        let alpha = self.temperature.alpha().inner();
        let next = self.actor.valid().sample(next_obs.clone(), noise);
        let backup = self.config.backup;
        let mut next_value = self.target_critic.min_q(next_obs, next.action);
        if !backup.is_some_and(|b| b.deterministic) {
            next_value = next_value - next.log_prob * alpha;
        }
        let y = rewards + (terminals.neg() + 1.0) * next_value * self.config.gamma;
        match backup.and_then(|b| b.floor) {
            Some(floor) => y.clamp_min(floor),
            None => y,
        }
    }

    /// min_i Q̄_i(s, ã) at ã ~ π(·|s) for every row of `observations`, ε from
    /// `rng`: the target critics' value of the policy (MOBILE's penalty samples).
    pub fn target_values(&self, observations: &[f32], rng: &mut ChaCha8Rng) -> Vec<f32> {
        let c = &self.actor.config;
        let b = observations.len() / c.obs_dim;
        let plain = self.device.clone().inner();
        let obs = Tensor::<2>::from_data(
            TensorData::new(observations.to_vec(), [b, c.obs_dim]),
            &plain,
        );
        let next = self
            .actor
            .valid()
            .sample(obs.clone(), normal([b, c.act_dim], rng, &plain));
        crate::nn::to_f32_vec(self.target_critic.min_q(obs, next.action))
    }

    /// L_Q = mean (Q₁(s, a) − y)² + mean (Q₂(s, a) − y)², returned as
    /// (L_Q, its two terms, mean Q₁).
    ///
    /// # Shapes
    /// - `obs`: `[batch, obs_dim]`, `actions`: `[batch, act_dim]`, `y`: `[batch, 1]`
    pub fn critic_loss(
        &self,
        obs: Tensor<2>,
        actions: Tensor<2>,
        y: Tensor<2>,
    ) -> (Tensor<1>, Tensor<1>, Tensor<1>, f32) {
        let (q1, q2) = self.critic.forward(obs, actions);
        let qf1_values = q1.clone().mean().into_scalar::<f32>();
        let qf1_loss = (q1 - y.clone()).powi_scalar(2).mean();
        let qf2_loss = (q2 - y).powi_scalar(2).mean();
        (
            qf1_loss.clone() + qf2_loss.clone(),
            qf1_loss,
            qf2_loss,
            qf1_values,
        )
    }

    /// The actor, α and their Adam state, for [`PolicyHalf::step`].
    pub fn policy_half(&mut self) -> (PolicyHalf<'_>, &TwinCritic) {
        let optimizer = self.optimizer();
        let half = PolicyHalf {
            actor: &mut self.actor,
            temperature: &mut self.temperature,
            adam: &mut self.adam,
            config: &self.config,
            optimizer,
            target_entropy: self.target_entropy,
        };
        (half, &self.critic)
    }

    /// One SAC update on `batch`, drawing the policy's ε from `rng`.
    pub fn update(&mut self, batch: &TransitionBatch, rng: &mut ChaCha8Rng) -> SacLosses {
        let c = &self.actor.config;
        let (obs_dim, act_dim) = (c.obs_dim, c.act_dim);
        let b = batch.rewards.len();
        let device = self.device.clone();
        let plain = device.clone().inner();
        let obs = rows_tensor(&batch.observations, obs_dim, &device);
        let actions = rows_tensor(&batch.actions, act_dim, &device);
        let adam = self.optimizer();

        let next_obs = rows_tensor(&batch.next_observations, obs_dim, &plain);
        let y = self.critic_target(
            next_obs,
            rows_tensor(&batch.rewards, 1, &plain),
            rows_tensor(&batch.terminals, 1, &plain),
            normal([b, act_dim], rng, &plain),
        );
        let alpha = self.temperature.alpha().inner();

        // Critic step.
        let (qf_loss, qf1_loss, qf2_loss, qf1_values) = self.critic_loss(obs.clone(), actions, y);
        let grads = GradientsParams::from_grads(qf_loss.backward(), &self.critic);
        self.critic = adam.step_module(
            self.config.critic_lr,
            self.critic.clone(),
            grads,
            &mut self.adam.critic,
        );

        // Actor step, through the updated critics, then the temperature's.
        let noise = normal([b, act_dim], rng, &device);
        let (half, critic) = self.policy_half();
        let policy = half.step(obs, noise, alpha.clone(), |o, a| critic.min_q(o, a));

        // Targets: Q̄ ← τ·Q + (1 − τ)·Q̄.
        self.target_critic =
            polyak_update(self.target_critic.clone(), &self.critic, self.config.tau);

        policy.losses(qf1_values, qf1_loss.into_scalar(), qf2_loss.into_scalar())
    }
}

/// What an update's actor and temperature steps change, borrowed from a
/// SAC-family agent: SAC's, CQL's and EDAC's steps are these, and differ only
/// in their critics and in whether the critics step first.
pub struct PolicyHalf<'a> {
    pub actor: &'a mut Actor,
    pub temperature: &'a mut Temperature,
    /// Only the actor's and α's moments are stepped.
    pub adam: &'a mut SacAdam,
    pub config: &'a SacConfig,
    pub optimizer: Adam,
    /// H̄
    pub target_entropy: f64,
}

/// The actor's and α's side of an update's [`SacLosses`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolicyLosses {
    pub actor_loss: f32,
    pub alpha: f32,
    pub alpha_loss: f32,
    pub entropy: f32,
}

impl PolicyLosses {
    /// The update's losses, with the critics' side.
    pub fn losses(self, qf1_values: f32, qf1_loss: f32, qf2_loss: f32) -> SacLosses {
        SacLosses {
            qf1_values,
            qf1_loss,
            qf2_loss,
            actor_loss: self.actor_loss,
            alpha: self.alpha,
            alpha_loss: self.alpha_loss,
            entropy: self.entropy,
        }
    }
}

impl PolicyHalf<'_> {
    /// One actor step on L_π, then one temperature step on L_α, with α read
    /// before either (`alpha`, off the graph, `[1, 1]`) and `min_q` the
    /// critics' min_i Q_i(s, a).
    pub fn step(
        self,
        obs: Tensor<2>,
        noise: Tensor<2>,
        alpha: Tensor<2>,
        min_q: impl FnOnce(Tensor<2>, Tensor<2>) -> Tensor<2>,
    ) -> PolicyLosses {
        let (actor_loss, log_prob) = actor_loss(self.actor, obs, noise, alpha.clone(), min_q);
        let grads = GradientsParams::from_grads(actor_loss.backward(), &*self.actor);
        *self.actor = self.optimizer.step_module(
            self.config.actor_lr,
            self.actor.clone(),
            grads,
            &mut self.adam.actor,
        );
        let log_prob = log_prob.inner();
        let entropy = -log_prob.clone().mean().into_scalar::<f32>();
        let alpha_loss = alpha_loss(self.temperature, log_prob, self.target_entropy);
        let grads = GradientsParams::from_grads(alpha_loss.backward(), &*self.temperature);
        *self.temperature = self.optimizer.step_module(
            self.config.alpha_lr,
            self.temperature.clone(),
            grads,
            &mut self.adam.alpha,
        );
        PolicyLosses {
            actor_loss: actor_loss.into_scalar(),
            alpha: alpha.into_scalar(),
            alpha_loss: alpha_loss.into_scalar(),
            entropy,
        }
    }
}

/// L_π = mean α·log π(ã|s) − min_i Q_i(s, ã), ã ~ π(·|s) drawn with `noise`,
/// `min_q` the critics' minimum; returns L_π and log π(ã|s) (`[batch, 1]`).
pub fn actor_loss(
    actor: &Actor,
    obs: Tensor<2>,
    noise: Tensor<2>,
    alpha: Tensor<2>,
    min_q: impl FnOnce(Tensor<2>, Tensor<2>) -> Tensor<2>,
) -> (Tensor<1>, Tensor<2>) {
    let sample = actor.sample(obs.clone(), noise);
    let log_prob = sample.log_prob.clone();
    let min_q = min_q(obs, sample.action);
    ((sample.log_prob * alpha - min_q).mean(), log_prob)
}

/// L_α = mean −log α·(log π(ã|s) + H̄), for `log_prob` off the graph.
pub fn alpha_loss(
    temperature: &Temperature,
    log_prob: Tensor<2>,
    target_entropy: f64,
) -> Tensor<1> {
    let log_alpha = temperature.log_alpha.val().unsqueeze::<2>();
    (log_alpha.neg() * (log_prob + target_entropy)).mean()
}
