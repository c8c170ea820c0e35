//! Training an MLP on plain `f32` buffers: the forward pass keeps each
//! layer's input (and, for swish, its pre-activation), the backward pass turns
//! the output's gradient into every weight's and bias's (`∂W = xᵀ·g`,
//! `∂b = Σ_rows g`) and the input's (`g ← (g·Wᵀ) ⊙ act'(z)`). Each product is single-threaded `gemm` on row
//! blocks, split over as many cores as the tape is given (gemm's own threads
//! measured no faster than one core; rayon-joined row blocks do pay); buffers
//! live in the tape and are reused every call.

use burn::module::{Module, ModuleMapper, Param};
use burn::tensor::{Tensor, TensorData};

use super::dense::{product_on_cores, product_on_cores_into};
use super::vector_math::{
    activate, activation_gradient, activation_slopes, bias_then_activate, column_sums,
};
use crate::nn::{Activation, Mlp, to_f32_vec};

/// One dense layer `y = x·W + b`, W row-major `[d_in, d_out]` (burn's layout).
#[derive(Debug, Clone, PartialEq)]
pub struct Layer {
    pub d_in: usize,
    pub d_out: usize,
    pub weight: Vec<f32>,
    pub bias: Vec<f32>,
}

/// An MLP with `activation` between its layers and none after the last: SAC's
/// actor and critics (ReLU), MOPO's ensemble members (swish). Also holds
/// gradients, which have the parameters' shapes.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainableMlp {
    pub layers: Vec<Layer>,
    pub activation: Activation,
}

/// What a forward pass keeps for the backward pass, and the buffers both use.
#[derive(Debug, Clone, Default)]
pub struct MlpTape {
    rows: usize,
    /// The input of each layer, `[rows, d_in]` (the activations past the first).
    inputs: Vec<Vec<f32>>,
    /// Each hidden layer's pre-activation `z`, kept only where act'(z) needs
    /// it (swish; ReLU's and tanh's derivatives follow from their outputs).
    pre_activations: Vec<Vec<f32>>,
    /// The last layer's output, `[rows, d_out]`.
    pub output: Vec<f32>,
    grad: Vec<f32>,
    grad_next: Vec<f32>,
    /// How many cores each product may split its rows over.
    cores: usize,
    /// The tangent pass of [`TrainableMlp::backward_through_input_gradient`]:
    /// each layer's input tangent ḣ (the first is Q), each hidden layer's
    /// pre-activation tangent ż, φ'(z) and φ''(z).
    tangent_inputs: Vec<Vec<f32>>,
    tangent_pre: Vec<Vec<f32>>,
    slopes: Vec<Vec<f32>>,
    curvatures: Vec<Vec<f32>>,
    /// ∂L/∂ż and its next layer's, beside `grad` and `grad_next` (∂L/∂z).
    tangent_grad: Vec<f32>,
    tangent_grad_next: Vec<f32>,
}

impl MlpTape {
    /// A tape whose passes split each product's rows over `cores` cores: for a
    /// network that runs while nothing else does (SAC's actor), or with a share
    /// of the cores (the twin critics, side by side).
    pub fn on_cores(cores: usize) -> Self {
        Self {
            cores,
            ..Self::default()
        }
    }
}

impl TrainableMlp {
    /// The weights of a burn [`Mlp`].
    pub fn from_burn(mlp: &Mlp) -> Self {
        let layers = mlp
            .layers
            .iter()
            .map(|layer| {
                let [d_in, d_out] = layer.weight.val().dims();
                Layer {
                    d_in,
                    d_out,
                    weight: to_f32_vec(layer.weight.val()),
                    bias: layer
                        .bias
                        .as_ref()
                        .map_or(vec![0.0; d_out], |b| to_f32_vec(b.val())),
                }
            })
            .collect();
        Self {
            layers,
            activation: mlp.activation,
        }
    }

