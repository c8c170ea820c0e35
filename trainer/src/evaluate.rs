//! `nuno-trainer evaluate`: episodes of a policy in the real MuJoCo task.

use anyhow::Context;
use clap::ValueEnum;
use nuno::agent::RandomPolicy;
use nuno::envs::{EvaluationConfig, MujocoTask, TaskConfig, TaskName, evaluate};

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum PolicyChoice {
    /// Uniform random actions in the task's action box.
    Random,
}

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Which policy to run.
    #[arg(long, value_enum)]
    policy: PolicyChoice,
    /// Task: hopper, halfcheetah or walker2d.
    #[arg(long)]
    task: TaskName,
    /// Number of episodes.
    #[arg(long, default_value_t = 10)]
    episodes: usize,
    /// Seed of the resets (episode i uses seed + i) and of the policy's noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// NeoRL's variant (observations include root x; NeoRL reference returns).
    #[arg(long)]
    neorl: bool,
    /// Print the full report as JSON instead of a table.
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let task = if args.neorl {
        TaskConfig::neorl(args.task)
    } else {
        TaskConfig::d4rl(args.task)
    };
    let probe = MujocoTask::new(task)?;
    let policy = match args.policy {
        PolicyChoice::Random => {
            let (low, high) = probe.action_bounds();
            let to_f32 = |v: Vec<f64>| v.into_iter().map(|x| x as f32).collect();
            RandomPolicy::new(probe.obs_dim(), to_f32(low), to_f32(high))
        }
    };
    let config = EvaluationConfig::new(task, args.episodes, args.seed);
    let report = evaluate(&policy, &config)
        .with_context(|| format!("evaluating {:?} on {}", args.policy, args.task))?;

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
        "{} {:?} policy, {} episodes: return {:.2} ± {:.2}, normalised score {:.2} ± {:.2}",
        args.task,
        args.policy,
        args.episodes,
        report.mean_return,
        report.std_return,
        report.mean_normalized_score,
        report.std_normalized_score
    );
    Ok(())
}
