//! SAC's tanh-Gaussian actor π(a|s) (Haarnoja et al., 2018): an MLP gives the
//! mean μ(s) and log-std log σ(s) (clamped); u = μ + σ·ε, a = tanh(u) mapped
//! onto the action box, and log π(a|s) carries the change-of-variables term
//! Σ log(1 − tanh²(u)) plus the box's scale.

use burn::config::Config;
use burn::module::Module;
use burn::tensor::activation::softplus;
use burn::tensor::{Device, Tensor, TensorData};
use rand::RngCore;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::nn::{Activation, Mlp, MlpConfig, standard_normal, to_f32_vec};
use crate::shared::{BatchPolicy, LoggedActions, act_batch};

/// The actor's sizes and limits.
#[derive(Config, Debug, PartialEq)]
pub struct ActorConfig {
    pub obs_dim: usize,
    pub act_dim: usize,
    /// Hidden layers (ReLU); SAC's default 2×256.
    #[config(default = "vec![256, 256]")]
    pub hidden: Vec<usize>,
    /// log σ is clamped to `[log_std_min, log_std_max]` (OfflineRL-Kit: −5, 2).
    #[config(default = -5.0)]
    pub log_std_min: f32,
    #[config(default = 2.0)]
    pub log_std_max: f32,
    /// The action box the tanh output is mapped onto.
    pub action_low: Vec<f32>,
    pub action_high: Vec<f32>,
}

impl ActorConfig {
    /// The action box's half-width and centre: a = centre + half·tanh(u).
    pub fn box_half_center(&self) -> (Vec<f32>, Vec<f32>) {
        let bounds = self.action_low.iter().zip(&self.action_high);
        let half = bounds.clone().map(|(l, h)| (h - l) / 2.0).collect();
        let center = bounds.map(|(l, h)| (h + l) / 2.0).collect();
        (half, center)
    }

    pub fn init(&self, device: &Device) -> Actor {
        Actor {
            net: MlpConfig::new(
                self.obs_dim,
                self.hidden.clone(),
                2 * self.act_dim,
                Activation::Relu,
            )
            .init(device),
            config: self.clone(),
        }
    }
}

/// Actions and their log-probabilities for a batch of states.
#[derive(Debug, Clone)]
pub struct ActorSample {
    /// `[batch, act_dim]`, inside the action box.
    pub action: Tensor<2>,
    /// log π(a|s): `[batch, 1]`
    pub log_prob: Tensor<2>,
}

/// π(a|s).
#[derive(Module, Debug)]
pub struct Actor {
    pub net: Mlp,
    #[module(skip)]
    pub config: ActorConfig,
}

impl Actor {
    /// μ(s) and the clamped log σ(s), each `[batch, act_dim]`.
    pub fn mean_log_std(&self, obs: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
        let out = self.net.forward(obs);
        let a = self.config.act_dim;
        let mean = out.clone().narrow(1, 0, a);
        let log_std = out
            .narrow(1, a, a)
            .clamp(self.config.log_std_min, self.config.log_std_max);
        (mean, log_std)
    }

    /// The box's half-width and centre, `[1, act_dim]` each.
    fn box_scale_center(&self, device: &Device) -> (Tensor<2>, Tensor<2>) {
        let (half, center) = self.config.box_half_center();
        let row =
            |v: Vec<f32>| Tensor::from_data(TensorData::new(v, [1, self.config.act_dim]), device);
        (row(half), row(center))
    }

    /// a = centre + half·tanh(μ + σ·ε) and log π(a|s), for given ε ~ N(0, I).
    ///
    /// # Shapes
    /// - `obs`: `[batch, obs_dim]`, `noise`: `[batch, act_dim]`
    pub fn sample(&self, obs: Tensor<2>, noise: Tensor<2>) -> ActorSample {
        let device = obs.device();
        let (mean, log_std) = self.mean_log_std(obs);
        let u = mean + log_std.clone().exp() * noise.clone();
        // log N(u; μ, σ) = −ε²/2 − log σ − log(2π)/2, per dimension.
        let gaussian =
            noise.powi_scalar(2) * (-0.5) - log_std - 0.5 * (2.0 * std::f32::consts::PI).ln();
        // log(1 − tanh²(u)) = 2·(log 2 − u − softplus(−2u)), stable for large |u|.
        let squash =
            (u.clone().neg() - softplus(u.clone() * (-2.0), 1.0) + std::f32::consts::LN_2) * 2.0;
        let (half, center) = self.box_scale_center(&device);
        let log_prob = (gaussian - squash - half.clone().log()).sum_dim(1);
        ActorSample {
            action: u.tanh() * half + center,
            log_prob,
        }
    }

