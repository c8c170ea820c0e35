//! `nuno-trainer fit-policy`: NUNO's policy optimisation on a fitted model
//! (and the baselines', in their models or on the dataset alone:
//! [`model_free`]), with checkpoints every epoch, `--resume`, metrics, plots,
//! and the best and last policy saved next to the dynamics artifact.

mod model_free;

use std::path::{Path, PathBuf};

use anyhow::Context;
use burn::tensor::Device;
use indicatif::{ProgressBar, ProgressStyle};
use nuno::agent::{
    ActionMode, AleatoricAsEta, EpochRecord, LoopContext, MOREL_PESSIMISM, Method, MopoSettings,
    PolicyLoopConfig, PolicyTraining, Preset, SacConfig, TruncatedStep, Truncation, combo_preset,
    mobile_preset, mopo_preset, preset, rambo_preset, run_threshold, tatu_pessimism,
};
use nuno::artifact::{
    BEST_POLICY, LAST_POLICY, ModelFolder, PolicyProvenance, latest_checkpoint, load_checkpoint,
    save_checkpoint, save_policy,
};
use nuno::data::{DatasetFormat, read_system_dataset};
use nuno::ensemble::EnsembleUncertainty;
use nuno::envs::{ForwardVelocity, RootXReward, System, TaskConfig, TaskName};
use nuno::infer::Kernel;
use nuno::sde::{ComputeDevice, Recipe};
use nuno::shared::{BatchDynamics, Metric, MetricsTable};
use serde::Serialize;

use crate::flag_defaults::with_defaults;
use crate::output::{with_sac_losses, write_text};
use crate::plot::{Series, line_chart};
use crate::resume::{checkpoint_to_resume, claim_output};
use crate::run_record::write_run_record;

