//! `nuno-trainer evaluate`: episodes of a policy in the real MuJoCo task.

use std::path::{Path, PathBuf};

use anyhow::Context;
use nuno::agent::{ActionMode, ActorPolicy, RandomPolicy};
use nuno::artifact::{ArtifactError, BEST_POLICY, ModelFolder, PolicyMetadata, load_policy};
use nuno::envs::{EvaluationConfig, MujocoTask, System, TaskConfig, TaskName, evaluate};
use nuno::infer::Kernel;
use nuno::shared::BatchPolicy;

use crate::data_source::{simulation_of, system_of};

#[derive(Debug, clap::Args)]
pub struct Args {
    /// `random` (uniform actions in the task's box), or a model directory
    /// holding a trained policy (see --policy-name).
    #[arg(long)]
    policy: String,
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

pub fn run(args: Args) -> anyhow::Result<()> {
    let given = match (args.task, args.system.as_deref()) {
        (None, None) => None,
        (task, file) => Some(simulation_of(&system_of(task, file, args.neorl)?)?),
    };
    let (policy, task): (Box<dyn BatchPolicy>, TaskConfig) = if args.policy == "random" {
        let task = given.context("--task or --system is required with --policy random")?;
        let probe = MujocoTask::new(&task)?;
        let (low, high) = probe.action_bounds();
        let to_f32 = |v: Vec<f64>| v.into_iter().map(|x| x as f32).collect();
        let random = RandomPolicy::new(probe.obs_dim(), to_f32(low), to_f32(high));
        (Box::new(random), task)
    } else {
        let dir = PathBuf::from(&args.policy);
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
        (args.kernel.policy(ActorPolicy { actor, mode }), task)
    };
    let config = EvaluationConfig::new(task.clone(), args.episodes, args.seed);
    let report = evaluate(policy.as_ref(), &config)
        .with_context(|| format!("evaluating {} on {}", args.policy, task.task))?;

    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    println!("episode      return  length  normalised");
    for (i, ((r, len), score)) in report
        .returns
        .iter()
        .zip(&report.lengths)
        .zip(&report.normalized_scores)
        .enumerate()
    {
        println!("{i:>7} {r:>11.2} {len:>7} {score:>11.2}");
    }
    println!(
        "{} {} policy, {} episodes: return {:.2} ± {:.2}, normalised score {:.2} ± {:.2}",
        task.task,
        args.policy,
        args.episodes,
        report.mean_return,
        report.std_return,
        report.mean_normalized_score,
        report.std_normalized_score
    );
    Ok(())
}

/// The task a policy acts in: the built-in one it records, or else the one
/// the model folder it was saved in records (a system file's, whole).
fn policy_task(dir: &Path, metadata: &PolicyMetadata) -> anyhow::Result<TaskConfig> {
    let recorded = metadata.simulated_task(dir);
    if recorded.is_ok() {
        return Ok(recorded?);
    }
    let folder = match ModelFolder::load(dir, &burn::tensor::Device::flex()) {
        Err(ArtifactError::NotAModel(_)) => return Ok(recorded?),
        folder => folder?,
    };
    let system = folder.system()?;
    let simulator = system.as_ref().and_then(System::simulator);
    simulator.with_context(|| format!("{}: {}", dir.display(), recorded.unwrap_err()))
}
