//! Behaviour cloning as OfflineRL-Kit's `run_bc.py` runs it: a deterministic
//! tanh actor regressed onto the dataset's actions, L = mean (π(s) − a)².
//!
//! The actor is SAC's [`Actor`] read through its mean head (see
//! [`super::td3_bc`]), so the policy saves, serves and evaluates as every other.

use burn::config::Config;
use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor};

use super::actor::{Actor, ActorConfig};
use super::sac::SacLosses;
use crate::nn::{Adam, AdamState, Initialised, rows_tensor};
use crate::shared::TransitionBatch;

/// BC's hyperparameters (OfflineRL-Kit's `run_bc.py`).
#[derive(Config, Debug, PartialEq)]
pub struct BcConfig {
    #[config(default = "vec![256, 256]")]
    pub hidden: Vec<usize>,
    #[config(default = 3e-4)]
    pub lr: f64,
    #[config(default = 256)]
    pub batch_size: usize,
    #[config(default = 1e-8)]
    pub adam_epsilon: f32,
}

/// The cloned policy and its optimiser.
pub struct Bc {
    pub config: BcConfig,
    pub actor: Actor,
    pub adam: AdamState,
    device: Device,
}

impl Initialised for Bc {
    fn draw_parameters(&self) {
        self.actor.draw_parameters();
    }
}

impl Bc {
    pub fn new(actor: ActorConfig, config: BcConfig, device: &Device) -> Self {
        let device = device.clone().autodiff();
        let actor = ActorConfig {
            hidden: config.hidden.clone(),
            ..actor
        }
        .init(&device);
        Self {
            config,
            actor,
            adam: AdamState::default(),
            device,
        }
    }

    pub fn device(&self) -> &Device {
        &self.device
    }

    /// L = mean over every entry of (π(s) − a)² (`F.mse_loss`).
    ///
    /// # Shapes
    /// - `obs`: `[batch, obs_dim]`, `actions`: `[batch, act_dim]`
    pub fn loss(&self, obs: Tensor<2>, actions: Tensor<2>) -> Tensor<1> {
        (self.actor.mean_action(obs) - actions)
            .powi_scalar(2)
            .mean()
    }

    /// One Adam step on `batch`; the loss is reported as the actor's.
    pub fn update(&mut self, batch: &TransitionBatch) -> SacLosses {
        let c = &self.actor.config;
        let loss = self.loss(
            rows_tensor(&batch.observations, c.obs_dim, &self.device),
            rows_tensor(&batch.actions, c.act_dim, &self.device),
        );
        let actor_loss = loss.clone().into_scalar();
        let grads = GradientsParams::from_grads(loss.backward(), &self.actor);
        self.actor = Adam::new(self.config.adam_epsilon).step_module(
            self.config.lr,
            self.actor.clone(),
            grads,
            &mut self.adam,
        );
        SacLosses {
            actor_loss,
            ..SacLosses::default()
        }
    }
}
