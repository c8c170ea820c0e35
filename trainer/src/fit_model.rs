//! `nuno-trainer fit-model`: fit the neural SDE on a dataset, compute the
//! truncation thresholds, and write the artifact with metrics and plots; a
//! checkpoint at every validation in `--out/fit-checkpoints`, which
//! `--resume` continues.

use std::fs::File;
use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use nuno::artifact::{DynamicsProvenance, load_sde_checkpoint, save_dynamics, save_sde_checkpoint};
use nuno::envs::MujocoTask;
use nuno::infer::Kernel;
use nuno::sde::{
    CalibrationConfig, ComputeDevice, DriftInputs, DynamicsSpec, EtaLossForm, FitConfig, FitRecord,
    LikelihoodPath, LossConfig, Recipe, SampleNoise, SdeConfig, SdeError, StepLosses,
    ThresholdConfig, calibration_report, compute_thresholds, fit_from, prediction_error,
};
use nuno::shared::{Metric, MetricsTable};

use crate::data_source::DataSource;
use crate::eta_report::{action_space, calibration_charts, print_calibration};
use crate::plot::{Series, line_chart};
use crate::resume::checkpoint_to_resume;

#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    data: DataSource,
    /// Output model directory (dynamics.safetensors, model.json, metrics.csv, plots).
    #[arg(long)]
    out: PathBuf,
    /// NUNO^R: also learn the reward as a cumulative-reward state.
    #[arg(long)]
    reward_model: bool,
    /// paper (the paper's equations and Appendix C) or code (NUNO's code where it
    /// differs: samples at sqrt(dt), steps weighed 0.9^(t−1), its 100k-step schedule,
    /// 20 % held out, pose drift inputs, its η losses, ε(h, 1) = 1.1 × max); the flags
    /// below override single settings.
    #[arg(long, default_value_t = Recipe::Paper)]
    recipe: Recipe,
    /// The scale of ε the model samples at: calibrated (Σ) or sqrt-dt (NUNO's code)
    /// (default: the recipe's). Σ stays the calibrated one-step uncertainty.
    #[arg(long)]
    sample_noise: Option<SampleNoise>,
    /// η's losses: paper (eq. 3, 4: μ a network, L_grad = ‖∇η‖² + η², on the fit's
    /// schedule) or code (NUNO's `losses_diffusion.py`: one scalar μ, ½μ in L_sc,
    /// λ_grad 1e-5, mean-η and set-one terms, the gradient floor, η's own Adam at
    /// 1e-3) (default: the recipe's); --lambda-grad overrides its weight.
    #[arg(long)]
    eta_losses: Option<EtaLossForm>,
    /// What the drift networks G, H, f_res see of the state: z-scores (eq. 8) or
    /// pose (NUNO's code's `RBD_Drift`: angles as cos and sin about their mean,
    /// and G sees the pose) (default: the recipe's).
    #[arg(long)]
    drift_inputs: Option<DriftInputs>,
    /// L_data's weight of window step t is this to the power t − 1, in (0, 1]
    /// (default: the recipe's: paper 1, code 0.9).
    #[arg(long)]
    step_discount: Option<f32>,
    /// ε(h, α = 1) = this × the largest accumulated η, ≥ 1 (default: the recipe's:
    /// paper 1, code 1.1).
    #[arg(long)]
    threshold_max_margin: Option<f32>,
    /// Upper bound on gradient steps (early stopping may end sooner; default: the
    /// recipe's, paper 20 000, code 200 000).
    #[arg(long)]
    max_steps: Option<usize>,
    /// Validation NLL every this many steps (default: the recipe's: paper 250, code 2000).
    #[arg(long)]
    eval_every: Option<usize>,
    /// Early-stopping patience, in evaluations (default: the recipe's: paper 8, code 20).
    #[arg(long)]
    patience: Option<usize>,
    /// Hidden sizes of the drift networks G, H, f_res (paper: 256,256,256).
    #[arg(long, value_delimiter = ',', default_value = "256,256,256")]
    drift_hidden: Vec<usize>,
    /// Ball radius r of L_sc's samples, in normalised units (default: the paper's 0.1).
    #[arg(long)]
    radius: Option<f32>,
    /// λ_grad, weight of L_grad (default: the η loss form's: paper 1e-4, code 1e-5).
    #[arg(long)]
    lambda_grad: Option<f32>,
    /// λ_far, weight of the far-field hinge on η (not in the paper; default 0 = off;
    /// see docs/paper-map.md before using it on high-dimensional data).
    #[arg(long)]
    lambda_far: Option<f32>,
    /// Where L_data's steps start: particle (eq. 6 as written: the previous step's
    /// sample) or data (the recorded state before each step; docs/paper-map.md).
    #[arg(long, default_value_t = LikelihoodPath::Particle)]
    likelihood: LikelihoodPath,
    /// W^max of h(η): the diffusion beyond the data, in multiples of each state
    /// dimension's diffusion scale; one value for all, or one per dimension.
    #[arg(long, value_delimiter = ',', default_value = "1")]
    w_max: Vec<f32>,
    /// Windows per horizon used for the CVaR thresholds.
    #[arg(long, default_value_t = ThresholdConfig::new().max_windows)]
    threshold_windows: usize,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Compute device: cpu, or wgpu in a build with the `wgpu` feature.
    #[arg(long, default_value_t = ComputeDevice::Cpu)]
    device: ComputeDevice,
    /// What takes the gradient steps: fused (the CPU kernels, every core) or burn
    /// (autodiff on --device); default fused on the CPU, burn on a GPU. Either
    /// resumes the other's checkpoints.
    #[arg(long)]
    kernel: Option<Kernel>,
    /// Continue the fit checkpointed in --out (the same settings; --max-steps may grow).
    #[arg(long)]
    resume: bool,
}

