//! `nuno-trainer dataset`: generate datasets in D4RL's layout, and inspect any
//! dataset nuno reads.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::Context;
use clap::{Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use nuno::agent::{ActionMode, ActorPolicy, OnlineSacConfig, PortableActor};
use nuno::artifact::{
    Behaviour, OnlineRunInfo, RunPolicy, load_behaviour, read_online_run, read_run_transitions,
    run_policies,
};
use nuno::data::{
    BehaviourLevel, Budget, Dataset, DatasetFormat, DatasetMetadata, GenerateConfig, generate,
    generator, read_dataset, write_d4rl, write_neorl,
};
use nuno::envs::{MujocoTask, System, TaskConfig, TaskName};
use nuno::sde::ComputeDevice;
use nuno::shared::BatchPolicy;

use crate::data_source::{simulation_of, system_of, task_config};

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run a behaviour policy in the real task and write a D4RL-layout HDF5 file.
    Generate(GenerateArgs),
    /// Print a dataset's size, trajectories, returns and metadata.
    Info(InfoArgs),
    /// Check a dataset against a system file: sizes, column ranges, the
    /// action box, and that each declared pair's d position/dt = velocity holds.
    Check(crate::dataset_check::CheckArgs),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Kind {
    /// D4RL: a randomly initialised tanh-Gaussian actor, actions sampled.
    Random,
    /// D4RL: the early-stopped SAC policy (~1/3 of the expert's return);
    /// NeoRL (`--layout neorl`): the policy at ~50 %.
    Medium,
    /// D4RL: the online run's transitions up to the medium policy's checkpoint.
    MediumReplay,
    /// D4RL: the converged SAC policy.
    Expert,
    /// D4RL: medium then expert, concatenated.
    MediumExpert,
    /// NeoRL: the policy at ~25 % of the expert's return.
    Low,
    /// NeoRL: the policy at ~75 % of the expert's return.
    High,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Layout {
    /// D4RL's HDF5 layout and observations (root x excluded).
    D4rl,
    /// NeoRL's observations (root x included), written as NeoRL's `.npz`
    /// and in D4RL's layout beside it.
    Neorl,
}

#[derive(Debug, clap::Args)]
pub struct GenerateArgs {
    #[arg(long, required_unless_present = "system", conflicts_with = "system")]
    task: Option<TaskName>,
    /// A system file with a `[mujoco]` table, in place of --task (`--kind random` only:
    /// the other recipes' behaviour policies are the built-in tasks').
    #[arg(long)]
    system: Option<PathBuf>,
    #[arg(long, value_enum)]
    kind: Kind,
    #[arg(long, value_enum, default_value = "d4rl")]
    layout: Layout,
    /// Transitions to record per policy (D4RL kinds; medium-expert records
    /// this many of each).
    #[arg(long, default_value_t = 1_000_000)]
    transitions: usize,
    /// Whole trajectories to record (NeoRL kinds).
    #[arg(long, default_value_t = 1000)]
    trajectories: usize,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Behaviour policies, `<dir>/<task>/<level>.safetensors` (from `collect select`).
    #[arg(long, default_value = "models/behaviour")]
    behaviour: PathBuf,
    /// medium-replay: the online run (`collect online-sac --out`) the medium policy came from.
    #[arg(long)]
    run: Option<PathBuf>,
    /// medium-replay: accept a `--run` with the medium policy's configuration
    /// whose policy at the medium step is not the medium policy (a re-run on
    /// another kind of CPU, say), and cut it at the same step; the dataset then
    /// records that run's own policy and evaluation there.
    #[arg(long)]
    accept_rerun: bool,
    /// Output file, written atomically: D4RL's `.hdf5`; with `--layout neorl`
    /// NeoRL's `.npz`, with the `.hdf5` of the same stem beside it.
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
        Command::Check(args) => crate::dataset_check::check(args),
    }
}

/// A kind as its flag spells it.
fn name(kind: Kind) -> String {
    kind.to_possible_value()
        .map_or_else(|| format!("{kind:?}"), |v| v.get_name().to_string())
}

/// The behaviour level a recipe runs, checked against the layout.
fn level(kind: Kind, layout: Layout) -> anyhow::Result<Option<BehaviourLevel>> {
    use {BehaviourLevel as L, Kind as K, Layout as Y};
    Ok(match (kind, layout) {
        (K::Random, _) => None,
        (K::Medium | K::MediumReplay, Y::D4rl) => Some(L::Medium),
        (K::Expert, Y::D4rl) => Some(L::Expert),
        (K::MediumExpert, Y::D4rl) => None,
        (K::Low, Y::Neorl) => Some(L::NeorlLow),
        (K::Medium, Y::Neorl) => Some(L::NeorlMedium),
        (K::High, Y::Neorl) => Some(L::NeorlHigh),
        (K::Low | K::High, Y::D4rl) => {
            anyhow::bail!("--kind {} is a NeoRL level: add --layout neorl", name(kind))
        }
        (K::MediumReplay | K::Expert | K::MediumExpert, Y::Neorl) => {
            anyhow::bail!(
                "--kind {} is a D4RL recipe; NeoRL's are low, medium and high",
                name(kind)
            )
        }
    })
}

/// Refuses flags that do not fit together, before anything is loaded.
fn check_generate(args: &GenerateArgs) -> anyhow::Result<()> {
    anyhow::ensure!(args.transitions > 0, "--transitions must be at least 1");
    anyhow::ensure!(args.trajectories > 0, "--trajectories must be at least 1");
    anyhow::ensure!(
        args.kind == Kind::MediumReplay || (args.run.is_none() && !args.accept_rerun),
        "--run and --accept-rerun are for --kind medium-replay only"
    );
    let neorl = args.layout == Layout::Neorl;
    anyhow::ensure!(
        args.system.is_none() || (args.kind == Kind::Random && !neorl),
        "--system generates --kind random in its own layout (the other recipes' behaviour policies are the built-in tasks')"
    );
    let extension = args.out.extension().and_then(|e| e.to_str());
    let wanted = if neorl { "npz" } else { "hdf5" };
    anyhow::ensure!(
        extension == Some(wanted),
        "--out must end in .{wanted} for --layout {:?}, got {}",
        args.layout,
        args.out.display()
    );
    Ok(())
}

fn generate_cmd(args: GenerateArgs) -> anyhow::Result<()> {
    check_generate(&args)?;
    let neorl = args.layout == Layout::Neorl;
    let task = simulation_of(&system_of(args.task, args.system.as_deref(), neorl)?)?;
    // Everything the recipe needs is loaded and checked before any episode runs.
    let level = level(args.kind, args.layout)?;
    let device = ComputeDevice::Cpu.device().map_err(anyhow::Error::msg)?;
    // A system file generates only random data (checked above): its behaviour never loads.
    let built_in = || {
        task.task
            .built_in()
            .context("behaviour policies are the built-in tasks'")
    };
    let load = |level| {
        load_behaviour(&args.behaviour, built_in()?, level, &device)
            .with_context(|| format!("loading the {level} behaviour policy"))
    };
    let dataset = match (args.kind, level) {
        (Kind::Random, _) => {
            let probe = MujocoTask::new(&task)?;
            let policy = PortableActor::rlkit_random(
                probe.obs_dim(),
                probe.act_dim(),
                &[256, 256],
                args.seed,
            );
            let config = GenerateConfig::new(task, "random", args.transitions, args.seed);
            record(
                &config,
                &policy,
                &policy.rlkit_description(),
                &DatasetMetadata::new(),
            )?
        }
        (Kind::MediumReplay, _) => {
            let behaviour = load(BehaviourLevel::Medium)?;
            let Some(run) = args.run.as_ref() else {
                anyhow::bail!(
                    "--kind medium-replay needs --run, the online run the medium policy came from{}",
                    rerun_hint(built_in()?, &behaviour)
                );
            };
            medium_replay(run, &behaviour, args.accept_rerun)?
        }
        (Kind::MediumExpert, _) => {
            let (medium, expert) = (load(BehaviourLevel::Medium)?, load(BehaviourLevel::Expert)?);
            medium_expert(task, &args, &medium, &expert)?
        }
        (_, Some(level)) => {
            let behaviour = load(level)?;
            let kind = name(args.kind);
            let kind = if neorl { format!("neorl-{kind}") } else { kind };
            from_behaviour(&task, &kind, &args, &behaviour)?
        }
        (_, None) => unreachable!("every other kind has a level"),
    };
    write_dataset(&dataset, &args.out, neorl)
}

/// D4RL's medium-expert: the medium dataset, then the expert one, on the
/// same seed, each part's behaviour recorded under its name.
fn medium_expert(
    task: TaskConfig,
    args: &GenerateArgs,
    medium: &Behaviour,
    expert: &Behaviour,
) -> anyhow::Result<Dataset> {
    let parts = [
        from_behaviour(&task, "medium", args, medium)?,
        from_behaviour(&task, "expert", args, expert)?,
    ];
    let mut metadata = parts[0].metadata.clone();
    metadata.retain(|k, _| !k.starts_with("behaviour"));
    metadata.insert("kind".into(), "medium-expert".into());
    metadata.insert(
        "policy".into(),
        format!(
            "the medium policy (step {}), then the expert policy (step {}); actions sampled",
            medium.entry.pick.step, expert.entry.pick.step
        ),
    );
    metadata.insert(
        "recipe".into(),
        "D4RL medium-expert: the medium dataset, then the expert dataset, same seed".into(),
    );
    for (part, prefix) in parts.iter().zip(["medium", "expert"]) {
        for (k, v) in part
            .metadata
            .iter()
            .filter(|(k, _)| k.starts_with("behaviour"))
        {
            metadata.insert(k.replacen("behaviour", prefix, 1), v.clone());
        }
    }
    Ok(Dataset::concat(&[&parts[0], &parts[1]], metadata)?)
}

/// Writes `dataset` to `out`: D4RL's HDF5, or NeoRL's `.npz` with the HDF5
/// of the same stem beside it.
fn write_dataset(dataset: &Dataset, out: &Path, neorl: bool) -> anyhow::Result<()> {
    let written = if neorl {
        let hdf5 = out.with_extension("hdf5");
        write_neorl(dataset, out).with_context(|| format!("writing {}", out.display()))?;
        write_d4rl(dataset, &hdf5).with_context(|| format!("writing {}", hdf5.display()))?;
        format!("{} and {}", out.display(), hdf5.display())
    } else {
        write_d4rl(dataset, out).with_context(|| format!("writing {}", out.display()))?;
        out.display().to_string()
    };
    println!(
        "wrote {} transitions in {} trajectories to {written}",
        dataset.len(),
        dataset.trajectories().len(),
    );
    Ok(())
}

/// Runs `behaviour`'s policy (actions sampled) in `task` for the recipe's budget.
fn from_behaviour(
    task: &TaskConfig,
    kind: &str,
    args: &GenerateArgs,
    behaviour: &Behaviour,
) -> anyhow::Result<Dataset> {
    let mut config = GenerateConfig::new(task.clone(), kind, args.transitions, args.seed);
    if args.layout == Layout::Neorl {
        config.budget = Budget::Episodes(args.trajectories);
    }
    config.policy_layout = behaviour.metadata.simulated_task(&args.behaviour)?.layout;
    // Portable arithmetic: the same recipe gives the same bytes on any CPU.
    let policy = PortableActor::new(&ActorPolicy {
        actor: behaviour.actor.clone(),
        mode: ActionMode::Sampled,
    });
    let p = &behaviour.entry.pick;
    let recipe = match args.layout {
        Layout::D4rl => "D4RL: 1M transitions of an online SAC policy, actions sampled".to_string(),
        Layout::Neorl => format!(
            "NeoRL: {} whole trajectories of an online SAC policy at a fraction of the expert's return, actions sampled",
            args.trajectories
        ),
    };
    let metadata = DatasetMetadata::from([
        ("recipe".into(), recipe),
        (
            "behaviour_policy".into(),
            behaviour.path.display().to_string(),
        ),
        (
            "behaviour_sha256".into(),
            behaviour.metadata.weights_sha256.clone(),
        ),
        ("behaviour_step".into(), p.step.to_string()),
        (
            "behaviour_eval_return".into(),
            format!("{:.3}", p.mean_return),
        ),
        (
            "behaviour_target_return".into(),
            format!("{:.3}", p.target_return),
        ),
        (
            "behaviour_expert_return".into(),
            format!("{:.3}", p.expert_return),
        ),
        ("behaviour_run".into(), behaviour.entry.run.clone()),
        (
            "behaviour_run_seed".into(),
            behaviour
                .metadata
                .provenance
                .online_training
                .as_ref()
                .map_or("unknown".into(), |c| c.seed.to_string()),
        ),
    ]);
    let description = format!(
        "online SAC policy at step {} (tanh-Gaussian, actions sampled)",
        p.step
    );
    record(&config, &policy, &description, &metadata)
}

/// How to re-create the medium policy's run up to its checkpoint (the run is
/// deterministic on the same kind of CPU).
fn rerun_hint(task: TaskName, medium: &Behaviour) -> String {
    let Some(c) = &medium.metadata.provenance.online_training else {
        return String::new();
    };
    let hidden: Vec<String> = c.sac.actor_hidden.iter().map(usize::to_string).collect();
    format!(
        "; to re-create it: nuno-trainer collect online-sac --task {task} --seed {} --steps {} \
         --checkpoint-every {} --start-steps {} --eval-episodes {} --batch-size {} --hidden {} --out runs/{task}-sac",
        c.seed,
        medium.entry.pick.step,
        c.checkpoint_every,
        c.start_steps,
        c.eval_episodes,
        c.sac.batch_size,
        hidden.join(",")
    )
}

/// The medium policy's run, from its start to the medium checkpoint.
fn medium_replay(run: &Path, medium: &Behaviour, accept_rerun: bool) -> anyhow::Result<Dataset> {
    let info =
        read_online_run(run).with_context(|| format!("reading the run in {}", run.display()))?;
    ensure_medium_run(run, &info, medium)?;
    let (saved, reproduced) = medium_checkpoint(run, medium, accept_rerun)?;
    let step = medium.entry.pick.step;
    let dataset = read_run_transitions(run, step)?;
    let metadata = medium_replay_metadata(&dataset, run, &info, medium, &saved, reproduced);
    Ok(dataset.with_metadata(metadata))
}

/// That `run` has the medium policy's task and online configuration (it may
/// have run more steps since).
fn ensure_medium_run(run: &Path, info: &OnlineRunInfo, medium: &Behaviour) -> anyhow::Result<()> {
    let same_run = medium
        .metadata
        .provenance
        .online_training
        .as_ref()
        .is_some_and(|c| {
            OnlineSacConfig {
                steps: info.config.steps,
                ..c.clone()
            } == info.config
        });
    anyhow::ensure!(
        same_run && info.task.is_some() && info.task == medium.metadata.task,
        "{} is not the run the medium policy came from ({})",
        run.display(),
        medium.entry.run
    );
    Ok(())
}

/// The policy `run` saved at the medium step, and whether it is the medium
/// policy itself (refused where it is not, unless `accept_rerun`).
fn medium_checkpoint(
    run: &Path,
    medium: &Behaviour,
    accept_rerun: bool,
) -> anyhow::Result<(RunPolicy, bool)> {
    let step = medium.entry.pick.step;
    // The same configuration is not the same run where the float arithmetic
    // differs (gemm blocks, and so rounds, by the CPU's cache sizes; a kernel
    // may change between revisions): the policy the run saved at the medium
    // step shows whether it is the medium policy's run.
    let saved = run_policies(run)?
        .into_iter()
        .find(|p| p.step == step)
        .with_context(|| {
            format!(
                "{} has no policy at step {step}, the medium policy's checkpoint",
                run.display()
            )
        })?;
    let reproduced = saved.metadata.weights_sha256 == medium.metadata.weights_sha256;
    anyhow::ensure!(
        reproduced || accept_rerun,
        "{}'s policy at step {step} is not the medium policy (weights SHA-256 {} against {}): \
         the run has the medium policy's configuration but did not reproduce it, as happens when \
         it is re-run on another kind of CPU (matrix kernels block, and so round, by cache size) \
         or with a nuno whose arithmetic has changed; --accept-rerun cuts this run at the same \
         step anyway, recording its own policy there (models/behaviour/README.md)",
        run.display(),
        saved.metadata.weights_sha256,
        medium.metadata.weights_sha256
    );
    Ok((saved, reproduced))
}

/// The medium-replay recipe's record: the run, its seed, the medium step and
/// the policy there.
fn medium_replay_metadata(
    dataset: &Dataset,
    run: &Path,
    info: &OnlineRunInfo,
    medium: &Behaviour,
    saved: &RunPolicy,
    reproduced: bool,
) -> DatasetMetadata {
    let step = medium.entry.pick.step;
    let mut metadata = dataset.metadata.clone();
    metadata.insert("kind".into(), "medium-replay".into());
    metadata.insert(
        "recipe".into(),
        "D4RL medium-replay: every transition of the online SAC run up to the medium policy's checkpoint".into(),
    );
    metadata.insert("run".into(), run.display().to_string());
    metadata.insert("run_seed".into(), info.config.seed.to_string());
    metadata.insert("behaviour_step".into(), step.to_string());
    metadata.insert(
        "behaviour_sha256".into(),
        saved.metadata.weights_sha256.clone(),
    );
    metadata.insert("medium_policy_reproduced".into(), reproduced.to_string());
    let eval_return = if reproduced {
        Some(medium.entry.pick.mean_return)
    } else {
        saved.metadata.provenance.mean_return
    };
    if let Some(r) = eval_return {
        metadata.insert("behaviour_eval_return".into(), format!("{r:.3}"));
    }
    metadata.insert("generator".into(), generator());
    metadata
}

/// Generates with a progress bar, adding `extra` to the dataset's metadata.
fn record(
    config: &GenerateConfig,
    policy: &dyn BatchPolicy,
    description: &str,
    extra: &DatasetMetadata,
) -> anyhow::Result<Dataset> {
    let (total, unit) = match config.budget {
        Budget::Transitions(n) => (n, "transitions"),
        Budget::Episodes(n) => (n, "trajectories"),
    };
    let bar = ProgressBar::new(total as u64).with_style(ProgressStyle::with_template(&format!(
        "{{bar:40}} {{pos}}/{{len}} {unit} ({}), {{per_sec}}, eta {{eta}}",
        config.kind
    ))?);
    let done = AtomicUsize::new(0);
    let progress = |steps: usize| {
        let count = match config.budget {
            Budget::Transitions(_) => steps,
            Budget::Episodes(_) => 1,
        };
        let so_far = done.fetch_add(count, Ordering::Relaxed) + count;
        bar.set_position(so_far.min(total) as u64);
    };
    let dataset = generate(config, policy, description, &progress)?;
    bar.finish();
    let mut metadata = dataset.metadata.clone();
    metadata.extend(extra.clone());
    Ok(dataset.with_metadata(metadata))
}

fn info(args: InfoArgs) -> anyhow::Result<()> {
    let dataset = read_dataset(&args.file, args.format)?;
    if let Some(task) = args.task {
        dataset.check_system(&System::Task(task_config(task, args.neorl)), &args.file)?;
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
