//! `nuno-trainer experiment`: run a grid of datasets × methods × seeds
//! (`run`, locally over a bounded pool of processes or as one Slurm job
//! array), see where it stands (`status`) and aggregate it (`report`). Each
//! cell is `fit-model`, then `fit-policy --resume`, then its `result.json`: a
//! finished cell is never rerun and a killed one resumes at its last epoch.

use std::collections::{BTreeMap, BTreeSet};
use std::fs::OpenOptions;
use std::path::{Path, PathBuf};
use std::process::{Child, Command as Process, Stdio};
use std::time::Instant;

use anyhow::Context;
use clap::{Subcommand, ValueEnum};
use nuno::agent::Method;
use nuno::data::read_dataset;
use nuno::envs::{ObservationLayout, TaskConfig};
use nuno::experiment::{
    Budget, Cell, CellResult, CellSelection, CellStatus, Grid, cell_dir, cell_status,
    markdown_table, policy_time_left, results_csv, summarize, summarize_run, write_result,
};

use crate::output::write_text;
use crate::plot::{Series, line_chart};

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run every unfinished cell of a grid (or of the cells `--dataset`, `--method`, `--seed` pick).
    Run(RunArgs),
    /// Run one cell (what each local worker and each Slurm array task runs).
    #[command(hide = true)]
    RunCell(CellArgs),
    /// Print each cell's state: done (with scores), training (epochs), pending.
    Status(StatusArgs),
    /// Aggregate the finished cells: results.csv, results.md, a learning-curve plot per dataset.
    Report(GridArgs),
}

#[derive(Debug, Clone, clap::Args)]
pub struct GridArgs {
    /// The grid file (TOML).
    #[arg(long)]
    grid: PathBuf,
    /// The experiment's folder: one folder per cell, the report.
    #[arg(long)]
    out: PathBuf,
}

/// Picks some of the grid's cells; each flag repeats, and a cell is picked
/// when it matches every flag given.
#[derive(Debug, Clone, clap::Args)]
pub struct SelectArgs {
    /// Only this dataset's cells (the grid's `name`).
    #[arg(long = "dataset")]
    datasets: Vec<String>,
    /// Only this method's cells.
    #[arg(long = "method")]
    methods: Vec<Method>,
    /// Only this seed's cells.
    #[arg(long = "seed")]
    seeds: Vec<u64>,
}

impl SelectArgs {
    fn select(&self, cells: &[Cell]) -> anyhow::Result<Vec<Cell>> {
        let selection = CellSelection {
            datasets: self.datasets.clone(),
            methods: self.methods.clone(),
            seeds: self.seeds.clone(),
        };
        Ok(selection.select(cells)?)
    }
}

#[derive(Debug, clap::Args)]
pub struct StatusArgs {
    #[command(flatten)]
    grid: GridArgs,
    #[command(flatten)]
    select: SelectArgs,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Executor {
    /// Cells as child processes on this machine, `--jobs` at a time.
    Local,
    /// One `sbatch --array` job whose task index selects the cell.
    Slurm,
}

#[derive(Debug, clap::Args)]
pub struct RunArgs {
    #[command(flatten)]
    grid: GridArgs,
    #[command(flatten)]
    select: SelectArgs,
    #[arg(long, value_enum, default_value = "local")]
    executor: Executor,
    /// Cells at once with `--executor local`.
    #[arg(long, default_value_t = 1)]
    jobs: usize,
    /// Passed to sbatch as is, e.g. `--slurm-arg=--partition=cpu --slurm-arg=--time=4:00:00`.
    #[arg(long, allow_hyphen_values = true)]
    slurm_arg: Vec<String>,
}

#[derive(Debug, clap::Args)]
pub struct CellArgs {
    #[command(flatten)]
    grid: GridArgs,
    /// The cell's index in the grid's order.
    #[arg(long)]
    cell: usize,
}

pub fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Run(args) => run_grid(args),
        Command::RunCell(args) => run_cell(args),
        Command::Status(args) => status(args),
        Command::Report(args) => report(args),
    }
}

