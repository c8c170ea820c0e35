//! The distance-aware uncertainty η_ϕ and its convexity constant μ_ϕ
//! (Section 4.1), with their losses L_sc, L_μ (eq. 3) and L_grad (eq. 4), in
//! the paper's form or NUNO's code's (`EtaLossForm`).
//!
//! η_ϕ(s, a) = η_max·sigmoid(NN_ϕ(s, a) − offset): near zero with near-zero
//! gradient on the data, locally strongly convex around it, high but bounded
//! far from it. Inputs are normalised `(s, a)`.

use burn::module::{Module, Param};
use burn::tensor::activation::{relu, sigmoid};
use burn::tensor::{Device, Tensor, TensorData};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::config::{EtaLossForm, LossConfig, MuForm, SCALAR_MU_FACTOR, SdeConfig};
use crate::nn::{Activation, Mlp, MlpConfig};

/// η_ϕ and μ_ϕ over inputs of width `d_input`.
#[derive(Module, Debug)]
pub struct DistanceAware {
    /// NN_ϕ inside η's sigmoid: 2×64 swish.
    pub eta_net: Mlp,
    /// NN_ϕ of μ_ϕ = exp(NN_ϕ): 2×32 swish (Appendix C.4), under [`MuForm::Network`].
    pub mu_net: Option<Mlp>,
    /// p of μ = |100·p| (`[1]`), under [`MuForm::Scalar`].
    pub mu_scalar: Option<Param<Tensor<1>>>,
    #[module(skip)]
    pub eta_max: f32,
    #[module(skip)]
    pub eta_offset: f32,
}

/// Where L_far looks: a fixed reference subset of the (normalised) data and
/// its bounding box, grown by a margin.
#[derive(Debug, Clone, PartialEq)]
pub struct FarField {
    dim: usize,
    reference: Vec<f32>,
    low: Vec<f32>,
    high: Vec<f32>,
    min_distance: f32,
}

impl FarField {
    /// A far field around `reference` (row-major `[n, dim]`) for `config`.
    pub fn new(reference: Vec<f32>, dim: usize, config: &LossConfig) -> Self {
        let mut low = vec![f32::INFINITY; dim];
        let mut high = vec![f32::NEG_INFINITY; dim];
        for row in reference.chunks_exact(dim) {
            for (d, &v) in row.iter().enumerate() {
                low[d] = low[d].min(v);
                high[d] = high[d].max(v);
            }
        }
        let margin = config.far_margin;
        Self {
            dim,
            reference,
            low: low.iter().map(|v| v - margin).collect(),
            high: high.iter().map(|v| v + margin).collect(),
            min_distance: config.far_radii * config.radius,
        }
    }

    /// `count` uniform points in the box, and a 1/0 mask of those farther than
    /// `far_radii`·r from every reference point.
    pub fn sample(
        &self,
        count: usize,
        rng: &mut ChaCha8Rng,
        device: &Device,
    ) -> (Tensor<2>, Tensor<2>) {
        let (points, mask) = self.sample_values(count, rng);
        (
            Tensor::from_data(TensorData::new(points, [count, self.dim]), device),
            Tensor::from_data(TensorData::new(mask, [count, 1]), device),
        )
    }

    /// [`FarField::sample`] as row-major values: points `[count, dim]`, mask `[count]`.
    pub fn sample_values(&self, count: usize, rng: &mut ChaCha8Rng) -> (Vec<f32>, Vec<f32>) {
        let points = self.sample_points(count, rng);
        let mask = points
            .chunks_exact(self.dim)
            .map(|p| self.far_mask(p))
            .collect();
        (points, mask)
    }

    /// The points of [`FarField::sample_values`] alone (the same draws), for a
    /// fit whose L_far is off: the mask, a distance to every reference point,
    /// costs more than the rest of the draw.
    pub fn sample_points(&self, count: usize, rng: &mut ChaCha8Rng) -> Vec<f32> {
        let mut points = Vec::with_capacity(count * self.dim);
        for _ in 0..count {
            for d in 0..self.dim {
                points.push(rng.random_range(self.low[d]..=self.high[d]));
            }
        }
        points
    }

