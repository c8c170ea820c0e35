//! EDAC (An et al., 2021) as OfflineRL-Kit's `edac.py` runs it: SAC with N
//! critics (the target the minimum over all N, with the entropy term), and
//! the ensemble-gradient diversity term added to the critics' loss,
//!
//! ```text
//! ES = 1/(N − 1) · mean_batch Σ_{i≠j} ⟨g_i, g_j⟩,  g_j = ∇_a Q_j(s, a) / (‖∇_a Q_j(s, a)‖ + 1e-10)
//! ```
//!
//! at the dataset's (s, a), computed as ‖Σ_j g_j‖² − Σ_j ‖g_j‖² per row. The
//! actor steps first, then α (read clamped to [0, 1]), then the critics.

use burn::config::Config;
use burn::module::{Module, Param};
use burn::optim::GradientsParams;
use burn::tensor::{Device, Distribution, Tensor};
use rand_chacha::ChaCha8Rng;

use super::actor::{Actor, ActorConfig};
use super::critic::Temperature;
use super::sac::{PolicyHalf, SacAdam, SacConfig, SacLosses};
use crate::nn::{
    Activation, Adam, Initialised, Mlp, MlpConfig, normal, polyak_update, rows_tensor,
};
use crate::shared::TransitionBatch;

/// EDAC's initial bias of every critic layer (OfflineRL-Kit's `VectorizedLinear`).
const CRITIC_BIAS_INIT: f32 = 0.1;
/// The last critic layer's weights and bias are drawn from U(±this).
const CRITIC_LAST_LAYER_INIT: f64 = 3e-3;
/// ε in the gradients' normalisation.
pub(crate) const GRADIENT_NORM_EPSILON: f32 = 1e-10;

/// EDAC's hyperparameters (OfflineRL-Kit's `run_edac.py`).
#[derive(Config, Debug, PartialEq)]
pub struct EdacConfig {
    /// SAC's settings: [256, 256, 256] networks, actor lr 1e-4, critic 3e-4, α lr 1e-4.
    #[config(default = "super::CqlConfig::kit_sac()")]
    pub sac: SacConfig,
    /// N, the critics (per task: 10, hopper 50).
    #[config(default = 10)]
    pub num_critics: usize,
    /// η, the diversity term's weight (per task: 1, 5 for some medium-expert).
    #[config(default = 1.0)]
    pub eta: f64,
}

/// N critics Q_j(s, a), each an MLP on `[s, a]`.
#[derive(Module, Debug)]
pub struct CriticEnsemble {
    pub members: Vec<Mlp>,
}

impl CriticEnsemble {
    /// N critics with EDAC's initialisation: every bias 0.1, the last layer's
    /// weights and bias U(±3e-3).
    pub fn init(
        obs_dim: usize,
        act_dim: usize,
        hidden: &[usize],
        n: usize,
        device: &Device,
    ) -> Self {
        let config = MlpConfig::new(obs_dim + act_dim, hidden.to_vec(), 1, Activation::Relu);
        let members = (0..n)
            .map(|_| {
                let mut mlp = config.init(device);
                let last = mlp.layers.len() - 1;
                for (i, layer) in mlp.layers.iter_mut().enumerate() {
                    let bias = layer.bias.take().map(|b| {
                        let value = if i == last {
                            uniform(b.val().dims(), device)
                        } else {
                            Tensor::full(b.val().dims(), CRITIC_BIAS_INIT, device)
                        };
                        Param::initialized(b.id, value.set_require_grad(true))
                    });
                    layer.bias = bias;
                    if i == last {
                        let w = &layer.weight;
                        let value = uniform(w.val().dims(), device);
                        layer.weight = Param::initialized(w.id, value.set_require_grad(true));
                    }
                }
                mlp
            })
            .collect();
        Self { members }
    }

    /// Q_j(s, a) for every critic, each `[batch, 1]`.
    pub fn forward(&self, obs: Tensor<2>, action: Tensor<2>) -> Vec<Tensor<2>> {
        let input = Tensor::cat(vec![obs, action], 1);
        self.members
            .iter()
            .map(|m| m.forward(input.clone()))
            .collect()
    }

    /// min_j Q_j(s, a): `[batch, 1]`.
    pub fn min_q(&self, obs: Tensor<2>, action: Tensor<2>) -> Tensor<2> {
        let qs = self.forward(obs, action);
        Tensor::cat(qs, 1).min_dim(1)
    }
}

fn uniform<const D: usize>(shape: [usize; D], device: &Device) -> Tensor<D> {
    let bound = CRITIC_LAST_LAYER_INIT;
    Tensor::random(shape, Distribution::Uniform(-bound, bound), device)
}

/// The agent.
pub struct Edac {
    pub config: EdacConfig,
    pub actor: Actor,
    pub critics: CriticEnsemble,
    pub target_critics: CriticEnsemble,
    pub temperature: Temperature,
    pub adam: SacAdam,
    /// H̄ = −|A|.
    pub target_entropy: f64,
    device: Device,
}

impl Initialised for Edac {
    fn draw_parameters(&self) {
        self.actor.draw_parameters();
        self.critics.draw_parameters();
        self.target_critics.draw_parameters();
        self.temperature.draw_parameters();
    }
}