/// The selected cells of the grid, every name checked, and each of their
/// datasets read once and checked against its task.
fn checked_cells(grid: &Path, select: &SelectArgs) -> anyhow::Result<(Grid, Vec<Cell>)> {
    let (parsed, cells) = Grid::read(grid)?;
    let cells = select.select(&cells)?;
    let mut seen = BTreeSet::new();
    for cell in &cells {
        if seen.insert(cell.dataset.clone()) {
            anyhow::ensure!(
                cell.file.exists(),
                "{}: dataset `{}`: {} does not exist",
                grid.display(),
                cell.dataset,
                cell.file.display()
            );
            let task = task_config(cell);
            read_dataset(&cell.file, None)
                .and_then(|d| d.check_task(&task, &cell.file))
                .with_context(|| {
                    format!("dataset `{}` does not fit {}", cell.dataset, cell.task)
                })?;
        }
    }
    Ok((parsed, cells))
}

fn task_config(cell: &Cell) -> TaskConfig {
    match cell.layout {
        ObservationLayout::D4rl => TaskConfig::d4rl(cell.task),
        ObservationLayout::Neorl => TaskConfig::neorl(cell.task),
    }
}

fn run_grid(args: RunArgs) -> anyhow::Result<()> {
    anyhow::ensure!(args.jobs > 0, "--jobs must be at least 1");
    let (grid, cells) = checked_cells(&args.grid.grid, &args.select)?;
    let mut pending = Vec::new();
    for cell in &cells {
        if !matches!(
            cell_status(&args.grid.out, cell, &grid.budget)?,
            CellStatus::Done(_)
        ) {
            pending.push(cell.clone());
        }
    }
    println!(
        "{} cells, {} finished, {} to run",
        cells.len(),
        cells.len() - pending.len(),
        pending.len()
    );
    if pending.is_empty() {
        return Ok(());
    }
    match args.executor {
        Executor::Local => run_local(&args.grid, &pending, args.jobs),
        Executor::Slurm => submit_slurm(&args.grid, &pending, &args.slurm_arg),
    }
}

/// How often the local pool looks for a finished cell.
const CELL_POLL: std::time::Duration = std::time::Duration::from_millis(200);

/// Runs the cells as child processes, at most `jobs` at a time.
fn run_local(grid: &GridArgs, cells: &[Cell], jobs: usize) -> anyhow::Result<()> {
    let exe = std::env::current_exe().context("locating nuno-trainer")?;
    let mut queue = cells.iter();
    let mut running: Vec<(Cell, Child, Instant)> = Vec::new();
    let mut failed = Vec::new();
    loop {
        while running.len() < jobs {
            let Some(cell) = queue.next() else { break };
            let dir = cell_dir(&grid.out, cell);
            std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
            let log = OpenOptions::new()
                .create(true)
                .append(true)
                .open(dir.join("log.txt"))?;
            let child = Process::new(&exe)
                .args(["experiment", "run-cell", "--cell", &cell.index.to_string()])
                .arg("--grid")
                .arg(&grid.grid)
                .arg("--out")
                .arg(&grid.out)
                .stdout(Stdio::from(log.try_clone()?))
                .stderr(Stdio::from(log))
                .spawn()
                .context("starting a cell")?;
            println!("started {}", cell.id());
            running.push((cell.clone(), child, Instant::now()));
        }
        if running.is_empty() {
            break;
        }
        // Whichever cell ends first frees its slot for the next.
        let (cell, status, started) = loop {
            let mut ended = None;
            for (i, (_, child, _)) in running.iter_mut().enumerate() {
                if let Some(status) = child.try_wait()? {
                    ended = Some((i, status));
                    break;
                }
            }
            match ended {
                Some((i, status)) => {
                    let (cell, _, started) = running.remove(i);
                    break (cell, status, started);
                }
                None => std::thread::sleep(CELL_POLL),
            }
        };
        if status.success() {
            println!(
                "finished {} in {:.1} min",
                cell.id(),
                started.elapsed().as_secs_f64() / 60.0
            );
        } else {
            println!(
                "FAILED {} ({status}); see {}/log.txt",
                cell.id(),
                cell_dir(&grid.out, &cell).display()
            );
            failed.push(cell.id());
        }
    }
    anyhow::ensure!(
        failed.is_empty(),
        "{} cells failed: {}",
        failed.len(),
        failed.join(", ")
    );
    Ok(())
}

