//! `nuno-trainer collect`: train behaviour policies online in the real tasks
//! (`online-sac`, with checkpoints, `--resume`, metrics and a return curve),
//! and pick the checkpoints each dataset recipe uses (`select`).

use std::path::{Path, PathBuf};

use anyhow::Context;
use burn::tensor::Device;
use clap::Subcommand;
use indicatif::{ProgressBar, ProgressStyle};
use nuno::agent::{ActionMode, ActorPolicy, OnlineRecord, OnlineSac, OnlineSacConfig, SacConfig};
use nuno::artifact::{
    RunPolicy, load_online_checkpoint, load_policy, read_online_run, run_policies, save_behaviour,
    save_online_checkpoint, snapshot_online_run, start_online_run,
};
use nuno::data::{BehaviourLevel, BehaviourPick, LEVEL_TOLERANCE, select_behaviour};
use nuno::envs::{EvaluationConfig, System, TaskConfig, TaskName, evaluate};
use nuno::infer::Kernel;
use nuno::sde::ComputeDevice;
use nuno::shared::{Metric, MetricsTable};

use crate::data_source::{simulation_of, system_of};
use crate::output::{with_sac_losses, write_text};
use crate::plot::{Series, line_chart};
use crate::resume::claim_output;

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Train SAC online in a MuJoCo task (built in, or a system file's
    /// `[mujoco]` table), saving the policy at every checkpoint.
    OnlineSac(OnlineArgs),
    /// Pick a run's checkpoints for each behaviour level and write them to a
    /// behaviour directory (`models/behaviour`), with their evaluations.
    Select(SelectArgs),
    /// Copy what a run needs to go on and to have its levels picked (no
    /// transitions) into a folder small enough to commit; continue it on
    /// another machine with `online-sac --resume --refill STEPS`.
    Snapshot(SnapshotArgs),
}

/// Online SAC's defaults (CleanRL's), which the flags' defaults read.
fn online_defaults() -> OnlineSacConfig {
    OnlineSacConfig::new(SacConfig::new())
}

#[derive(Debug, clap::Args)]
pub struct OnlineArgs {
    /// A built-in task.
    #[arg(long, required_unless_present = "system", conflicts_with = "system")]
    task: Option<TaskName>,
    /// A system file with a `[mujoco]` table, to train in its simulator.
    #[arg(long)]
    system: Option<PathBuf>,
    /// Environment steps in all (a resumed run may be given more).
    #[arg(long, default_value_t = online_defaults().steps)]
    steps: usize,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Steps between checkpoints (evaluation, policy, run state).
    #[arg(long, default_value_t = online_defaults().checkpoint_every)]
    checkpoint_every: usize,
    /// Steps of uniformly random actions before SAC acts and updates.
    #[arg(long, default_value_t = online_defaults().start_steps)]
    start_steps: usize,
    /// Deterministic evaluation episodes per checkpoint.
    #[arg(long, default_value_t = online_defaults().eval_episodes)]
    eval_episodes: usize,
    /// SAC batch size.
    #[arg(long, default_value_t = online_defaults().sac.batch_size)]
    batch_size: usize,
    /// Hidden sizes of the actor and critics.
    #[arg(long, value_delimiter = ',', default_values_t = online_defaults().sac.actor_hidden)]
    hidden: Vec<usize>,
    /// NeoRL's observation layout (root x included).
    #[arg(long)]
    neorl: bool,
    /// Run directory.
    #[arg(long)]
    out: PathBuf,
    /// Continue from the last checkpoint in --out.
    #[arg(long)]
    resume: bool,
    /// With --resume, where the run's recorded transitions are missing (a
    /// snapshot): continue without them, the policy acting this many steps
    /// before SAC updates resume, to refill the replay buffer.
    #[arg(long, requires = "resume")]
    refill: Option<usize>,
}

#[derive(Debug, clap::Args)]
pub struct SnapshotArgs {
    /// Run directory written by `collect online-sac`.
    #[arg(long)]
    run: PathBuf,
    /// Snapshot folder (replaced whole), e.g. `models/behaviour/<task>/run`.
    #[arg(long)]
    out: PathBuf,
    /// Keep the first policy in each band of this many normalised points (and
    /// the best and latest); narrower than `select`'s tolerance loses no pick.
    #[arg(long, default_value_t = 2.5)]
    band: f64,
    /// Keep the run's transitions up to this checkpoint step, zstd-compressed
    /// (the medium policy's: D4RL's medium-replay, which another kind of CPU
    /// cannot re-create).
    #[arg(long)]
    replay_until: Option<usize>,
}

