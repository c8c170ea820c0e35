//! The physics-structured neural SDE (eq. 5, 8) and its Euler–Maruyama step.
//!
//! ```text
//! ds = f_θ(s, a) dt + (σ_ϕ(s, a) + h_ϕ(η_ϕ(s, a))) dW                       (eq. 5)
//! f_pos = s_vel,  f_vel = G(s_vel)·a + H(s)·s_vel,  f = [f_pos, f_vel] + f_res (eq. 8;
//!   what G, H and f_res see of s: `drift_inputs`)
//! h_ϕ(η) = W^max·sigmoid(W·logit(η/η_max) + b),  W ≥ 1   (on η's logit, W and b fixed; see below)
//! s' = s + f·dt + Σ·sqrt(dt)·ε                                             (Euler–Maruyama)
//! ```
//!
//! Networks see normalised inputs and produce outputs of order one, mapped to
//! physical units by the [`PhysicalScales`]; integration happens in physical
//! units, so with G, H and f_res at zero, `pos' = pos + vel·dt` exactly.
//!
//! h_ϕ takes η through its logit ℓ = NN_ϕ(s, a) − offset (η = η_max·sigmoid(ℓ)),
//! as NUNO's code does: on the bounded η itself, `W·η + b` spans at most W and
//! h could never reach W^max beyond the data. W and b are settings, not trained:
//! L_data sees only the data, where it taught h to carry on-data noise (a third
//! of Σ) instead of staying ≈ 0 there (docs/paper-map.md, deviations).

use burn::module::Module;
use burn::tensor::activation::{sigmoid, softplus};
use burn::tensor::{Device, Int, Tensor, TensorData};

use super::config::SdeConfig;
use super::drift_inputs::DriftFeatures;
use super::eta::DistanceAware;
use super::spec::{DynamicsSpec, PhysicalScales};
use crate::nn::{Activation, Mlp, MlpConfig, to_f32_vec};
use crate::shared::BatchShape;

/// What the model does not learn: the system and the data's scales.
#[derive(Debug, Clone, PartialEq)]
pub struct SdeConstants {
    pub spec: DynamicsSpec,
    pub scales: PhysicalScales,
    pub config: SdeConfig,
}

impl SdeConstants {
    /// Width of the integrated state: observations, plus r_c for NUNO^R.
    pub fn state_dim(&self) -> usize {
        self.spec.obs_dim + usize::from(self.config.reward_model)
    }

    /// What the batch interface reports of a model with these constants.
    pub fn batch_shape(&self) -> BatchShape {
        BatchShape {
            obs_dim: self.spec.obs_dim,
            act_dim: self.spec.act_dim,
            learns_reward: self.config.reward_model,
            dt: self.spec.dt,
        }
    }
}

/// Everything one evaluation of the SDE at `(s, a)` produces.
#[derive(Debug, Clone)]
pub struct SdeTerms {
    /// `s + f(s, a)·dt`, the mean of the next state. `[batch, state_dim]`
    pub mean: Tensor<2>,
    /// Drift f(s, a) in physical units per second. `[batch, state_dim]`
    pub drift: Tensor<2>,
    /// Aleatoric diffusion σ_ϕ(s, a). `[batch, state_dim]`
    pub sigma: Tensor<2>,
    /// Epistemic diffusion h_ϕ(η_ϕ(s, a)). `[batch, state_dim]`
    pub h_eta: Tensor<2>,
    /// Distance-aware uncertainty η_ϕ(s, a). `[batch, 1]`
    pub eta: Tensor<2>,
    /// f_res in normalised units, for its penalty. `[batch, obs_dim]`
    pub residual: Tensor<2>,
}

impl SdeTerms {
    /// Total diffusion Σ = σ_ϕ + h_ϕ(η_ϕ). `[batch, state_dim]`
    pub fn diffusion(&self) -> Tensor<2> {
        self.sigma.clone() + self.h_eta.clone()
    }
}