/// The validated settings of a fit: the task (its simulator, for the action box),
/// the model's spec, the fit and the threshold configurations (the recipe's, with
/// single flags over it).
fn fit_plan(args: &Args) -> anyhow::Result<(MujocoTask, DynamicsSpec, FitConfig, ThresholdConfig)> {
    let mut loss = LossConfig::new();
    loss.radius = args.radius.unwrap_or(loss.radius);
    loss.lambda_far = args.lambda_far.unwrap_or(loss.lambda_far);
    loss.likelihood = args.likelihood;
    anyhow::ensure!(
        !args.drift_hidden.is_empty() && args.drift_hidden.iter().all(|&h| h > 0),
        "--drift-hidden needs positive layer sizes"
    );
    let task = args.data.task_config();
    let probe = MujocoTask::new(task)?;
    let spec = DynamicsSpec {
        obs_dim: probe.obs_dim(),
        act_dim: probe.act_dim(),
        split: probe.state_split(),
        dt: probe.dt(),
    };
    let mut model_config = SdeConfig::new();
    model_config.reward_model = args.reward_model;
    model_config.drift_hidden = args.drift_hidden.clone();
    model_config.w_max = args.w_max.clone();
    let mut config = FitConfig::new(model_config, loss);
    args.recipe.apply_to_fit(&mut config, spec.dt);
    if let Some(noise) = args.sample_noise {
        config.model.sample_noise_scale = noise.scale(spec.dt);
    }
    if let Some(form) = args.eta_losses {
        form.apply_to_fit(&mut config);
    }
    config.model.drift_inputs = args.drift_inputs.unwrap_or(config.model.drift_inputs);
    config.loss.lambda_grad = args.lambda_grad.unwrap_or(config.loss.lambda_grad);
    config.loss.step_discount = args.step_discount.unwrap_or(config.loss.step_discount);
    config.max_steps = args.max_steps.unwrap_or(config.max_steps);
    config.eval_every = args.eval_every.unwrap_or(config.eval_every);
    config.patience = args.patience.unwrap_or(config.patience);
    config.seed = args.seed;
    config.kernel = match (args.kernel, args.device) {
        (Some(Kernel::Fused), ComputeDevice::Wgpu) => {
            anyhow::bail!("--kernel fused runs on the CPU: use --kernel burn with --device wgpu")
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
        .validate(spec.obs_dim + usize::from(args.reward_model))
        .context("check --w-max")?;
    anyhow::ensure!(config.max_steps > 0, "--max-steps must be at least 1");
    anyhow::ensure!(config.eval_every > 0, "--eval-every must be at least 1");
    let mut threshold_config = ThresholdConfig {
        max_windows: args.threshold_windows,
        seed: args.seed,
        ..ThresholdConfig::new()
    };
    args.recipe.apply_to_thresholds(&mut threshold_config);
    threshold_config.max_margin = args
        .threshold_max_margin
        .unwrap_or(threshold_config.max_margin);
    threshold_config
        .validate()
        .context("check --threshold-windows and --threshold-max-margin")?;
    Ok((probe, spec, config, threshold_config))
}

pub fn run(args: Args) -> anyhow::Result<()> {
    // Every setting is checked before the data is read or any work starts.
    let (probe, spec, config, threshold_config) = fit_plan(&args)?;
    let task = args.data.task_config();
    let dataset = args.data.read()?;
    let (train, valid) = dataset.split_by_trajectory(config.valid_fraction, config.seed);
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;

    // Fit, with a progress bar and a metrics CSV.
    let device = args.device.device().map_err(anyhow::Error::msg)?;
    let bar = ProgressBar::new(config.max_steps as u64).with_style(ProgressStyle::with_template(
        "{bar:30} {pos}/{len} steps {per_sec} | {msg}",
    )?);
    let checkpoints = args.out.join("fit-checkpoints");
    let resume = match checkpoint_to_resume(&checkpoints, args.resume, &args.out, "a fit")? {
        Some(checkpoint) => {
            let state = load_sde_checkpoint(&checkpoint, &config, &device)
                .with_context(|| format!("resuming from {}", checkpoint.display()))?;
            println!(
                "resumed from {} (step {})",
                checkpoint.display(),
                state.step
            );
            Some(state)
        }
        None => None,
    };
    let metrics_path = args.out.join("metrics.csv");
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
    // A resumed fit's metrics start with the records before the checkpoint.
    for r in resume.iter().flat_map(|state| &state.records) {
        log(r);
    }
    let (model, summary) = fit_from(
        &train,
        &valid,
        spec,
        &config,
        &device,
        resume,
        &mut log,
        &mut |state| {
            save_sde_checkpoint(&checkpoints, &config, state)
                .map(|_| ())
                .map_err(|e| SdeError::Checkpoint(e.to_string()))
        },
    )?;
    bar.finish();
    if let Some(e) = write_error {
        return Err(e).with_context(|| format!("writing {}", metrics_path.display()));
    }
    println!(
        "fitted {} steps in {:.0} s; best validation NLL {:.3} at step {}",
        summary.steps, summary.seconds, summary.best_valid_nll, summary.best_step
    );

    // Section 4.3: ε(h, α) over the whole dataset.
    let thresholds = compute_thresholds(&model, &dataset, &threshold_config, &device)?;
    // How Σ and truncation behave on the held-out trajectories.
    let calibration = calibration_report(
        &model,
        &valid,
        Some(&thresholds),
        config.loss.radius,
        &action_space(&probe),
        &CalibrationConfig::new().with_seed(args.seed),
        &device,
    )?;
    print_calibration(&calibration);
    let provenance = DynamicsProvenance {
        task: Some(task),
        fit: Some(config),
        thresholds: Some(thresholds),
        calibration: Some(calibration.clone()),
        training: Some(summary),
        dataset: Some(args.data.info(&dataset)),
    };
    save_dynamics(&args.out, &model, provenance)?;

    // Plots: loss curves and validation error by horizon.
    let curve = |name, f: &dyn Fn(&nuno::sde::FitRecord) -> Option<f32>| Series {
        name,
        points: records
            .iter()
            .filter_map(|r| f(r).map(|v| (r.step as f64, f64::from(v))))
            .collect(),
    };
    line_chart(
        &args.out.join("loss_curves.svg"),
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
    calibration_charts(&args.out, &calibration)?;
    let errors = prediction_error(&model, &valid, 50, 256, args.seed, &device);
    if !errors.is_empty() {
        line_chart(
            &args.out.join("horizon_error.svg"),
            "Open-loop error on validation trajectories",
            "horizon (steps)",
            "RMSE (normalised units)",
            &[
                Series {
                    name: "neural SDE",
                    points: errors
                        .iter()
                        .map(|e| (e.horizon as f64, e.model_rmse))
                        .collect(),
                },
                Series {
                    name: "constant velocity",
                    points: errors
                        .iter()
                        .map(|e| (e.horizon as f64, e.constant_velocity_rmse))
                        .collect(),
                },
            ],
        )?;
    }
    println!("wrote {}", args.out.display());
    Ok(())
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
