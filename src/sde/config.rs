//! Every knob of the neural SDE, its losses and its fitting, with the paper's
//! Appendix C values as defaults. Saved in each artifact's `model.json`.

use burn::config::Config;

use super::drift_inputs::DriftInputs;
use crate::infer::Kernel;

/// Network sizes and output transforms (Appendix C.4, eq. 5 and 8).
#[derive(Config, Debug, PartialEq)]
pub struct SdeConfig {
    /// Hidden sizes of the drift networks G, H and f_res: 3×256 swish (Appendix C.4).
    #[config(default = "vec![256, 256, 256]")]
    pub drift_hidden: Vec<usize>,
    /// Hidden sizes of the reward drift f_rew (NUNO^R): 3×64 swish.
    #[config(default = "vec![64, 64, 64]")]
    pub reward_hidden: Vec<usize>,
    /// Hidden sizes of the aleatoric diffusion σ_ϕ: 2×256 tanh.
    #[config(default = "vec![256, 256]")]
    pub sigma_hidden: Vec<usize>,
    /// Hidden sizes of the distance-aware term η_ϕ: 2×64 swish.
    #[config(default = "vec![64, 64]")]
    pub eta_hidden: Vec<usize>,
    /// Hidden sizes of the convexity constant μ_ϕ = exp(NN_ϕ): 2×32 swish.
    #[config(default = "vec![32, 32]")]
    pub mu_hidden: Vec<usize>,
    /// NUNO^R: augment the state with the cumulative reward r_c, dr_c = f_rew(s, a) dt.
    #[config(default = false)]
    pub reward_model: bool,
    /// W^max of h(η) = W^max·sigmoid(W·ℓ + b) (eq. 5, ℓ = η's logit): the diffusion
    /// beyond the data, per state dimension, as a multiple of that dimension's
    /// diffusion scale (the std of its one-step change over sqrt(dt)). One value
    /// applies to every dimension. See docs/paper-map.md for why 1.
    #[config(default = "vec![1.0]")]
    pub w_max: Vec<f32>,
    /// Bound of η: η = η_max·sigmoid(NN(s, a) − η_offset), so η is high but bounded far from data.
    #[config(default = 1.0)]
    pub eta_max: f32,
    /// Offset inside η's sigmoid (NUNO's code uses 7).
    #[config(default = 7.0)]
    pub eta_offset: f32,
    /// W of h(η) = W^max·sigmoid(W·ℓ + b) on η's logit ℓ: how sharply h rises, ≥ 1
    /// (eq. 5; NUNO's code starts at ≈ 2).
    #[config(default = 2.0)]
    pub h_weight: f32,
    /// b of h(η), set by the fit from the data (`NeuralSde::calibrate_h_bias`):
    /// h is `h_on_data`·W^max at the `h_data_quantile` of η's logit on the
    /// training data, so it is ≈ 0 there whatever η a fit reaches on its data,
    /// and → W^max where η → η_max (docs/paper-map.md).
    #[config(default = 0.0)]
    pub h_bias: f32,
    /// h/W^max at the data's `h_data_quantile` of η.
    #[config(default = 0.01)]
    pub h_on_data: f32,
    /// The quantile of η on the training data where h is `h_on_data`·W^max.
    #[config(default = 0.9)]
    pub h_data_quantile: f64,
    /// Smallest σ_ϕ, as a fraction of each dimension's diffusion scale.
    #[config(default = 1e-3)]
    pub sigma_min: f32,
    /// The scale of ε at which the model samples: s' = mean + c·(σ + h(η))·sqrt(dt)·ε
    /// on L_data's particle path, in the threshold rollouts, in policy rollouts
    /// and (by default) in the server's answers. Σ itself stays the calibrated
    /// one-step uncertainty whatever c is. 1 is eq. 5 as written (the paper
    /// recipe); NUNO's code fits its diffusion without dt (variance = diffusion²,
    /// so it matches the one-step error) yet samples diffusion·sqrt(dt)·ε, which is
    /// c = sqrt(dt) here (≈ 0.09 on hopper: `Recipe::Code`). Models saved before
    /// this field sampled at 1, and load so.
    #[config(default = 1.0)]
    pub sample_noise_scale: f32,
    /// μ_ϕ's form: a network (Appendix C.4) or NUNO's code's one learned scalar
    /// (`MuForm`). Models saved before this field used the network, and load so.
    #[config(default = "MuForm::Network")]
    pub mu_form: MuForm,
    /// What the drift networks see of the state: the paper's z-scores or NUNO's
    /// code's pose features (`DriftInputs`). Models saved before this field saw
    /// z-scores, and load so.
    #[config(default = "DriftInputs::ZScores")]
    pub drift_inputs: DriftInputs,
}

