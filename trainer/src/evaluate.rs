//! `nuno-trainer evaluate`: episodes of a policy in the real MuJoCo task, or
//! of model-predictive control with a planner in a model (beside the
//! model's own policy, on the same resets).

use std::path::{Path, PathBuf};

use anyhow::Context;
use nuno::agent::{ActionMode, ActorPolicy, RandomPolicy};
use nuno::artifact::{
    ArtifactError, BEST_POLICY, ModelFolder, PolicyMetadata, has_policy, load_policy,
    read_online_run,
};
use nuno::envs::{
    EvaluationConfig, EvaluationReport, MujocoTask, System, TaskConfig, TaskName, evaluate,
};
use nuno::infer::Kernel;
use nuno::planning::{
    Cost, PlanBudget, PlanConfig, Planner, PlannerSettings, ScoreConfig, evaluate_mpc,
};
use nuno::sde::requested_threshold;
use nuno::shared::{BatchPolicy, Cancel};

use crate::data_source::{simulation_of, system_of};

#[derive(Debug, clap::Args)]
pub struct Args {
    /// `random` (uniform actions in the task's box), or a model directory
    /// holding a trained policy (see --policy-name).
    #[arg(long, required_unless_present = "planner", conflicts_with = "planner")]
    policy: Option<String>,
    /// Model-predictive control instead of a policy: at every step, plan in
    /// --model's model with `mppi` or `cem` from the observed state and take
    /// the plan's first action; the model's own policy, if it has one, is
    /// evaluated beside it on the same resets.
    #[arg(long, requires = "model")]
    planner: Option<Planner>,
    /// The model directory --planner plans in.
    #[arg(long, requires = "planner")]
    model: Option<PathBuf>,
    #[command(flatten)]
    planning: PlanningFlags,
    /// Which saved policy in that directory: `policy` (best) or `policy-last`.
    #[arg(long, default_value = BEST_POLICY)]
    policy_name: String,
    /// Sample actions from π instead of taking its mean.
    #[arg(long)]
    sampled: bool,
    /// Task: hopper, halfcheetah, walker2d, swimmer, invertedpendulum or ant (default: the policy's own task).
    #[arg(long, conflicts_with = "system")]
    task: Option<TaskName>,
    /// A system file with a `[mujoco]` table, simulated in place of a built-in task.
    #[arg(long)]
    system: Option<PathBuf>,
    /// Number of episodes.
    #[arg(long, default_value_t = 10)]
    episodes: usize,
    /// Seed of the resets (episode i uses seed + i) and of the policy's noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// NeoRL's variant (observations include root x; NeoRL reference returns).
    #[arg(long, conflicts_with = "system")]
    neorl: bool,
    /// Print the full report as JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// What evaluates the policy: the fused CPU path or burn (`fused` or `burn`).
    #[arg(long, default_value_t = Kernel::Fused)]
    kernel: Kernel,
}

