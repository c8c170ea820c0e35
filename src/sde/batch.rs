//! The neural SDE on burn's tensors behind the batch interface
//! ([`BatchDynamics`]); [`super::FusedSde`] is the fused CPU one.

use burn::tensor::{Tensor, TensorData};

use super::model::NeuralSde;
use crate::nn::to_f32_vec;
use crate::shared::{BatchDynamics, BatchShape, ModelStep, step_batch};

impl BatchDynamics for NeuralSde {
    fn shape(&self) -> BatchShape {
        self.constants.batch_shape()
    }

    fn sample_noise_scale(&self) -> f32 {
        self.constants.config.sample_noise_scale
    }

    fn step(&self, states: &[f32], actions: &[f32], noise: &[f32]) -> ModelStep {
        let device = self.sigma_net.layers[0].weight.val().device();
        let batch = step_batch(self, states, actions, noise);
        let state_dim = self.state_dim();
        let act_dim = self.constants.spec.act_dim;
        let tensor = |values: &[f32], width: usize| {
            Tensor::<2>::from_data(TensorData::new(values.to_vec(), [batch, width]), &device)
        };
        let (next, terms) = NeuralSde::step(
            self,
            tensor(states, state_dim),
            tensor(actions, act_dim),
            tensor(noise, state_dim),
        );
        ModelStep {
            next_states: to_f32_vec(next),
            means: to_f32_vec(terms.mean),
            sigma: to_f32_vec(terms.sigma),
            h_eta: to_f32_vec(terms.h_eta),
            eta: to_f32_vec(terms.eta),
            truncation_signal: None,
        }
    }
}