/// The neural SDE: drift networks, diffusion networks, η_ϕ and μ_ϕ.
#[derive(Module, Debug)]
pub struct NeuralSde {
    /// G(s_vel): `[n_vel × act_dim]` control matrix of eq. 8 (G(φ) under pose drift inputs).
    pub g_net: Mlp,
    /// H(s): `[n_vel × n_vel]` velocity matrix of eq. 8 (H(φ)).
    pub h_net: Mlp,
    /// f_res(s, a): the penalised residual drift (f_res(φ, a)).
    pub res_net: Mlp,
    /// f_rew(s, a): the reward drift of NUNO^R.
    pub reward_net: Option<Mlp>,
    /// σ_ϕ(s, a): aleatoric diffusion, 2×256 tanh, made positive by softplus.
    pub sigma_net: Mlp,
    /// η_ϕ and μ_ϕ.
    pub distance: DistanceAware,
    #[module(skip)]
    pub constants: SdeConstants,
}

/// A 1-D constant tensor.
pub(crate) fn constant(values: &[f32], device: &Device) -> Tensor<1> {
    Tensor::from_data(TensorData::new(values.to_vec(), [values.len()]), device)
}

impl NeuralSde {
    /// A freshly initialised model for `spec`, with scales measured on the data.
    pub fn init(
        spec: DynamicsSpec,
        scales: PhysicalScales,
        config: SdeConfig,
        device: &Device,
    ) -> Self {
        let (n_obs, n_act, n_vel) = (spec.obs_dim, spec.act_dim, spec.n_vel());
        let constants = SdeConstants {
            spec,
            scales,
            config,
        };
        let config = &constants.config;
        let inputs = n_obs + n_act;
        let features = DriftFeatures::of(&constants);
        let swish = |d_in, hidden: &Vec<usize>, d_out| {
            MlpConfig::new(d_in, hidden.clone(), d_out, Activation::Swish).init(device)
        };
        let state_dim = constants.state_dim();
        Self {
            g_net: swish(
                features.g_columns().len(),
                &config.drift_hidden,
                n_vel * n_act,
            ),
            h_net: swish(features.width(), &config.drift_hidden, n_vel * n_vel),
            res_net: swish(features.width() + n_act, &config.drift_hidden, n_obs),
            reward_net: config
                .reward_model
                .then(|| swish(inputs, &config.reward_hidden, 1)),
            sigma_net: MlpConfig::new(
                inputs,
                config.sigma_hidden.clone(),
                state_dim,
                Activation::Tanh,
            )
            .init(device),
            distance: DistanceAware::init(inputs, config, device),
            constants,
        }
    }

    pub fn spec(&self) -> &DynamicsSpec {
        &self.constants.spec
    }

    /// Normalised `(s, a)`, the input of every network.
    ///
    /// # Shapes
    /// - `state`: `[batch, ≥ obs_dim]`, `action`: `[batch, act_dim]` → `[batch, obs_dim + act_dim]`
    pub fn normalized_input(&self, state: Tensor<2>, action: Tensor<2>) -> Tensor<2> {
        let device = state.device();
        let n = &self.constants.scales.normalizer;
        let obs = state.narrow(1, 0, self.constants.spec.obs_dim);
        let obs = (obs - constant(&n.state.mean, &device).unsqueeze())
            / constant(&n.state.std, &device).unsqueeze();
        let act = (action - constant(&n.action.mean, &device).unsqueeze())
            / constant(&n.action.std, &device).unsqueeze();
        Tensor::cat(vec![obs, act], 1)
    }