#[derive(Debug, clap::Args)]
pub struct SelectArgs {
    /// Run directory written by `collect online-sac`.
    #[arg(long)]
    run: PathBuf,
    /// Behaviour directory; the policies go to `<out>/<task>/`.
    #[arg(long, default_value = "models/behaviour")]
    out: PathBuf,
    /// Levels to pick (default: all).
    #[arg(long, value_delimiter = ',')]
    levels: Vec<BehaviourLevel>,
    /// How far a level's checkpoint may be from its target, as a fraction of
    /// the expert's return.
    #[arg(long, default_value_t = LEVEL_TOLERANCE)]
    tolerance: f64,
    /// Evaluate every policy of the run again over this many episodes (from
    /// the run's start states, as its checkpoints were) and pick on those
    /// returns; without it, on the run's own checkpoint evaluations.
    #[arg(long)]
    episodes: Option<usize>,
}

pub fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::OnlineSac(args) => online_sac(args),
        Command::Select(args) => select(args),
        Command::Snapshot(args) => snapshot(args),
    }
}

impl OnlineArgs {
    /// The run's configuration, the flags checked before anything is written.
    fn config(&self) -> anyhow::Result<OnlineSacConfig> {
        anyhow::ensure!(
            !self.hidden.is_empty() && self.hidden.iter().all(|&h| h > 0),
            "--hidden needs positive layer sizes"
        );
        anyhow::ensure!(
            self.refill != Some(0),
            "--refill needs at least one step: SAC samples batches from what the refill records"
        );
        let sac = SacConfig::new()
            .with_batch_size(self.batch_size)
            .with_actor_hidden(self.hidden.clone())
            .with_critic_hidden(self.hidden.clone());
        Ok(OnlineSacConfig::new(sac)
            .with_steps(self.steps)
            .with_seed(self.seed)
            .with_checkpoint_every(self.checkpoint_every)
            .with_start_steps(self.start_steps)
            .with_eval_episodes(self.eval_episodes))
    }
}

fn online_sac(args: OnlineArgs) -> anyhow::Result<()> {
    let config = args.config()?;
    let system = system_of(args.task, args.system.as_deref(), args.neorl)?;
    let task = simulation_of(&system)?;
    let device = ComputeDevice::Cpu.device().map_err(anyhow::Error::msg)?;
    let mut run = OnlineSac::new(config, task, &device)?;
    let _claim = claim_output(&args.out)?;
    let has_run = args.out.join("run.json").exists();
    anyhow::ensure!(
        args.resume || !has_run,
        "{} already holds a run; pass --resume to continue it or choose another --out",
        args.out.display()
    );
    start_online_run(&args.out, &run, &system)?;
    if args.resume && load_online_checkpoint(&args.out, &mut run, args.refill)? {
        println!(
            "resumed at step {} (updates from step {})",
            run.step, run.updates_after
        );
    }
    train_online(&args.out, &mut run, &system)?;
    if let Some(last) = run.history.last() {
        println!(
            "{} steps, {} updates, {} episodes: evaluation return {:.1} (normalised {:.1}); run in {}",
            last.step,
            last.updates,
            last.episodes,
            last.eval.mean_return,
            last.eval.normalized_score,
            args.out.display()
        );
    }
    Ok(())
}

/// Interval after interval to the run's last step, each checkpointed with its
/// metrics in `out`, the latest evaluation on a progress bar.
fn train_online(out: &Path, run: &mut OnlineSac, system: &System) -> anyhow::Result<()> {
    let bar = ProgressBar::new(run.config.steps as u64).with_style(ProgressStyle::with_template(
        "{bar:30} {pos}/{len} steps | {msg}",
    )?);
    bar.set_position(run.step as u64);
    while !run.is_finished() {
        let record = run.run_interval()?;
        save_online_checkpoint(out, run, system)?;
        write_metrics(out, &run.history)?;
        bar.set_position(run.step as u64);
        bar.set_message(format!(
            "return {:.0} (score {:.1}) | env steps/s {:.0} | updates/s {:.1}",
            record.eval.mean_return,
            record.eval.normalized_score,
            record.env_steps_per_second,
            record.updates_per_second
        ));
    }
    bar.finish();
    Ok(())
}

fn select(args: SelectArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.tolerance > 0.0 && args.tolerance.is_finite(),
        "--tolerance must be a positive fraction, got {}",
        args.tolerance
    );
    let info = read_online_run(&args.run)
        .with_context(|| format!("reading the run in {}", args.run.display()))?;
    // Checked before any level: the recipes' levels are the built-in tasks'.
    anyhow::ensure!(
        info.task.is_some(),
        "behaviour policies are picked for the built-in tasks, not for `{}` (D4RL's and NeoRL's \
         recipes are theirs); the run's policies are in {}",
        info.system(&args.run)?.name(),
        args.run.join("policies").display()
    );
    let policies = run_policies(&args.run)
        .with_context(|| format!("reading the run in {}", args.run.display()))?;
    let levels = if args.levels.is_empty() {
        BehaviourLevel::ALL.to_vec()
    } else {
        args.levels.clone()
    };
    let returns = match args.episodes {
        Some(episodes) => {
            let task = simulation_of(&info.system(&args.run)?)?;
            reevaluated_returns(&policies, task, episodes, info.config.seed)?
        }
        None => policies
            .iter()
            .map(|p| {
                (
                    p.step,
                    p.metadata.provenance.mean_return.unwrap_or(f64::NAN),
                )
            })
            .collect(),
    };
    // Every level is checked before anything is written.
    let picks = levels
        .iter()
        .map(|&level| Ok((level, select_behaviour(&returns, level, args.tolerance)?)))
        .collect::<anyhow::Result<Vec<_>>>()?;
    for (level, pick) in picks {
        let policy = policies
            .iter()
            .find(|p| p.step == pick.step)
            .context("the selected checkpoint has no policy")?;
        let pick = BehaviourPick {
            evaluation_episodes: args.episodes,
            ..pick
        };
        let written = save_behaviour(&args.out, &args.run, policy, level, &pick)?;
        println!(
            "{level}: step {} (return {:.1}, target {:.1}) -> {}",
            pick.step,
            pick.mean_return,
            pick.target_return,
            written.display()
        );
    }
    Ok(())
}