/// The form of the convexity constant μ_ϕ in L_sc (eq. 3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MuForm {
    /// μ_ϕ(s, a) = exp(NN_ϕ(s, a)), 2×32 swish (Appendix C.4).
    Network,
    /// One μ for every input, μ = |`SCALAR_MU_FACTOR`·p| with p learned from 1
    /// (NUNO's code, `losses_diffusion.py`).
    Scalar,
}

/// μ = |100·p| under [`MuForm::Scalar`]: p starts at 1, so μ at 100.
pub const SCALAR_MU_FACTOR: f32 = 100.0;

crate::shared::named_enum!(MuForm, "mu form", MuForm::Network => "network", MuForm::Scalar => "scalar");

/// The form of η's losses (eq. 3, 4) beside L_data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EtaLossForm {
    /// The paper's: c = η(x + δ) − η(x) − ∇η·δ − μ‖δ‖² in L_sc, L_grad = ‖∇η‖² + η²,
    /// L_μ = 1/μ.
    Paper,
    /// NUNO's code's (`losses_diffusion.py`): c with ½μ‖δ‖², L_grad = ‖∇η‖² alone,
    /// λ_value·η and λ_one·(η(x + δ)/η_max − 1)² beside it, L_μ = 1/μ², and the
    /// gradient floor (`LossConfig::grad_floor`).
    Code,
}

crate::shared::named_enum!(EtaLossForm, "eta loss form", EtaLossForm::Paper => "paper", EtaLossForm::Code => "code");

impl EtaLossForm {
    /// The factor of μ‖δ‖² in L_sc's constraint: 1 in eq. 3, ½ in NUNO's code.
    pub fn mu_factor(self) -> f32 {
        match self {
            Self::Paper => 1.0,
            Self::Code => 0.5,
        }
    }
}

impl SdeConfig {
    /// Refuses settings no model can use, naming the field; `state_dim` is the
    /// width of the integrated state (W^max has one value or one per dimension).
    pub fn validate(&self, state_dim: usize) -> Result<(), super::SdeError> {
        let bad = |message: String| super::SdeError::Config(format!("model config: {message}"));
        if self.w_max.len() != 1 && self.w_max.len() != state_dim {
            return Err(bad(format!(
                "w_max has {} values: give one, or one per state dimension ({state_dim})",
                self.w_max.len()
            )));
        }
        if let Some(w) = self.w_max.iter().find(|w| !(w.is_finite() && **w > 0.0)) {
            return Err(bad(format!("w_max value {w}: must be finite and > 0")));
        }
        if !(self.h_weight.is_finite() && self.h_weight >= 1.0) {
            return Err(bad(format!("h_weight = {}: must be >= 1", self.h_weight)));
        }
        if !self.h_bias.is_finite() {
            return Err(bad(format!("h_bias = {}: must be finite", self.h_bias)));
        }
        if !(self.h_on_data > 0.0 && self.h_on_data < 1.0) {
            return Err(bad(format!(
                "h_on_data = {}: must lie strictly between 0 and 1",
                self.h_on_data
            )));
        }
        if !(self.h_data_quantile > 0.0 && self.h_data_quantile <= 1.0) {
            return Err(bad(format!(
                "h_data_quantile = {}: must lie in (0, 1]",
                self.h_data_quantile
            )));
        }
        if !(self.eta_max.is_finite() && self.eta_max > 0.0) {
            return Err(bad(format!("eta_max = {}: must be > 0", self.eta_max)));
        }
        if !(self.sigma_min.is_finite() && self.sigma_min > 0.0) {
            return Err(bad(format!("sigma_min = {}: must be > 0", self.sigma_min)));
        }
        if !(self.sample_noise_scale.is_finite() && self.sample_noise_scale >= 0.0) {
            return Err(bad(format!(
                "sample_noise_scale = {}: must be finite and >= 0",
                self.sample_noise_scale
            )));
        }
        Ok(())
    }

