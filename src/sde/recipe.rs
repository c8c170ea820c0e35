//! Two readings of NUNO: the paper's equations and Appendix C (`paper`), and
//! what its authors' code (sde4mbrltatu, branch iclr2025), which produced the
//! paper's numbers, does where the two differ (`code`). A recipe fills the
//! settings it covers; a flag given beside it overrides that one setting.
//! docs/paper-map.md ("Recipes") lists each setting, the file of NUNO's code it
//! comes from, and which recipe is the default and why.

use super::config::{EtaLossForm, FitConfig, LossConfig, MuForm};
use super::drift_inputs::DriftInputs;
use super::threshold::ThresholdConfig;

/// Which reading of NUNO a fit or a policy run follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Recipe {
    /// The paper's equations and Appendix C.
    #[default]
    Paper,
    /// NUNO's code where it differs from the paper (D1–D7 of the faithful-NUNO issue).
    Code,
}

/// At which scale of the calibrated Σ the model samples (`SdeConfig::sample_noise_scale`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SampleNoise {
    /// ε at full scale: s' = mean + Σ·sqrt(dt)·ε, eq. 5 as written.
    Calibrated,
    /// ε at sqrt(dt): NUNO's code scores its diffusion as the one-step std
    /// (`nll_sdes_with_kernel_gaussian_approx`: variance = diffusion², no dt) and
    /// samples diffusion·sqrt(dt)·ε (`integration_schemes.py`), so each model step
    /// injects sqrt(dt) of the one-step error (≈ 0.09 on hopper's dt = 0.008).
    SqrtDt,
}

impl SampleNoise {
    /// The scale of ε for a model stepping `dt` seconds.
    pub fn scale(self, dt: f64) -> f32 {
        match self {
            Self::Calibrated => 1.0,
            Self::SqrtDt => dt.sqrt() as f32,
        }
    }
}

/// NUNO's code's weight of L_data's window step t: 0.9^(t − 1) (`losses_trajectories.py`).
pub const CODE_STEP_DISCOUNT: f32 = 0.9;
/// NUNO's code's ε(h, α ≥ 1): 1.1 × the maximum (`fake_env.py`, `compute_threshold_truncation`).
pub const CODE_MAX_MARGIN: f32 = 1.1;
/// NUNO's code's model buffer: 10 × rollout batch × h × retained epochs (`train_tatu_modelbased.py`).
pub const CODE_MODEL_BUFFER_FACTOR: usize = 10;
/// NUNO's code's weight of ‖∇η‖² (`hop_rand_final`'s config).
pub const CODE_LAMBDA_GRAD: f32 = 1e-5;
/// NUNO's code's η optimiser: Adam at a constant 1e-3 (`loss_diffusion`).
pub const CODE_ETA_LR: f64 = 1e-3;

impl EtaLossForm {
    /// `fit` with η's losses in this form and what goes with it: the code's
    /// scalar μ, λ_grad = 1e-5 and η's own Adam at 1e-3 (D5); the paper's
    /// μ network, λ_grad = 1e-4 on the fit's schedule.
    pub fn apply_to_fit(self, fit: &mut FitConfig) {
        fit.loss.eta_losses = self;
        match self {
            Self::Paper => {
                fit.model.mu_form = MuForm::Network;
                fit.loss.lambda_grad = LossConfig::new().lambda_grad;
                fit.eta_lr = None;
            }
            Self::Code => {
                fit.model.mu_form = MuForm::Scalar;
                fit.loss.lambda_grad = CODE_LAMBDA_GRAD;
                fit.eta_lr = Some(CODE_ETA_LR);
            }
        }
    }
}

impl Recipe {
    /// How the model samples under this recipe.
    pub fn sample_noise(self) -> SampleNoise {
        match self {
            Self::Paper => SampleNoise::Calibrated,
            Self::Code => SampleNoise::SqrtDt,
        }
    }

    /// η's losses under this recipe.
    pub fn eta_losses(self) -> EtaLossForm {
        match self {
            Self::Paper => EtaLossForm::Paper,
            Self::Code => EtaLossForm::Code,
        }
    }

    /// What the drift networks see under this recipe (D4).
    pub fn drift_inputs(self) -> DriftInputs {
        match self {
            Self::Paper => DriftInputs::ZScores,
            Self::Code => DriftInputs::Pose,
        }
    }

    /// `fit` with this recipe's fit settings, for a model stepping `dt` seconds.
    /// The code's schedule (D2, `hop_rand_final`'s config): the learning rate
    /// decays 1e-2 → 1e-3 over 100 000 steps, validation every 2000 steps, early
    /// stop after 20 evaluations without improvement, 20 % of trajectories held out.
    pub fn apply_to_fit(self, fit: &mut FitConfig, dt: f64) {
        fit.model.sample_noise_scale = self.sample_noise().scale(dt);
        fit.model.drift_inputs = self.drift_inputs();
        self.eta_losses().apply_to_fit(fit);
        if self == Self::Code {
            fit.loss.step_discount = CODE_STEP_DISCOUNT;
            fit.lr_decay_steps = 100_000;
            fit.max_steps = 200_000;
            fit.eval_every = 2000;
            fit.patience = 20;
            fit.valid_fraction = 0.2;
        }
    }

    /// `thresholds` with this recipe's rule for α ≥ 1.
    pub fn apply_to_thresholds(self, thresholds: &mut ThresholdConfig) {
        thresholds.max_margin = match self {
            Self::Paper => 1.0,
            Self::Code => CODE_MAX_MARGIN,
        };
    }
}

crate::shared::named_enum!(Recipe, "recipe", Recipe::Paper => "paper", Recipe::Code => "code");
crate::shared::named_enum!(SampleNoise, "sample noise", SampleNoise::Calibrated => "calibrated", SampleNoise::SqrtDt => "sqrt-dt");

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_unknown_ones_are_refused_by_name() {
        for recipe in [Recipe::Paper, Recipe::Code] {
            assert_eq!(recipe.to_string().parse::<Recipe>(), Ok(recipe));
        }
        let error = "codes".parse::<Recipe>().unwrap_err();
        assert_eq!(error, "unknown recipe \"codes\": use paper or code");
        assert!(
            "full"
                .parse::<SampleNoise>()
                .unwrap_err()
                .contains("calibrated or sqrt-dt")
        );
    }

    #[test]
    fn the_code_samples_at_sqrt_dt() {
        // hopper's dt = 0.008: sqrt = 0.0894…, the "≈ 11× smaller" noise of NUNO's code.
        assert!((SampleNoise::SqrtDt.scale(0.008) - 0.089_442_72).abs() < 1e-7);
        assert_eq!(SampleNoise::Calibrated.scale(0.008), 1.0);
    }
}