/// The policy loop's defaults (Appendix C), which the flags' defaults read.
fn loop_defaults() -> PolicyLoopConfig {
    PolicyLoopConfig::new(SacConfig::new(), 0, 0.0, 0.0)
}

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Model directory written by `fit-model` or `fit-ensemble` (the policies
    /// are saved there too); not for the model-free methods (bc, td3-bc, cql, edac).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// The dataset the model was fitted on (start states and real transitions).
    #[arg(long)]
    pub dataset: PathBuf,
    /// Reader to use (default: detected).
    #[arg(long)]
    pub format: Option<DatasetFormat>,
    /// Table 3 row giving h, α and λ_pen, e.g. hopper-random or neorl-hopper-low
    /// (with --algo mopo or tatu-mopo: the same dataset's row of MOPO's h and λ).
    /// Without one (a system of your own), give --horizon, --cvar-alpha and --penalty.
    #[arg(long)]
    pub preset: Option<String>,
    /// The method: nuno, nuno-r and nuno-al train in the neural SDE of fit-model,
    /// mopo, tatu-mopo, combo, morel, mobile and rambo in the Gaussian ensemble of fit-ensemble; bc, td3-bc,
    /// cql and edac on the dataset alone (no --model).
    #[arg(long, default_value_t = Method::Nuno)]
    pub algo: Method,
    /// edac: the critics N (default: OfflineRL-Kit's for the preset's dataset).
    #[arg(long)]
    pub edac_critics: Option<usize>,
    /// edac: the diversity weight η (default: OfflineRL-Kit's for the preset's dataset).
    #[arg(long)]
    pub edac_eta: Option<f64>,
    /// The model-free methods: the built-in task the data is of (default: the preset's).
    #[arg(long, conflicts_with = "system")]
    pub task: Option<TaskName>,
    /// The model-free methods: a system file (with a [mujoco] table to evaluate in) in place of --task.
    #[arg(long)]
    pub system: Option<PathBuf>,
    /// The model-free methods with --task: NeoRL's observation layout (root x included).
    #[arg(long, conflicts_with = "system")]
    pub neorl: bool,
    /// TATU's pessimism coefficient (tatu-mopo; default: TATU's for the dataset, else 2),
    /// or MOReL's (morel: the HALT threshold's multiple of the largest disagreement; default 3).
    #[arg(long)]
    pub pessimism: Option<f64>,
    /// Total gradient steps (rounded up to whole epochs).
    #[arg(long, default_value_t = loop_defaults().epochs * loop_defaults().steps_per_epoch)]
    pub steps: usize,
    /// Gradient steps per epoch (evaluation and checkpoint after each).
    #[arg(long, default_value_t = loop_defaults().steps_per_epoch)]
    pub steps_per_epoch: usize,
    /// Gradient steps between model rollouts.
    #[arg(long, default_value_t = loop_defaults().rollout_freq)]
    pub rollout_freq: usize,
    /// Start states per model rollout (default: NUNO's scripts' 5000; mopo and
    /// tatu-mopo: their --mopo-settings', OfflineRL-Kit's 50 000).
    #[arg(long)]
    pub rollout_batch: Option<usize>,
    /// SAC settings of MOPO's and NUNO's policy step: offlinerl-kit (MOPO's
    /// published baseline: actor lr 1e-4 with cosine decay, α lr 1e-4, 50 000
    /// rollout starts) or nuno (NUNO's: 3e-4, constant, 5000) [default: mopo
    /// and tatu-mopo offlinerl-kit, NUNO's methods nuno].
    #[arg(long)]
    pub mopo_settings: Option<MopoSettings>,
    /// SDE trajectories per start state.
    #[arg(long, default_value_t = loop_defaults().particles)]
    pub particles: usize,
    /// paper, or code: NUNO's code's loop (a 10× model buffer, the known reward on
    /// the mean forward velocity over a step); the flags below override single settings.
    #[arg(long, default_value_t = Recipe::Paper)]
    pub recipe: Recipe,
    /// The model buffer holds this many times rollout batch × h × particles × 5
    /// rollouts (default: the recipe's: paper 1, code 10).
    #[arg(long)]
    pub model_buffer_factor: Option<usize>,
    /// The velocity the known reward reads on D4RL observations: next (after the
    /// step) or mean (over the step, NUNO's code) (default: the recipe's).
    #[arg(long)]
    pub forward_velocity: Option<ForwardVelocity>,
    /// What the known reward reads on observations that hold root x (NeoRL's):
    /// difference ((x′ − x)/dt, the data's own and NUNO's code's) or velocity
    /// (the observed x velocity, as --forward-velocity picks it) (default: difference).
    #[arg(long)]
    pub root_x_reward: Option<RootXReward>,
    /// End a model rollout as diverged once its state leaves the dataset's range
    /// widened by this many times that range on each side (nuno's guard; default:
    /// none, as the paper and NUNO's code).
    #[arg(long)]
    pub state_box_margin: Option<f64>,
    /// Clip each model next observation as the task clips its own (hopper's and
    /// walker2d's joint velocities to ±10; halfcheetah observes them unclipped)
    /// (nuno's guard; default: off, as the paper and NUNO's code).
    #[arg(long)]
    pub clip_observations: bool,
    /// What a truncating rollout keeps of the step that takes its accumulated
    /// uncertainty past the threshold: drop (the paper's) or terminal (kept as a
    /// terminal transition, NUNO's and TATU's code) (default: drop).
    #[arg(long)]
    pub truncated_step: Option<TruncatedStep>,
    /// The scale of the model's noise in the policy's rollouts (default: the
    /// model's own; 0 rolls the drift, or the ensemble's mean, alone).
    #[arg(long)]
    pub rollout_noise_scale: Option<f32>,
    /// β, the real-data fraction of each SAC batch (default: the method's:
    /// 0.05, combo 0.5).
    #[arg(long)]
    pub real_ratio: Option<f64>,
    /// morel: κ, subtracted from a halting step's reward (default: the authors' code's 0).
    #[arg(long)]
    pub halt_penalty: Option<f64>,
    /// combo: the conservative term's weight β (default: OfflineRL-Kit's for the preset's dataset).
    #[arg(long)]
    pub combo_weight: Option<f64>,
    /// mobile: the Bellman penalty's weight β (default: OfflineRL-Kit's for the preset's dataset).
    #[arg(long)]
    pub mobile_penalty: Option<f64>,
    /// rambo: the adversarial term's weight w_adv (default: OfflineRL-Kit's for the preset's dataset).
    #[arg(long)]
    pub rambo_weight: Option<f64>,
    /// rambo: adversarial model steps per phase (default 1000, one phase every 1000 policy steps).
    #[arg(long)]
    pub adversary_steps: Option<usize>,
    /// rambo: passes of behaviour cloning over the dataset before any update (default 50).
    #[arg(long)]
    pub bc_epochs: Option<usize>,
    /// SAC batch size.
    #[arg(long, default_value_t = loop_defaults().sac.batch_size)]
    pub batch_size: usize,
    /// H̄, SAC's target entropy (default: −|A|, SAC's rule; NUNO's code uses −3 for every task).
    #[arg(long, allow_hyphen_values = true)]
    pub target_entropy: Option<f64>,
    /// Hidden sizes of the actor and critics (default: the method's own: 256,256; cql 256,256,256).
    #[arg(long, value_delimiter = ',')]
    pub hidden: Option<Vec<usize>>,
    /// MuJoCo evaluation episodes per epoch.
    #[arg(long, default_value_t = loop_defaults().eval_episodes)]
    pub eval_episodes: usize,
    /// Override the preset's h.
    #[arg(long)]
    pub horizon: Option<usize>,
    /// Override the preset's α.
    #[arg(long)]
    pub cvar_alpha: Option<f64>,
    /// Override the preset's λ_pen.
    #[arg(long)]
    pub penalty: Option<f64>,
    /// Do not truncate rollouts at ε(h, α) (penalty only).
    #[arg(long)]
    pub no_truncation: bool,
    #[arg(long, default_value_t = loop_defaults().seed)]
    pub seed: u64,
    /// Run directory: checkpoints, metrics.csv, metrics.jsonl, plots.
    #[arg(long)]
    pub out: PathBuf,
    /// Where the best and last policies are written (default: --model, next to
    /// the dynamics, where the server finds them; --out for the model-free methods).
    #[arg(long)]
    pub policies: Option<PathBuf>,
    /// Continue from the last checkpoint in --out.
    #[arg(long)]
    pub resume: bool,
    /// Compute device: cpu, or wgpu in a build with the `wgpu` feature.
    #[arg(long, default_value_t = ComputeDevice::Cpu)]
    pub device: ComputeDevice,
    /// What runs SAC's updates, model rollouts and evaluation episodes: the
    /// fused CPU path, or burn on --device (default: fused on cpu, burn on wgpu).
    /// Either kernel resumes the other's checkpoints.
    #[arg(long)]
    pub kernel: Option<Kernel>,
}

