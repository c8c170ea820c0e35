//! `nuno-trainer fit-model`: fit the neural SDE on a dataset, compute the
//! truncation thresholds, and write the artifact with metrics and plots; a
//! checkpoint at every validation in `--out/fit-checkpoints`, which
//! `--resume` continues.

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use burn::tensor::Device;
use indicatif::{ProgressBar, ProgressStyle};
use nuno::artifact::{DynamicsProvenance, load_sde_checkpoint, save_dynamics, save_sde_checkpoint};
use nuno::data::Dataset;
use nuno::envs::System;
use nuno::infer::Kernel;
use nuno::sde::{
    ComputeDevice, DriftInputs, DynamicsSpec, EtaLossForm, FitConfig, FitRecord, FitReport,
    FitReportConfig, FitSummary, HorizonError, LikelihoodPath, LossConfig, NeuralSde, Recipe,
    SampleNoise, SdeConfig, SdeError, SdeFitState, StepLosses, ThresholdConfig, fit_from,
    fit_report,
};
use nuno::shared::{Metric, MetricsTable};
use serde::Serialize;

use crate::data_source::DataSource;
use crate::eta_report::{calibration_charts, print_calibration};
use crate::flag_defaults::with_defaults;
use crate::plot::{Series, line_chart};
use crate::resume::{checkpoint_to_resume, claim_output};
use crate::run_record::write_run_record;

/// The fit's checkpoints, in --out.
const FIT_CHECKPOINTS: &str = "fit-checkpoints";

#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub data: DataSource,
    /// Output model directory (dynamics.safetensors, model.json, metrics.csv, plots).
    #[arg(long)]
    pub out: PathBuf,
    /// NUNO^R: also learn the reward as a cumulative-reward state.
    #[arg(long)]
    pub reward_model: bool,
    /// paper (the paper's equations and Appendix C) or code (NUNO's code where it
    /// differs: samples at sqrt(dt), steps weighed 0.9^(t−1), its 100k-step schedule,
    /// 20 % held out, pose drift inputs, its η losses, ε(h, 1) = 1.1 × max); the flags
    /// below override single settings.
    #[arg(long, default_value_t = Recipe::Paper)]
    pub recipe: Recipe,
    /// The scale of ε the model samples at: calibrated (Σ) or sqrt-dt (NUNO's code)
    /// (default: the recipe's). Σ stays the calibrated one-step uncertainty.
    #[arg(long)]
    pub sample_noise: Option<SampleNoise>,
    /// η's losses: paper (eq. 3, 4: μ a network, L_grad = ‖∇η‖² + η², on the fit's
    /// schedule) or code (NUNO's `losses_diffusion.py`: one scalar μ, ½μ in L_sc,
    /// λ_grad 1e-5, mean-η and set-one terms, the gradient floor, η's own Adam at
    /// 1e-3) (default: the recipe's); --lambda-grad overrides its weight.
    #[arg(long)]
    pub eta_losses: Option<EtaLossForm>,
    /// What the drift networks G, H, f_res see of the state: z-scores (eq. 8) or
    /// pose (NUNO's code's `RBD_Drift`: angles as cos and sin about their mean,
    /// and G sees the pose) (default: the recipe's).
    #[arg(long)]
    pub drift_inputs: Option<DriftInputs>,
    /// L_data's weight of window step t is this to the power t − 1, in (0, 1]
    /// (default: the recipe's: paper 1, code 0.9).
    #[arg(long)]
    pub step_discount: Option<f32>,
    /// ε(h, α = 1) = this × the largest accumulated η, ≥ 1 (default: the recipe's:
    /// paper 1, code 1.1).
    #[arg(long)]
    pub threshold_max_margin: Option<f32>,
    /// Upper bound on gradient steps (early stopping may end sooner; default: the
    /// recipe's, paper 20 000, code 200 000).
    #[arg(long)]
    pub max_steps: Option<usize>,
    /// Validation NLL every this many steps (default: the recipe's: paper 250, code 2000).
    #[arg(long)]
    pub eval_every: Option<usize>,
    /// Early-stopping patience, in evaluations (default: the recipe's: paper 8, code 20).
    #[arg(long)]
    pub patience: Option<usize>,
    /// Hidden sizes of the drift networks G, H, f_res (paper: 256,256,256).
    #[arg(long, value_delimiter = ',', default_values_t = SdeConfig::new().drift_hidden)]
    pub drift_hidden: Vec<usize>,
    /// Ball radius r of L_sc's samples, in normalised units (default: the paper's 0.1).
    #[arg(long)]
    pub radius: Option<f32>,
    /// λ_grad, weight of L_grad (default: the η loss form's: paper 1e-4, code 1e-5).
    #[arg(long)]
    pub lambda_grad: Option<f32>,
    /// λ_far, weight of the far-field hinge on η (not in the paper; default 0 = off;
    /// see docs/paper-map.md before using it on high-dimensional data).
    #[arg(long)]
    pub lambda_far: Option<f32>,
    /// Where L_data's steps start: particle (eq. 6 as written: the previous step's
    /// sample) or data (the recorded state before each step; docs/paper-map.md).
    #[arg(long, default_value_t = LikelihoodPath::Particle)]
    pub likelihood: LikelihoodPath,
    /// W^max of h(η): the diffusion beyond the data, in multiples of each state
    /// dimension's diffusion scale; one value for all, or one per dimension.
    #[arg(long, value_delimiter = ',', default_values_t = SdeConfig::new().w_max)]
    pub w_max: Vec<f32>,
    /// Windows per horizon used for the CVaR thresholds.
    #[arg(long, default_value_t = ThresholdConfig::new().max_windows)]
    pub threshold_windows: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Compute device: cpu, or wgpu in a build with the `wgpu` feature.
    #[arg(long, default_value_t = ComputeDevice::Cpu)]
    pub device: ComputeDevice,
    /// What takes the gradient steps: fused (the CPU kernels, every core) or burn
    /// (autodiff on --device); default fused on the CPU, burn on a GPU. Either
    /// resumes the other's checkpoints.
    #[arg(long)]
    pub kernel: Option<Kernel>,
    /// Continue the fit checkpointed in --out (the same settings; --max-steps may grow).
    #[arg(long)]
    pub resume: bool,
}