    /// Drift, diffusion and η at `(state, action)`.
    ///
    /// # Shapes
    /// - `state`: `[batch, state_dim]`, `action`: `[batch, act_dim]`
    pub fn terms(&self, state: Tensor<2>, action: Tensor<2>) -> SdeTerms {
        let c = &self.constants;
        let spec = &c.spec;
        let device = state.device();
        let batch = state.dims()[0];
        let (n_pos, n_vel, n_act) = (spec.n_pos(), spec.n_vel(), spec.act_dim);
        let input = self.normalized_input(state.clone(), action.clone());
        let features = DriftFeatures::of(c);
        let phi = features.tensor(state.clone().narrow(1, 0, spec.obs_dim));

        // eq. 8: f_pos = the velocities of the observed positions.
        let pairs: Vec<i64> = spec
            .split
            .position_velocity
            .iter()
            .map(|&i| i as i64)
            .collect();
        let pairs = Tensor::<1, Int>::from_data(TensorData::new(pairs, [n_pos]), &device);
        let f_pos = state.clone().select(1, pairs);
        // eq. 8: f_vel = G(φ)·a + H(φ)·s_vel, velocities scaled (not shifted) so H stays linear in them.
        let velocity = state.clone().narrow(1, n_pos, n_vel);
        let vel_std = &c.scales.normalizer.state.std[n_pos..spec.obs_dim];
        let velocity_hat = velocity / constant(vel_std, &device).unsqueeze();
        let g_columns = features.g_columns();
        let g = self
            .g_net
            .forward(phi.clone().narrow(1, g_columns.start, g_columns.len()))
            .reshape([batch, n_vel, n_act]);
        let g_a = (g * action.unsqueeze_dim::<3>(1))
            .sum_dim(2)
            .reshape([batch, n_vel]);
        let h = self
            .h_net
            .forward(phi.clone())
            .reshape([batch, n_vel, n_vel]);
        let h_v = (h * velocity_hat.unsqueeze_dim::<3>(1))
            .sum_dim(2)
            .reshape([batch, n_vel]);
        let f_vel = (g_a + h_v) * constant(&c.scales.acceleration, &device).unsqueeze();
        // f = [f_pos, f_vel] + f_res, the residual penalised in the loss.
        let action_hat = input.clone().narrow(1, spec.obs_dim, n_act);
        let residual = self.res_net.forward(Tensor::cat(vec![phi, action_hat], 1));
        let mut drift = Tensor::cat(vec![f_pos, f_vel], 1)
            + residual.clone() * constant(&c.scales.derivative, &device).unsqueeze();
        if let Some(reward_net) = &self.reward_net {
            // NUNO^R: dr_c = f_rew(s, a) dt.
            let f_rew = reward_net.forward(input.clone()) * c.scales.reward_rate;
            drift = Tensor::cat(vec![drift, f_rew], 1);
        }

        // eq. 5: Σ = σ_ϕ(s, a) + h_ϕ(η_ϕ(s, a)).
        let state_dim = c.state_dim();
        let diffusion_scale = constant(&c.scales.diffusion[..state_dim], &device).unsqueeze::<2>();
        let sigma = (softplus(self.sigma_net.forward(input.clone()), 1.0) + c.config.sigma_min)
            * diffusion_scale.clone();
        let logit = self.distance.logit(input);
        let eta = sigmoid(logit.clone()) * self.distance.eta_max;
        let w_max = constant(&c.config.w_max_per_dimension(state_dim), &device).unsqueeze::<2>();
        // η is shaped by its own losses only: L_data does not pull η up to
        // explain noise through h (see docs/paper-map.md, deviations).
        let h_eta =
            sigmoid(logit.detach() * c.config.h_weight + c.config.h_bias) * diffusion_scale * w_max;
        SdeTerms {
            mean: state + drift.clone() * spec.dt,
            drift,
            sigma,
            h_eta,
            eta,
            residual,
        }
    }

    /// Sets b of h(η) so that h = `h_on_data`·W^max at the `h_data_quantile` of
    /// η's logit over `inputs` (normalised training `(s, a)`, `[n, obs_dim + act_dim]`):
    /// b = logit(h_on_data) − W·ℓ_q. The data decides where "near" ends, not a
    /// constant, since the η a fit reaches on its data differs from task to task.
    pub fn calibrate_h_bias(&mut self, inputs: Tensor<2>) {
        let logits = to_f32_vec(self.distance.logit(inputs));
        let config = &mut self.constants.config;
        if let Some(bias) = config.calibrated_h_bias(logits) {
            config.h_bias = bias;
        }
    }

    /// One Euler–Maruyama step: `s' = s + f·dt + Σ·sqrt(dt)·ε`.
    ///
    /// # Shapes
    /// - `state`: `[batch, state_dim]`, `action`: `[batch, act_dim]`, `noise` (ε): `[batch, state_dim]`
    pub fn step(
        &self,
        state: Tensor<2>,
        action: Tensor<2>,
        noise: Tensor<2>,
    ) -> (Tensor<2>, SdeTerms) {
        let terms = self.terms(state, action);
        let next = terms.mean.clone() + terms.diffusion() * noise * self.constants.spec.dt.sqrt();
        (next, terms)
    }
}