    /// 1 where `point` lies farther than `far_radii`·r from every reference point, else 0.
    fn far_mask(&self, point: &[f32]) -> f32 {
        let threshold = self.min_distance * self.min_distance;
        let far = self.reference.chunks_exact(self.dim).all(|r| {
            r.iter()
                .zip(point)
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f32>()
                >= threshold
        });
        if far { 1.0 } else { 0.0 }
    }
}

/// The η loss terms, each a scalar tensor (mean over the batch).
#[derive(Debug, Clone)]
pub struct EtaLosses {
    /// L_sc, eq. 3: Σ over samples of min(c, 0)².
    pub sc: Tensor<1>,
    /// L_grad, eq. 4: ‖∇η‖² + η² (paper form), ‖∇η‖² (code form).
    pub grad: Tensor<1>,
    /// L_μ, eq. 3: 1/μ (paper form), 1/μ² (code form).
    pub mu: Tensor<1>,
    /// L_far: mean over the far points of relu(logit(far_target) − (NN_ϕ − offset))²,
    /// zero exactly where η ≥ far_target·η_max.
    pub far: Tensor<1>,
    /// Code form: mean η at the data (0 in the paper form).
    pub value: Tensor<1>,
    /// Code form: mean (η(x + δ)/η_max − 1)² at the ball's points (0 in the paper form).
    pub one: Tensor<1>,
    /// Code form: `grad_floor_weight`·(−ln ‖∇η‖²) while ‖∇η‖² < `grad_floor`,
    /// already weighted (0 otherwise, and in the paper form).
    pub floor: Tensor<1>,
}

impl EtaLosses {
    /// The terms' share of eq. 7, each times its λ.
    pub fn weighted(&self, config: &LossConfig) -> Tensor<1> {
        let terms = [
            &self.sc,
            &self.grad,
            &self.mu,
            &self.far,
            &self.value,
            &self.one,
            &self.floor,
        ];
        let mut weighted = terms.into_iter().zip(config.eta_weights());
        let (first, w) = weighted.next().expect("η has seven terms");
        weighted.fold(first.clone() * w, |sum, (t, w)| sum + t.clone() * w)
    }
}

impl DistanceAware {
    pub fn init(d_input: usize, config: &SdeConfig, device: &burn::tensor::Device) -> Self {
        let network = config.mu_form == MuForm::Network;
        Self {
            eta_net: MlpConfig::new(d_input, config.eta_hidden.clone(), 1, Activation::Swish)
                .init(device),
            mu_net: network.then(|| {
                MlpConfig::new(d_input, config.mu_hidden.clone(), 1, Activation::Swish).init(device)
            }),
            mu_scalar: (!network).then(|| Param::from_tensor(Tensor::ones([1], device))),
            eta_max: config.eta_max,
            eta_offset: config.eta_offset,
        }
    }

    /// η_ϕ at normalised inputs.
    ///
    /// # Shapes
    /// - `x`: `[batch, d_input]` → `[batch, 1]`
    pub fn eta(&self, x: Tensor<2>) -> Tensor<2> {
        sigmoid(self.logit(x)) * self.eta_max
    }

    /// η's logit ℓ = NN_ϕ(x) − offset, so η = η_max·sigmoid(ℓ); unbounded, it is
    /// what h_ϕ reads (eq. 5).
    ///
    /// # Shapes
    /// - `x`: `[batch, d_input]` → `[batch, 1]`
    pub fn logit(&self, x: Tensor<2>) -> Tensor<2> {
        self.eta_net.forward(x) - self.eta_offset
    }

    /// η_ϕ and ∇ₓη_ϕ, both differentiable with respect to the parameters.
    ///
    /// # Shapes
    /// - `x`: `[batch, d_input]` → (`[batch, 1]`, `[batch, d_input]`)
    pub fn eta_with_grad(&self, x: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
        let (d, grad_d) = self.eta_net.forward_with_input_grad(x);
        let s = sigmoid(d - self.eta_offset);
        // dη/dd = η_max·s·(1 − s)
        let slope = s.clone() * (s.clone().neg() + 1.0) * self.eta_max;
        (s * self.eta_max, grad_d * slope)
    }