/// What a fit-model run does, validated before the data is read: the task and
/// the model's spec, the fit and the post-fit report (the recipe's, with single
/// flags over it), written to `run.json` at start.
#[derive(Debug, Serialize)]
pub struct Plan {
    pub data: DataSource,
    pub system: System,
    /// The system's action box, where the fit's report probes η.
    pub action_space: Vec<(f32, f32)>,
    pub spec: DynamicsSpec,
    pub fit: FitConfig,
    pub report: FitReportConfig,
    pub device: ComputeDevice,
    pub out: PathBuf,
    pub resume: bool,
}

impl Args {
    /// The flags' defaults for fitting `data` into `out`: what `fit-model
    /// --dataset … --task … --out …` alone runs (the experiment runner sets its
    /// budget's fields over them).
    pub fn defaults(data: DataSource, out: PathBuf) -> Self {
        let mut args: Args = with_defaults(&[
            "fit-model",
            "--dataset",
            "-",
            "--task",
            "hopper",
            "--out",
            "-",
        ]);
        (args.data, args.out) = (data, out);
        args
    }

    /// The validated plan: every setting is checked before the data is read
    /// or any work starts.
    pub fn plan(self) -> anyhow::Result<Plan> {
        anyhow::ensure!(
            !self.drift_hidden.is_empty() && self.drift_hidden.iter().all(|&h| h > 0),
            "--drift-hidden needs positive layer sizes"
        );
        let system = self.data.system()?;
        let shape = system.shape()?;
        let spec = DynamicsSpec {
            obs_dim: shape.obs_dim,
            act_dim: shape.act_dim,
            split: shape.split.clone(),
            dt: shape.dt,
        };
        let learned_reward = system.rules()?.learned_reward();
        anyhow::ensure!(
            self.reward_model || !learned_reward,
            "{} learns its reward (reward.learned in its file): add --reward-model",
            system.name()
        );
        let fit = self.fit_config(&spec)?;
        let report = self.report_config()?;
        Ok(Plan {
            data: self.data,
            action_space: shape.action_space(),
            system,
            spec,
            fit,
            report,
            device: self.device,
            out: self.out,
            resume: self.resume,
        })
    }