/// Writes one array job over `cells` and submits it with sbatch.
fn submit_slurm(grid: &GridArgs, cells: &[Cell], extra: &[String]) -> anyhow::Result<()> {
    let sbatch =
        which("sbatch").context("--executor slurm needs `sbatch` on PATH (Slurm's client)")?;
    let exe = std::env::current_exe().context("locating nuno-trainer")?;
    let absolute =
        |p: &Path| std::path::absolute(p).with_context(|| format!("resolving {}", p.display()));
    let (grid_file, out) = (absolute(&grid.grid)?, absolute(&grid.out)?);
    let slurm = out.join("slurm");
    std::fs::create_dir_all(&slurm)?;
    let indices: Vec<String> = cells.iter().map(|c| c.index.to_string()).collect();
    let script = format!(
        "#!/bin/sh\n#SBATCH --job-name=nuno-experiment\n#SBATCH --array={}\n#SBATCH --output={}/%A_%a.log\n\
         exec {} experiment run-cell --grid {} --out {} --cell \"$SLURM_ARRAY_TASK_ID\"\n",
        indices.join(","),
        slurm.display(),
        shell_quote(&exe),
        shell_quote(&grid_file),
        shell_quote(&out)
    );
    let path = slurm.join("cells.sh");
    write_text(&path, &script)?;
    let output = Process::new(sbatch)
        .arg("--parsable")
        .args(extra)
        .arg(&path)
        .output()
        .context("running sbatch")?;
    anyhow::ensure!(
        output.status.success(),
        "sbatch refused the job: {}",
        String::from_utf8_lossy(&output.stderr).trim()
    );
    let job = String::from_utf8_lossy(&output.stdout).trim().to_string();
    println!(
        "submitted Slurm job {job}: {} cells ({})",
        cells.len(),
        path.display()
    );
    Ok(())
}

fn which(tool: &str) -> Option<PathBuf> {
    std::env::var_os("PATH")?
        .to_str()?
        .split(':')
        .map(|dir| Path::new(dir).join(tool))
        .find(|p| p.is_file())
}

fn shell_quote(path: &Path) -> String {
    format!("'{}'", path.display().to_string().replace('\'', r"'\''"))
}

