//! What the fit's loop (`super::fit`) asks of the code that takes its
//! gradient steps on eq. 7, and burn's answer: autodiff on the model's device,
//! the reference for the fused CPU trainer (`super::fused_fit`) and the path
//! for a GPU. Both see the same draws, take the same Adam step (moments by
//! module path, each parameter's gradient clipped first) and so resume each
//! other's checkpoints.

use std::collections::BTreeMap;

use burn::module::Module;
use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};

use super::config::{FitConfig, LossConfig};
use super::fit::window_tensors;
use super::losses::LossTerms;
use super::model::NeuralSde;
use crate::data::WindowBatch;
#[cfg(test)]
use crate::nn::gradients_by_path;
use crate::nn::{Adam, AdamState, assign_params, to_f32_vec};

/// The random draws of one gradient step, in the order the fit draws them.
#[derive(Debug, Clone)]
pub struct StepDraws {
    /// The windows, states `[batch, horizon + 1, obs_dim]`.
    pub windows: WindowBatch,
    /// ε of each step's particle, `[batch, horizon, state_dim]`.
    pub step_noise: Vec<f32>,
    /// L_sc's ball offsets before the radius, `[batch · samples, obs_dim + act_dim]`.
    pub ball_noise: Vec<f32>,
    /// L_far's uniform points `[n, obs_dim + act_dim]` and their far mask `[n]`.
    pub far_points: Vec<f32>,
    pub far_mask: Vec<f32>,
}

/// Every term of eq. 7 at one step, before its update (see [`LossTerms`] and
/// [`crate::sde::EtaLosses`]); the code form's terms read 0 in the paper's, and are absent
/// (0) in records written before them.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct StepLosses {
    #[serde(rename = "loss")]
    pub total: f32,
    pub data: f32,
    pub sc: f32,
    pub grad: f32,
    pub mu: f32,
    pub far: f32,
    pub residual: f32,
    #[serde(default)]
    pub value: f32,
    #[serde(default)]
    pub one: f32,
    #[serde(default)]
    pub floor: f32,
}

impl StepLosses {
    /// η's terms' share of eq. 7, each times its λ ([`crate::sde::EtaLosses::weighted`]).
    pub fn weighted_eta(&self, config: &LossConfig) -> f32 {
        let terms = [
            self.sc, self.grad, self.mu, self.far, self.value, self.one, self.floor,
        ];
        terms
            .iter()
            .zip(config.eta_weights())
            .map(|(t, w)| t * w)
            .sum()
    }
}

/// Each parameter's gradient, by its module path (`g_net.layers.0.weight`, ...).
pub type Gradients = BTreeMap<String, Vec<f32>>;

/// Takes the fit's gradient steps.
pub(crate) trait SdeTrainer {
    /// eq. 7 on `draws` and its gradient, without a step (held to each other in tests).
    #[cfg(test)]
    fn gradients(&mut self, draws: &StepDraws) -> (StepLosses, Gradients);
    /// One Adam step at `lr` on eq. 7 over `draws`; the losses before it.
    fn step(&mut self, draws: &StepDraws, lr: f64) -> StepLosses;
    /// Sets h(η)'s b from η's logits on `reference` (normalised `(s, a)` rows).
    fn calibrate_h_bias(&mut self, reference: &[f32]);
    /// The model now, without autodiff.
    fn model(&self) -> NeuralSde;
    /// Adam's state, moments by module path.
    fn optimizer_state(&self) -> AdamState;
    /// Continues from `current`'s weights and constants and `adam`'s state.
    fn restore(&mut self, current: &NeuralSde, adam: AdamState);
}

/// What both trainers need of the fit's config.
#[derive(Debug, Clone)]
pub(crate) struct StepSettings {
    pub loss: LossConfig,
    pub adam: Adam,
    pub clip_norm: f32,
    /// η's and μ's own constant rate (`FitConfig::eta_lr`).
    pub eta_lr: Option<f64>,
}

impl StepSettings {
    pub fn of(config: &FitConfig) -> Self {
        Self {
            loss: config.loss.clone(),
            adam: Adam::new(config.adam_epsilon),
            clip_norm: config.grad_clip_norm,
            eta_lr: config.eta_lr,
        }
    }