    /// The deterministic action centre + half·tanh(μ(s)), used for evaluation.
    pub fn mean_action(&self, obs: Tensor<2>) -> Tensor<2> {
        let device = obs.device();
        let (mean, _) = self.mean_log_std(obs);
        let (half, center) = self.box_scale_center(&device);
        mean.tanh() * half + center
    }
}

/// How a trained actor chooses actions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "lowercase")]
pub enum ActionMode {
    /// tanh(μ(s)): what SAC evaluates (and the default for serving).
    #[default]
    Deterministic,
    /// a ~ π(·|s).
    Sampled,
}

/// A trained actor behind [`BatchPolicy`].
#[derive(Debug, Clone)]
pub struct ActorPolicy {
    pub actor: Actor,
    pub mode: ActionMode,
}

impl BatchPolicy for ActorPolicy {
    fn obs_dim(&self) -> usize {
        self.actor.config.obs_dim
    }

    fn act_dim(&self) -> usize {
        self.actor.config.act_dim
    }

    fn act(&self, observations: &[f32], rng: &mut dyn RngCore) -> Vec<f32> {
        let device = self.actor.net.layers[0].weight.val().device();
        let batch = act_batch(self, observations);
        let obs = Tensor::from_data(
            TensorData::new(observations.to_vec(), [batch, self.obs_dim()]),
            &device,
        );
        let action = match self.mode {
            ActionMode::Deterministic => self.actor.mean_action(obs),
            ActionMode::Sampled => {
                let noise = action_noise(batch * self.act_dim(), rng);
                let noise =
                    Tensor::from_data(TensorData::new(noise, [batch, self.act_dim()]), &device);
                self.actor.sample(obs, noise).action
            }
        };
        to_f32_vec(action)
    }

    fn act_logged(&self, observations: &[f32], rng: &mut dyn RngCore) -> LoggedActions {
        if self.mode == ActionMode::Deterministic {
            return LoggedActions {
                actions: self.act(observations, rng),
                log_probs: None,
            };
        }
        let device = self.actor.net.layers[0].weight.val().device();
        let batch = act_batch(self, observations);
        let obs = Tensor::from_data(
            TensorData::new(observations.to_vec(), [batch, self.obs_dim()]),
            &device,
        );
        let noise = action_noise(batch * self.act_dim(), rng);
        let noise = Tensor::from_data(TensorData::new(noise, [batch, self.act_dim()]), &device);
        let sample = self.actor.sample(obs, noise);
        LoggedActions {
            actions: to_f32_vec(sample.action),
            log_probs: Some(to_f32_vec(sample.log_prob)),
        }
    }
}

/// ½·log(2π), the Gaussian's normalising constant per dimension.
const HALF_LOG_TWO_PI: f32 = 0.918_938_5;

/// log of the density of tanh(u), u = μ + σ·ε, for one dimension:
/// log N(u; μ, σ) − log(1 − tanh²u), the tanh-Gaussian's change of variables
/// (the action box's scale is the caller's). As [`Actor::sample`] computes it.
#[inline]
pub(crate) fn tanh_gaussian_log_density(eps: f32, log_std: f32, u: f32) -> f32 {
    // log(1 − tanh²u) = 2·(log 2 − u − softplus(−2u)), stable for large |u|.
    let squash = 2.0 * (std::f32::consts::LN_2 - u - softplus_f32(-2.0 * u));
    -0.5 * eps * eps - log_std - HALF_LOG_TWO_PI - squash
}

/// log(1 + eˣ) without overflow.
fn softplus_f32(x: f32) -> f32 {
    x.max(0.0) + (-x.abs()).exp().ln_1p()
}

/// ε ~ N(0, I) for `n` sampled action entries: drawn from a local generator
/// seeded off the caller's stream, so every kernel draws the same ε.
pub(crate) fn action_noise(n: usize, rng: &mut dyn RngCore) -> Vec<f32> {
    standard_normal(n, &mut ChaCha8Rng::seed_from_u64(rng.next_u64()))
}