/// Each policy's mean return over `episodes` deterministic episodes from the
/// start states of seed `seed`, the run's own (so every checkpoint meets the same ones).
fn reevaluated_returns(
    policies: &[RunPolicy],
    task: TaskConfig,
    episodes: usize,
    seed: u64,
) -> anyhow::Result<Vec<(usize, f64)>> {
    anyhow::ensure!(episodes > 0, "--episodes must be at least 1");
    let config = EvaluationConfig::new(task, episodes, seed);
    let bar = ProgressBar::new(policies.len() as u64).with_style(ProgressStyle::with_template(
        "{bar:30} {pos}/{len} policies evaluated, eta {eta}",
    )?);
    let returns = policies
        .iter()
        .map(|p| {
            let (actor, _) = load_policy(&p.dir, &p.stem, &Device::flex())?;
            let policy = Kernel::Fused.policy(ActorPolicy {
                actor,
                mode: ActionMode::Deterministic,
            });
            let report = evaluate(policy.as_ref(), &config)
                .with_context(|| format!("evaluating the policy at step {}", p.step))?;
            bar.inc(1);
            Ok((p.step, report.mean_return))
        })
        .collect();
    bar.finish_and_clear();
    returns
}

fn snapshot(args: SnapshotArgs) -> anyhow::Result<()> {
    let kept = snapshot_online_run(&args.run, &args.out, args.band, args.replay_until)
        .with_context(|| format!("snapshotting the run in {}", args.run.display()))?;
    let replay = kept.replay_until.map_or(String::new(), |to| {
        format!(", the transitions up to step {to}")
    });
    println!(
        "step {}: the checkpoint and {} policies (steps {:?}){replay} -> {}",
        kept.step,
        kept.policies.len(),
        kept.policies,
        args.out.display()
    );
    Ok(())
}

/// metrics.csv and the return curve, rewritten from the whole history.
fn write_metrics(out: &Path, history: &[OnlineRecord]) -> anyhow::Result<()> {
    let csv = online_metrics().csv(history);
    let path = out.join("metrics.csv");
    write_text(&path, &csv)?;
    let series = |name, f: fn(&OnlineRecord) -> f64| Series {
        name,
        points: history.iter().map(|r| (r.step as f64, f(r))).collect(),
    };
    line_chart(
        &out.join("returns.svg"),
        "Online SAC: return",
        "environment step",
        "return",
        &[
            series("evaluation (deterministic)", |r| r.eval.mean_return),
            series("training episodes", |r| r.train_return),
        ],
    )
}

/// metrics.csv's columns (CleanRL's names): one row per evaluation.
fn online_metrics() -> MetricsTable<'static, OnlineRecord> {
    let table = MetricsTable::new()
        .column("step", |r: &OnlineRecord| r.step.into())
        .column("updates", |r: &OnlineRecord| r.updates.into())
        .column("episodes", |r: &OnlineRecord| r.episodes.into())
        .column("charts/episodic_return", |r: &OnlineRecord| {
            r.train_return.into()
        })
        .column("eval/mean_return", |r: &OnlineRecord| {
            r.eval.mean_return.into()
        })
        .column("eval/std_return", |r: &OnlineRecord| {
            r.eval.std_return.into()
        })
        .column("eval/normalized_score", |r: &OnlineRecord| {
            r.eval.normalized_score.into()
        });
    with_sac_losses(table, |r: &OnlineRecord| &r.losses)
        .column("charts/env_steps_per_second", |r: &OnlineRecord| {
            Metric::fixed(r.env_steps_per_second, 1)
        })
        .column("charts/updates_per_second", |r: &OnlineRecord| {
            Metric::fixed(r.updates_per_second, 2)
        })
        .column("time/environment", |r: &OnlineRecord| {
            Metric::fixed(r.seconds.environment, 3)
        })
        .column("time/updates", |r: &OnlineRecord| {
            Metric::fixed(r.seconds.updates, 3)
        })
        .column("time/evaluation", |r: &OnlineRecord| {
            Metric::fixed(r.seconds.evaluation, 3)
        })
}
