//! `nuno-trainer dataset`: generate datasets in D4RL's layout, and inspect any
//! dataset nuno reads.

use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::Context;
use clap::{Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use nuno::agent::RandomNetworkPolicy;
use nuno::data::{DatasetFormat, GenerateConfig, generate, read_dataset, write_d4rl};
use nuno::envs::{MujocoTask, TaskConfig, TaskName};

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run a behaviour policy in the real task and write a D4RL-layout HDF5 file.
    Generate(GenerateArgs),
    /// Print a dataset's size, trajectories, returns and metadata.
    Info(InfoArgs),
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum Kind {
    /// D4RL's recipe: a randomly initialised tanh-Gaussian actor, actions sampled.
    Random,
}

#[derive(Debug, clap::Args)]
pub struct GenerateArgs {
    #[arg(long)]
    task: TaskName,
    #[arg(long, value_enum)]
    kind: Kind,
    /// Transitions to record.
    #[arg(long, default_value_t = 1_000_000)]
    transitions: usize,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// NeoRL's observation layout (root x included).
    #[arg(long)]
    neorl: bool,
    /// Output HDF5 file (written atomically).
    #[arg(long)]
    out: PathBuf,
}

#[derive(Debug, clap::Args)]
pub struct InfoArgs {
    /// Dataset file (D4RL .hdf5, NeoRL .npz) or Minari dataset directory.
    #[arg(long)]
    file: PathBuf,
    /// Reader to use (default: detected from the file).
    #[arg(long)]
    format: Option<DatasetFormat>,
    /// Check widths against this task.
    #[arg(long)]
    task: Option<TaskName>,
    /// With --task: NeoRL's observation layout.
    #[arg(long)]
    neorl: bool,
}

pub fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Generate(args) => generate_cmd(args),
        Command::Info(args) => info(args),
    }
}

fn task_config(task: TaskName, neorl: bool) -> TaskConfig {
    if neorl {
        TaskConfig::neorl(task)
    } else {
        TaskConfig::d4rl(task)
    }
}

fn generate_cmd(args: GenerateArgs) -> anyhow::Result<()> {
    anyhow::ensure!(args.transitions > 0, "--transitions must be at least 1");
    let task = task_config(args.task, args.neorl);
    let probe = MujocoTask::new(task)?;
    let (policy, kind) = match args.kind {
        Kind::Random => (
            RandomNetworkPolicy::new(probe.obs_dim(), probe.act_dim(), &[256, 256], args.seed),
            "random",
        ),
    };
    let config = GenerateConfig::new(task, kind, args.transitions, args.seed);
    let bar = ProgressBar::new(args.transitions as u64).with_style(ProgressStyle::with_template(
        "{bar:40} {pos}/{len} transitions, {per_sec}, eta {eta}",
    )?);
    let done = AtomicUsize::new(0);
    let progress = |steps: usize| {
        let total = done.fetch_add(steps, Ordering::Relaxed) + steps;
        bar.set_position(total.min(args.transitions) as u64);
    };
    let dataset = generate(&config, &policy, &policy.description(), &progress)?;
    bar.finish();
    write_d4rl(&dataset, &args.out).with_context(|| format!("writing {}", args.out.display()))?;
    println!(
        "wrote {} transitions in {} trajectories to {}",
        dataset.len(),
        dataset.trajectories().len(),
        args.out.display()
    );
    Ok(())
}

fn info(args: InfoArgs) -> anyhow::Result<()> {
    let dataset = read_dataset(&args.file, args.format)?;
    if let Some(task) = args.task {
        dataset.check_task(&task_config(task, args.neorl), &args.file)?;
    }
    let returns: Vec<f64> = dataset
        .trajectories()
        .iter()
        .map(|t| {
            (t.start..t.end)
                .map(|i| f64::from(dataset.rewards[i]))
                .sum()
        })
        .collect();
    let mean = returns.iter().sum::<f64>() / returns.len() as f64;
    let terminals = dataset.terminals.iter().filter(|&&t| t).count();
    println!("file:          {}", args.file.display());
    println!("transitions:   {}", dataset.len());
    println!("trajectories:  {} ({terminals} terminal)", returns.len());
    println!("state width:   {}", dataset.obs_dim());
    println!("action width:  {}", dataset.act_dim());
    println!("mean return:   {mean:.2}");
    println!(
        "mujoco state:  {}",
        if dataset.qpos.is_some() { "yes" } else { "no" }
    );
    for (key, value) in &dataset.metadata {
        println!("metadata/{key}: {value}");
    }
    Ok(())
}
