//! `nuno-trainer analyze`: the paper's model analyses (Figures 3–5) for one
//! or more fitted models of one task, NUNO's SDEs and MOPO's ensembles alike,
//! each written as CSV and SVG:
//! - `prediction_error.csv|svg`: open-loop error per horizon step on the
//!   in-distribution dataset and, given one, an out-of-distribution one (NaN,
//!   with `windows` 0, at steps no prediction reached: the model ended them);
//! - `uncertainty.csv|svg`: each model's η at dataset states for dataset,
//!   random and (given --policy) the policy's actions;
//! - `exploitation.csv|svg` (given --policy): the policy's return in each model,
//!   with and without the penalty, against the real task, and the share of the
//!   states it reaches in each that lie outside the dataset's range;
//! - `action_sensitivity.csv` (a task with a simulator): each model's ∂s′/∂a
//!   at dataset states against the simulator's, for the dataset's, random
//!   and saturated actions.

use std::path::{Path, PathBuf};

use anyhow::Context;
use burn::tensor::Device;
use nuno::agent::{ActionMode, ActorPolicy, StateBox};
use nuno::artifact::{BEST_POLICY, ModelFolder, load_policy};
use nuno::data::{Dataset, DatasetFormat, NormalizerConfig, Stats, read_system_dataset};
use nuno::envs::{Rules, System, TaskConfig};
use nuno::experiment::{
    ActionSensitivity, Exploitation, ExploitationConfig, LinearModel, PredictionConfig,
    SensitivityConfig, action_sensitivity, exploitation, prediction_error, uncertainty_by_action,
};
use nuno::infer::Kernel;
use nuno::shared::{BatchDynamics, BatchPolicy, Metric, MetricsTable};

use crate::output::write_text;
use crate::plot::{Series, line_chart};

#[derive(Debug, clap::Args)]
pub struct Args {
    /// A model directory (fit-model's or fit-ensemble's), as DIR or NAME=DIR;
    /// repeat for each model to compare. All must be for one task.
    #[arg(long = "model", required = true)]
    models: Vec<String>,
    /// In-distribution data: trajectories the models were not fitted on, or
    /// their training data (say which when you report it).
    #[arg(long)]
    dataset: PathBuf,
    /// Out-of-distribution data of the same task (another behaviour policy).
    #[arg(long)]
    ood_dataset: Option<PathBuf>,
    /// Reader for both datasets (default: detected).
    #[arg(long)]
    format: Option<DatasetFormat>,
    /// A directory holding a trained policy (policy.json): its actions are
    /// probed (Figure 3) and its returns compared (Figure 4).
    #[arg(long)]
    policy: Option<PathBuf>,
    /// Steps predicted open-loop from each window.
    #[arg(long, default_value_t = 50)]
    horizon: usize,
    /// Windows per dataset (non-overlapping, drawn uniformly).
    #[arg(long, default_value_t = 500)]
    windows: usize,
    /// Samples per window (their mean is the prediction).
    #[arg(long, default_value_t = 5)]
    particles: usize,
    /// Dataset states the uncertainty is probed at.
    #[arg(long, default_value_t = 2000)]
    probe_states: usize,
    /// Episodes (reset states) of the exploitation comparison.
    #[arg(long, default_value_t = 10)]
    episodes: usize,
    /// Steps of each exploitation episode.
    #[arg(long, default_value_t = 200)]
    episode_steps: usize,
    /// λ of the penalised model return.
    #[arg(long, default_value_t = 1.0)]
    penalty: f64,
    /// The action step of the ∂s′/∂a differences (one-sided at the box's bounds).
    #[arg(long, default_value_t = 0.01)]
    action_delta: f32,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Also predict with a linear model, s' = W·[s, a, 1] fitted by least squares
    /// on --dataset (the baseline a learned model should beat; Figure 5 only).
    #[arg(long)]
    linear_baseline: bool,
    /// Output folder for the CSV files and plots.
    #[arg(long)]
    out: PathBuf,
}

/// One model to analyse, on the fused CPU path.
struct Model {
    name: String,
    dynamics: Box<dyn BatchDynamics>,
    system: System,
    rules: Rules,
}