    /// `mlp` with these weights (parameter ids and trainability kept).
    pub fn write_to(&self, mlp: Mlp) -> Mlp {
        struct Writer<'a> {
            layers: &'a [Layer],
            path: Vec<String>,
        }
        impl ModuleMapper for Writer<'_> {
            fn enter_module(&mut self, name: &str, _: &str) {
                self.path.push(name.to_string());
            }
            fn exit_module(&mut self, _: &str, _: &str) {
                self.path.pop();
            }
            fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
                let (id, old) = (param.id, param.val());
                let values = match self.path.as_slice() {
                    [_, index, leaf] => index.parse::<usize>().ok().and_then(|i| {
                        let layer = self.layers.get(i)?;
                        match leaf.as_str() {
                            "weight" => Some(layer.weight.clone()),
                            "bias" => Some(layer.bias.clone()),
                            _ => None,
                        }
                    }),
                    _ => None,
                };
                let values = values.expect("TrainableMlp::write_to: the MLP's layout");
                let require_grad = old.is_require_grad();
                let tensor = Tensor::from_data(TensorData::new(values, old.dims()), &old.device());
                Param::initialized(id, tensor.set_require_grad(require_grad))
            }
        }
        mlp.map(&mut Writer {
            layers: &self.layers,
            path: Vec::new(),
        })
    }

    /// Zeros of this network's shape.
    pub fn zeros_like(&self) -> Self {
        Self {
            layers: self
                .layers
                .iter()
                .map(|l| Layer {
                    d_in: l.d_in,
                    d_out: l.d_out,
                    weight: vec![0.0; l.weight.len()],
                    bias: vec![0.0; l.bias.len()],
                })
                .collect(),
            activation: self.activation,
        }
    }

    /// Each parameter under its burn module path (`layers.0.weight`, ...),
    /// mutably, with the same parameter of `other` (gradients, a target).
    pub fn params_with<'a>(
        &'a mut self,
        other: &'a Self,
    ) -> impl Iterator<Item = (String, &'a mut Vec<f32>, &'a Vec<f32>)> {
        self.layers
            .iter_mut()
            .zip(&other.layers)
            .enumerate()
            .flat_map(|(i, (l, o))| {
                [
                    (format!("layers.{i}.weight"), &mut l.weight, &o.weight),
                    (format!("layers.{i}.bias"), &mut l.bias, &o.bias),
                ]
            })
    }

    pub fn d_in(&self) -> usize {
        self.layers[0].d_in
    }

    pub fn d_out(&self) -> usize {
        self.layers[self.layers.len() - 1].d_out
    }

    /// The network on `rows` rows of `input` (`[rows, d_in]`), into `tape.output`,
    /// keeping what [`TrainableMlp::backward`] needs.
    pub fn forward(&self, input: &[f32], rows: usize, tape: &mut MlpTape) {
        assert_eq!(input.len(), rows * self.d_in(), "MLP input size");
        let last = self.layers.len() - 1;
        tape.rows = rows;
        tape.inputs.resize_with(self.layers.len(), Vec::new);
        let keeps_pre_activations = self.activation == Activation::Swish;
        if keeps_pre_activations {
            tape.pre_activations.resize_with(last, Vec::new);
        }
        tape.inputs[0].clear();
        tape.inputs[0].extend_from_slice(input);
        for (i, layer) in self.layers.iter().enumerate() {
            let (before, after) = tape.inputs.split_at_mut(i + 1);
            let out = if i == last {
                &mut tape.output
            } else {
                &mut after[0]
            };
            out.resize(rows * layer.d_out, 0.0);
            let x = &before[i];
            // out = x·W
            product_on_cores(
                tape.cores,
                (rows, layer.d_out, layer.d_in),
                out,
                (x, layer.d_in as isize, 1),
                (&layer.weight, layer.d_out as isize, 1),
            );
            if i == last {
                bias_then_activate(out, &layer.bias, None);
            } else if keeps_pre_activations {
                bias_then_activate(out, &layer.bias, None);
                tape.pre_activations[i].clear();
                tape.pre_activations[i].extend_from_slice(out);
                activate(out, self.activation);
            } else {
                bias_then_activate(out, &layer.bias, Some(self.activation));
            }
        }
    }

    /// Back-propagates `grad_output` (`[rows, d_out]`, ∂L/∂output) through the
    /// last [`TrainableMlp::forward`]: writes ∂L/∂θ into `grads` (overwriting) and
    /// ∂L/∂input into `grad_input` (`[rows, d_in]`), each only when asked.
    pub fn backward(
        &self,
        tape: &mut MlpTape,
        grad_output: &[f32],
        mut grads: Option<&mut TrainableMlp>,
        grad_input: Option<&mut Vec<f32>>,
    ) {
        let rows = tape.rows;
        assert_eq!(
            grad_output.len(),
            rows * self.d_out(),
            "MLP output gradient size"
        );
        tape.grad.clear();
        tape.grad.extend_from_slice(grad_output);
        let wants_input = grad_input.is_some();
        for (i, layer) in self.layers.iter().enumerate().rev() {
            let x = &tape.inputs[i];
            if let Some(grads) = grads.as_deref_mut() {
                let g = &mut grads.layers[i];
                // ∂W = xᵀ·g: x read column-major as a [d_in, rows] matrix.
                product_on_cores(
                    tape.cores,
                    (layer.d_in, layer.d_out, rows),
                    &mut g.weight,
                    (x, 1, layer.d_in as isize),
                    (&tape.grad, layer.d_out as isize, 1),
                );
                column_sums(&tape.grad, &mut g.bias);
            }
            if i == 0 && !wants_input {
                break;
            }
            // g·Wᵀ: W read column-major as a [d_out, d_in] matrix.
            tape.grad_next.resize(rows * layer.d_in, 0.0);
            product_on_cores(
                tape.cores,
                (rows, layer.d_in, layer.d_out),
                &mut tape.grad_next,
                (&tape.grad, layer.d_out as isize, 1),
                (&layer.weight, 1, layer.d_out as isize),
            );
            if i > 0 {
                // This layer's input is the previous layer's activation.
                let pre = tape.pre_activations.get(i - 1).map(Vec::as_slice);
                activation_gradient(self.activation, &mut tape.grad_next, x, pre);
            }
            std::mem::swap(&mut tape.grad, &mut tape.grad_next);
        }
        if let Some(grad_input) = grad_input {
            grad_input.clear();
            grad_input.extend_from_slice(&tape.grad);
        }
    }

    /// For a scalar network d(x) (`d_out == 1`) after [`TrainableMlp::forward`]:
    /// writes into `grads` (overwriting) the gradient of a loss L(d, ∇ₓd), given
    /// ∂L/∂d per row (`grad_output`, `[rows]`) and Q = ∂L/∂∇ₓd (`grad_input_grad`,
    /// `[rows, d_in]`): η's losses, which hold ∇ₓη (eq. 3, 4).
    ///
    /// Σ_rows Qᵀ∇ₓd is the tangent ḋ of d along Q (forward mode: ż = ḣ·W,
    /// ḣ = φ'(z)⊙ż from ḣ₀ = Q), so with Q held fixed its parameter gradient
    /// is the reverse pass over the pair (z, ż), seeded with ∂L/∂d and 1:
    /// ∂W = hᵀ·g_z + ḣᵀ·g_ż, ∂b = Σ g_z, and below each hidden layer
    /// g_z ← (g_z·Wᵀ)⊙φ' + (g_ż·Wᵀ)⊙ż⊙φ'', g_ż ← (g_ż·Wᵀ)⊙φ'.
    pub fn backward_through_input_gradient(
        &self,
        tape: &mut MlpTape,
        grad_output: &[f32],
        grad_input_grad: &[f32],
        grads: &mut TrainableMlp,
    ) {
        let rows = tape.rows;
        let last = self.layers.len() - 1;
        assert_eq!(self.d_out(), 1, "an input gradient needs a scalar network");
        assert_eq!(grad_output.len(), rows, "MLP output gradient size");
        assert_eq!(
            grad_input_grad.len(),
            rows * self.d_in(),
            "MLP input-gradient gradient size"
        );
        let cores = tape.cores;
        // The tangent pass, hidden layers only (the output's tangent is not needed).
        tape.tangent_inputs.resize_with(last + 1, Vec::new);
        tape.tangent_pre.resize_with(last, Vec::new);
        tape.slopes.resize_with(last, Vec::new);
        tape.curvatures.resize_with(last, Vec::new);
        tape.tangent_inputs[0].clear();
        tape.tangent_inputs[0].extend_from_slice(grad_input_grad);
        for (i, layer) in self.layers[..last].iter().enumerate() {
            let pre = tape.pre_activations.get(i).map(Vec::as_slice);
            activation_slopes(
                self.activation,
                &tape.inputs[i + 1],
                pre,
                &mut tape.slopes[i],
                &mut tape.curvatures[i],
            );
            let z_dot = &mut tape.tangent_pre[i];
            z_dot.resize(rows * layer.d_out, 0.0);
            product_on_cores(
                cores,
                (rows, layer.d_out, layer.d_in),
                z_dot,
                (&tape.tangent_inputs[i], layer.d_in as isize, 1),
                (&layer.weight, layer.d_out as isize, 1),
            );
            let h_dot = &mut tape.tangent_inputs[i + 1];
            h_dot.clear();
            h_dot.extend(z_dot.iter().zip(&tape.slopes[i]).map(|(z, p)| z * p));
        }
        // The reverse pass over (z, ż).
        tape.grad.clear();
        tape.grad.extend_from_slice(grad_output);
        tape.tangent_grad.clear();
        tape.tangent_grad.resize(rows, 1.0);
        for (i, layer) in self.layers.iter().enumerate().rev() {
            let g = &mut grads.layers[i];
            let (d_in, d_out) = (layer.d_in as isize, layer.d_out as isize);
            let dims = (layer.d_in, layer.d_out, rows);
            product_on_cores(
                cores,
                dims,
                &mut g.weight,
                (&tape.inputs[i], 1, d_in),
                (&tape.grad, d_out, 1),
            );
            product_on_cores_into(
                cores,
                dims,
                &mut g.weight,
                (&tape.tangent_inputs[i], 1, d_in),
                (&tape.tangent_grad, d_out, 1),
                true,
            );
            column_sums(&tape.grad, &mut g.bias);
            if i == 0 {
                break;
            }
            let back = (rows, layer.d_in, layer.d_out);
            tape.grad_next.resize(rows * layer.d_in, 0.0);
            tape.tangent_grad_next.resize(rows * layer.d_in, 0.0);
            product_on_cores(
                cores,
                back,
                &mut tape.grad_next,
                (&tape.grad, d_out, 1),
                (&layer.weight, 1, d_out),
            );
            product_on_cores(
                cores,
                back,
                &mut tape.tangent_grad_next,
                (&tape.tangent_grad, d_out, 1),
                (&layer.weight, 1, d_out),
            );
            let (p, q, z_dot) = (
                &tape.slopes[i - 1],
                &tape.curvatures[i - 1],
                &tape.tangent_pre[i - 1],
            );
            for j in 0..tape.grad_next.len() {
                let g_h_dot = tape.tangent_grad_next[j];
                tape.grad_next[j] = tape.grad_next[j] * p[j] + g_h_dot * z_dot[j] * q[j];
                tape.tangent_grad_next[j] = g_h_dot * p[j];
            }
            std::mem::swap(&mut tape.grad, &mut tape.grad_next);
            std::mem::swap(&mut tape.tangent_grad, &mut tape.tangent_grad_next);
        }
    }
}
