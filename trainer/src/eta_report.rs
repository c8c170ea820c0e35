//! `nuno-trainer eta-report`: how well a fitted model's η separates a dataset
//! from random actions and from perturbed data (AUROC), before any policy is trained.

use std::path::PathBuf;

use anyhow::Context;
use nuno::artifact::load_dynamics;
use nuno::data::{DatasetFormat, read_dataset};
use nuno::sde::{ComputeDevice, EtaReportConfig, LossConfig, eta_report};

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Model directory (dynamics.safetensors + model.json).
    #[arg(long)]
    model: PathBuf,
    /// Dataset file (D4RL .hdf5, NeoRL .npz) or Minari directory.
    #[arg(long)]
    dataset: PathBuf,
    /// Reader to use (default: detected).
    #[arg(long)]
    format: Option<DatasetFormat>,
    /// Transitions to draw from the dataset.
    #[arg(long, default_value_t = EtaReportConfig::new().rows)]
    rows: usize,
    /// Perturbation scales, in multiples of the model's L_sc radius r.
    #[arg(long, value_delimiter = ',', default_value = "1,3")]
    radii: Vec<f32>,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Print the report as JSON instead of a table.
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let device = ComputeDevice::Cpu.device().map_err(anyhow::Error::msg)?;
    let (model, metadata) = load_dynamics(&args.model, &device)
        .with_context(|| format!("loading the model in {}", args.model.display()))?;
    let dataset = read_dataset(&args.dataset, args.format)?;
    if let Some(task) = &metadata.provenance.task {
        dataset.check_task(task, &args.dataset)?;
    }
    // r as the model was fitted with (older artifacts: the paper's default).
    let radius = metadata
        .provenance
        .fit
        .as_ref()
        .map_or(LossConfig::new().radius, |fit| fit.loss.radius);
    let config = EtaReportConfig {
        rows: args.rows,
        radii: args.radii,
        seed: args.seed,
    };
    let report = eta_report(&model, &dataset, radius, &config, &device)
        .context("check --rows and --radii")?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    println!(
        "η on {} dataset transitions (η_max {}, r {}): mean {:.4}",
        report.rows, report.eta_max, report.radius, report.data_mean_eta
    );
    println!("| points | mean η | AUROC vs data |");
    println!("|---|---|---|");
    let row = |name: &str, c: &nuno::sde::EtaComparison| {
        println!("| {name} | {:.4} | {:.3} |", c.mean_eta, c.auroc_vs_data);
    };
    row("same states, random actions", &report.random_actions);
    for (k, comparison) in &report.perturbed {
        row(&format!("data + N(0, ({k}·r)²)"), comparison);
    }
    Ok(())
}