/// What a fit-policy run does, validated before anything is read: the policy
/// loop's every setting resolved (the preset's h, α and λ_pen, the method's,
/// the recipe's, single flags over them), written to `run.json` at start.
#[derive(Debug, Serialize)]
pub struct Plan {
    pub dataset: PathBuf,
    pub format: Option<DatasetFormat>,
    #[serde(skip)]
    pub preset: Option<&'static Preset>,
    pub method: Method,
    /// The model and loop, or the model-free run's system and settings, at
    /// the plan's top level in `run.json`.
    #[serde(flatten)]
    pub training: Training,
    pub device: ComputeDevice,
    pub kernel: Kernel,
    pub out: PathBuf,
    pub policies: PathBuf,
    pub resume: bool,
}

/// How the method trains: SAC in a model's rollouts, or on the dataset alone.
#[derive(Debug, Serialize)]
#[serde(untagged)]
pub enum Training {
    InModel(Box<InModel>),
    ModelFree(Box<model_free::ModelFreePlan>),
}

/// A model-based method's run: the model folder and the policy loop.
#[derive(Debug, Serialize)]
pub struct InModel {
    pub model: PathBuf,
    pub config: PolicyLoopConfig,
    /// TATU's pessimism coefficient (tatu-mopo only).
    pub pessimism: Option<f64>,
}

impl Args {
    /// The flags' defaults for training in `model` on `dataset` under the
    /// Table 3 row `preset` (none for a system file's data) into `out`: what fit-policy with only those flags
    /// runs (the experiment runner sets its budget's fields over them).
    pub fn defaults(
        model: Option<PathBuf>,
        dataset: PathBuf,
        preset: Option<String>,
        out: PathBuf,
    ) -> Self {
        let mut args: Args = with_defaults(&[
            "fit-policy",
            "--dataset",
            "-",
            "--preset",
            "-",
            "--out",
            "-",
        ]);
        (args.model, args.dataset, args.out) = (model, dataset, out);
        args.preset = preset;
        args
    }

    /// The validated plan: flags no run can use, or that do not fit `--algo`,
    /// are refused here, before anything is read.
    pub fn plan(self) -> anyhow::Result<Plan> {
        self.check()?;
        let preset = self.preset.as_deref().map(preset).transpose()?;
        let training = if self.algo.is_model_free() {
            Training::ModelFree(Box::new(self.model_free_plan(preset)?))
        } else {
            Training::InModel(Box::new(self.in_model(preset)?))
        };
        let kernel = self.kernel.unwrap_or(match self.device {
            ComputeDevice::Cpu => Kernel::Fused,
            ComputeDevice::Wgpu => Kernel::Burn,
        });
        let policies = self.policies.unwrap_or_else(|| match &training {
            Training::InModel(run) => run.model.clone(),
            Training::ModelFree(_) => self.out.clone(),
        });
        Ok(Plan {
            policies,
            dataset: self.dataset,
            format: self.format,
            preset,
            method: self.algo,
            training,
            device: self.device,
            kernel,
            out: self.out,
            resume: self.resume,
        })
    }

    /// The ensemble baselines' own settings over the preset's loop: MOPO's
    /// (h, λ) and SAC settings, COMBO's (h, β), MOReL's HALT.
    fn apply_baseline(&self, config: &mut PolicyLoopConfig) -> anyhow::Result<()> {
        if self.algo.is_mopo() {
            // MOPO's own h and λ with the ensemble's max ‖σ‖ as the penalty; TATU
            // adds its truncation to MOPO's, MOPO alone has none.
            // Given both, --horizon and --penalty stand in for a dataset MOPO's
            // table has no row for (NeoRL's).
            if let (Some(name), false) = (&self.preset, self.horizon.and(self.penalty).is_some()) {
                (config.horizon, config.penalty) = mopo_preset(name)?;
            }
            config.truncate = self.algo.truncation() != Truncation::Never;
            config.apply_mopo_settings(self.mopo_settings.unwrap_or_default());
        }
        if self.algo.uses_sde()
            && let Some(settings) = self.mopo_settings
        {
            // NUNO's loop under MOPO's SAC settings, to separate the two.
            config.apply_mopo_settings(settings);
        }
        if self.algo == Method::Combo {
            // COMBO's own h and β (its table, or --horizon and --combo-weight).
            let (horizon, beta) = match (&self.preset, self.horizon, self.combo_weight) {
                (_, Some(h), Some(beta)) => (h, beta),
                (Some(name), _, _) => combo_preset(name)?,
                (None, _, _) => anyhow::bail!(
                    "--algo combo takes h and β per dataset: give a --preset OfflineRL-Kit has them for, or --horizon and --combo-weight"
                ),
            };
            config.horizon = horizon;
            config.apply_combo_settings(self.combo_weight.unwrap_or(beta));
        }
        anyhow::ensure!(
            self.combo_weight.is_none() || self.algo == Method::Combo,
            "--combo-weight is COMBO's β: it needs --algo combo"
        );
        if self.algo == Method::Morel {
            // MOPO's rollout length for the dataset (MOReL's own rollouts are
            // NPG's whole episodes), no penalty, the HALT.
            if let (Some(name), None) = (&self.preset, self.horizon) {
                (config.horizon, _) = mopo_preset(name)?;
            }
            config.apply_morel_settings(self.halt_penalty.unwrap_or(0.0));
        }
        anyhow::ensure!(
            self.halt_penalty.is_none() || self.algo == Method::Morel,
            "--halt-penalty is MOReL's κ: it needs --algo morel"
        );
        self.apply_mobile(config)?;
        self.apply_rambo(config)
    }

