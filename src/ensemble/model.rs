//! The ensemble's networks: member i maps normalised (s, a) to a diagonal
//! Gaussian over y = (s' − s, r), mean μᵢ and log-variance bounded softly
//! between learned limits (PETS, Chua et al. 2018):
//! log σ² = max − softplus(max − raw), then min + softplus(log σ² − min).

use burn::module::{Module, Param};
use burn::tensor::activation;
use burn::tensor::{Device, Tensor};

use crate::nn::{Activation, Mlp, MlpConfig};

#[derive(Module, Debug)]
pub struct GaussianEnsemble {
    pub members: Vec<Mlp>,
    /// Upper and lower log-variance limits per output, shared by the members.
    pub max_logvar: Param<Tensor<1>>,
    pub min_logvar: Param<Tensor<1>>,
}

impl GaussianEnsemble {
    pub fn init(
        d_input: usize,
        d_output: usize,
        hidden: &[usize],
        members: usize,
        (max_logvar, min_logvar): (f32, f32),
        device: &Device,
    ) -> Self {
        let member = MlpConfig::new(d_input, hidden.to_vec(), 2 * d_output, Activation::Swish);
        Self {
            members: (0..members).map(|_| member.init(device)).collect(),
            max_logvar: Param::from_tensor(Tensor::full([d_output], max_logvar, device)),
            min_logvar: Param::from_tensor(Tensor::full([d_output], min_logvar, device)),
        }
    }

    /// Member `m`'s mean and bounded log-variance for normalised inputs.
    ///
    /// # Shapes
    /// - `x`: `[batch, d_input]` → (`[batch, d_output]`, `[batch, d_output]`)
    pub fn member(&self, m: usize, x: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
        let out = self.members[m].forward(x);
        let d = out.dims()[1] / 2;
        let mean = out.clone().narrow(1, 0, d);
        let raw = out.narrow(1, d, d);
        let max = self.max_logvar.val().unsqueeze::<2>();
        let min = self.min_logvar.val().unsqueeze::<2>();
        let logvar = max.clone() - activation::softplus(max - raw, 1.0);
        let logvar = min.clone() + activation::softplus(logvar - min, 1.0);
        (mean, logvar)
    }
}

/// ln(1 + eˣ), without overflow for large x: the bounds on host buffers (the
/// fused step and fit).
pub(super) fn softplus(x: f32) -> f32 {
    if x > 20.0 { x } else { x.exp().ln_1p() }
}

fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// [`GaussianEnsemble::member`]'s soft bounds on one host value, with the
/// derivatives of log σ² by the raw output and by the two limits (s the
/// sigmoid, above = max − raw, below = log σ²₁ − min):
/// ∂/∂raw = s(below)·s(above), ∂/∂max = s(below)·s(−above), ∂/∂min = s(−below).
pub(super) struct BoundedLogvar {
    pub value: f32,
    pub d_raw: f32,
    pub d_max: f32,
    pub d_min: f32,
}

impl BoundedLogvar {
    pub fn of(raw: f32, max: f32, min: f32) -> Self {
        let above = max - raw;
        let below = max - softplus(above) - min;
        let s_below = sigmoid(below);
        Self {
            value: min + softplus(below),
            d_raw: s_below * sigmoid(above),
            d_max: s_below * sigmoid(-above),
            d_min: sigmoid(-below),
        }
    }
}