    /// μ_ϕ = exp(NN_ϕ) > 0, or the one μ = |100·p| of [`MuForm::Scalar`].
    ///
    /// # Shapes
    /// - `x`: `[batch, d_input]` → `[batch, 1]`
    pub fn mu(&self, x: Tensor<2>) -> Tensor<2> {
        match (&self.mu_net, &self.mu_scalar) {
            (Some(net), _) => net.forward(x).exp(),
            (None, Some(p)) => {
                let mu = (p.val() * SCALAR_MU_FACTOR).abs().reshape([1, 1]);
                mu.expand([x.dims()[0], 1])
            }
            (None, None) => unreachable!("DistanceAware::init builds one form of μ"),
        }
    }

    /// L_sc, L_grad and L_μ at data points `x` (eq. 3, 4), in `config`'s form.
    ///
    /// For each datum `x_t` and offset `δ = r·ε` (`noise` holds the ε, `samples`
    /// per datum), the strong-convexity constraint is
    /// `c = η(x_t + δ) − η(x_t) − ∇η(x_t)ᵀδ − κ·μ_t‖δ‖²` (κ = 1 in eq. 3, ½ in
    /// NUNO's code), and L_sc sums `min(c, 0)²`.
    ///
    /// # Shapes
    /// - `x`: `[batch, d]`; `noise`: `[batch · samples, d]`
    ///
    /// `far` holds uniform points and their far mask from [`FarField::sample`].
    pub fn losses(
        &self,
        x: Tensor<2>,
        noise: Tensor<2>,
        far: (Tensor<2>, Tensor<2>),
        config: &LossConfig,
    ) -> EtaLosses {
        let batch = x.dims()[0];
        let samples = noise.dims()[0] / batch;
        let form = config.eta_losses;
        let (eta, grad) = self.eta_with_grad(x.clone());
        let mu = self.mu(x.clone());
        let repeat = |t: Tensor<2>| {
            let width = t.dims()[1];
            t.unsqueeze_dim::<3>(1)
                .expand([batch, samples, width])
                .reshape([batch * samples, width])
        };
        let delta = noise * config.radius;
        let eta_near = self.eta(repeat(x) + delta.clone());
        let linear = (repeat(grad.clone()) * delta.clone()).sum_dim(1);
        let distance2 = delta.square().sum_dim(1);
        let constraint = eta_near.clone()
            - repeat(eta.clone())
            - linear
            - repeat(mu.clone()) * distance2 * form.mu_factor();
        let sc = constraint
            .clamp_max(0.0)
            .square()
            .sum()
            .div_scalar(batch as f32);
        let grad2 = grad.square().sum_dim(1).mean();
        let zero = || Tensor::<1>::zeros([1], &eta.device());
        let (grad_loss, mu_loss, value, one, floor) = match form {
            EtaLossForm::Paper => (
                grad2 + eta.clone().square().mean(),
                mu.recip().mean(),
                zero(),
                zero(),
                zero(),
            ),
            EtaLossForm::Code => {
                let below = grad2.clone().lower_elem(config.grad_floor).float();
                let floor = below * grad2.clone().log().neg() * config.grad_floor_weight;
                let one = (eta_near / self.eta_max - 1.0).square().mean();
                (
                    grad2,
                    mu.powi_scalar(2).recip().mean(),
                    eta.mean(),
                    one,
                    floor,
                )
            }
        };
        let (far_points, far_mask) = far;
        // On η's logit: where η ≈ 0 the sigmoid is flat, and a hinge on η itself
        // could not lift it (a ring's interior stayed low that way).
        let logit = self.logit(far_points);
        let target = (config.far_target / (1.0 - config.far_target)).ln();
        let shortfall = relu(logit.neg() + target);
        EtaLosses {
            sc,
            grad: grad_loss,
            mu: mu_loss,
            far: (shortfall.square() * far_mask).mean(),
            value,
            one,
            floor,
        }
    }
}
