//! The training objective (eq. 7): λ_data·L_data + λ_sc·L_sc + λ_grad·L_grad
//! + λ_μ·L_μ (and the code form's η terms), plus the residual-drift penalty.

use burn::tensor::Tensor;

use super::config::{LikelihoodPath, LossConfig};
use super::eta::EtaLosses;
use super::model::{NeuralSde, constant};

/// One batch of training windows as tensors.
#[derive(Debug, Clone)]
pub struct WindowTensors {
    /// `[batch, horizon + 1, state_dim]` (r_c last for NUNO^R, starting at 0)
    pub states: Tensor<3>,
    /// `[batch, horizon, act_dim]`
    pub actions: Tensor<3>,
}

/// Every term of eq. 7 for one batch, as scalar tensors.
#[derive(Debug, Clone)]
pub struct LossTerms {
    pub total: Tensor<1>,
    /// L_data, eq. 6.
    pub data: Tensor<1>,
    /// η's losses (eq. 3, 4).
    pub eta: EtaLosses,
    /// Mean ‖f_res‖² in normalised units.
    pub residual: Tensor<1>,
}

impl NeuralSde {
    /// L_data (eq. 6): the Gaussian NLL of the window under Euler–Maruyama
    /// transitions, each step started where `path` says (a particle drawn at the
    /// model's `sample_noise_scale`), step t weighted `step_discount`^(t − 1),
    /// summed over steps and dimensions, averaged over the batch; errors are
    /// measured in normalised units. Also returns the mean squared residual drift
    /// along the way.
    ///
    /// # Shapes
    /// - `noise` (ε of each step's particle, read on the particle path):
    ///   `[batch, horizon, state_dim]`
    pub fn data_nll(
        &self,
        windows: &WindowTensors,
        noise: Tensor<3>,
        path: LikelihoodPath,
        step_discount: f32,
    ) -> (Tensor<1>, Tensor<1>) {
        let [batch, steps_plus_one, state_dim] = windows.states.dims();
        let horizon = steps_plus_one - 1;
        let act_dim = windows.actions.dims()[2];
        let device = windows.states.device();
        let c = &self.constants;
        let mut scale: Vec<f32> = c.scales.normalizer.state.std.clone();
        scale.truncate(c.spec.obs_dim);
        if c.config.reward_model {
            scale.push(c.scales.normalizer.reward.std[0]);
        }
        let inv_scale2 = constant(&scale, &device).unsqueeze::<2>().square().recip();
        let at = |t: &Tensor<3>, k: usize, width: usize| {
            t.clone().narrow(1, k, 1).reshape([batch, width])
        };

        let mut start = at(&windows.states, 0, state_dim);
        let mut nll = Tensor::<1>::zeros([1], &device);
        let mut residual = Tensor::<1>::zeros([1], &device);
        let mut weight = 1.0;
        for k in 0..horizon {
            let action = at(&windows.actions, k, act_dim);
            let terms = self.terms(start, action);
            let variance = terms.diffusion().square() * c.spec.dt;
            let next = at(&windows.states, k + 1, state_dim);
            let error = next.clone() - terms.mean.clone();
            // Normalised units: error² / var is unchanged, log var shifts by a constant.
            let variance_hat = variance.clone() * inv_scale2.clone();
            let term = error.square() / variance.clone() + variance_hat.log();
            nll = nll + term.sum().mul_scalar(weight / batch as f32);
            weight *= step_discount;
            residual = residual + terms.residual.square().sum_dim(1).mean();
            start = match path {
                LikelihoodPath::Data => next,
                LikelihoodPath::Particle => {
                    let spread = variance.sqrt().mul_scalar(c.config.sample_noise_scale);
                    terms.mean + spread * at(&noise, k, state_dim)
                }
            };
        }
        (nll, residual.div_scalar(horizon as f32))
    }

    /// All terms of eq. 7; the η losses are taken at each window's first `(s_t, a_t)`.
    ///
    /// # Shapes
    /// - `step_noise`: `[batch, horizon, state_dim]`; `ball_noise`: `[batch · samples, obs_dim + act_dim]`;
    ///   `far`: points `[n, obs_dim + act_dim]` and their mask `[n, 1]`
    pub fn loss(
        &self,
        windows: &WindowTensors,
        step_noise: Tensor<3>,
        ball_noise: Tensor<2>,
        far: (Tensor<2>, Tensor<2>),
        config: &LossConfig,
    ) -> LossTerms {
        let [batch, _, state_dim] = windows.states.dims();
        let act_dim = windows.actions.dims()[2];
        let (data, residual) =
            self.data_nll(windows, step_noise, config.likelihood, config.step_discount);
        let first_state = windows
            .states
            .clone()
            .narrow(1, 0, 1)
            .reshape([batch, state_dim]);
        let first_action = windows
            .actions
            .clone()
            .narrow(1, 0, 1)
            .reshape([batch, act_dim]);
        let input = self.normalized_input(first_state, first_action);
        let eta = self.distance.losses(input, ball_noise, far, config);
        let total = data.clone() * config.lambda_data
            + eta.weighted(config)
            + residual.clone() * config.lambda_res;
        LossTerms {
            total,
            data,
            eta,
            residual,
        }
    }
}