fn run_cell(args: CellArgs) -> anyhow::Result<()> {
    let (grid, cells) = Grid::read(&args.grid.grid)?;
    let cell = cells.get(args.cell).with_context(|| {
        format!(
            "the grid has {} cells, there is no cell {}",
            cells.len(),
            args.cell
        )
    })?;
    let root = &args.grid.out;
    if let CellStatus::Done(_) = cell_status(root, cell, &grid.budget)? {
        println!("{} is finished", cell.id());
        return Ok(());
    }
    let dir = cell_dir(root, cell);
    let (model, policy) = (root.join(cell.model_id()), dir.join("policy"));
    let b = &grid.budget;
    let exe = std::env::current_exe().context("locating nuno-trainer")?;
    let trainer = |args: Vec<String>| -> anyhow::Result<()> {
        let status = Process::new(&exe)
            .args(&args)
            .status()
            .context("running nuno-trainer")?;
        anyhow::ensure!(
            status.success(),
            "nuno-trainer {} failed ({status})",
            args[0]
        );
        Ok(())
    };
    let path = |p: &Path| p.display().to_string();
    // Each fit writes its JSON last: without it the fit did not finish.
    let (subcommand, finished) = if cell.method.uses_ensemble() {
        ("fit-ensemble", "ensemble.json")
    } else {
        ("fit-model", "model.json")
    };
    // Cells sharing the model fit it once: the first to hold the lock fits,
    // the others wait on it and find the model there. The operating system
    // drops the lock of a killed cell, whose successor continues the fit
    // from its last checkpoint.
    std::fs::create_dir_all(&model).with_context(|| format!("creating {}", model.display()))?;
    let lock_path = model.with_extension("lock");
    let lock = std::fs::File::create(&lock_path)
        .with_context(|| format!("creating {}", lock_path.display()))?;
    lock.lock()
        .with_context(|| format!("locking {}", lock_path.display()))?;
    if !model.join(finished).is_file() {
        let mut fit: Vec<String> = vec![
            subcommand.into(),
            "--dataset".into(),
            path(&cell.file),
            "--task".into(),
            cell.task.to_string(),
            "--out".into(),
            path(&model),
            "--seed".into(),
            cell.seed.to_string(),
        ];
        if cell.layout == ObservationLayout::Neorl {
            fit.push("--neorl".into());
        }
        // A killed fit continues from its last checkpoint.
        fit.push("--resume".into());
        fit.extend(model_fit_options(b, cell.method));
        trainer(fit)?;
    }
    drop(lock);
    let hidden: Vec<String> = b.hidden.iter().map(usize::to_string).collect();
    let mut fit_policy = vec![
        "fit-policy".into(),
        "--model".into(),
        path(&model),
        "--dataset".into(),
        path(&cell.file),
        "--preset".into(),
        cell.preset.clone(),
        "--steps".into(),
        b.policy_steps.to_string(),
        "--steps-per-epoch".into(),
        b.steps_per_epoch.to_string(),
        "--eval-episodes".into(),
        b.eval_episodes.to_string(),
        "--hidden".into(),
        hidden.join(","),
        "--seed".into(),
        cell.seed.to_string(),
        "--out".into(),
        path(&policy),
        "--policies".into(),
        path(&dir),
        "--algo".into(),
        cell.method.as_str().into(),
        "--resume".into(),
    ];
    fit_policy.extend(policy_options(b, cell.method));
    trainer(fit_policy)?;
    let result = summarize_run(cell, &grid.budget, &policy.join("metrics.jsonl"))?;
    write_result(root, &result)?;
    println!(
        "{}: best normalised score {:.1} at step {}, final {:.1}",
        cell.id(),
        result.best_score,
        result.best_step,
        result.final_score
    );
    Ok(())
}

/// `flag value` when the budget gives a value, nothing otherwise.
fn option(flag: &str, value: Option<impl ToString>) -> Vec<String> {
    value.map_or_else(Vec::new, |v| vec![flag.to_string(), v.to_string()])
}

/// The budget's options of `method`'s model fit (fit-model or fit-ensemble).
fn model_fit_options(b: &Budget, method: Method) -> Vec<String> {
    if method.uses_ensemble() {
        return option("--max-epochs", b.ensemble_max_epochs);
    }
    let mut options = [
        option("--max-steps", Some(b.model_steps)),
        option("--likelihood", Some(b.model_likelihood)),
        option("--recipe", Some(b.recipe)),
        option("--sample-noise", b.model_sample_noise),
        option("--step-discount", b.model_step_discount),
        option("--eta-losses", b.model_eta_losses),
        option("--threshold-max-margin", b.threshold_max_margin),
        option("--drift-inputs", b.model_drift_inputs),
    ]
    .concat();
    if method == Method::NunoR {
        options.push("--reward-model".into());
    }
    options
}

/// The budget's optional fit-policy options for `method`: the recipe and the
/// reward's velocity are NUNO's loop (an ensemble learns its rewards), the
/// MOPO settings MOPO's.
fn policy_options(b: &Budget, method: Method) -> Vec<String> {
    let shared = [
        option("--rollout-batch", b.rollout_batch),
        option("--model-buffer-factor", b.model_buffer_factor),
    ];
    let own = if method.uses_ensemble() {
        [option("--mopo-settings", b.mopo_settings), Vec::new()]
    } else {
        [
            option("--recipe", Some(b.recipe)),
            option("--forward-velocity", b.forward_velocity),
        ]
    };
    [shared, own].concat().concat()
}

