//! TD3+BC (Fujimoto & Gu, 2021): TD3's twin critics and delayed deterministic
//! actor, the actor's loss given a behaviour-cloning term and its Q term scaled
//! by λ = α / mean|Q₁(s, π(s))|. Defaults are the authors' `main.py` (=
//! OfflineRL-Kit's `run_td3bc.py` and d3rlpy's), states normalised by the caller.
//!
//! The actor is SAC's [`Actor`] read through its mean head, a = centre +
//! half·tanh(μ(s)): the same network as the authors' `max_action·tanh(Linear)`
//! on a symmetric box, so the policy saves, serves and evaluates as every
//! other; its log σ head gets no gradient and stays as initialised.

use burn::config::Config;
use burn::module::Module;
use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor, TensorData};
use rand_chacha::ChaCha8Rng;

use super::actor::{Actor, ActorConfig};
use super::critic::TwinCritic;
use super::sac::SacLosses;
use crate::nn::{Adam, AdamState, Initialised, normal, polyak_update, rows_tensor};
use crate::shared::TransitionBatch;

/// TD3+BC's hyperparameters (the authors' `main.py`).
#[derive(Config, Debug, PartialEq)]
pub struct Td3BcConfig {
    #[config(default = "vec![256, 256]")]
    pub actor_hidden: Vec<usize>,
    #[config(default = "vec![256, 256]")]
    pub critic_hidden: Vec<usize>,
    #[config(default = 0.99)]
    pub gamma: f64,
    /// τ, the Polyak rate of the target actor and critics (on actor steps).
    #[config(default = 0.005)]
    pub tau: f64,
    #[config(default = 3e-4)]
    pub actor_lr: f64,
    #[config(default = 3e-4)]
    pub critic_lr: f64,
    #[config(default = 256)]
    pub batch_size: usize,
    /// σ of the target policy smoothing noise, in units of the box's half-width.
    #[config(default = 0.2)]
    pub policy_noise: f64,
    /// The smoothing noise is clipped to ±this, in half-widths.
    #[config(default = 0.5)]
    pub noise_clip: f64,
    /// The actor and the targets update every this many critic updates.
    #[config(default = 2)]
    pub policy_freq: usize,
    /// α, the weight of the Q term before its normalisation (2.5 for every D4RL task).
    #[config(default = 2.5)]
    pub alpha: f64,
    #[config(default = 1e-8)]
    pub adam_epsilon: f32,
}

/// Adam's state of the actor and the critics.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Td3BcAdam {
    pub actor: AdamState,
    pub critic: AdamState,
}

/// The agent: actor and critics on the autodiff device, their targets off it.
pub struct Td3Bc {
    pub config: Td3BcConfig,
    pub actor: Actor,
    pub target_actor: Actor,
    pub critic: TwinCritic,
    pub target_critic: TwinCritic,
    pub adam: Td3BcAdam,
    /// Critic updates taken (the actor steps on every `policy_freq`-th).
    pub updates: usize,
    /// The last actor step's loss, reported on the critic-only updates too so
    /// an epoch's mean is the actor steps' mean.
    pub last_actor_loss: f32,
    device: Device,
}

impl Initialised for Td3Bc {
    fn draw_parameters(&self) {
        self.actor.draw_parameters();
        self.target_actor.draw_parameters();
        self.critic.draw_parameters();
        self.target_critic.draw_parameters();
    }
}

