//! Open-loop Euler–Maruyama rollouts along given action sequences, with
//! particles folded into the batch: the basis of the truncation thresholds
//! (Section 4.3) and of multi-step prediction error.

use burn::tensor::{Device, Tensor, TensorData};
use rand_chacha::ChaCha8Rng;

use super::model::NeuralSde;
use crate::nn::normal;
use crate::nn::to_f32_vec;

/// States and η along open-loop rollouts, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct OpenLoopRollout {
    pub batch: usize,
    pub particles: usize,
    pub horizon: usize,
    pub state_dim: usize,
    /// `[batch, particles, horizon + 1, state_dim]`
    pub states: Vec<f32>,
    /// η_ϕ(s̃_k, a_k), η_max where s̃_k is not finite: `[batch, particles, horizon]`
    pub eta: Vec<f32>,
}

impl OpenLoopRollout {
    /// State `k` of particle `p` of rollout `b`.
    pub fn state(&self, b: usize, p: usize, k: usize) -> &[f32] {
        let row = ((b * self.particles + p) * (self.horizon + 1) + k) * self.state_dim;
        &self.states[row..row + self.state_dim]
    }
}

/// How many steps and particles an open-loop rollout takes, and how much noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OpenLoop {
    pub horizon: usize,
    pub particles: usize,
    /// Multiplies ε: 1 samples the SDE, 0 follows the drift alone.
    pub noise_scale: f32,
}

impl NeuralSde {
    /// Rolls `plan.particles` trajectories per start state along the given actions.
    ///
    /// # Shapes
    /// - `starts`: `[batch, state_dim]`; `actions`: `[batch, horizon, act_dim]`
    pub fn rollout_open_loop(
        &self,
        starts: &[f32],
        actions: &[f32],
        plan: OpenLoop,
        rng: &mut ChaCha8Rng,
        device: &Device,
    ) -> OpenLoopRollout {
        let OpenLoop {
            horizon,
            particles,
            noise_scale,
        } = plan;
        let state_dim = self.constants.state_dim();
        let act_dim = self.spec().act_dim;
        let batch = starts.len() / state_dim;
        let rows = batch * particles;
        // Particle p of rollout b is row b·particles + p.
        let repeat = |values: &[f32], width: usize| -> Vec<f32> {
            values
                .chunks_exact(width)
                .flat_map(|row| std::iter::repeat_n(row, particles).flatten().copied())
                .collect()
        };
        let mut state = Tensor::<2>::from_data(
            TensorData::new(repeat(starts, state_dim), [rows, state_dim]),
            device,
        );
        let step_actions = repeat(actions, horizon * act_dim);
        let mut states = vec![state.clone()];
        let mut etas = Vec::with_capacity(horizon);
        for k in 0..horizon {
            let action: Vec<f32> = step_actions
                .chunks_exact(horizon * act_dim)
                .flat_map(|row| row[k * act_dim..(k + 1) * act_dim].iter().copied())
                .collect();
            let action = Tensor::<2>::from_data(TensorData::new(action, [rows, act_dim]), device);
            let noise = normal([rows, state_dim], rng, device) * noise_scale;
            let (next, terms) = self.step(state, action, noise);
            etas.push(terms.eta);
            states.push(next.clone());
            state = next;
        }
        // [rows, horizon + 1, state_dim] and [rows, horizon], then flattened row-major.
        let states = to_f32_vec(Tensor::stack::<3>(states, 1));
        // A particle whose state stopped being finite (the drift diverged off the
        // data) is as far from the data as η goes.
        let eta_max = self.constants.config.eta_max;
        let eta = to_f32_vec(Tensor::cat(etas, 1))
            .into_iter()
            .map(|eta| if eta.is_finite() { eta } else { eta_max })
            .collect();
        OpenLoopRollout {
            batch,
            particles,
            horizon,
            state_dim,
            states,
            eta,
        }
    }
}