    /// MOBILE's own h, β and (hopper-medium) fixed α: its table, or
    /// --horizon and --mobile-penalty.
    fn apply_mobile(&self, config: &mut PolicyLoopConfig) -> anyhow::Result<()> {
        anyhow::ensure!(
            self.mobile_penalty.is_none() || self.algo == Method::Mobile,
            "--mobile-penalty is MOBILE's β: it needs --algo mobile"
        );
        if self.algo != Method::Mobile {
            return Ok(());
        }
        let (horizon, beta, fixed_alpha) = match (&self.preset, self.horizon, self.mobile_penalty) {
            (_, Some(h), Some(beta)) => (h, beta, None),
            (Some(name), _, _) => mobile_preset(name)?,
            (None, _, _) => anyhow::bail!(
                "--algo mobile takes h and β per dataset: give a --preset OfflineRL-Kit has them for, or --horizon and --mobile-penalty"
            ),
        };
        config.horizon = horizon;
        config.apply_mobile_settings(self.mobile_penalty.unwrap_or(beta), fixed_alpha);
        Ok(())
    }

    /// RAMBO's own h and w_adv: its table, or --horizon and --rambo-weight.
    fn apply_rambo(&self, config: &mut PolicyLoopConfig) -> anyhow::Result<()> {
        anyhow::ensure!(
            (self.rambo_weight.or(self.adversary_steps.map(|n| n as f64)))
                .or(self.bc_epochs.map(|n| n as f64))
                .is_none()
                || self.algo == Method::Rambo,
            "--rambo-weight, --adversary-steps and --bc-epochs are RAMBO's: they need --algo rambo"
        );
        if self.algo != Method::Rambo {
            return Ok(());
        }
        let (horizon, weight) = match (&self.preset, self.horizon, self.rambo_weight) {
            (_, Some(h), Some(w)) => (h, w),
            (Some(name), _, _) => rambo_preset(name)?,
            (None, _, _) => anyhow::bail!(
                "--algo rambo takes h and w_adv per dataset: give a --preset OfflineRL-Kit has them for, or --horizon and --rambo-weight"
            ),
        };
        config.horizon = horizon;
        config.apply_rambo_settings(self.rambo_weight.unwrap_or(weight));
        if let Some(rambo) = config.rambo.as_mut() {
            rambo.adversary_steps = self.adversary_steps.unwrap_or(rambo.adversary_steps);
            rambo.bc_epochs = self.bc_epochs.unwrap_or(rambo.bc_epochs);
        }
        Ok(())
    }