    /// The fit: the recipe's, with single flags over it.
    fn fit_config(&self, spec: &DynamicsSpec) -> anyhow::Result<FitConfig> {
        let mut loss = LossConfig::new();
        loss.radius = self.radius.unwrap_or(loss.radius);
        loss.lambda_far = self.lambda_far.unwrap_or(loss.lambda_far);
        loss.likelihood = self.likelihood;
        let mut model = SdeConfig::new();
        model.reward_model = self.reward_model;
        model.drift_hidden = self.drift_hidden.clone();
        model.w_max = self.w_max.clone();
        let mut config = FitConfig::new(model, loss);
        self.recipe.apply_to_fit(&mut config, spec.dt);
        if let Some(noise) = self.sample_noise {
            config.model.sample_noise_scale = noise.scale(spec.dt);
        }
        if let Some(form) = self.eta_losses {
            form.apply_to_fit(&mut config);
        }
        config.model.drift_inputs = self.drift_inputs.unwrap_or(config.model.drift_inputs);
        config.loss.lambda_grad = self.lambda_grad.unwrap_or(config.loss.lambda_grad);
        config.loss.step_discount = self.step_discount.unwrap_or(config.loss.step_discount);
        config.max_steps = self.max_steps.unwrap_or(config.max_steps);
        config.eval_every = self.eval_every.unwrap_or(config.eval_every);
        config.patience = self.patience.unwrap_or(config.patience);
        config.seed = self.seed;
        config.kernel = match (self.kernel, self.device) {
            (Some(Kernel::Fused), ComputeDevice::Wgpu) => {
                anyhow::bail!(
                    "--kernel fused runs on the CPU: use --kernel burn with --device wgpu"
                )
            }
            (Some(kernel), _) => kernel,
            (None, ComputeDevice::Cpu) => Kernel::Fused,
            (None, ComputeDevice::Wgpu) => Kernel::Burn,
        };
        config
            .loss
            .validate()
            .context("check --radius, --lambda-grad, --lambda-far and --step-discount")?;
        config
            .model
            .validate(spec.obs_dim + usize::from(self.reward_model))
            .context("check --w-max")?;
        anyhow::ensure!(config.max_steps > 0, "--max-steps must be at least 1");
        anyhow::ensure!(config.eval_every > 0, "--eval-every must be at least 1");
        Ok(config)
    }

