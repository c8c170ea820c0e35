//! The narrow "step a batch" interface that model rollouts and the server call,
//! so the kernel under it can change (burn here; a fused CPU path later)
//! without touching its callers.

use burn::tensor::{Tensor, TensorData};

use super::model::NeuralSde;
use super::spec::DynamicsSpec;
use crate::nn::to_f32_vec;

/// Everything one Euler–Maruyama step reports, row-major `[batch, ·]`.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelStep {
    /// s' = s + f·dt + Σ·sqrt(dt)·ε: `[batch, state_dim]`
    pub next_states: Vec<f32>,
    /// s + f·dt, the mean of s': `[batch, state_dim]`
    pub means: Vec<f32>,
    /// σ_ϕ(s, a): `[batch, state_dim]`
    pub sigma: Vec<f32>,
    /// h_ϕ(η_ϕ(s, a)): `[batch, state_dim]`
    pub h_eta: Vec<f32>,
    /// η_ϕ(s, a): `[batch]`
    pub eta: Vec<f32>,
}

/// s' = mean + (σ + h(η))·ε·sqrt(dt) for one state dimension: the EM step's
/// sample, in the order of operations both kernels use (so a sample drawn
/// from a step's reported terms equals the step's own).
#[inline]
pub fn euler_maruyama(mean: f32, sigma: f32, h_eta: f32, noise: f32, sqrt_dt: f32) -> f32 {
    mean + (sigma + h_eta) * noise * sqrt_dt
}

/// A dynamics model stepped on a batch of `(state, action)` rows at once.
pub trait BatchDynamics: Sync {
    fn spec(&self) -> &DynamicsSpec;
    /// Width of a state row: `obs_dim`, plus the cumulative reward r_c for NUNO^R.
    fn state_dim(&self) -> usize;
    /// Whether the state carries r_c (NUNO^R), so rewards come from the model.
    fn learns_reward(&self) -> bool;
    /// One Euler–Maruyama step with the given standard normal noise ε.
    ///
    /// # Shapes
    /// - `states`, `noise`: `[batch, state_dim]`; `actions`: `[batch, act_dim]`
    fn step(&self, states: &[f32], actions: &[f32], noise: &[f32]) -> ModelStep;

    /// State rows for observation rows (`[batch, obs_dim]`): NUNO^R's cumulative
    /// reward r_c starts at 0, so its increment over a step is that step's reward.
    fn states_from_observations(&self, observations: &[f32]) -> Vec<f32> {
        let obs_dim = self.spec().obs_dim;
        let extra = self.state_dim() - obs_dim;
        if extra == 0 {
            return observations.to_vec();
        }
        observations
            .chunks_exact(obs_dim)
            .flat_map(|o| o.iter().copied().chain(std::iter::repeat_n(0.0, extra)))
            .collect()
    }
}

impl<T: BatchDynamics + ?Sized> BatchDynamics for &T {
    fn spec(&self) -> &DynamicsSpec {
        (**self).spec()
    }

    fn state_dim(&self) -> usize {
        (**self).state_dim()
    }

    fn learns_reward(&self) -> bool {
        (**self).learns_reward()
    }

    fn step(&self, states: &[f32], actions: &[f32], noise: &[f32]) -> ModelStep {
        (**self).step(states, actions, noise)
    }
}

impl BatchDynamics for NeuralSde {
    fn spec(&self) -> &DynamicsSpec {
        &self.constants.spec
    }

    fn state_dim(&self) -> usize {
        self.constants.state_dim()
    }

    fn learns_reward(&self) -> bool {
        self.constants.config.reward_model
    }

    fn step(&self, states: &[f32], actions: &[f32], noise: &[f32]) -> ModelStep {
        let device = self.sigma_net.layers[0].weight.val().device();
        let state_dim = self.state_dim();
        let batch = states.len() / state_dim;
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
        }
    }
}