/// The planner's flags; each is refused without --planner.
#[derive(Debug, clap::Args)]
struct PlanningFlags {
    /// Planner: steps H of each plan (default 30, PETS' on hopper).
    #[arg(long, requires = "planner")]
    horizon: Option<usize>,
    /// Planner: candidates per iteration (default 350, PETS').
    #[arg(long, requires = "planner")]
    population: Option<usize>,
    /// Planner: iterations per control step (default 5, PETS').
    #[arg(long, requires = "planner")]
    iterations: Option<usize>,
    /// Planner: model samples of each candidate (default 1; PETS' 20 cost 20×).
    #[arg(long, requires = "planner")]
    particles: Option<usize>,
    /// Planner: λ on η in the candidates' returns, Σ γ^t (r_t − λ·η_t) (default 1).
    #[arg(long, requires = "planner")]
    penalty: Option<f64>,
    /// Planner: γ of the returns (default 1).
    #[arg(long, requires = "planner")]
    discount: Option<f64>,
    /// Planner: maximise the CVaR of the return over this share of particles.
    #[arg(long, requires = "planner")]
    cvar_alpha: Option<f64>,
    /// Planner: truncate candidates at the model's ε(H, α) for this α.
    #[arg(long, requires = "planner")]
    alpha: Option<f64>,
    /// Planner: sampling spread, a share of each action's half-range (default: cem and icem 0.5, mppi 1).
    #[arg(long, requires = "planner")]
    noise: Option<f64>,
    /// MPPI: the temperature of its weights (default 1).
    #[arg(long, requires = "planner")]
    temperature: Option<f64>,
    /// MPPI: β of its smoothed noise (default 0.9).
    #[arg(long, requires = "planner")]
    smoothing: Option<f64>,
    /// CEM and iCEM: candidates each iteration refits to (default ⌈population / 10⌉).
    #[arg(long, requires = "planner")]
    elites: Option<usize>,
    /// CEM and iCEM: share of the old distribution kept per refit (default 0.1).
    #[arg(long, requires = "planner")]
    momentum: Option<f64>,
    /// iCEM: iteration i samples ⌈population·decay^(−i)⌉ (default 1.3).
    #[arg(long, requires = "planner")]
    decay: Option<f64>,
    /// iCEM: exponent β of the samples' power spectrum f^(−β) along time (default 2).
    #[arg(long, requires = "planner")]
    colored_noise: Option<f64>,
    /// iCEM: share of elites carried to the next iteration and control step (default 0.3).
    #[arg(long, requires = "planner")]
    keep_elites: Option<f64>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let given = match (args.task, args.system.as_deref()) {
        (None, None) => None,
        (task, file) => Some(simulation_of(&system_of(task, file, args.neorl)?)?),
    };
    if let Some(planner) = args.planner {
        return run_planner(&args, planner, given);
    }
    let name = args.policy.as_deref().unwrap_or_default();
    let (policy, task) = policy_and_task(&args, name, given)?;
    let config = EvaluationConfig::new(task.clone(), args.episodes, args.seed);
    let report = evaluate(policy.as_ref(), &config)
        .with_context(|| format!("evaluating {name} on {}", task.task))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    print_report(&format!("{} {name} policy", task.task), &report);
    Ok(())
}

/// The policy `--policy` names and the task it acts in.
fn policy_and_task(
    args: &Args,
    name: &str,
    given: Option<TaskConfig>,
) -> anyhow::Result<(Box<dyn BatchPolicy>, TaskConfig)> {
    if name == "random" {
        let task = given.context("--task or --system is required with --policy random")?;
        let probe = MujocoTask::new(&task)?;
        let (low, high) = probe.action_bounds();
        let to_f32 = |v: Vec<f64>| v.into_iter().map(|x| x as f32).collect();
        let random = RandomPolicy::new(probe.obs_dim(), to_f32(low), to_f32(high));
        return Ok((Box::new(random), task));
    }
    let dir = PathBuf::from(name);
    let (actor, metadata) = load_policy(&dir, &args.policy_name, &burn::tensor::Device::flex())
        .with_context(|| {
            format!(
                "loading policy `{}` from {}",
                args.policy_name,
                dir.display()
            )
        })?;
    let task = match given {
        Some(task) => task,
        None => policy_task(&dir, &metadata)?,
    };
    let mode = if args.sampled {
        ActionMode::Sampled
    } else {
        ActionMode::Deterministic
    };
    Ok((args.kernel.policy(ActorPolicy { actor, mode }), task))
}

/// MPC with `planner` in `--model`'s model, and that folder's own policy
/// (when it has one) on the same resets.
fn run_planner(args: &Args, planner: Planner, given: Option<TaskConfig>) -> anyhow::Result<()> {
    let dir = args.model.as_deref().context("--planner needs --model")?;
    let folder = ModelFolder::load(dir, &burn::tensor::Device::flex())
        .with_context(|| format!("loading the model in {}", dir.display()))?;
    let system = (folder.system()?)
        .with_context(|| format!("{} records no system to simulate", dir.display()))?;
    let task = match given {
        Some(task) => task,
        None => simulation_of(&system)?,
    };
    let rules = folder.rules(&system)?;
    let dynamics = folder.dynamics(args.kernel);
    let config = args
        .planning
        .config(planner, &folder, dynamics.sample_noise_scale())?;
    let evaluation = EvaluationConfig::new(task.clone(), args.episodes, args.seed);
    let mpc = evaluate_mpc(
        dynamics.as_ref(),
        &rules,
        &config,
        &evaluation,
        &Cancel::default(),
    )
    .with_context(|| format!("planning with {planner} on {}", task.task))?;
    let policy = if has_policy(dir, &args.policy_name) {
        let name = dir.display().to_string();
        let (policy, _) = policy_and_task(args, &name, Some(task.clone()))?;
        Some(evaluate(policy.as_ref(), &evaluation)?)
    } else {
        None
    };
    if args.json {
        let both = serde_json::json!({ "planner": mpc, "policy": policy });
        println!("{}", serde_json::to_string_pretty(&both)?);
        return Ok(());
    }
    print_report(&format!("{} {planner} planner", task.task), &mpc);
    if let Some(report) = &policy {
        print_report(
            &format!("{} the model's `{}`", task.task, args.policy_name),
            report,
        );
    }
    Ok(())
}

