//! `nuno-trainer experiment`: run a grid of datasets × methods × seeds
//! (`run`, locally over a bounded pool of processes or as one Slurm job
//! array), see where it stands (`status`) and aggregate it (`report`; `table`
//! lays several experiments out as the paper's Tables 1 and 2). Each
//! cell is `fit-model`, then `fit-policy --resume`, then its `result.json`: a
//! finished cell is never rerun and a killed one resumes at its last epoch.

use std::collections::{BTreeMap, BTreeSet};
use std::fs::OpenOptions;
use std::path::{Path, PathBuf};
use std::process::{Child, Command as Process, ExitStatus, Stdio};
use std::time::Instant;

use anyhow::Context;
use clap::{Subcommand, ValueEnum};
use nuno::agent::Method;
use nuno::data::read_system_dataset;
use nuno::envs::{ObservationLayout, System};
use nuno::experiment::{
    Budget, Cell, CellResult, CellSelection, CellStatus, Grid, MeanCurve, cell_dir, cell_status,
    check_fitted_sde, collect_results, markdown_table, mean_curves, paper_layout_table,
    policy_time_left, results_csv, summarize, summarize_run, write_result,
};

use crate::data_source::{DataSource, system_of};
use crate::output::write_text;
use crate::plot::{Series, line_chart};
use crate::{fit_ensemble, fit_model, fit_policy};

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
    /// The paper's Tables 1 and 2 laid out over the finished cells of any
    /// number of experiment folders (kept results included), the paper's
    /// figure beside each of nuno's.
    Table(TableArgs),
}

#[derive(Debug, clap::Args)]
pub struct TableArgs {
    /// A folder holding finished cells' result.json at any depth (repeat it).
    #[arg(long = "results", required = true)]
    results: Vec<PathBuf>,
    /// Where to write the table (markdown); printed either way.
    #[arg(long)]
    out: Option<PathBuf>,
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
        Command::Table(args) => table(args),
    }
}