impl Td3Bc {
    /// A new agent for `actor`'s state and action box; the networks train on
    /// `device`'s autodiff version, the targets start as their copies.
    pub fn new(actor: ActorConfig, config: Td3BcConfig, device: &Device) -> Self {
        let device = device.clone().autodiff();
        let actor = ActorConfig {
            hidden: config.actor_hidden.clone(),
            ..actor
        }
        .init(&device);
        let (obs_dim, act_dim) = (actor.config.obs_dim, actor.config.act_dim);
        let critic = TwinCritic::init(obs_dim, act_dim, &config.critic_hidden, &device);
        Self {
            target_actor: actor.valid(),
            target_critic: critic.valid(),
            actor,
            critic,
            adam: Td3BcAdam::default(),
            updates: 0,
            last_actor_loss: 0.0,
            config,
            device,
        }
    }

    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The critic target, off the graph:
    /// y = r + γ(1 − d)·min_i Q̄_i(s', clip(π̄(s') + clip(σε, ±c), box)),
    /// σ and c in half-widths of the box, for given ε ~ N(0, I).
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
        let c = &self.target_actor.config;
        let (half, _) = c.box_half_center();
        let row = |v: Vec<f32>| {
            Tensor::<2>::from_data(TensorData::new(v, [1, c.act_dim]), &next_obs.device())
        };
        let (half, low, high) = (
            row(half),
            row(c.action_low.clone()),
            row(c.action_high.clone()),
        );
        let clip = self.config.noise_clip as f32;
        let smoothing = (noise * self.config.policy_noise).clamp(-clip, clip) * half;
        let next_action = (self.target_actor.mean_action(next_obs.clone()) + smoothing)
            .max_pair(low)
            .min_pair(high);
        let next_value = self.target_critic.min_q(next_obs, next_action);
        rewards + (terminals.neg() + 1.0) * next_value * self.config.gamma
    }

    /// L_π = −λ·mean Q₁(s, π(s)) + mean (π(s) − a)², λ = α / mean|Q₁(s, π(s))|
    /// taken off the graph (`TD3_BC.py`); the BC term is the authors'
    /// `F.mse_loss(pi, action)`, a mean over every entry. Returns (L_π, λ).
    pub fn actor_loss(&self, obs: Tensor<2>, dataset_actions: Tensor<2>) -> (Tensor<1>, f32) {
        let action = self.actor.mean_action(obs.clone());
        let (q1, _) = self.critic.forward(obs, action.clone());
        let lambda = self.config.alpha as f32
            / q1.clone()
                .abs()
                .mean()
                .into_scalar::<f32>()
                .max(f32::MIN_POSITIVE);
        let bc = (action - dataset_actions).powi_scalar(2).mean();
        ((q1.mean() * (-lambda)) + bc, lambda)
    }

    /// One update on `batch` (states already normalised): the critics every
    /// call; the actor and the Polyak targets every `policy_freq`-th.
    pub fn update(&mut self, batch: &TransitionBatch, rng: &mut ChaCha8Rng) -> SacLosses {
        let c = &self.actor.config;
        let (obs_dim, act_dim) = (c.obs_dim, c.act_dim);
        let b = batch.rewards.len();
        let device = self.device.clone();
        let plain = device.clone().inner();
        let obs = rows_tensor(&batch.observations, obs_dim, &device);
        let actions = rows_tensor(&batch.actions, act_dim, &device);
        let adam = Adam::new(self.config.adam_epsilon);

        let y = self.critic_target(
            rows_tensor(&batch.next_observations, obs_dim, &plain),
            rows_tensor(&batch.rewards, 1, &plain),
            rows_tensor(&batch.terminals, 1, &plain),
            normal([b, act_dim], rng, &plain),
        );
        let (q1, q2) = self.critic.forward(obs.clone(), actions.clone());
        let qf1_values = q1.clone().mean().into_scalar::<f32>();
        let qf1_loss = (q1 - y.clone()).powi_scalar(2).mean();
        let qf2_loss = (q2 - y).powi_scalar(2).mean();
        let grads = GradientsParams::from_grads(
            (qf1_loss.clone() + qf2_loss.clone()).backward(),
            &self.critic,
        );
        self.critic = adam.step_module(
            self.config.critic_lr,
            self.critic.clone(),
            grads,
            &mut self.adam.critic,
        );
        self.updates += 1;
        if self.updates.is_multiple_of(self.config.policy_freq.max(1)) {
            let (actor_loss, _) = self.actor_loss(obs, actions);
            self.last_actor_loss = actor_loss.clone().into_scalar();
            let grads = GradientsParams::from_grads(actor_loss.backward(), &self.actor);
            self.actor = adam.step_module(
                self.config.actor_lr,
                self.actor.clone(),
                grads,
                &mut self.adam.actor,
            );
            let tau = self.config.tau;
            self.target_critic = polyak_update(self.target_critic.clone(), &self.critic, tau);
            self.target_actor = polyak_update(self.target_actor.clone(), &self.actor, tau);
        }
        SacLosses {
            qf1_values,
            qf1_loss: qf1_loss.into_scalar(),
            qf2_loss: qf2_loss.into_scalar(),
            actor_loss: self.last_actor_loss,
            ..SacLosses::default()
        }
    }
}