    /// The learning rate of the parameter at module path `path` in a step at
    /// the fit's `lr`: η's and μ's (under `distance.`) their own where set.
    pub fn rate(&self, path: &str, lr: f64) -> f64 {
        match self.eta_lr {
            Some(eta_lr) if path.starts_with("distance.") => eta_lr,
            _ => lr,
        }
    }
}

/// burn's autodiff over the whole model.
pub(crate) struct BurnSdeTrainer {
    model: NeuralSde,
    state: AdamState,
    settings: StepSettings,
    device: Device,
}

impl BurnSdeTrainer {
    /// Trains `model`, which lives on the autodiff `device`.
    pub fn new(model: NeuralSde, settings: StepSettings, device: Device) -> Self {
        Self {
            model,
            state: AdamState::default(),
            settings,
            device,
        }
    }

    fn loss(&self, draws: &StepDraws) -> LossTerms {
        let model = &self.model;
        let (obs_dim, act_dim) = (model.spec().obs_dim, model.spec().act_dim);
        let reward_model = model.constants.config.reward_model;
        let windows = window_tensors(&draws.windows, obs_dim, reward_model, &self.device);
        let (batch, horizon) = (draws.windows.batch, draws.windows.horizon);
        let state_dim = model.constants.state_dim();
        let tensor = |values: &[f32], shape: [usize; 2]| {
            Tensor::<2>::from_data(TensorData::new(values.to_vec(), shape), &self.device)
        };
        let step_noise = Tensor::<3>::from_data(
            TensorData::new(draws.step_noise.clone(), [batch, horizon, state_dim]),
            &self.device,
        );
        let input_dim = obs_dim + act_dim;
        let ball = tensor(
            &draws.ball_noise,
            [draws.ball_noise.len() / input_dim, input_dim],
        );
        let far_rows = draws.far_mask.len();
        let far = (
            tensor(&draws.far_points, [far_rows, input_dim]),
            tensor(&draws.far_mask, [far_rows, 1]),
        );
        model.loss(&windows, step_noise, ball, far, &self.settings.loss)
    }
}

fn scalar(t: Tensor<1>) -> f32 {
    to_f32_vec(t)[0]
}

impl From<&LossTerms> for StepLosses {
    fn from(terms: &LossTerms) -> Self {
        let eta = &terms.eta;
        Self {
            total: scalar(terms.total.clone()),
            data: scalar(terms.data.clone()),
            sc: scalar(eta.sc.clone()),
            grad: scalar(eta.grad.clone()),
            mu: scalar(eta.mu.clone()),
            far: scalar(eta.far.clone()),
            residual: scalar(terms.residual.clone()),
            value: scalar(eta.value.clone()),
            one: scalar(eta.one.clone()),
            floor: scalar(eta.floor.clone()),
        }
    }
}

impl SdeTrainer for BurnSdeTrainer {
    #[cfg(test)]
    fn gradients(&mut self, draws: &StepDraws) -> (StepLosses, Gradients) {
        let terms = self.loss(draws);
        let grads = GradientsParams::from_grads(terms.total.backward(), &self.model);
        (
            StepLosses::from(&terms),
            gradients_by_path(&self.model, &grads),
        )
    }

    fn step(&mut self, draws: &StepDraws, lr: f64) -> StepLosses {
        let terms = self.loss(draws);
        let grads = GradientsParams::from_grads(terms.total.backward(), &self.model);
        let settings = &self.settings;
        self.model = settings.adam.step_module_at_rates(
            &|path| settings.rate(path, lr),
            self.model.clone(),
            grads,
            &mut self.state,
            Some(settings.clip_norm),
        );
        StepLosses::from(&terms)
    }

    fn calibrate_h_bias(&mut self, reference: &[f32]) {
        let input_dim = self.model.spec().obs_dim + self.model.spec().act_dim;
        let rows = reference.len() / input_dim;
        let inputs = Tensor::<2>::from_data(
            TensorData::new(reference.to_vec(), [rows, input_dim]),
            &self.device,
        );
        self.model.calibrate_h_bias(inputs);
    }

    fn model(&self) -> NeuralSde {
        self.model.valid()
    }

    fn optimizer_state(&self) -> AdamState {
        self.state.clone()
    }

    fn restore(&mut self, current: &NeuralSde, adam: AdamState) {
        self.model = assign_params(self.model.clone(), current);
        self.model.constants = current.constants.clone();
        self.state = adam;
    }
}