fn table(args: TableArgs) -> anyhow::Result<()> {
    let results = collect_results(&args.results)?;
    anyhow::ensure!(
        !results.is_empty(),
        "no result.json under {}",
        args.results
            .iter()
            .map(|d| d.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    let table = paper_layout_table(&results)?;
    if let Some(out) = &args.out {
        write_text(out, &table)?;
    }
    print!("{table}");
    Ok(())
}

/// Each of `cells`' datasets, read once and checked against its task: the
/// cells about to run (a finished cell needs no data, so a fresh machine makes
/// only the files the grid's pending cells read).
fn check_cell_data(grid: &Path, cells: &[Cell]) -> anyhow::Result<()> {
    let mut seen = BTreeSet::new();
    for cell in cells {
        if seen.insert(cell.dataset.clone()) {
            anyhow::ensure!(
                cell.file.exists(),
                "{}: dataset `{}`: {} does not exist",
                grid.display(),
                cell.dataset,
                cell.file.display()
            );
            let system = cell_system(cell)?;
            read_system_dataset(&cell.file, None, &system).with_context(|| {
                format!("dataset `{}` does not fit {}", cell.dataset, system.name())
            })?;
        }
    }
    Ok(())
}

/// The built-in task or the system file (read and checked) the cell's data is of.
fn cell_system(cell: &Cell) -> anyhow::Result<System> {
    system_of(
        cell.task,
        cell.system.as_deref(),
        cell.layout == ObservationLayout::Neorl,
    )
    .with_context(|| format!("dataset `{}`", cell.dataset))
}

fn run_grid(args: RunArgs) -> anyhow::Result<()> {
    anyhow::ensure!(args.jobs > 0, "--jobs must be at least 1");
    let (grid, cells) = Grid::read(&args.grid.grid)?;
    let cells = args.select.select(&cells)?;
    let mut pending = Vec::new();
    for cell in &cells {
        if !matches!(
            cell_status(&args.grid.out, cell, &grid.budget_for(cell))?,
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
    check_cell_data(&args.grid.grid, &pending)?;
    match args.executor {
        Executor::Local => run_local(&args.grid, &pending, args.jobs),
        Executor::Slurm => submit_slurm(&args.grid, &pending, &args.slurm_arg),
    }
}

/// How often the local pool looks for a finished cell.
const CELL_POLL: std::time::Duration = std::time::Duration::from_millis(200);

/// Runs the cells as child processes, at most `jobs` at a time.
fn run_local(grid: &GridArgs, cells: &[Cell], jobs: usize) -> anyhow::Result<()> {
    let exe = crate::run_record::running_binary()?;
    let mut queue = cells.iter();
    let mut running: Vec<(Cell, Child, Instant)> = Vec::new();
    let mut failed = Vec::new();
    loop {
        while running.len() < jobs {
            let Some(cell) = queue.next() else { break };
            let child = spawn_cell(grid, cell, &exe)?;
            println!("started {}", cell.id());
            running.push((cell.clone(), child, Instant::now()));
        }
        if running.is_empty() {
            break;
        }
        let (cell, status, started) = first_to_end(&mut running)?;
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

/// `experiment run-cell` for `cell` in a child process, its output appended
/// to the cell's log.txt.
fn spawn_cell(grid: &GridArgs, cell: &Cell, exe: &Path) -> anyhow::Result<Child> {
    let dir = cell_dir(&grid.out, cell);
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let log = OpenOptions::new()
        .create(true)
        .append(true)
        .open(dir.join("log.txt"))?;
    let mut command = Process::new(exe);
    // The cell's record names the binary as the runner was invoked.
    #[cfg(unix)]
    if let Some(name) = std::env::args_os().next() {
        std::os::unix::process::CommandExt::arg0(&mut command, name);
    }
    command
        .args(["experiment", "run-cell", "--cell", &cell.index.to_string()])
        .arg("--grid")
        .arg(&grid.grid)
        .arg("--out")
        .arg(&grid.out)
        .stdout(Stdio::from(log.try_clone()?))
        .stderr(Stdio::from(log))
        .spawn()
        .context("starting a cell")
}

/// Waits for whichever running cell ends first (freeing its slot for the
/// next) and takes it out of `running`.
fn first_to_end(
    running: &mut Vec<(Cell, Child, Instant)>,
) -> anyhow::Result<(Cell, ExitStatus, Instant)> {
    loop {
        for i in 0..running.len() {
            if let Some(status) = running[i].1.try_wait()? {
                let (cell, _, started) = running.remove(i);
                return Ok((cell, status, started));
            }
        }
        std::thread::sleep(CELL_POLL);
    }
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
    let (root, budget) = (&args.grid.out, &grid.budget_for(cell));
    if let CellStatus::Done(_) = cell_status(root, cell, budget)? {
        println!("{} is finished", cell.id());
        return Ok(());
    }
    let dir = cell_dir(root, cell);
    let policy = dir.join("policy");
    let model = cell.model_id().map(|id| root.join(id));
    if let Some(model) = &model {
        fit_cell_model(cell, budget, model)?;
    }
    fit_policy::train(&policy_args(cell, budget, model, dir).plan()?)?;
    let result = summarize_run(cell, budget, &policy.join("metrics.jsonl"))?;
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

/// Fits the cell's model into `model` unless it is there. Cells sharing the
/// model fit it once: the first to hold the lock fits, the others wait on it
/// and find the model there. The operating system drops the lock of a killed
/// cell, whose successor continues the fit from its last checkpoint.
fn fit_cell_model(cell: &Cell, budget: &Budget, model: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(model).with_context(|| format!("creating {}", model.display()))?;
    let lock_path = model.with_extension("lock");
    let lock = std::fs::File::create(&lock_path)
        .with_context(|| format!("creating {}", lock_path.display()))?;
    lock.lock()
        .with_context(|| format!("locking {}", lock_path.display()))?;
    let data = cell_data(cell);
    // Each fit writes its JSON last: without it the fit did not finish.
    let out = model.to_path_buf();
    if cell.method.uses_ensemble() {
        if !model.join("ensemble.json").is_file() {
            let mut args = fit_ensemble::Args::defaults(data, out);
            (args.seed, args.resume) = (cell.seed, true);
            args.max_epochs = budget.ensemble_max_epochs;
            fit_ensemble::fit(&args.plan()?)?;
        }
    } else {
        let plan = model_args(cell, budget, data, out).plan()?;
        if model.join("model.json").is_file() {
            check_fitted_sde(model, &plan.fit, plan.report.thresholds.max_margin)?;
        } else {
            fit_model::fit(&plan)?;
        }
    }
    Ok(())
}

/// The cell's data as the fits read it.
fn cell_data(cell: &Cell) -> DataSource {
    DataSource {
        dataset: cell.file.clone(),
        format: None,
        task: cell.task,
        system: cell.system.clone(),
        neorl: cell.layout == ObservationLayout::Neorl,
    }
}

/// fit-model's flags for the cell's SDE: the budget's over the defaults,
/// resuming a killed fit.
fn model_args(cell: &Cell, b: &Budget, data: DataSource, out: PathBuf) -> fit_model::Args {
    let mut args = fit_model::Args::defaults(data, out);
    (args.seed, args.resume) = (cell.seed, true);
    args.reward_model = cell.method == Method::NunoR;
    args.max_steps = Some(b.model_steps);
    args.likelihood = b.model_likelihood;
    args.recipe = b.recipe;
    args.sample_noise = b.model_sample_noise;
    args.step_discount = b.model_step_discount;
    args.eta_losses = b.model_eta_losses;
    args.threshold_max_margin = b.threshold_max_margin;
    args.drift_inputs = b.model_drift_inputs;
    args
}

/// fit-policy's flags for the cell: the budget's over the defaults, the
/// policies in the cell's folder, resuming a killed run. The recipe and the
/// reward's velocity are NUNO's loop (an ensemble learns its rewards), the
/// MOPO settings MOPO's and NUNO's; a model-free method takes the budget and the data's system.
fn policy_args(cell: &Cell, b: &Budget, model: Option<PathBuf>, dir: PathBuf) -> fit_policy::Args {
    let out = dir.join("policy");
    let mut args = fit_policy::Args::defaults(model, cell.file.clone(), cell.preset.clone(), out);
    (args.seed, args.resume, args.algo) = (cell.seed, true, cell.method);
    args.policies = Some(dir);
    args.steps = b.policy_steps;
    args.steps_per_epoch = b.steps_per_epoch;
    args.eval_episodes = b.eval_episodes;
    args.hidden = b.hidden.clone();
    if let Some(edac) = cell.edac {
        (args.edac_critics, args.edac_eta) = (Some(edac.critics), Some(edac.eta));
    }
    if cell.method.is_model_free() {
        args.task = cell.task;
        args.neorl = cell.layout == ObservationLayout::Neorl;
        args.system = cell.system.clone();
        return args;
    }
    if let Some(policy) = cell.policy {
        args.horizon = Some(policy.horizon);
        args.cvar_alpha = Some(policy.cvar_alpha);
        args.penalty = Some(policy.penalty);
    }
    if let Some(mopo) = cell.mopo {
        // MOReL reads MOPO's h alone (it has no penalty).
        args.horizon = Some(mopo.horizon);
        args.penalty = cell.method.is_mopo().then_some(mopo.penalty);
    }
    if let Some(rambo) = cell.rambo {
        (args.horizon, args.rambo_weight) = (Some(rambo.horizon), Some(rambo.weight));
    }
    if let Some(combo) = cell.combo {
        (args.horizon, args.combo_weight) = (Some(combo.horizon), Some(combo.weight));
    }
    args.rollout_batch = b.rollout_batch;
    args.model_buffer_factor = b.model_buffer_factor;
    args.state_box_margin = b.state_box_margin;
    args.clip_observations = b.clip_observations;
    args.target_entropy = b.target_entropy;
    args.rollout_noise_scale = b.rollout_noise_scale;
    args.truncated_step = b
        .truncated_step
        .filter(|_| cell.method.truncation().accumulates());
    // The method's budget names settings only where the method takes them.
    args.mopo_settings = b.mopo_settings;
    if cell.method.uses_sde() {
        args.penalty = b.penalty.or(args.penalty);
        args.recipe = b.recipe;
        args.forward_velocity = b.forward_velocity;
        args.root_x_reward = b.root_x_reward;
    }
    args
}

fn status(args: StatusArgs) -> anyhow::Result<()> {
    let StatusArgs { grid: args, select } = args;
    let (grid, cells) = Grid::read(&args.grid)?;
    let cells = select.select(&cells)?;
    let mut statuses = Vec::new();
    for cell in &cells {
        let status = cell_status(&args.out, cell, &grid.budget_for(cell))?;
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
    println!("{done}/{} cells done", cells.len());
    let b = &grid.budget;
    let methods = cells.iter().map(|c| c.method).zip(&statuses);
    let left = policy_time_left(
        &methods.collect::<Vec<_>>(),
        b.policy_steps.div_ceil(b.steps_per_epoch),
    );
    if left.seconds > 0.0 {
        println!(
            "about {:.1} h of policy training left, each method at its finished cells' pace (model fits not included)",
            left.seconds / 3600.0
        );
    }
    if !left.unpaced.is_empty() {
        let names: Vec<&str> = left.unpaced.iter().map(|m| m.as_str()).collect();
        println!("no finished cell to pace {} by yet", names.join(", "));
    }
    Ok(())
}

fn report(args: GridArgs) -> anyhow::Result<()> {
    let (grid, cells) = Grid::read(&args.grid)?;
    let mut results: Vec<CellResult> = Vec::new();
    for cell in &cells {
        if let CellStatus::Done(r) = cell_status(&args.out, cell, &grid.budget_for(cell))? {
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
    let curves = mean_curves(results);
    let mut by_dataset: BTreeMap<&str, Vec<&MeanCurve>> = BTreeMap::new();
    for curve in &curves {
        by_dataset.entry(&curve.dataset).or_default().push(curve);
    }
    for (dataset, curves) in by_dataset {
        let names: Vec<String> = curves
            .iter()
            .map(|c| format!("{} ({} seeds)", c.method, c.seeds))
            .collect();
        let series: Vec<Series> = curves
            .iter()
            .zip(&names)
            .map(|(c, name)| Series {
                name,
                points: c.points.iter().map(|&(s, v)| (s as f64, v)).collect(),
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

#[cfg(test)]
mod tests {
    use std::path::Path;

    use clap::Parser;
    use nuno::agent::{LearnerConfig, PolicyLoopConfig, TruncatedStep};
    use nuno::envs::RootXReward;
    use nuno::experiment::{Grid, fit_changes};

    use super::{cell_data, model_args, policy_args};
    use crate::{fit_model, fit_policy};

    /// The command lines a user would type, parsed as the trainer parses them.
    #[derive(Parser)]
    enum Typed {
        FitModel(Box<fit_model::Args>),
        FitPolicy(Box<fit_policy::Args>),
    }

    /// The budget keys every method takes.
    const SHARED: &str = "model_steps = 300\npolicy_steps = 4500\nsteps_per_epoch = 500\neval_episodes = 3\n\
                          hidden = [64, 32]\nrollout_batch = 700\nmodel_buffer_factor = 3\n";
    /// The budget keys of NUNO's model and loop.
    const NUNO: &str = "recipe = \"code\"\nmodel_likelihood = \"data\"\nmodel_sample_noise = \"calibrated\"\n\
                        model_step_discount = 0.8\nmodel_eta_losses = \"paper\"\nthreshold_max_margin = 1.3\n\
                        model_drift_inputs = \"z-scores\"\nforward_velocity = \"next\"\n";

    /// A grid of one `method` cell under the shared budget keys and `own`.
    fn cell_of(dir: &Path, method: &str, own: &str) -> (Grid, super::Cell) {
        let grid = dir.join(format!("{method}.toml"));
        let text = format!(
            "[budget]\n{SHARED}{own}\n[[datasets]]\nname = \"h\"\nfile = \"h.hdf5\"\ntask = \"hopper\"\n\
             preset = \"hopper-medium\"\nmethods = [\"{method}\"]\nseeds = [4]\n"
        );
        std::fs::write(&grid, text).unwrap();
        let (grid, cells) = Grid::read(&grid).unwrap();
        (grid, cells[0].clone())
    }

    fn json(value: &impl serde::Serialize) -> serde_json::Value {
        serde_json::to_value(value).unwrap()
    }

    #[test]
    fn a_cell_fits_what_the_same_flags_typed_would_fit() {
        let dir = tempfile::tempdir().unwrap();
        let (grid, cell) = cell_of(dir.path(), "nuno-r", NUNO);
        let file = cell.file.display().to_string();
        let data = cell_data(&cell);
        let runner = model_args(&cell, &grid.budget_for(&cell), data, "m".into());
        let typed = [
            "t",
            "fit-model",
            "--dataset",
            &file,
            "--task",
            "hopper",
            "--out",
            "m",
            "--seed",
            "4",
            "--resume",
            "--reward-model",
            "--max-steps",
            "300",
            "--likelihood",
            "data",
            "--recipe",
            "code",
            "--sample-noise",
            "calibrated",
            "--step-discount",
            "0.8",
            "--eta-losses",
            "paper",
            "--threshold-max-margin",
            "1.3",
            "--drift-inputs",
            "z-scores",
        ];
        let Typed::FitModel(typed) = Typed::parse_from(typed) else {
            unreachable!()
        };
        assert_eq!(json(&runner.plan().unwrap()), json(&typed.plan().unwrap()));
    }

    /// Every budget key that shapes a cell's SDE, with a value other than
    /// `cell_of`'s (its model_steps, 300, is changed on the parsed budget).
    const FIT_KEYS: [(&str, &str); 8] = [
        ("model_steps", ""),
        ("recipe", "recipe = \"code\""),
        ("model_likelihood", "model_likelihood = \"data\""),
        ("model_sample_noise", "model_sample_noise = \"sqrt-dt\""),
        ("model_step_discount", "model_step_discount = 0.8"),
        ("model_eta_losses", "model_eta_losses = \"code\""),
        ("model_drift_inputs", "model_drift_inputs = \"pose\""),
        ("threshold_max_margin", "threshold_max_margin = 1.3"),
    ];
    /// The budget keys that do not reach fit-model.
    const OTHER_KEYS: [&str; 16] = [
        "ensemble_max_epochs",
        "policy_steps",
        "steps_per_epoch",
        "eval_episodes",
        "rollout_batch",
        "state_box_margin",
        "clip_observations",
        "target_entropy",
        "penalty",
        "rollout_noise_scale",
        "mopo_settings",
        "hidden",
        "model_buffer_factor",
        "forward_velocity",
        "root_x_reward",
        "truncated_step",
    ];

    /// A model folder is checked against every budget key that shapes the fit:
    /// changing any one of them is a change the runner names, and a key added
    /// to the budget fails here until it is sorted into one list or the other.
    #[test]
    fn every_budget_key_that_shapes_a_fit_is_checked_against_a_fitted_model() {
        let dir = tempfile::tempdir().unwrap();
        let fit = |own: &str, steps: usize| {
            let (mut grid, cell) = cell_of(dir.path(), "nuno", own);
            grid.budget.model_steps = steps;
            let data = cell_data(&cell);
            let plan =
                (model_args(&cell, &grid.budget_for(&cell), data, "m".into()).plan()).unwrap();
            (plan.fit, plan.report.thresholds.max_margin)
        };
        let (base, base_margin) = fit("", 300);
        for (key, line) in FIT_KEYS {
            let (now, margin) = match key {
                "model_steps" => fit("", 301),
                _ => fit(line, 300),
            };
            let changes = fit_changes((&base, Some(base_margin)), (&now, margin));
            assert!(!changes.is_empty(), "{key} changed nothing the check reads");
        }
        // Set, because a budget writes these keys only when they are given.
        let every_key = cell_of(
            dir.path(),
            "nuno",
            "state_box_margin = 0.1\nclip_observations = true\ntarget_entropy = -3.0\npenalty = 5.0\n\
             rollout_noise_scale = 0.0\ntruncated_step = \"terminal\"",
        )
        .0;
        let serde_json::Value::Object(keys) = json(&every_key.budget) else {
            unreachable!()
        };
        for key in keys.keys() {
            let sorted =
                FIT_KEYS.iter().any(|(k, _)| k == key) || OTHER_KEYS.contains(&key.as_str());
            assert!(sorted, "budget key {key}: add it to FIT_KEYS or OTHER_KEYS");
        }
    }

    /// The flags a user types for `cell_of`'s cell and budget, besides the model, dataset
    /// and method.
    const TYPED_BUDGET: [&str; 21] = [
        "--preset",
        "hopper-medium",
        "--out",
        "c/policy",
        "--policies",
        "c",
        "--seed",
        "4",
        "--resume",
        "--steps",
        "4500",
        "--steps-per-epoch",
        "500",
        "--eval-episodes",
        "3",
        "--hidden",
        "64,32",
        "--rollout-batch",
        "700",
        "--model-buffer-factor",
        "3",
    ];

    #[test]
    fn a_cell_trains_the_policy_the_same_flags_typed_would_train() {
        let dir = tempfile::tempdir().unwrap();
        for (method, budget, own) in [
            (
                "nuno",
                NUNO,
                vec!["--recipe", "code", "--forward-velocity", "next"],
            ),
            (
                "mopo",
                "mopo_settings = \"nuno\"\nclip_observations = true\ntarget_entropy = -3.0\nrollout_noise_scale = 0.5\n",
                vec![
                    "--mopo-settings",
                    "nuno",
                    "--clip-observations",
                    "--target-entropy",
                    "-3",
                    "--rollout-noise-scale",
                    "0.5",
                ],
            ),
            (
                "nuno",
                "mopo_settings = \"offlinerl-kit\"\npenalty = 7.5\n",
                vec!["--mopo-settings", "offlinerl-kit", "--penalty", "7.5"],
            ),
        ] {
            let (grid, cell) = cell_of(dir.path(), method, budget);
            let file = cell.file.display().to_string();
            let runner = policy_args(&cell, &grid.budget_for(&cell), Some("m".into()), "c".into());
            let mut typed = vec![
                "t",
                "fit-policy",
                "--model",
                "m",
                "--dataset",
                &file,
                "--algo",
                method,
            ];
            typed.extend(TYPED_BUDGET);
            typed.extend(own);
            let Typed::FitPolicy(typed) = Typed::parse_from(typed) else {
                unreachable!()
            };
            let plan = runner.plan().unwrap();
            assert_eq!(json(&plan), json(&typed.plan().unwrap()), "{method}");
            // Not a tautology of two defaults: the budget reached the plan.
            let fit_policy::Training::InModel(run) = &plan.training else {
                panic!("{method} trains in a model");
            };
            assert_eq!(run.config.rollout_batch, 700, "{method}");
            let kit = budget.contains("offlinerl-kit");
            assert_eq!(run.config.sac.actor_lr == 1e-4, kit, "{method}: {budget}");
            assert_eq!(run.config.penalty == 7.5, kit, "{method}: {budget}");
            let half = budget.contains("rollout_noise_scale = 0.5");
            assert_eq!(
                run.config.rollout_noise_scale == Some(0.5),
                half,
                "{method}"
            );
        }
    }

    /// The budget's root x reward reaches NUNO's loop; MOPO's ensemble learns
    /// its rewards, and its cells run without it.
    #[test]
    fn the_root_x_reward_reaches_nunos_loop_only() {
        let dir = tempfile::tempdir().unwrap();
        for (method, reaches) in [("nuno", true), ("mopo", false)] {
            let (mut grid, cell) = cell_of(dir.path(), method, "");
            grid.budget.root_x_reward = Some(RootXReward::Velocity);
            let velocity = loop_config(&grid, &cell).root_x_reward == RootXReward::Velocity;
            assert_eq!(velocity, reaches, "{method}");
        }
    }

    /// The policy loop the runner would train `cell` with, in a model.
    fn loop_config(grid: &Grid, cell: &super::Cell) -> PolicyLoopConfig {
        let runner = policy_args(cell, &grid.budget_for(cell), Some("m".into()), "c".into());
        match runner.plan().unwrap().training {
            fit_policy::Training::InModel(run) => run.config,
            fit_policy::Training::ModelFree(_) => panic!("{} trains in a model", cell.method),
        }
    }

    /// A random row's RAMBO, COMBO and EDAC settings are what their cells'
    /// runs take, as `--horizon` and each method's weight or critics would give them.
    #[test]
    fn a_rows_baseline_settings_reach_their_methods_runs() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("random.toml");
        let text = format!(
            "[budget]\n{SHARED}\n[[datasets]]\nname = \"r\"\nfile = \"r.hdf5\"\ntask = \"hopper\"\n\
             preset = \"hopper-random\"\nrambo = {{ horizon = 2, weight = 3e-4 }}\n\
             combo = {{ horizon = 3, weight = 2.5 }}\nedac = {{ critics = 7, eta = 0.5 }}\n\
             methods = [\"rambo\", \"combo\", \"edac\"]\nseeds = [0]\n"
        );
        std::fs::write(&path, text).unwrap();
        let (grid, cells) = Grid::read(&path).unwrap();
        let rambo = loop_config(&grid, &cells[0]);
        let adversary = rambo.rambo.expect("RAMBO's adversary").adversary;
        assert_eq!((rambo.horizon, adversary.adv_weight), (2, 3e-4));
        let combo = loop_config(&grid, &cells[1]);
        let term = combo.conservative.expect("COMBO's conservative term");
        assert_eq!((combo.horizon, term.cql_weight), (3, 2.5));
        let edac = policy_args(&cells[2], &grid.budget_for(&cells[2]), None, "c".into());
        let fit_policy::Training::ModelFree(plan) = edac.plan().unwrap().training else {
            panic!("EDAC trains on the data alone");
        };
        let LearnerConfig::Edac(config) = plan.config.learner else {
            panic!("an EDAC cell plans EDAC");
        };
        assert_eq!((config.num_critics, config.eta), (7, 0.5));
    }

    /// The budget's truncated step reaches the methods that truncate on an
    /// accumulated signal, and is no part of MOPO's budget, so naming it leaves
    /// MOPO's finished cells finished; naming the default is leaving it out.
    #[test]
    fn the_truncated_step_reaches_the_truncating_methods_only() {
        let dir = tempfile::tempdir().unwrap();
        let key = "truncated_step = \"terminal\"";
        for (method, reaches) in [("nuno", true), ("tatu-mopo", true), ("mopo", false)] {
            let (grid, cell) = cell_of(dir.path(), method, key);
            let terminal = loop_config(&grid, &cell).truncated_step == TruncatedStep::Terminal;
            assert_eq!(terminal, reaches, "{method}");
            let (plain, _) = cell_of(dir.path(), method, "");
            let unchanged =
                plain.budget.for_method(cell.method) == grid.budget.for_method(cell.method);
            assert_eq!(unchanged, !reaches, "{method}");
        }
        let (named_default, cell) = cell_of(dir.path(), "nuno", "truncated_step = \"drop\"");
        let (plain, _) = cell_of(dir.path(), "nuno", "");
        assert_eq!(
            named_default.budget.for_method(cell.method),
            plain.budget.for_method(cell.method)
        );
    }
}