    /// h(η)'s b from η's logits on the training data (none without data):
    /// b = logit(h_on_data) − W·ℓ_q, ℓ_q the logits' `h_data_quantile`
    /// (`NeuralSde::calibrate_h_bias`).
    pub fn calibrated_h_bias(&self, mut logits: Vec<f32>) -> Option<f32> {
        if logits.is_empty() {
            return None;
        }
        logits.sort_by(f32::total_cmp);
        let at = ((logits.len() - 1) as f64 * self.h_data_quantile).round() as usize;
        let target = (self.h_on_data / (1.0 - self.h_on_data)).ln();
        Some(target - self.h_weight * logits[at])
    }

    /// W^max for each of `state_dim` dimensions, in multiples of the diffusion scale.
    pub fn w_max_per_dimension(&self, state_dim: usize) -> Vec<f32> {
        match self.w_max.as_slice() {
            [one] => vec![*one; state_dim],
            many => many.to_vec(),
        }
    }
}

/// Where each step of L_data's window starts (eq. 6).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LikelihoodPath {
    /// Eq. 6 as written (and NUNO's code): step k + 1 starts from step k's sampled
    /// particle. The default: the drift learns from its own samples; Σ comes out
    /// over-dispersed on one step, because later steps also see the noise earlier
    /// steps drew (docs/paper-map.md, known gaps).
    Particle,
    /// Every step starts from the recorded state before it: the exact likelihood
    /// of the Euler–Maruyama chain given the observed states. Σ is calibrated on
    /// one step, but the drift is less exact, model samples leave the data sooner
    /// (weaker truncation of off-data actions) and long rollouts can diverge.
    Data,
}

crate::shared::named_enum!(LikelihoodPath, "likelihood path", LikelihoodPath::Data => "data", LikelihoodPath::Particle => "particle");

/// Weights and sampling of the loss terms (eq. 3, 4, 6, 7; Appendix C.4).
#[derive(Config, Debug, PartialEq)]
pub struct LossConfig {
    /// Where each step of L_data's window starts (docs/paper-map.md, deviations).
    #[config(default = "LikelihoodPath::Particle")]
    pub likelihood: LikelihoodPath,
    /// λ_data, weight of L_data (eq. 6, 7).
    #[config(default = 1.0)]
    pub lambda_data: f32,
    /// L_data's weight of window step t is `step_discount`^(t − 1): 1 is eq. 6 (every
    /// step alike); NUNO's code weighs them 0.9^(t − 1) (`losses_trajectories.py`).
    /// Fits saved before this field weighed every step 1, and load so.
    #[config(default = 1.0)]
    pub step_discount: f32,
    /// λ_sc, weight of the strong-convexity hinge L_sc (eq. 3); the paper's "strong convexity coefficient of 1".
    #[config(default = 1.0)]
    pub lambda_sc: f32,
    /// λ_grad, weight of L_grad (eq. 4): 1e-4.
    #[config(default = 1e-4)]
    pub lambda_grad: f32,
    /// λ_μ, weight of L_μ = Σ 1/μ (eq. 3).
    #[config(default = 1.0)]
    pub lambda_mu: f32,
    /// Weight of the residual-drift penalty ‖f_res‖² (Section 4.2, "we penalize the residual term").
    #[config(default = 1e-3)]
    pub lambda_res: f32,
    /// Weight of L_far, the far-field hinge (not in the paper; see docs/paper-map.md):
    /// uniform points at least `far_radii`·r from every reference datum are pushed to
    /// η ≥ `far_target`·η_max, hinged on η's logit. Off by default (the paper's losses
    /// only); it lifts η inside non-convex low-dimensional data (a ring's interior,
    /// with ~0.02 here), but in high dimensions a reference subset is too sparse to
    /// tell "far" from "between data". Too large a weight (≳ 0.05 on the toy sets)
    /// can saturate η on whole clusters of data.
    #[config(default = 0.0)]
    pub lambda_far: f32,
    /// L_far's points are "far" beyond this many radii r from every reference datum.
    #[config(default = 3.0)]
    pub far_radii: f32,
    /// L_far's target, as a fraction of η_max.
    #[config(default = 0.9)]
    pub far_target: f32,
    /// L_far samples uniformly in the reference data's bounding box grown by this margin (normalised units).
    #[config(default = 1.0)]
    pub far_margin: f32,
    /// Data points L_far measures distances to (a fixed random subset of the training data).
    #[config(default = 2048)]
    pub far_reference: usize,
    /// Ball radius r of L_sc's samples N((s_t, a_t), r), in normalised units: 0.1.
    #[config(default = 0.1)]
    pub radius: f32,
    /// Samples per datum for L_sc: 20.
    #[config(default = 20)]
    pub convexity_samples: usize,
    /// The form of η's losses (`EtaLossForm`). Fits saved before this field used
    /// the paper's, and load so.
    #[config(default = "EtaLossForm::Paper")]
    pub eta_losses: EtaLossForm,
    /// λ_value, weight of mean η at the data (code form only): 1e-3.
    #[config(default = 1e-3)]
    pub lambda_value: f32,
    /// λ_one, weight of the "set-one" term mean (η(x + δ)/η_max − 1)² at L_sc's
    /// ball points (code form only): 1e-4.
    #[config(default = 1e-4)]
    pub lambda_one: f32,
    /// Code form only: while the batch mean of ‖∇η‖² is below this,
    /// `grad_floor_weight`·(−ln of it) joins the loss, so η cannot go flat everywhere.
    #[config(default = 1e-6)]
    pub grad_floor: f32,
    #[config(default = 1000.0)]
    pub grad_floor_weight: f32,
}

