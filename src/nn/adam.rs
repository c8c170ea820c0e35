//! Adam (Kingma & Ba, 2015) on plain `f32` buffers: the one implementation
//! every fit steps with (SAC's two kernels, the ensemble's two trainers, the
//! SDE), so that their states are moments by module path, which checkpoints
//! save and either kernel resumes. The arithmetic follows burn's `Adam` (bias
//! corrections folded into one factor, ε scaled by √(1 − β₂ᵗ)); a 60-step SDE
//! fit through it matches one through burn's optimiser to 1e-7.

use std::collections::BTreeMap;

use burn::module::{Module, ModuleMapper, Param};
use burn::optim::GradientsParams;
use burn::tensor::{Tensor, TensorData};
use serde::{Deserialize, Serialize};

use super::to_f32_vec;

/// Adam's constants.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Adam {
    pub beta_1: f32,
    pub beta_2: f32,
    pub epsilon: f32,
}

/// One parameter's first and second moments.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Moments {
    pub first: Vec<f32>,
    pub second: Vec<f32>,
}

/// One optimiser's state: the steps taken and each parameter's moments, by
/// module path (`q1.layers.0.weight`, ...).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct AdamState {
    pub time: u64,
    pub moments: BTreeMap<String, Moments>,
}

/// The step-dependent factors of one Adam step, shared by its parameters.
#[derive(Debug, Clone, Copy)]
pub struct AdamStep {
    lr: f32,
    /// √(1 − β₂ᵗ) / (1 − β₁ᵗ)
    combined: f32,
    /// ε·√(1 − β₂ᵗ)
    epsilon: f32,
}

impl AdamStep {
    /// This step at another learning rate (a parameter group's own).
    pub fn at_rate(self, lr: f64) -> Self {
        Self {
            lr: lr as f32,
            ..self
        }
    }
}

impl Adam {
    /// PyTorch's and optax's β (0.9, 0.999) with the given ε.
    pub fn new(epsilon: f32) -> Self {
        Self {
            beta_1: 0.9,
            beta_2: 0.999,
            epsilon,
        }
    }

    /// Counts one step on `state` and returns its factors.
    pub fn begin(&self, state: &mut AdamState, lr: f64) -> AdamStep {
        state.time += 1;
        let t = state.time as i32;
        let correction_2 = (1.0 - self.beta_2.powi(t)).sqrt();
        AdamStep {
            lr: lr as f32,
            combined: correction_2 / (1.0 - self.beta_1.powi(t)),
            epsilon: self.epsilon * correction_2,
        }
    }

    /// θ ← θ − lr·m̂/(√v̂ + ε) for one parameter; moments start at zero.
    pub fn update(&self, step: AdamStep, params: &mut [f32], grads: &[f32], moments: &mut Moments) {
        assert_eq!(
            params.len(),
            grads.len(),
            "Adam: parameter and gradient sizes"
        );
        if moments.first.len() != params.len() {
            moments.first = vec![0.0; params.len()];
            moments.second = vec![0.0; params.len()];
        }
        let (b1, b2) = (self.beta_1, self.beta_2);
        for (((p, &g), m), v) in params
            .iter_mut()
            .zip(grads)
            .zip(&mut moments.first)
            .zip(&mut moments.second)
        {
            *m = *m * b1 + g * (1.0 - b1);
            *v = *v * b2 + g * g * (1.0 - b2);
            *p -= *m * step.combined / (v.sqrt() + step.epsilon) * step.lr;
        }
    }

    /// One step of every parameter of a burn `module` that has a gradient in
    /// `grads`, through [`Adam::update`] on the host.
    pub fn step_module<M: Module>(
        &self,
        lr: f64,
        module: M,
        grads: GradientsParams,
        state: &mut AdamState,
    ) -> M {
        self.step_module_clipped(lr, module, grads, state, None)
    }

    /// [`Adam::step_module`] with each parameter's gradient first scaled to an
    /// L2 norm of at most `clip_norm` (burn's `GradientClipping::Norm`:
    /// g·min(1, c/(‖g‖ + the smallest positive f32)), per parameter tensor).
    pub fn step_module_clipped<M: Module>(
        &self,
        lr: f64,
        module: M,
        grads: GradientsParams,
        state: &mut AdamState,
        clip_norm: Option<f32>,
    ) -> M {
        self.step_module_at_rates(&|_| lr, module, grads, state, clip_norm)
    }

    /// [`Adam::step_module_clipped`] with each parameter's learning rate read
    /// from its module path: parameter groups as separate Adams that step
    /// together (one step count, moments by path either way).
    pub fn step_module_at_rates<M: Module>(
        &self,
        lr: &dyn Fn(&str) -> f64,
        module: M,
        mut grads: GradientsParams,
        state: &mut AdamState,
        clip_norm: Option<f32>,
    ) -> M {
        struct Stepper<'a> {
            adam: &'a Adam,
            step: AdamStep,
            lr: &'a dyn Fn(&str) -> f64,
            grads: &'a mut GradientsParams,
            state: &'a mut AdamState,
            clip_norm: Option<f32>,
            path: Vec<String>,
        }
        impl ModuleMapper for Stepper<'_> {
            fn enter_module(&mut self, name: &str, _: &str) {
                self.path.push(name.to_string());
            }
            fn exit_module(&mut self, _: &str, _: &str) {
                self.path.pop();
            }
            fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
                let Some(grad) = self.grads.remove::<D>(param.id) else {
                    return param;
                };
                let (id, value) = (param.id, param.val());
                let (shape, device) = (value.dims(), value.device());
                let mut values = to_f32_vec(value);
                let mut grad = to_f32_vec(grad);
                if let Some(clip) = self.clip_norm {
                    clip_to_norm(&mut grad, clip);
                }
                let path = self.path.join(".");
                let step = self.step.at_rate((self.lr)(&path));
                let moments = self.state.moments.entry(path).or_default();
                self.adam.update(step, &mut values, &grad, moments);
                let tensor = Tensor::from_data(TensorData::new(values, shape), &device);
                Param::initialized(id, tensor.require_grad())
            }
        }
        let step = self.begin(state, 0.0);
        module.map(&mut Stepper {
            adam: self,
            step,
            lr,
            grads: &mut grads,
            state,
            clip_norm,
            path: Vec::new(),
        })
    }
}

/// Scales `grad` to an L2 norm of at most `clip` (burn's
/// `GradientClipping::Norm`: g·min(1, c/(‖g‖ + the smallest positive f32))).
pub fn clip_to_norm(grad: &mut [f32], clip: f32) {
    let norm = grad.iter().map(|g| g * g).sum::<f32>().sqrt();
    let coef = (clip / (norm + f32::MIN_POSITIVE)).min(1.0);
    grad.iter_mut().for_each(|g| *g *= coef);
}