    /// A model-based method's model folder and policy loop: the preset's h, α
    /// and λ_pen (MOPO's row for MOPO's methods), the recipe's, single flags over them.
    fn in_model(&self, preset: Option<&'static Preset>) -> anyhow::Result<InModel> {
        let model = self.model.clone().with_context(|| {
            format!(
                "--algo {} trains in a model: give --model (a fit-model or fit-ensemble folder)",
                self.algo
            )
        })?;
        anyhow::ensure!(
            self.task.is_none() && self.system.is_none() && !self.neorl,
            "--task, --system and --neorl name a model-free method's system; --algo {} reads its model's",
            self.algo
        );
        let hidden = (self.hidden.clone()).unwrap_or_else(|| self.algo.default_hidden());
        let sac = SacConfig::new()
            .with_batch_size(self.batch_size)
            .with_target_entropy(self.target_entropy)
            .with_actor_hidden(hidden.clone())
            .with_critic_hidden(hidden);
        let mut config = match preset {
            Some(preset) => PolicyLoopConfig::from_preset(preset, sac),
            None => match (self.horizon, self.cvar_alpha, self.penalty) {
                (Some(h), Some(alpha), Some(penalty)) => {
                    PolicyLoopConfig::new(sac, h, alpha, penalty)
                }
                _ => anyhow::bail!("without --preset, give --horizon, --cvar-alpha and --penalty"),
            },
        };
        self.apply_baseline(&mut config)?;

        config.horizon = self.horizon.unwrap_or(config.horizon);
        config.cvar_alpha = self.cvar_alpha.unwrap_or(config.cvar_alpha);
        config.penalty = self.penalty.unwrap_or(config.penalty);
        config.truncate &= !self.no_truncation;
        config.rollout_freq = self.rollout_freq;
        config.rollout_batch = self.rollout_batch.unwrap_or(config.rollout_batch);
        config.particles = self.particles;
        config.apply_recipe(self.recipe);
        config.model_buffer_factor = self
            .model_buffer_factor
            .unwrap_or(config.model_buffer_factor);
        config.forward_velocity = self.forward_velocity.unwrap_or(config.forward_velocity);
        config.root_x_reward = self.root_x_reward.unwrap_or(config.root_x_reward);
        config.real_ratio = self.real_ratio.unwrap_or(config.real_ratio);
        config.state_box_margin = self.state_box_margin;
        config.clip_observations = self.clip_observations;
        config.truncated_step = self.truncated_step.unwrap_or(config.truncated_step);
        config.rollout_noise_scale = self.rollout_noise_scale;
        config.steps_per_epoch = self.steps_per_epoch;
        config.epochs = self.steps.div_ceil(self.steps_per_epoch);
        config.eval_episodes = self.eval_episodes;
        config.seed = self.seed;
        let pessimism = match self.algo {
            Method::TatuMopo => Some(
                self.pessimism
                    .unwrap_or_else(|| tatu_pessimism(self.preset.as_deref().unwrap_or_default())),
            ),
            Method::Morel => Some(self.pessimism.unwrap_or(MOREL_PESSIMISM)),
            _ => None,
        };
        Ok(InModel {
            model,
            config,
            pessimism,
        })
    }

    fn check(&self) -> anyhow::Result<()> {
        self.check_sizes()?;
        self.check_values()?;
        self.check_method_flags()
    }

    /// Counts and layer sizes: each at least 1.
    fn check_sizes(&self) -> anyhow::Result<()> {
        anyhow::ensure!(self.steps > 0, "--steps must be at least 1");
        anyhow::ensure!(
            self.steps_per_epoch > 0,
            "--steps-per-epoch must be at least 1"
        );
        anyhow::ensure!(
            self.rollout_batch != Some(0),
            "--rollout-batch must be at least 1"
        );
        anyhow::ensure!(self.particles > 0, "--particles must be at least 1");
        anyhow::ensure!(self.batch_size > 0, "--batch-size must be at least 1");
        anyhow::ensure!(
            (self.hidden.as_ref()).is_none_or(|h| !h.is_empty() && h.iter().all(|&h| h > 0)),
            "--hidden needs positive layer sizes"
        );
        anyhow::ensure!(
            self.model_buffer_factor != Some(0),
            "--model-buffer-factor must be at least 1"
        );
        Ok(())
    }

    /// Ratios, margins and coefficients: finite and in their range.
    fn check_values(&self) -> anyhow::Result<()> {
        if let Some(ratio) = self.real_ratio {
            anyhow::ensure!(
                (0.0..=1.0).contains(&ratio),
                "--real-ratio must lie in [0, 1], got {ratio}"
            );
        }
        if let Some(m) = self.state_box_margin {
            anyhow::ensure!(
                m.is_finite() && m >= 0.0,
                "--state-box-margin must be finite and at least 0, got {m}"
            );
        }
        if let Some(h) = self.target_entropy {
            anyhow::ensure!(h.is_finite(), "--target-entropy must be finite, got {h}");
        }
        if let Some(scale) = self.rollout_noise_scale {
            anyhow::ensure!(
                scale.is_finite() && scale >= 0.0,
                "--rollout-noise-scale must be finite and at least 0, got {scale}"
            );
        }
        if let Some(p) = self.pessimism {
            anyhow::ensure!(
                p.is_finite() && p > 0.0,
                "--pessimism must be positive, got {p}"
            );
        }
        Ok(())
    }