impl Args {
    /// Refuses sizes no analysis can use, before anything is loaded.
    fn check(&self) -> anyhow::Result<()> {
        for (flag, value) in [
            ("--horizon", self.horizon),
            ("--windows", self.windows),
            ("--particles", self.particles),
            ("--probe-states", self.probe_states),
            ("--episodes", self.episodes),
            ("--episode-steps", self.episode_steps),
        ] {
            anyhow::ensure!(value > 0, "{flag} must be at least 1");
        }
        anyhow::ensure!(
            self.penalty.is_finite() && self.penalty >= 0.0,
            "--penalty must be a finite number ≥ 0, got {}",
            self.penalty
        );
        anyhow::ensure!(
            self.action_delta.is_finite() && self.action_delta > 0.0,
            "--action-delta must be a finite number > 0, got {}",
            self.action_delta
        );
        Ok(())
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    args.check()?;
    let models = load_models(&args.models)?;
    let system = &models[0].system;
    let read = |path: &Path| -> anyhow::Result<Dataset> {
        Ok(read_system_dataset(path, args.format, system)?)
    };
    let dataset = read(&args.dataset)?;
    let ood = args.ood_dataset.as_deref().map(read).transpose()?;
    let policy = args.policy.as_deref().map(load_actor).transpose()?;
    let policy = policy.map(|p| Kernel::Fused.policy(p));
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let linear = args
        .linear_baseline
        .then(|| linear_baseline(&models[0], &dataset))
        .transpose()?;
    let predictors: Vec<&Model> = models.iter().chain(&linear).collect();
    write_prediction_error(&args, &predictors, &dataset, ood.as_ref())?;
    write_uncertainty(&args, &models, system, &dataset, policy.as_deref())?;
    if let Some(task) = system.simulator() {
        write_action_sensitivity(&args, &predictors, &task, &dataset)?;
    }
    match (&policy, system.simulator()) {
        (Some(policy), Some(task)) => {
            let data = StateBox::around(&dataset.observation_bounds(), 0.0);
            write_exploitation(&args, &models, (task, &data), policy.as_ref())?
        }
        (Some(_), None) => println!(
            "no Figure 4: {} is a system described in a file, with no simulator to run the policy in",
            system.name()
        ),
        (None, _) => {}
    }
    println!("wrote {}", args.out.display());
    Ok(())
}

/// The least-squares linear model of `dataset`, under the first model's
/// system and rules.
fn linear_baseline(first: &Model, dataset: &Dataset) -> anyhow::Result<Model> {
    let dt = first.system.shape()?.dt;
    Ok(Model {
        name: "linear least squares".into(),
        dynamics: Box::new(LinearModel::fit(dataset, dt)?),
        system: first.system.clone(),
        rules: first.rules.clone(),
    })
}

/// The models of `specs`, checked to be of one task.
fn load_models(specs: &[String]) -> anyhow::Result<Vec<Model>> {
    let models = specs
        .iter()
        .map(|spec| load_model(spec))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let first = &models[0];
    if let Some(other) = models.iter().find(|m| m.system != first.system) {
        anyhow::bail!(
            "models of different systems: {} is {} ({:?}), {} is {} ({:?})",
            first.name,
            first.system.name(),
            first.system.task().map(|t| t.layout),
            other.name,
            other.system.name(),
            other.system.task().map(|t| t.layout)
        );
    }
    Ok(models)
}

/// A row of prediction_error.csv: model, data, step, RMSE, windows.
type PredictionRow<'a> = (String, &'a str, usize, f64, usize);

/// Figure 5: each model's open-loop error per step on both datasets, in the
/// in-distribution data's units.
fn write_prediction_error(
    args: &Args,
    models: &[&Model],
    dataset: &Dataset,
    ood: Option<&Dataset>,
) -> anyhow::Result<()> {
    let scale = Stats::fit(dataset.observations.view(), &NormalizerConfig::default()).std;
    let prediction = PredictionConfig {
        horizon: args.horizon,
        windows: args.windows,
        particles: args.particles,
        seed: args.seed,
    };
    let mut rows: Vec<PredictionRow> = Vec::new();
    let mut curves = Vec::new();
    for model in models {
        let splits = [
            ("in-distribution", Some(dataset)),
            ("out-of-distribution", ood),
        ];
        for (split, data) in splits {
            let Some(data) = data else { continue };
            let error = prediction_error(
                model.dynamics.as_ref(),
                &model.rules,
                data,
                &scale,
                &prediction,
            )
            .with_context(|| format!("{} on the {split} data", model.name))?;
            for (k, (&rmse, &n)) in error.rmse.iter().zip(&error.windows).enumerate() {
                rows.push((model.name.clone(), split, k + 1, rmse, n));
            }
            curves.push((format!("{} ({split})", model.name), error.rmse));
        }
    }
    let table = MetricsTable::new()
        .column("model", |r: &PredictionRow| r.0.as_str().into())
        .column("data", |r: &PredictionRow| r.1.into())
        .column("step", |r: &PredictionRow| r.2.into())
        .column("rmse", |r: &PredictionRow| r.3.into())
        .column("windows", |r: &PredictionRow| r.4.into());
    write_text(&args.out.join("prediction_error.csv"), &table.csv(&rows))?;
    line_chart(
        &args.out.join("prediction_error.svg"),
        "Open-loop prediction error (Figure 5)",
        "horizon step",
        "RMSE / dataset std",
        &per_step(&curves),
    )
}