    /// The post-fit report: the thresholds' search (the recipe's margin, single
    /// flags over it), every part on the fit's seed.
    fn report_config(&self) -> anyhow::Result<FitReportConfig> {
        let mut thresholds = ThresholdConfig::new().with_max_windows(self.threshold_windows);
        self.recipe.apply_to_thresholds(&mut thresholds);
        thresholds.max_margin = self.threshold_max_margin.unwrap_or(thresholds.max_margin);
        thresholds
            .validate()
            .context("check --threshold-windows and --threshold-max-margin")?;
        Ok(FitReportConfig::seeded(thresholds, self.seed))
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    fit(&args.plan()?)
}

/// Fits the SDE (from the last checkpoint under --resume), measures it and
/// writes the artifact, its metrics and plots.
pub fn fit(plan: &Plan) -> anyhow::Result<()> {
    let _claim = claim_output(&plan.out)?;
    let dataset = plan.data.read(&plan.system)?;
    let (train, valid) = dataset.split_by_trajectory(plan.fit.valid_fraction, plan.fit.seed);
    let device = plan.device.device().map_err(anyhow::Error::msg)?;
    let resume = resume_state(plan, &device)?;
    write_run_record(&plan.out, "fit-model", plan, &[&plan.data.dataset])?;
    let (model, summary, records) = fit_logged(plan, &train, &valid, resume, &device)?;
    println!(
        "fitted {} steps in {:.0} s; best validation NLL {:.3} at step {}",
        summary.steps, summary.seconds, summary.best_valid_nll, summary.best_step
    );
    let report = fit_report(
        &model,
        &dataset,
        &valid,
        plan.fit.loss.radius,
        &plan.action_space,
        &plan.report,
        &device,
    )?;
    print_calibration(&report.calibration);
    let provenance = DynamicsProvenance {
        task: plan.system.task(),
        system: plan.system.file_text(),
        fit: Some(plan.fit.clone()),
        thresholds: Some(report.thresholds.clone()),
        calibration: Some(report.calibration.clone()),
        training: Some(summary),
        dataset: Some(plan.data.info(&dataset)),
    };
    save_dynamics(&plan.out, &model, provenance)?;
    write_charts(&plan.out, &records, &report)?;
    println!("wrote {}", plan.out.display());
    Ok(())
}

/// The fit's state at its last checkpoint under --resume; none for a fresh
/// fit (refused where --out holds a fit already).
fn resume_state(plan: &Plan, device: &Device) -> anyhow::Result<Option<SdeFitState>> {
    let checkpoints = plan.out.join(FIT_CHECKPOINTS);
    let Some(checkpoint) = checkpoint_to_resume(&checkpoints, plan.resume, &plan.out, "a fit")?
    else {
        return Ok(None);
    };
    let state = load_sde_checkpoint(&checkpoint, &plan.fit, device)
        .with_context(|| format!("resuming from {}", checkpoint.display()))?;
    println!(
        "resumed from {} (step {})",
        checkpoint.display(),
        state.step
    );
    Ok(Some(state))
}

/// Runs the fit with a progress bar, each record a line of metrics.csv (a
/// resumed fit's file starts with the records before its checkpoint) and a
/// checkpoint at every validation; the model, its summary and the records.
fn fit_logged(
    plan: &Plan,
    train: &Dataset,
    valid: &Dataset,
    resume: Option<SdeFitState>,
    device: &Device,
) -> anyhow::Result<(NeuralSde, FitSummary, Vec<FitRecord>)> {
    std::fs::create_dir_all(&plan.out)
        .with_context(|| format!("creating {}", plan.out.display()))?;
    let bar = ProgressBar::new(plan.fit.max_steps as u64).with_style(ProgressStyle::with_template(
        "{bar:30} {pos}/{len} steps {per_sec} | {msg}",
    )?);
    let metrics_path = plan.out.join("metrics.csv");
    let mut csv = File::create(&metrics_path)
        .with_context(|| format!("creating {}", metrics_path.display()))?;
    let table = fit_metrics();
    write!(csv, "{}", table.header())?;
    let mut records = Vec::new();
    let mut write_error = None;
    let mut log = |r: &FitRecord| {
        bar.set_position(r.step as u64);
        let valid_nll = r.valid_nll.map_or(String::new(), |v| v.to_string());
        let l = &r.losses;
        bar.set_message(format!(
            "L_data {:.2} L_sc {:.3} L_grad {:.3} valid NLL {}",
            l.data, l.sc, l.grad, valid_nll
        ));
        if let Err(e) = write!(csv, "{}", table.line(r)) {
            write_error.get_or_insert(e);
        }
        records.push(r.clone());
    };
    for r in resume.iter().flat_map(|state| &state.records) {
        log(r);
    }
    let checkpoints = plan.out.join(FIT_CHECKPOINTS);
    let (spec, config) = (plan.spec.clone(), &plan.fit);
    let (model, summary) = fit_from(
        train,
        valid,
        spec,
        config,
        device,
        resume,
        &mut log,
        &mut |state| {
            save_sde_checkpoint(&checkpoints, config, state)
                .map(|_| ())
                .map_err(|e| SdeError::Checkpoint(e.to_string()))
        },
    )?;
    bar.finish();
    if let Some(e) = write_error {
        return Err(e).with_context(|| format!("writing {}", metrics_path.display()));
    }
    Ok((model, summary, records))
}

/// The fit's plots: loss curves, Σ's calibration, validation error by horizon.
fn write_charts(out: &Path, records: &[FitRecord], report: &FitReport) -> anyhow::Result<()> {
    let curve = |name, f: &dyn Fn(&FitRecord) -> Option<f32>| Series {
        name,
        points: records
            .iter()
            .filter_map(|r| f(r).map(|v| (r.step as f64, f64::from(v))))
            .collect(),
    };
    line_chart(
        &out.join("loss_curves.svg"),
        "Neural SDE fit",
        "gradient step",
        "loss",
        &[
            curve("L_data (train)", &|r| Some(r.losses.data)),
            curve("L_data (validation)", &|r| r.valid_nll),
            curve("L_sc", &|r| Some(r.losses.sc)),
            curve("L_mu", &|r| Some(r.losses.mu)),
        ],
    )?;
    calibration_charts(out, &report.calibration)?;
    let errors = &report.horizon_errors;
    if errors.is_empty() {
        return Ok(());
    }
    let series = |name, f: fn(&HorizonError) -> f64| Series {
        name,
        points: errors.iter().map(|e| (e.horizon as f64, f(e))).collect(),
    };
    line_chart(
        &out.join("horizon_error.svg"),
        "Open-loop error on validation trajectories",
        "horizon (steps)",
        "RMSE (normalised units)",
        &[
            series("neural SDE", |e| e.model_rmse),
            series("constant velocity", |e| e.constant_velocity_rmse),
        ],
    )
}

/// metrics.csv's columns: one row per logged fit step.
fn fit_metrics() -> MetricsTable<'static, FitRecord> {
    let loss = |f: fn(&StepLosses) -> f32| move |r: &FitRecord| Metric::from(f(&r.losses));
    MetricsTable::new()
        .column("step", |r: &FitRecord| r.step.into())
        .column("learning_rate", |r: &FitRecord| r.learning_rate.into())
        .column("loss", loss(|l| l.total))
        .column("data", loss(|l| l.data))
        .column("sc", loss(|l| l.sc))
        .column("grad", loss(|l| l.grad))
        .column("mu", loss(|l| l.mu))
        .column("far", loss(|l| l.far))
        .column("residual", loss(|l| l.residual))
        .column("value", loss(|l| l.value))
        .column("one", loss(|l| l.one))
        .column("floor", loss(|l| l.floor))
        .column("valid_nll", |r: &FitRecord| {
            r.valid_nll.map_or_else(Metric::none, Metric::from)
        })
}
