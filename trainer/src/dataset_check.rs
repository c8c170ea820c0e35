//! `nuno-trainer dataset check`: a dataset against the system file it is
//! said to log — its size, each column's range, actions outside the box, and
//! whether every declared pair's d position/dt = velocity holds at the
//! declared dt — so a wrong `dt` or a wrong pair is caught before a fit.

use std::path::PathBuf;
use std::sync::Arc;

use nuno::data::{DatasetFormat, PAIR_ERROR_LIMIT, SystemCheck, check_system, read_system_dataset};
use nuno::envs::{System, SystemSpec};

#[derive(Debug, clap::Args)]
pub struct CheckArgs {
    /// The system file (docs/your-own-system.md).
    #[arg(long)]
    system: PathBuf,
    /// The dataset: a CSV log of the system, D4RL .hdf5, .npz or Minari directory.
    #[arg(long)]
    dataset: PathBuf,
    /// Reader to use (default: detected from the file).
    #[arg(long)]
    format: Option<DatasetFormat>,
    /// Print the report as JSON instead of tables.
    #[arg(long)]
    json: bool,
}

/// Prints the report; fails when a pair does not hold or an action leaves its box.
pub fn check(args: CheckArgs) -> anyhow::Result<()> {
    let spec = Arc::new(SystemSpec::read(&args.system)?);
    let system = System::File(spec.clone());
    let dataset = read_system_dataset(&args.dataset, args.format, &system)?;
    let report = check_system(&dataset, &spec);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_report(&report, spec.dt);
    }
    anyhow::ensure!(
        report.passed(),
        "{} does not fit {}: see the pairs and action counts above",
        args.dataset.display(),
        args.system.display()
    );
    Ok(())
}

fn print_report(report: &SystemCheck, dt: f64) {
    println!(
        "{}: {} transitions in {} episodes ({} terminal)",
        report.system, report.transitions, report.episodes, report.terminals
    );
    println!("| column | min | max | mean | std | outside the action box |");
    println!("|---|---|---|---|---|---|");
    for c in &report.observations {
        println!(
            "| {} | {:.4} | {:.4} | {:.4} | {:.4} | |",
            c.name, c.min, c.max, c.mean, c.std
        );
    }
    for (c, outside) in report.actions.iter().zip(&report.actions_outside_box) {
        println!(
            "| {} | {:.4} | {:.4} | {:.4} | {:.4} | {outside} |",
            c.name, c.min, c.max, c.mean, c.std
        );
    }
    if report.pairs.is_empty() {
        println!("no [physics] pairs declared: the drift is learned alone");
        return;
    }
    println!(
        "\nd position/dt = velocity at the declared dt = {dt}, relative RMS error of the finite difference (holds ≤ {PAIR_ERROR_LIMIT}):"
    );
    println!("| pair | vs velocity | vs next velocity | vs mean | the log's dt | holds |");
    println!("|---|---|---|---|---|---|");
    for p in &report.pairs {
        println!(
            "| {} → {} | {:.4} | {:.4} | {:.4} | {:.4} | {} |",
            p.position,
            p.velocity,
            p.against_velocity,
            p.against_next_velocity,
            p.against_mean_velocity,
            p.fitted_dt,
            if p.holds() {
                "yes"
            } else {
                "NO: check dt and the pair"
            }
        );
    }
}