impl PlanningFlags {
    /// The planner's configuration: the flags over [`PlanBudget::MPC`] and
    /// the library's defaults, ε(H, α) from the model's table.
    fn config(
        &self,
        planner: Planner,
        folder: &ModelFolder,
        noise_scale: f32,
    ) -> anyhow::Result<PlanConfig> {
        let budget = PlanBudget::MPC;
        let population = self.population.unwrap_or(budget.population);
        let horizon = self.horizon.unwrap_or(budget.horizon);
        let settings = PlannerSettings {
            temperature: self.temperature,
            smoothing: self.smoothing,
            elites: self.elites,
            momentum: self.momentum,
            decay: self.decay,
            colored_noise: self.colored_noise,
            keep_elites: self.keep_elites,
            noise: self.noise,
        };
        let (optimizer, noise) = planner.configure(&settings, population)?;
        Ok(PlanConfig {
            optimizer,
            population,
            iterations: self.iterations.unwrap_or(budget.iterations),
            noise,
            score: ScoreConfig {
                horizon,
                particles: self.particles.unwrap_or(budget.particles),
                discount: self.discount.unwrap_or(1.0),
                penalty: self.penalty.unwrap_or(1.0),
                cvar_alpha: self.cvar_alpha,
                threshold: requested_threshold(folder.thresholds(), None, self.alpha, horizon)?,
                noise_scale,
                cost: Cost::default(),
            },
        })
    }
}

/// Each episode's return, length and score, then the summary under `label`.
fn print_report(label: &str, report: &EvaluationReport) {
    println!("episode      return  length  normalised");
    for (i, ((r, len), score)) in (report.returns.iter())
        .zip(&report.lengths)
        .zip(&report.normalized_scores)
        .enumerate()
    {
        println!("{i:>7} {r:>11.2} {len:>7} {score:>11.2}");
    }
    println!(
        "{label}, {} episodes: return {:.2} ± {:.2}, normalised score {:.2} ± {:.2}",
        report.returns.len(),
        report.mean_return,
        report.std_return,
        report.mean_normalized_score,
        report.std_normalized_score
    );
}

/// The task a policy acts in: the built-in one it records, or else the one
/// the model folder it was saved in records (a system file's, whole).
fn policy_task(dir: &Path, metadata: &PolicyMetadata) -> anyhow::Result<TaskConfig> {
    let recorded = metadata.simulated_task(dir);
    if recorded.is_ok() {
        return Ok(recorded?);
    }
    // A system file's policy: the file the model folder or online run it
    // sits in recorded (their metadata alone, no weights).
    let system = match ModelFolder::recorded_system(dir) {
        Err(ArtifactError::NotAModel(_)) => online_run_system(dir)?,
        system => system?,
    };
    let simulator = system.as_ref().and_then(System::simulator);
    simulator.with_context(|| format!("{}: {}", dir.display(), recorded.unwrap_err()))
}

/// The system of the online run whose `policies/` folder is `dir`, if it is one.
fn online_run_system(dir: &Path) -> anyhow::Result<Option<System>> {
    let Some(run) = dir.parent().filter(|run| run.join("run.json").is_file()) else {
        return Ok(None);
    };
    Ok(Some(read_online_run(run)?.system(run)?))
}