/// A row of uncertainty.csv: model, actions, [mean, p10, p50, p90, max] of η.
type UncertaintyRow<'a> = (String, &'a str, [Metric; 5]);

/// Figure 3: each model's η at dataset states by action source, as each
/// source's sorted values.
fn write_uncertainty(
    args: &Args,
    models: &[Model],
    system: &System,
    dataset: &Dataset,
    policy: Option<&dyn BatchPolicy>,
) -> anyhow::Result<()> {
    let bounds = system.shape()?.action_space();
    let mut rows: Vec<UncertaintyRow> = Vec::new();
    let mut curves = Vec::new();
    for model in models {
        let probes = uncertainty_by_action(
            model.dynamics.as_ref(),
            dataset,
            policy,
            &bounds,
            args.probe_states,
            args.seed,
        );
        for (source, eta) in probes {
            let at = |q: f64| Metric::from(eta[((eta.len() - 1) as f64 * q).round() as usize]);
            let mean = eta.iter().map(|&x| f64::from(x)).sum::<f64>() / eta.len() as f64;
            let stats = [mean.into(), at(0.1), at(0.5), at(0.9), at(1.0)];
            rows.push((model.name.clone(), source.as_str(), stats));
            curves.push((format!("{} ({})", model.name, source.as_str()), eta));
        }
    }
    let mut table = MetricsTable::new()
        .column("model", |r: &UncertaintyRow| r.0.as_str().into())
        .column("actions", |r: &UncertaintyRow| r.1.into());
    for (i, name) in ["mean", "p10", "p50", "p90", "max"].into_iter().enumerate() {
        table = table.column(name, move |r: &UncertaintyRow| r.2[i].clone());
    }
    write_text(&args.out.join("uncertainty.csv"), &table.csv(&rows))?;
    let series: Vec<Series> = curves
        .iter()
        .map(|(name, eta)| Series {
            name,
            points: eta
                .iter()
                .enumerate()
                .map(|(i, &e)| (i as f64 / (eta.len() - 1).max(1) as f64, f64::from(e)))
                .collect(),
        })
        .collect();
    line_chart(
        &args.out.join("uncertainty.svg"),
        "Uncertainty at dataset states by action source (Figure 3)",
        "quantile",
        "η",
        &series,
    )
}

/// Each model's ∂s′/∂a against the simulator's, at --probe-states dataset
/// states, printed and written as action_sensitivity.csv.
fn write_action_sensitivity(
    args: &Args,
    models: &[&Model],
    task: &TaskConfig,
    dataset: &Dataset,
) -> anyhow::Result<()> {
    let config = SensitivityConfig {
        states: args.probe_states,
        delta: args.action_delta,
        seed: args.seed,
    };
    let mut rows: Vec<(String, ActionSensitivity)> = Vec::new();
    for model in models {
        for measured in action_sensitivity(model.dynamics.as_ref(), task, dataset, &config)? {
            println!(
                "{}: ‖∂s′/∂a‖ at {} actions: model {:.3}, task {:.3}, error {:.3}, median ratio {:.2}",
                model.name,
                measured.actions.as_str(),
                measured.model,
                measured.task,
                measured.error,
                measured.median_ratio
            );
            rows.push((model.name.clone(), measured));
        }
    }
    type Row = (String, ActionSensitivity);
    let table = MetricsTable::new()
        .column("model", |r: &Row| r.0.as_str().into())
        .column("actions", |r: &Row| r.1.actions.as_str().into())
        .column("model_norm", |r: &Row| r.1.model.into())
        .column("task_norm", |r: &Row| r.1.task.into())
        .column("error_norm", |r: &Row| r.1.error.into())
        .column("median_ratio", |r: &Row| r.1.median_ratio.into())
        .column("states", |r: &Row| r.1.states.into());
    write_text(&args.out.join("action_sensitivity.csv"), &table.csv(&rows))
}

/// A row of exploitation.csv.
struct ExploitationRow {
    model: String,
    step: usize,
    real: f64,
    in_model: f64,
    penalized: f64,
    real_outside: f64,
    model_outside: f64,
}