impl Edac {
    pub fn new(actor: ActorConfig, config: EdacConfig, device: &Device) -> Self {
        let device = device.clone().autodiff();
        let sac = &config.sac;
        let actor = ActorConfig {
            hidden: sac.actor_hidden.clone(),
            ..actor
        }
        .init(&device);
        let (obs_dim, act_dim) = (actor.config.obs_dim, actor.config.act_dim);
        let critics = CriticEnsemble::init(
            obs_dim,
            act_dim,
            &sac.critic_hidden,
            config.num_critics,
            &device,
        );
        Self {
            target_critics: critics.valid(),
            critics,
            actor,
            temperature: Temperature::init(sac.initial_alpha, &device),
            adam: SacAdam::default(),
            target_entropy: sac.target_entropy.unwrap_or(-(act_dim as f64)),
            config,
            device,
        }
    }

    pub fn device(&self) -> &Device {
        &self.device
    }

    /// α = exp(log α) clamped to [0, 1], off the graph, `[1, 1]`.
    fn alpha(&self) -> Tensor<2> {
        self.temperature.alpha().inner().clamp(0.0, 1.0)
    }

    /// ES at the dataset's (s, a), differentiable in the critics' parameters.
    ///
    /// # Shapes
    /// - `obs`: `[batch, obs_dim]`, `actions`: `[batch, act_dim]` → `[1]`
    pub fn diversity_loss(&self, obs: Tensor<2>, actions: Tensor<2>) -> Tensor<1> {
        let [_, obs_dim] = obs.dims();
        let act_dim = actions.dims()[1];
        let input = Tensor::cat(vec![obs, actions], 1);
        let normalised: Vec<Tensor<2>> = (self.critics.members.iter())
            .map(|m| {
                let (_, grad) = m.forward_with_input_grad(input.clone());
                let g = grad.narrow(1, obs_dim, act_dim);
                let norm = g.clone().powi_scalar(2).sum_dim(1).sqrt() + GRADIENT_NORM_EPSILON;
                g / norm
            })
            .collect();
        let n = normalised.len();
        let sum = (normalised.iter().cloned())
            .reduce(|a, b| a + b)
            .expect("N ≥ 1 critics");
        let squares = (normalised.into_iter())
            .map(|g| g.powi_scalar(2).sum_dim(1))
            .reduce(|a, b| a + b)
            .expect("N ≥ 1 critics");
        let cross = sum.powi_scalar(2).sum_dim(1) - squares;
        cross.mean() / (n.max(2) - 1) as f64
    }

    /// The critics' target off the graph, at the current α:
    /// y = r + γ(1 − d)(min_j Q̄_j(s', ã') − α·log π(ã'|s')), ã' ~ π(·|s').
    fn critic_target(
        &self,
        batch: &TransitionBatch,
        rng: &mut ChaCha8Rng,
        plain: &Device,
    ) -> Tensor<2> {
        let (obs_dim, act_dim) = (self.actor.config.obs_dim, self.actor.config.act_dim);
        let b = batch.rewards.len();
        let next_obs = rows_tensor(&batch.next_observations, obs_dim, plain);
        let next = (self.actor.valid()).sample(next_obs.clone(), normal([b, act_dim], rng, plain));
        let next_value =
            self.target_critics.min_q(next_obs, next.action) - next.log_prob * self.alpha();
        let not_done = rows_tensor(&batch.terminals, 1, plain).neg() + 1.0;
        rows_tensor(&batch.rewards, 1, plain) + not_done * next_value * self.config.sac.gamma
    }

    /// One update on `batch`: actor, α, then the critics with the diversity
    /// term, then the Polyak targets.
    pub fn update(&mut self, batch: &TransitionBatch, rng: &mut ChaCha8Rng) -> SacLosses {
        let c = &self.actor.config;
        let (obs_dim, act_dim) = (c.obs_dim, c.act_dim);
        let b = batch.rewards.len();
        let device = self.device.clone();
        let obs = rows_tensor(&batch.observations, obs_dim, &device);
        let actions = rows_tensor(&batch.actions, act_dim, &device);
        let sac = self.config.sac.clone();
        let adam = Adam::new(sac.adam_epsilon.unwrap_or(1e-8));

        // Actor, then α.
        let alpha = self.alpha();
        let noise = normal([b, act_dim], rng, &device);
        let policy = PolicyHalf {
            actor: &mut self.actor,
            temperature: &mut self.temperature,
            adam: &mut self.adam,
            config: &sac,
            optimizer: adam,
            target_entropy: self.target_entropy,
        }
        .step(obs.clone(), noise, alpha, |o, a| self.critics.min_q(o, a));

        let y = self.critic_target(batch, rng, &device.clone().inner());
        let qs = self.critics.forward(obs.clone(), actions.clone());
        let qf1_values = qs[0].clone().mean().into_scalar::<f32>();
        let td: Vec<Tensor<1>> = qs
            .into_iter()
            .map(|q| (q - y.clone()).powi_scalar(2).mean())
            .collect();
        let (qf1_loss, qf2_loss) = (
            td[0].clone().into_scalar(),
            td.get(1).map_or(0.0, |t| t.clone().into_scalar()),
        );
        let td_sum = td.into_iter().reduce(|a, b| a + b).expect("N ≥ 1 critics");
        let diversity = self.diversity_loss(obs, actions);
        let critic_loss = td_sum + diversity * self.config.eta;
        let grads = GradientsParams::from_grads(critic_loss.backward(), &self.critics);
        self.critics = adam.step_module(
            sac.critic_lr,
            self.critics.clone(),
            grads,
            &mut self.adam.critic,
        );
        self.target_critics = polyak_update(self.target_critics.clone(), &self.critics, sac.tau);
        policy.losses(qf1_values, qf1_loss, qf2_loss)
    }
}
