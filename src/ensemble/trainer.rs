//! What the fit's loop asks of the code that trains the members, and burn's
//! answer (autodiff on the model's device; the reference for the fused CPU
//! trainer, `super::fused_trainer`, and the path for a GPU).
//!
//! The loss of one step, summed over members m (OfflineRL-Kit's
//! `EnsembleDynamics.learn`):
//! Σ_m [ mean((μ_m − y)²·e^(−log σ²_m)) + mean(log σ²_m) + Σ_l c_l·‖W_l‖²/2 ]
//! + coef·(Σ max log σ² − Σ min log σ²).

use burn::module::Module;
use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor, TensorData};

use super::config::EnsembleConfig;
use super::model::GaussianEnsemble;
use crate::nn::{Adam, AdamState, Mlp, assign_params, to_f32_vec};

/// Rows for one member: normalised inputs `[rows, d_in]` and targets
/// `[rows, d_out]`, row-major.
#[derive(Debug, Clone, Default)]
pub(super) struct MemberBatch {
    pub x: Vec<f32>,
    pub y: Vec<f32>,
}

/// Trains the members; the fit's loop (`super::fit`) decides what they see.
pub(super) trait EnsembleTrainer {
    /// A member's weights, kept at its best epoch.
    type Member;
    /// One Adam step on the loss above, member m on `batches[m]`; returns the
    /// loss before the step.
    fn step(&mut self, batches: &[MemberBatch]) -> f64;
    /// Each member's mean squared error of its mean on `holdout`.
    fn holdout_mse(&mut self, holdout: &MemberBatch) -> Vec<f32>;
    /// Member `m`'s weights now.
    fn member(&self, m: usize) -> Self::Member;
    /// A member's weights from a saved ensemble's member.
    fn member_of(&self, mlp: &Mlp) -> Self::Member;
    /// The ensemble with `best` as its members and the current bounds.
    fn model_with(&self, best: &[Self::Member]) -> GaussianEnsemble;
    /// Adam's state, moments by the ensemble's module paths
    /// (`members.0.layers.0.weight`, ..., `max_logvar`), the same for both
    /// trainers, so that either resumes the other's checkpoint.
    fn optimizer_state(&self) -> AdamState;
    /// Continues from `current`'s weights and `adam`'s state.
    fn restore(&mut self, current: &GaussianEnsemble, adam: AdamState);
}

/// The loss's constants, shared by both trainers.
#[derive(Debug, Clone)]
pub(super) struct LossTerms {
    pub learning_rate: f64,
    /// c_l per layer, hidden layers then the output.
    pub weight_decay: Vec<f64>,
    /// coef of the bounds' loss.
    pub bounds_coef: f64,
}

impl LossTerms {
    pub fn of(config: &EnsembleConfig) -> Self {
        Self {
            learning_rate: config.learning_rate,
            weight_decay: config.weight_decay.clone(),
            bounds_coef: config.logvar_loss_coef,
        }
    }
}

/// Adam's ε in OfflineRL-Kit's fit (PyTorch's default).
pub(super) const ADAM_EPSILON: f32 = 1e-8;

/// burn's autodiff over the whole ensemble.
pub(super) struct BurnTrainer {
    model: GaussianEnsemble,
    adam: Adam,
    state: AdamState,
    terms: LossTerms,
    device: Device,
}

impl BurnTrainer {
    /// Trains `model` (on an autodiff device).
    pub fn new(model: GaussianEnsemble, terms: LossTerms) -> Self {
        let device = model.max_logvar.val().device();
        Self {
            model,
            adam: Adam::new(ADAM_EPSILON),
            state: AdamState::default(),
            terms,
            device,
        }
    }

    fn tensors(&self, batch: &MemberBatch, device: &Device) -> (Tensor<2>, Tensor<2>) {
        let d_in = self.model.members[0].layers[0].weight.val().dims()[0];
        let rows = batch.x.len() / d_in;
        let d_out = batch.y.len() / rows.max(1);
        (
            Tensor::from_data(TensorData::new(batch.x.clone(), [rows, d_in]), device),
            Tensor::from_data(TensorData::new(batch.y.clone(), [rows, d_out]), device),
        )
    }
}

impl EnsembleTrainer for BurnTrainer {
    type Member = Mlp;

    fn step(&mut self, batches: &[MemberBatch]) -> f64 {
        let model = &self.model;
        let mut loss = bounds_loss(model, self.terms.bounds_coef);
        for (m, batch) in batches.iter().enumerate() {
            let (x, y) = self.tensors(batch, &self.device);
            loss = loss
                + member_nll(model, m, x, y)
                + weight_decay(&model.members[m], &self.terms.weight_decay);
        }
        let value = f64::from(to_f32_vec(loss.clone())[0]);
        let grads = GradientsParams::from_grads(loss.backward(), &self.model);
        let model = self.model.clone();
        self.model = self
            .adam
            .step_module(self.terms.learning_rate, model, grads, &mut self.state);
        value
    }

    fn holdout_mse(&mut self, holdout: &MemberBatch) -> Vec<f32> {
        let valid = self.model.valid();
        let (x, y) = self.tensors(holdout, &valid.max_logvar.val().device());
        (0..valid.members.len())
            .map(|m| {
                let (mean, _) = valid.member(m, x.clone());
                to_f32_vec((mean - y.clone()).powi_scalar(2).mean())[0]
            })
            .collect()
    }

    fn member(&self, m: usize) -> Mlp {
        self.model.members[m].valid()
    }

    fn member_of(&self, mlp: &Mlp) -> Mlp {
        mlp.clone()
    }

    fn model_with(&self, best: &[Mlp]) -> GaussianEnsemble {
        let mut model = self.model.valid();
        model.members = best.to_vec();
        model
    }

    fn optimizer_state(&self) -> AdamState {
        self.state.clone()
    }

    fn restore(&mut self, current: &GaussianEnsemble, adam: AdamState) {
        self.model = assign_params(self.model.clone(), current);
        self.state = adam;
    }
}

/// Member `m`'s Gaussian negative log-likelihood of targets `y` at inputs
/// `x` (up to constants): mean((μ − y)²·e^(−log σ²)) + mean(log σ²).
pub(super) fn member_nll(
    model: &GaussianEnsemble,
    m: usize,
    x: Tensor<2>,
    y: Tensor<2>,
) -> Tensor<1> {
    let (mean, logvar) = model.member(m, x);
    let inverse_variance = logvar.clone().neg().exp();
    (mean - y).powi_scalar(2).mul(inverse_variance).mean() + logvar.mean()
}

/// coef·(Σ max log σ² − Σ min log σ²): keeps the learned bounds tight.
pub(super) fn bounds_loss(model: &GaussianEnsemble, coef: f64) -> Tensor<1> {
    (model.max_logvar.val().sum() - model.min_logvar.val().sum()) * coef
}

/// Σ_l c_l·‖W_l‖²/2 over a member's layers.
pub(super) fn weight_decay(member: &Mlp, coefficients: &[f64]) -> Tensor<1> {
    member
        .layers
        .iter()
        .zip(coefficients)
        .map(|(layer, &c)| layer.weight.val().powi_scalar(2).sum() * (0.5 * c))
        .reduce(|a, b| a + b)
        .expect("at least one layer")
}