    /// Flags that set one method's mechanism, refused for the others.
    fn check_method_flags(&self) -> anyhow::Result<()> {
        anyhow::ensure!(
            self.mopo_settings.is_none() || self.algo.takes_mopo_settings(),
            "--mopo-settings sets the SAC settings of MOPO's or NUNO's policy step: it needs --algo mopo, tatu-mopo, nuno, nuno-r or nuno-al ({} runs its own)",
            self.algo
        );
        anyhow::ensure!(
            self.pessimism.is_none() || matches!(self.algo, Method::TatuMopo | Method::Morel),
            "--pessimism is TATU's or MOReL's coefficient: it needs --algo tatu-mopo or morel"
        );
        anyhow::ensure!(
            !self.algo.uses_ensemble()
                || (self.recipe == Recipe::Paper
                    && self.forward_velocity.is_none()
                    && self.root_x_reward.is_none()),
            "--recipe, --forward-velocity and --root-x-reward set NUNO's loop: {} rolls an ensemble that learns its rewards",
            self.algo
        );
        anyhow::ensure!(
            self.truncated_step.is_none()
                || (self.algo.truncation().accumulates() && !self.no_truncation),
            "--truncated-step says what a truncating rollout keeps of its last step: {} {}",
            self.algo,
            if self.no_truncation {
                "runs with --no-truncation"
            } else {
                "never truncates on accumulated uncertainty"
            }
        );
        Ok(())
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    train(&args.plan()?)
}

/// Trains as the plan says: in its model, or on the dataset alone.
pub fn train(plan: &Plan) -> anyhow::Result<()> {
    let _claim = claim_output(&plan.out)?;
    match &plan.training {
        Training::InModel(run) => train_in_model(plan, run),
        Training::ModelFree(run) => model_free::train(plan, run),
    }
}

/// Loads the model and the dataset, then trains epoch by epoch from the start
/// or from the last checkpoint, saving the best and last policies.
fn train_in_model(plan: &Plan, run: &InModel) -> anyhow::Result<()> {
    let device = plan.device.device().map_err(anyhow::Error::msg)?;
    let (model, system) = load_model(plan, run, &device)?;
    let dataset = read_system_dataset(&plan.dataset, plan.format, &system)?;
    let base = model.dynamics(plan.kernel);
    let aleatoric;
    let dynamics: &dyn BatchDynamics = if plan.method == Method::NunoAl {
        aleatoric = AleatoricAsEta::new(base.as_ref());
        &aleatoric
    } else {
        base.as_ref()
    };
    // MOBILE samples the ensemble's elites one by one; RAMBO trains it.
    let ensemble = model
        .ensemble(plan.kernel)
        .filter(|_| matches!(plan.method, Method::Mobile | Method::Rambo));
    let ctx = LoopContext {
        dataset: &dataset,
        dynamics,
        rules: model.rules(&system)?,
        system,
        kernel: plan.kernel,
        ensemble: ensemble.as_ref(),
    };
    let mut training = start(plan, run, &model, &ctx, &device)?;
    write_run_record(&plan.out, "fit-policy", plan, &[&plan.dataset])?;
    let bar = ProgressBar::new((training.config.epochs * training.config.steps_per_epoch) as u64)
        .with_style(ProgressStyle::with_template(
            "{bar:30} {pos}/{len} steps | {msg}",
        )?);
    bar.set_position(training.step as u64);
    std::fs::create_dir_all(&plan.policies)
        .with_context(|| format!("creating {}", plan.policies.display()))?;
    while training.epoch < training.config.epochs {
        let record = training.run_epoch(&ctx)?;
        bar.set_position(training.step as u64);
        bar.set_message(format!(
            "SPS {:.1} | {} {:.1} | η policy {:.3} data {:.3} | rollout len {:.1}",
            record.sps,
            record.eval.score_name(),
            record.eval.score(),
            record.eta.policy,
            record.eta.dataset,
            record.rollout.mean_length
        ));
        save_policies(plan, &model, &ctx.system, &record, &training)?;
        save_checkpoint(&plan.out.join("checkpoints"), &training)?;
        write_metrics(&plan.out, &training.history)?;
    }
    bar.finish();
    if let Some(last) = training.history.last() {
        println!(
            "{} epochs, {} steps: last {} {:.1}; policies in {}",
            last.epoch,
            last.step,
            last.eval.score_name(),
            last.eval.score(),
            plan.policies.display()
        );
    }
    Ok(())
}

/// The training state: fresh, with its truncation threshold, or continued
/// from the last checkpoint under `--resume`.
fn start(
    plan: &Plan,
    run: &InModel,
    model: &ModelFolder,
    ctx: &LoopContext,
    device: &Device,
) -> anyhow::Result<PolicyTraining> {
    let checkpoints = plan.out.join("checkpoints");
    let resuming = plan.resume && latest_checkpoint(&checkpoints)?.is_some();
    let threshold = truncation_threshold(plan, run, model, ctx, resuming)?;
    let mut training = PolicyTraining::new(run.config.clone(), ctx, threshold, device)?;
    if let Some(checkpoint) = checkpoint_to_resume(&checkpoints, plan.resume, &plan.out, "a run")? {
        load_checkpoint(&checkpoint, &mut training)
            .with_context(|| format!("resuming from {}", checkpoint.display()))?;
        println!(
            "resumed from {} (epoch {}, step {})",
            checkpoint.display(),
            training.epoch,
            training.step
        );
    }
    if let Some(threshold) = training.threshold {
        let c = &training.config;
        println!(
            "{} ({}): h = {}, α = {}, λ_pen = {}, truncation threshold {threshold:.4}",
            plan.preset.map_or("no preset", |p| p.name),
            plan.method,
            c.horizon,
            c.cvar_alpha,
            c.penalty
        );
    }
    Ok(training)
}

/// The last policy after every epoch, and the best so far when this epoch's
/// score ties or beats every earlier one, each with what it was trained on.
fn save_policies(
    plan: &Plan,
    model: &ModelFolder,
    system: &System,
    record: &EpochRecord,
    training: &PolicyTraining,
) -> anyhow::Result<()> {
    let provenance = || PolicyProvenance {
        preset: plan.preset.map(|p| p.name.to_string()),
        dynamics_sha256: Some(model.weights_sha256().to_string()),
        dataset_sha256: model.dataset_sha256().map(String::from),
        training: Some(training.config.clone()),
        epoch: record.epoch,
        step: record.step,
        normalized_score: Some(record.eval.normalized_score),
        mean_return: Some(record.eval.mean_return),
        online_training: None,
        model_free_training: None,
        algorithm: Some(plan.method.to_string()),
        truncation_threshold: training.threshold,
    };
    let actor = training.policy(ActionMode::Deterministic).actor;
    save_policy(&plan.policies, LAST_POLICY, &actor, system, provenance())?;
    let best = training
        .history
        .iter()
        .map(|r| r.eval.score())
        .fold(f64::NEG_INFINITY, f64::max);
    if record.eval.score() >= best {
        save_policy(&plan.policies, BEST_POLICY, &actor, system, provenance())?;
    }
    Ok(())
}

/// metrics.csv and metrics.jsonl (CleanRL metric names) and the two plots,
/// rewritten from the whole history so a resumed run's files stay consistent.
fn write_metrics(out: &Path, history: &[EpochRecord]) -> anyhow::Result<()> {
    let csv = epoch_metrics().csv(history);
    // The records themselves, nested as `experiment` reads them back.
    let mut jsonl = String::new();
    for r in history {
        jsonl.push_str(&serde_json::to_string(r)?);
        jsonl.push('\n');
    }
    for (name, text) in [("metrics.csv", csv), ("metrics.jsonl", jsonl)] {
        let path = out.join(name);
        write_text(&path, &text)?;
    }
    let series = |name, f: fn(&EpochRecord) -> f64| Series {
        name,
        points: history.iter().map(|r| (r.step as f64, f(r))).collect(),
    };
    // A system without a simulator charts the model's own estimate instead.
    let score = history
        .last()
        .map_or("normalised score", |r| r.eval.score_name());
    line_chart(
        &out.join("normalized_score.svg"),
        &format!("NUNO: {score}"),
        "gradient step",
        score,
        &[series("evaluation (mean of episodes)", |r| r.eval.score())],
    )?;
    line_chart(
        &out.join("eta.svg"),
        "η on dataset states",
        "gradient step",
        "mean η",
        &[
            series("policy actions", |r| f64::from(r.eta.policy)),
            series("dataset actions", |r| f64::from(r.eta.dataset)),
            series("random actions", |r| f64::from(r.eta.random)),
        ],
    )?;
    Ok(())
}

/// The model folder `--algo` trains in, checked to hold the kind it reads (a
/// neural SDE for NUNO's methods, a Gaussian ensemble for MOPO's), with its
/// task (a model.json from before tasks were recorded: the preset's), checked
/// against the preset's.
fn load_model(
    plan: &Plan,
    run: &InModel,
    device: &Device,
) -> anyhow::Result<(ModelFolder, System)> {
    let dir = &run.model;
    let folder = ModelFolder::load(dir, device)
        .with_context(|| format!("loading the model in {}", dir.display()))?;
    let folder = for_method(folder, plan.method, dir)?;
    let system = system_of(&folder, plan, run, dir)?;
    Ok((folder, system))
}

/// The model folder as `algo` rolls it (TATU's and MOReL's truncation signal
/// set on the ensemble), or why `algo` cannot train in it.
fn for_method(folder: ModelFolder, algo: Method, dir: &Path) -> anyhow::Result<ModelFolder> {
    Ok(match folder {
        ModelFolder::NeuralSde { .. } if algo.uses_ensemble() => anyhow::bail!(
            "--algo {algo} trains in a Gaussian ensemble (ensemble.json, from fit-ensemble); {} holds a neural SDE",
            dir.display()
        ),
        ModelFolder::GaussianEnsemble { .. } if !algo.uses_ensemble() => anyhow::bail!(
            "--algo {algo} trains in a neural SDE (model.json, from fit-model); {} holds a Gaussian ensemble",
            dir.display()
        ),
        ModelFolder::NeuralSde { ref model, .. }
            if algo == Method::NunoR && !model.constants.config.reward_model =>
        {
            anyhow::bail!(
                "--algo nuno-r needs a model that learned the reward (fit-model --reward-model); \
                 the one in {} did not",
                dir.display()
            )
        }
        ModelFolder::GaussianEnsemble { model, metadata } if algo == Method::TatuMopo => {
            ModelFolder::GaussianEnsemble {
                model: Box::new(model.with_truncation_signal(EnsembleUncertainty::MaxDisagreement)),
                metadata,
            }
        }
        ModelFolder::GaussianEnsemble { model, metadata } if algo == Method::Morel => {
            ModelFolder::GaussianEnsemble {
                model: Box::new(model.with_truncation_signal(EnsembleUncertainty::MaxPairwise)),
                metadata,
            }
        }
        folder => folder,
    })
}

/// The task or system the model was fitted on, checked against the plan's
/// preset and reward.
fn system_of(
    folder: &ModelFolder,
    plan: &Plan,
    run: &InModel,
    dir: &Path,
) -> anyhow::Result<System> {
    let system = match (folder.system()?, plan.preset) {
        (Some(system), _) => system,
        // A model.json from before tasks were recorded: the preset's.
        (None, Some(preset)) => System::Task(TaskConfig {
            layout: preset.layout,
            ..TaskConfig::d4rl(preset.task)
        }),
        (None, None) => anyhow::bail!(
            "{}: the model records no task or system, and no --preset names one",
            dir.display()
        ),
    };
    anyhow::ensure!(
        run.config.root_x_reward == RootXReward::Difference
            || system.task().is_some_and(|task| task.observes_root_x()),
        "--root-x-reward velocity changes the reward on observations that hold root x (NeoRL's layout); \
         those of {} do not",
        system.name()
    );
    if let Some(preset) = plan.preset {
        let matches = system
            .task()
            .is_some_and(|task| task.task == preset.task && task.layout == preset.layout);
        anyhow::ensure!(
            matches,
            "preset {} is for {} ({:?}), the model is of {} ({:?})",
            preset.name,
            preset.task,
            preset.layout,
            system.name(),
            system.task().map(|t| t.layout)
        );
    }
    Ok(system)
}

/// What the run's rollouts truncate at (`agent::run_threshold`). A threshold
/// the run computes (NUNO^al's, TATU's) is kept in `threshold.json` in --out,
/// which a resumed run reads instead of computing it again.
fn truncation_threshold(
    plan: &Plan,
    run: &InModel,
    model: &ModelFolder,
    ctx: &LoopContext,
    resuming: bool,
) -> anyhow::Result<Option<f32>> {
    let method = plan.method;
    let computed = run.config.truncate && method.truncation().computed_per_run();
    let path = plan.out.join("threshold.json");
    if computed && resuming && path.is_file() {
        let saved: SavedThreshold = serde_json::from_str(&std::fs::read_to_string(&path)?)
            .with_context(|| format!("reading {}", path.display()))?;
        anyhow::ensure!(
            saved.algorithm == method.as_str(),
            "{} was computed for {}, this run is {method}",
            path.display(),
            saved.algorithm,
        );
        return Ok(Some(saved.threshold));
    }
    let threshold = run_threshold(method, &run.config, model.thresholds(), ctx, run.pessimism)?;
    if let (true, Some(t)) = (computed, &threshold) {
        std::fs::create_dir_all(&plan.out)?;
        let saved = SavedThreshold {
            algorithm: method.to_string(),
            threshold: t.value,
            how: t.how.clone(),
        };
        write_text(&path, &serde_json::to_string_pretty(&saved)?)?;
    }
    Ok(threshold.map(|t| t.value))
}

/// `threshold.json`: a baseline's computed truncation threshold.
#[derive(serde::Serialize, serde::Deserialize)]
struct SavedThreshold {
    algorithm: String,
    threshold: f32,
    how: String,
}

/// metrics.csv's columns (CleanRL's names): one row per epoch.
fn epoch_metrics() -> MetricsTable<'static, EpochRecord> {
    let table = MetricsTable::new()
        .column("epoch", |r: &EpochRecord| r.epoch.into())
        .column("step", |r: &EpochRecord| r.step.into())
        .column("charts/SPS", |r: &EpochRecord| Metric::fixed(r.sps, 3))
        .column("charts/normalized_score", |r: &EpochRecord| {
            r.eval.normalized_score.into()
        })
        .column("charts/normalized_score_std", |r: &EpochRecord| {
            r.eval.std_normalized_score.into()
        })
        .column("charts/episodic_return", |r: &EpochRecord| {
            r.eval.mean_return.into()
        });
    with_sac_losses(table, |r: &EpochRecord| &r.losses)
        .column("rollout/mean_length", |r: &EpochRecord| {
            r.rollout.mean_length.into()
        })
        .column("rollout/mean_eta", |r: &EpochRecord| {
            r.rollout.mean_eta.into()
        })
        .column("rollout/truncated", |r: &EpochRecord| {
            r.rollout.truncated.into()
        })
        .column("rollout/terminated", |r: &EpochRecord| {
            r.rollout.terminated.into()
        })
        .column("rollout/diverged", |r: &EpochRecord| {
            r.rollout.diverged.into()
        })
        .column("rollout/mean_penalized_reward", |r: &EpochRecord| {
            r.rollout.mean_penalized_reward.into()
        })
        .column("eta/policy", |r: &EpochRecord| r.eta.policy.into())
        .column("eta/dataset", |r: &EpochRecord| r.eta.dataset.into())
        .column("eta/random", |r: &EpochRecord| r.eta.random.into())
        .column("model_buffer", |r: &EpochRecord| r.model_buffer.into())
        .column("time/updates", |r: &EpochRecord| {
            Metric::fixed(r.seconds.updates, 3)
        })
        .column("time/rollouts", |r: &EpochRecord| {
            Metric::fixed(r.seconds.rollouts, 3)
        })
        .column("time/evaluation", |r: &EpochRecord| {
            Metric::fixed(r.seconds.evaluation, 3)
        })
        .column("time/eta_probe", |r: &EpochRecord| {
            Metric::fixed(r.seconds.eta_probe, 3)
        })
}