impl LossConfig {
    /// The λ of each of η's terms, in the order L_sc, L_grad, L_μ, L_far, the
    /// value term, the set-one term and the gradient floor (whose weight is
    /// inside it: 1), as `EtaLosses::weighted` and `StepLosses::weighted_eta` sum them.
    pub fn eta_weights(&self) -> [f32; 7] {
        [
            self.lambda_sc,
            self.lambda_grad,
            self.lambda_mu,
            self.lambda_far,
            self.lambda_value,
            self.lambda_one,
            1.0,
        ]
    }

    /// Refuses weights and sampling settings no fit can use, naming the field.
    pub fn validate(&self) -> Result<(), super::SdeError> {
        let weights = [
            ("lambda_data", self.lambda_data),
            ("lambda_sc", self.lambda_sc),
            ("lambda_grad", self.lambda_grad),
            ("lambda_mu", self.lambda_mu),
            ("lambda_res", self.lambda_res),
            ("lambda_far", self.lambda_far),
            ("lambda_value", self.lambda_value),
            ("lambda_one", self.lambda_one),
            ("grad_floor", self.grad_floor),
            ("grad_floor_weight", self.grad_floor_weight),
        ];
        for (name, value) in weights {
            if !(value.is_finite() && value >= 0.0) {
                return Err(invalid(format!(
                    "{name} = {value}: must be finite and >= 0"
                )));
            }
        }
        if !(self.step_discount.is_finite()
            && self.step_discount > 0.0
            && self.step_discount <= 1.0)
        {
            return Err(invalid(format!(
                "step_discount = {}: must lie in (0, 1]",
                self.step_discount
            )));
        }
        if !(self.radius.is_finite() && self.radius > 0.0) {
            return Err(invalid(format!("radius = {}: must be > 0", self.radius)));
        }
        if self.convexity_samples == 0 {
            return Err(invalid("convexity_samples = 0: L_sc needs samples".into()));
        }
        if self.lambda_far > 0.0 {
            if !(self.far_target > 0.0 && self.far_target < 1.0) {
                return Err(invalid(format!(
                    "far_target = {}: must lie strictly between 0 and 1 (a fraction of η_max)",
                    self.far_target
                )));
            }
            if self.far_reference == 0 {
                return Err(invalid(
                    "far_reference = 0: L_far needs reference points".into(),
                ));
            }
        }
        Ok(())
    }
}

fn invalid(message: String) -> super::SdeError {
    super::SdeError::Config(format!("loss config: {message}"))
}

