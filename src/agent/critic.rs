//! SAC's twin critics Q₁, Q₂(s, a) (clipped double Q), and the entropy
//! temperature α = exp(log α) as a module of its own so it has its own optimiser.

use burn::module::{Module, Param};
use burn::tensor::{Device, Tensor};

use crate::nn::{Activation, Mlp, MlpConfig};

/// Q₁ and Q₂, each an MLP on `[s, a]`.
#[derive(Module, Debug)]
pub struct TwinCritic {
    pub q1: Mlp,
    pub q2: Mlp,
}

impl TwinCritic {
    pub fn init(obs_dim: usize, act_dim: usize, hidden: &[usize], device: &Device) -> Self {
        let q =
            || MlpConfig::new(obs_dim + act_dim, hidden.to_vec(), 1, Activation::Relu).init(device);
        Self { q1: q(), q2: q() }
    }

    /// (Q₁(s, a), Q₂(s, a)), each `[batch, 1]`.
    pub fn forward(&self, obs: Tensor<2>, action: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
        let input = Tensor::cat(vec![obs, action], 1);
        (self.q1.forward(input.clone()), self.q2.forward(input))
    }

    /// min(Q₁, Q₂)(s, a): `[batch, 1]`.
    pub fn min_q(&self, obs: Tensor<2>, action: Tensor<2>) -> Tensor<2> {
        let (q1, q2) = self.forward(obs, action);
        q1.min_pair(q2)
    }
}

/// The entropy temperature α, learned through log α.
#[derive(Module, Debug)]
pub struct Temperature {
    pub log_alpha: Param<Tensor<1>>,
}

impl Temperature {
    pub fn init(initial_alpha: f64, device: &Device) -> Self {
        Self {
            log_alpha: Param::from_tensor(Tensor::full([1], initial_alpha.ln(), device)),
        }
    }

    /// The same parameter (id and trainability kept) holding `log_alpha`.
    pub fn with_log_alpha(&self, log_alpha: f32) -> Self {
        let (id, old) = (self.log_alpha.id, self.log_alpha.val());
        let value = Tensor::full([1], log_alpha, &old.device());
        Self {
            log_alpha: Param::initialized(id, value.set_require_grad(old.is_require_grad())),
        }
    }

    /// α as a `[1, 1]` tensor.
    pub fn alpha(&self) -> Tensor<2> {
        self.log_alpha.val().exp().unsqueeze()
    }
}