fn status(args: StatusArgs) -> anyhow::Result<()> {
    let StatusArgs { grid: args, select } = args;
    let (grid, cells) = Grid::read(&args.grid)?;
    let cells = select.select(&cells)?;
    let mut statuses = Vec::new();
    for cell in &cells {
        let status = cell_status(&args.out, cell, &grid.budget)?;
        let state = match &status {
            CellStatus::Done(r) => format!(
                "done: best {:.1}, final {:.1} ({} steps)",
                r.best_score, r.final_score, r.steps
            ),
            CellStatus::Partial { epochs } => format!("training: {epochs} epochs checkpointed"),
            CellStatus::Pending => "pending".into(),
        };
        println!("{:>4} {:<40} {state}", cell.index, cell.id());
        statuses.push(status);
    }
    let done = statuses
        .iter()
        .filter(|s| matches!(s, CellStatus::Done(_)))
        .count();
    let b = &grid.budget;
    let epochs_per_cell = b.policy_steps.div_ceil(b.steps_per_epoch);
    match policy_time_left(&statuses, epochs_per_cell) {
        Some(left) if done < cells.len() => println!(
            "{done}/{} cells done; about {:.1} h of policy training left at the finished cells' pace (model fits not included)",
            cells.len(),
            left / 3600.0
        ),
        _ => println!("{done}/{} cells done", cells.len()),
    }
    Ok(())
}

fn report(args: GridArgs) -> anyhow::Result<()> {
    let (grid, cells) = Grid::read(&args.grid)?;
    let mut results: Vec<CellResult> = Vec::new();
    for cell in &cells {
        if let CellStatus::Done(r) = cell_status(&args.out, cell, &grid.budget)? {
            results.push(*r);
        }
    }
    anyhow::ensure!(
        !results.is_empty(),
        "no cell of {} has finished",
        args.grid.display()
    );
    let order: Vec<&str> = grid.datasets.iter().map(|d| d.name.as_str()).collect();
    let summaries = summarize(&results, &order);
    let timed: Vec<f64> = results.iter().filter_map(|r| r.policy_seconds).collect();
    // Results written before policy time was recorded have none to add.
    let time = if timed.is_empty() {
        String::new()
    } else {
        format!(
            "; {:.2} h of policy training over {} cells (model fits not counted)",
            timed.iter().sum::<f64>() / 3600.0,
            timed.len()
        )
    };
    let table = format!(
        "# {}\n\n{} of {} cells finished{time}.\n\n{}",
        args.grid.display(),
        results.len(),
        cells.len(),
        markdown_table(&summaries)
    );
    for (name, text) in [
        ("results.csv", results_csv(&results)),
        ("results.md", table.clone()),
    ] {
        let path = args.out.join(name);
        write_text(&path, &text)?;
    }
    learning_curves(&args.out, &results)?;
    print!("{table}");
    Ok(())
}

/// One SVG per dataset: each method's normalised score by step, the mean over its seeds.
fn learning_curves(out: &Path, results: &[CellResult]) -> anyhow::Result<()> {
    let mut by_dataset: BTreeMap<&str, BTreeMap<Method, Vec<&CellResult>>> = BTreeMap::new();
    for r in results {
        by_dataset
            .entry(&r.cell.dataset)
            .or_default()
            .entry(r.cell.method)
            .or_default()
            .push(r);
    }
    for (dataset, methods) in by_dataset {
        let series: Vec<(String, Vec<(f64, f64)>)> = methods
            .iter()
            .map(|(method, runs)| {
                let mut steps: BTreeMap<usize, Vec<f64>> = BTreeMap::new();
                for run in runs {
                    for &(step, score) in &run.curve {
                        steps.entry(step).or_default().push(score);
                    }
                }
                let points = steps
                    .into_iter()
                    .map(|(s, v)| (s as f64, v.iter().sum::<f64>() / v.len() as f64))
                    .collect();
                (format!("{method} ({} seeds)", runs.len()), points)
            })
            .collect();
        let series: Vec<Series> = series
            .iter()
            .map(|(name, points)| Series {
                name,
                points: points.clone(),
            })
            .collect();
        line_chart(
            &out.join(format!("curves-{dataset}.svg")),
            &format!("{dataset}: normalised score, mean over seeds"),
            "gradient step",
            "normalised score",
            &series,
        )?;
    }
    Ok(())
}