/// The fitting procedure (Appendix C.4).
#[derive(Config, Debug, PartialEq)]
pub struct FitConfig {
    pub model: SdeConfig,
    pub loss: LossConfig,
    /// Prediction horizon H of the training sequences: 2.
    #[config(default = 2)]
    pub horizon: usize,
    /// Batch size: 128.
    #[config(default = 128)]
    pub batch_size: usize,
    /// Adam learning rate, decayed linearly from `lr_start` to `lr_end` over `lr_decay_steps`.
    #[config(default = 1e-2)]
    pub lr_start: f64,
    #[config(default = 1e-3)]
    pub lr_end: f64,
    #[config(default = 5000)]
    pub lr_decay_steps: usize,
    /// Gradient steps between recalibrations of h(η)'s b on the training data.
    #[config(default = 50)]
    pub h_bias_every: usize,
    /// Adam's ε. burn's 1e-5, not NUNO's (optax's) 1e-8: with 1e-8 the small fit
    /// of `tests/sde.rs` on narrow-action hopper data no longer beat constant velocity
    /// at horizon 1 after 1500 steps (docs/paper-map.md, deviations).
    #[config(default = 1e-5)]
    pub adam_epsilon: f32,
    /// Each parameter's gradient is clipped to this L2 norm before Adam's update.
    /// Not in the paper: the NLL's 1/Σ² makes early steps explode once Σ shrinks
    /// on near-deterministic dimensions (positions), and Adam at lr 1e-2 then diverges.
    #[config(default = 10.0)]
    pub grad_clip_norm: f32,
    /// η's and μ's learning rate, constant, where set (NUNO's code: 1e-3, its
    /// `loss_diffusion` optimiser); unset, they follow the fit's schedule. Only
    /// η's losses reach η and μ (h(η) reads η detached), so this is their own
    /// Adam. Fits saved before this field had it unset, and load so.
    #[config(default = "None")]
    pub eta_lr: Option<f64>,
    /// What takes the gradient steps: `fused` (the CPU kernels, every core) or
    /// `burn` (autodiff on the fit's device: a GPU's path). The same loss, draws
    /// and Adam; either resumes the other's checkpoints. Fits recorded before
    /// this field ran on burn, and load so.
    #[config(default = "Kernel::Fused")]
    pub kernel: Kernel,
    /// Upper bound on gradient steps (early stopping usually ends sooner).
    #[config(default = 20000)]
    pub max_steps: usize,
    /// Validation NLL is measured every `eval_every` steps.
    #[config(default = 250)]
    pub eval_every: usize,
    /// Early stopping: stop after this many evaluations without improvement.
    #[config(default = 8)]
    pub patience: usize,
    /// Fraction of trajectories held out for validation.
    #[config(default = 0.1)]
    pub valid_fraction: f64,
    /// Validation windows (a fixed subset, for a stable metric).
    #[config(default = 2048)]
    pub valid_windows: usize,
    /// Training losses are recorded every `log_every` steps.
    #[config(default = 50)]
    pub log_every: usize,
    /// Smallest per-dimension std of the normaliser.
    #[config(default = 1e-3)]
    pub std_floor: f32,
    #[config(default = 0)]
    pub seed: u64,
}

impl FitConfig {
    /// Refuses a fit that cannot run on states of `obs_dim` observations, naming the
    /// field: the model's and the loss's settings, and every period and learning rate.
    pub fn validate(&self, obs_dim: usize) -> Result<(), super::SdeError> {
        self.model
            .validate(obs_dim + usize::from(self.model.reward_model))?;
        self.loss.validate()?;
        let bad = |message: String| super::SdeError::Config(format!("fit config: {message}"));
        if let Some(message) = zero_count(&[
            ("h_bias_every", self.h_bias_every),
            ("eval_every", self.eval_every),
            ("log_every", self.log_every),
        ]) {
            return Err(bad(message));
        }
        if let Some(lr) = self.eta_lr.filter(|lr| !(lr.is_finite() && *lr > 0.0)) {
            return Err(bad(format!("eta_lr = {lr}: must be finite and > 0")));
        }
        Ok(())
    }

    /// Adam's learning rate at `step`: linear from `lr_start` to `lr_end` over
    /// `lr_decay_steps`, then constant.
    pub fn learning_rate(&self, step: usize) -> f64 {
        let t = (step as f64 / self.lr_decay_steps.max(1) as f64).min(1.0);
        self.lr_start + t * (self.lr_end - self.lr_start)
    }
}

/// "NAME = 0: must be at least 1" for the first of `fields` (name, value) that is 0.
pub(super) fn zero_count(fields: &[(&str, usize)]) -> Option<String> {
    let (name, _) = fields.iter().find(|(_, value)| *value == 0)?;
    Some(format!("{name} = 0: must be at least 1"))
}