/// Figure 4: the policy's mean cumulative return in each model, with and
/// without the penalty, against the real task; and where each leaves `data`,
/// the dataset's range, also printed at a few steps.
fn write_exploitation(
    args: &Args,
    models: &[Model],
    (task, data): (TaskConfig, &StateBox),
    policy: &dyn BatchPolicy,
) -> anyhow::Result<()> {
    let config = ExploitationConfig {
        starts: args.episodes,
        horizon: args.episode_steps,
        penalty: args.penalty,
        seed: args.seed,
    };
    let mut rows: Vec<ExploitationRow> = Vec::new();
    let mut curves = Vec::new();
    for model in models {
        let result = exploitation(
            (model.dynamics.as_ref(), &model.rules),
            &task,
            policy,
            data,
            &config,
        )?;
        println!("{}", outside_summary(&model.name, &result));
        for k in 0..args.episode_steps {
            rows.push(ExploitationRow {
                model: model.name.clone(),
                step: k + 1,
                real: result.real[k],
                in_model: result.model[k],
                penalized: result.model_penalized[k],
                real_outside: result.real_outside_data[k],
                model_outside: result.model_outside_data[k],
            });
        }
        if curves.is_empty() {
            curves.push(("real task".to_string(), result.real.clone()));
        }
        curves.push((format!("{}: model", model.name), result.model));
        curves.push((
            format!("{}: model, r − {}·η", model.name, args.penalty),
            result.model_penalized,
        ));
    }
    let table = MetricsTable::new()
        .column("model", |r: &ExploitationRow| r.model.as_str().into())
        .column("step", |r: &ExploitationRow| r.step.into())
        .column("real", |r: &ExploitationRow| r.real.into())
        .column("model", |r: &ExploitationRow| r.in_model.into())
        .column("model_penalized", |r: &ExploitationRow| r.penalized.into())
        .column("real_outside_data", |r: &ExploitationRow| {
            r.real_outside.into()
        })
        .column("model_outside_data", |r: &ExploitationRow| {
            r.model_outside.into()
        });
    write_text(&args.out.join("exploitation.csv"), &table.csv(&rows))?;
    line_chart(
        &args.out.join("exploitation.svg"),
        "The policy's return: models against the real task (Figure 4)",
        "step",
        "mean cumulative return",
        &per_step(&curves),
    )
}

/// "NAME: states outside the data's range at steps 1 / 5 / 20 / H: model …, real task …"
fn outside_summary(name: &str, result: &Exploitation) -> String {
    let horizon = result.real.len();
    let mut steps: Vec<usize> = [1, 5, 20, horizon]
        .into_iter()
        .filter(|&k| k <= horizon)
        .collect();
    steps.dedup();
    let shares = |values: &[f64]| -> String {
        let each: Vec<String> = (steps.iter())
            .map(|&k| match values[k - 1] {
                v if v.is_nan() => "–".to_string(),
                v => format!("{:.0} %", 100.0 * v),
            })
            .collect();
        each.join(" / ")
    };
    let at: Vec<String> = steps.iter().map(usize::to_string).collect();
    format!(
        "{name}: states outside the dataset's range after steps {}: model {}, real task {}",
        at.join(" / "),
        shares(&result.model_outside_data),
        shares(&result.real_outside_data)
    )
}

/// Named curves of per-step values as plot series, step k + 1 at index k.
fn per_step(curves: &[(String, Vec<f64>)]) -> Vec<Series<'_>> {
    curves
        .iter()
        .map(|(name, values)| Series {
            name,
            points: values
                .iter()
                .enumerate()
                .map(|(k, &v)| ((k + 1) as f64, v))
                .collect(),
        })
        .collect()
}

/// `DIR` or `NAME=DIR`: the model folder's dynamics (a neural SDE or an ensemble), on the fused path.
fn load_model(spec: &str) -> anyhow::Result<Model> {
    let (name, dir) = match spec.split_once('=') {
        Some((name, dir)) => (name.to_string(), PathBuf::from(dir)),
        None => {
            let dir = PathBuf::from(spec);
            let name = dir
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| spec.to_string());
            (name, dir)
        }
    };
    let context = || format!("loading the model {name} from {}", dir.display());
    let folder = ModelFolder::load(&dir, &Device::flex()).with_context(context)?;
    let system = folder
        .system()?
        .with_context(|| format!("{}: its metadata names no task or system", dir.display()))?;
    Ok(Model {
        rules: folder.rules(&system)?,
        dynamics: folder.fused_dynamics(),
        system,
        name,
    })
}

/// The deterministic actor of the policy saved in `dir`.
fn load_actor(dir: &Path) -> anyhow::Result<ActorPolicy> {
    let (actor, _) = load_policy(dir, BEST_POLICY, &Device::flex())
        .with_context(|| format!("loading the policy in {}", dir.display()))?;
    Ok(ActorPolicy {
        actor,
        mode: ActionMode::Deterministic,
    })
}
