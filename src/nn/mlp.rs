//! Multilayer perceptrons, and the input gradient of a scalar one computed as
//! forward tensor ops.
//!
//! The η losses (eq. 3, 4) contain ∇ₓη inside a loss that is differentiated
//! with respect to the parameters. burn 0.22's autodiff cannot differentiate a
//! gradient, so [`Mlp::forward_with_input_grad`] backpropagates through the
//! layers by hand (`g ← (g ⊙ act'(z)) Wᵀ`); autodiff then differentiates that
//! expression like any other.

use burn::config::Config;
use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::Tensor;
use burn::tensor::activation::{relu, sigmoid, silu};

/// Hidden-layer nonlinearity.
#[derive(Config, Debug, Copy, PartialEq, Eq)]
pub enum Activation {
    /// swish(z) = z·sigmoid(z)
    Swish,
    Tanh,
    Relu,
}

impl Activation {
    fn apply(self, z: Tensor<2>) -> Tensor<2> {
        match self {
            Activation::Swish => silu(z),
            Activation::Tanh => z.tanh(),
            Activation::Relu => relu(z),
        }
    }

    /// The derivative at `z`; swish'(z) = s(z)·(1 + z·(1 − s(z))).
    fn derivative(self, z: Tensor<2>) -> Tensor<2> {
        match self {
            Activation::Swish => {
                let s = sigmoid(z.clone());
                s.clone() * (z * (s.neg() + 1.0) + 1.0)
            }
            Activation::Tanh => {
                let t = z.tanh();
                t.clone().mul(t).neg() + 1.0
            }
            Activation::Relu => z.greater_elem(0.0).float(),
        }
    }
}

/// An MLP's sizes and nonlinearity.
#[derive(Config, Debug, PartialEq)]
pub struct MlpConfig {
    pub d_input: usize,
    pub hidden: Vec<usize>,
    pub d_output: usize,
    pub activation: Activation,
}

impl MlpConfig {
    pub fn init(&self, device: &burn::tensor::Device) -> Mlp {
        let mut widths = vec![self.d_input];
        widths.extend(&self.hidden);
        widths.push(self.d_output);
        let layers = widths
            .windows(2)
            .map(|w| LinearConfig::new(w[0], w[1]).init(device))
            .collect();
        Mlp {
            layers,
            activation: self.activation,
        }
    }
}

/// Dense layers with the activation between them and none after the last.
#[derive(Module, Debug)]
pub struct Mlp {
    pub layers: Vec<Linear>,
    #[module(skip)]
    pub activation: Activation,
}

impl Mlp {
    /// # Shapes
    /// - `x`: `[batch, d_input]` → `[batch, d_output]`
    pub fn forward(&self, x: Tensor<2>) -> Tensor<2> {
        let last = self.layers.len() - 1;
        self.layers.iter().enumerate().fold(x, |h, (i, layer)| {
            let z = layer.forward(h);
            if i < last {
                self.activation.apply(z)
            } else {
                z
            }
        })
    }

    /// The output and its gradient with respect to the input, for a scalar MLP
    /// (`d_output == 1`), both differentiable with respect to the parameters.
    ///
    /// # Shapes
    /// - `x`: `[batch, d_input]` → (`[batch, 1]`, `[batch, d_input]`)
    pub fn forward_with_input_grad(&self, x: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
        let last = self.layers.len() - 1;
        let mut pre_activations = Vec::with_capacity(last);
        let mut h = x;
        for layer in &self.layers[..last] {
            let z = layer.forward(h);
            h = self.activation.apply(z.clone());
            pre_activations.push(z);
        }
        let output = self.layers[last].forward(h);
        // d output / d h_last = W_lastᵀ, broadcast over the batch.
        let batch = output.dims()[0];
        let w_last = self.layers[last].weight.val(); // [hidden, 1]
        let hidden = w_last.dims()[0];
        let mut grad = w_last.transpose().expand([batch, hidden]);
        for (layer, z) in self.layers[..last].iter().zip(pre_activations).rev() {
            grad = (grad * self.activation.derivative(z)).matmul(layer.weight.val().transpose());
        }
        (output, grad)
    }
}
