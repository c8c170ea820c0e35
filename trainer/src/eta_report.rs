//! `nuno-trainer eta-report`: before any policy is trained, how well a fitted
//! model's η separates a dataset from random actions and from perturbed data
//! (AUROC), and how its diffusion and truncation are calibrated on held-out
//! transitions (z-scores, h(η)'s share of Σ, Σ off the data, truncation rates).

use std::path::{Path, PathBuf};

use anyhow::Context;
use nuno::artifact::{DYNAMICS_METADATA, DynamicsProvenance, load_dynamics, sha256_file};
use nuno::data::{Dataset, DatasetFormat, read_dataset, read_system_dataset};
use nuno::envs::System;
use nuno::sde::{
    CalibrationConfig, CalibrationReport, ComputeDevice, EtaReport, EtaReportConfig, LossConfig,
    Z_STD_BAND, calibration_report, eta_report,
};
use serde::Serialize;

use crate::plot::{Series, line_chart};

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Model directory (dynamics.safetensors + model.json).
    #[arg(long)]
    model: PathBuf,
    /// Dataset file (D4RL .hdf5, NeoRL .npz) or Minari directory. When it is the
    /// model's training dataset, calibration uses the fit's held-out trajectories.
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
    /// Open-loop windows per horizon for the truncation rates.
    #[arg(long, default_value_t = CalibrationConfig::new().windows)]
    windows: usize,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Print the report as JSON instead of tables.
    #[arg(long)]
    json: bool,
}

/// What `--json` prints.
#[derive(Serialize)]
struct Report<'a> {
    separation: &'a EtaReport,
    calibration: &'a CalibrationReport,
}

impl Args {
    /// The separation's and the calibration's configurations, checked.
    fn configs(&self) -> anyhow::Result<(EtaReportConfig, CalibrationConfig)> {
        let eta_config = EtaReportConfig {
            rows: self.rows,
            radii: self.radii.clone(),
            seed: self.seed,
        };
        let calibration_config = CalibrationConfig {
            rows: self.rows,
            radii: self.radii.clone(),
            windows: self.windows,
            seed: self.seed,
            ..CalibrationConfig::new()
        };
        calibration_config
            .validate()
            .context("check --rows, --radii and --windows")?;
        Ok((eta_config, calibration_config))
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let (eta_config, calibration_config) = args.configs()?;
    let device = ComputeDevice::Cpu.device().map_err(anyhow::Error::msg)?;
    let (model, metadata) = load_dynamics(&args.model, &device)
        .with_context(|| format!("loading the model in {}", args.model.display()))?;
    let system = System::recorded(
        metadata.provenance.task.clone(),
        metadata.provenance.system.as_deref(),
        &args.model.join(DYNAMICS_METADATA),
    )?;
    let dataset = match &system {
        Some(system) => read_system_dataset(&args.dataset, args.format, system)?,
        None => read_dataset(&args.dataset, args.format)?,
    };
    let fit = metadata.provenance.fit.as_ref();
    // r as the model was fitted with (older artifacts: the paper's default).
    let radius = fit.map_or(LossConfig::new().radius, |fit| fit.loss.radius);
    let separation = eta_report(&model, &dataset, radius, &eta_config, &device)
        .context("check --rows and --radii")?;
    let held_out = new_to_the_model(dataset, &args.dataset, &metadata.provenance)?;
    let thresholds = metadata.provenance.thresholds.as_ref();
    // Random actions span the system's action space (older artifacts: the data's range).
    let actions = match &system {
        Some(system) => system.shape()?.action_space(),
        None => held_out.action_bounds(),
    };
    let calibration = calibration_report(
        &model,
        &held_out,
        thresholds,
        radius,
        &actions,
        &calibration_config,
        &device,
    )?;
    if args.json {
        let report = Report {
            separation: &separation,
            calibration: &calibration,
        };
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    print_separation(&separation);
    println!();
    print_calibration(&calibration);
    Ok(())
}

/// The part of `dataset` new to the model: on its training dataset, the
/// trajectories the fit held out; any other dataset whole.
fn new_to_the_model(
    dataset: Dataset,
    path: &Path,
    provenance: &DynamicsProvenance,
) -> anyhow::Result<Dataset> {
    let trained_on = provenance.dataset.as_ref().map(|d| &d.sha256);
    Ok(match &provenance.fit {
        Some(fit) if trained_on == Some(&sha256_file(path)?) => {
            dataset.split_by_trajectory(fit.valid_fraction, fit.seed).1
        }
        _ => dataset,
    })
}

fn print_separation(report: &EtaReport) {
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
}

/// The calibration report as markdown tables (also printed by `fit-model`).
pub fn print_calibration(report: &CalibrationReport) {
    let (low, high) = Z_STD_BAND;
    println!(
        "Calibration on {} held-out transitions: z std in [{low}, {high}] for {:.0} % of \
         dimensions; h(η) is {:.1} % of Σ at the median η ({:.4})",
        report.rows,
        100.0 * report.z_std_in_band,
        100.0 * report.h_share_at_median_eta,
        report.median_eta
    );
    println!("| dim | z mean | z std | |z| ≤ 1 | |z| ≤ 2 | h(η)/Σ |");
    println!("|---|---|---|---|---|---|");
    for (d, c) in report.dimensions.iter().enumerate() {
        println!(
            "| {d} | {:+.3} | {:.3} | {:.3} | {:.3} | {:.3} |",
            c.z_mean, c.z_std, c.within_one, c.within_two, c.h_share
        );
    }
    println!();
    println!("| points | mean η | mean Σ (diffusion scales) | Σ / Σ on data |");
    println!("|---|---|---|---|");
    for d in &report.diffusion {
        let name = if d.radii == 0.0 {
            "held-out data".to_string()
        } else {
            format!("data + N(0, ({}·r)²)", d.radii)
        };
        println!(
            "| {name} | {:.4} | {:.4} | {:.2} |",
            d.mean_eta, d.mean_sigma, d.ratio_to_data
        );
    }
    println!(
        "η one step ahead: {:.4} at real next states, {:.4} at model samples",
        report.eta_next_real, report.eta_next_model
    );
    println!();
    println!("| h | α | ε(h, α) | truncated, dataset actions | truncated, random actions |");
    println!("|---|---|---|---|---|");
    for h in &report.horizons {
        for t in &h.truncation {
            println!(
                "| {} | {} | {:.3} | {:.1} % | {:.1} % |",
                h.horizon,
                t.alpha,
                t.epsilon,
                100.0 * t.dataset_actions,
                100.0 * t.random_actions
            );
        }
    }
    for h in &report.horizons {
        println!(
            "h = {}: mean accumulated η {:.3} on dataset actions, {:.3} on random actions \
             (bound h·η_max = {}; {} windows)",
            h.horizon,
            h.dataset_mean_accumulated_eta,
            h.random_mean_accumulated_eta,
            h.bound,
            h.windows
        );
    }
}

/// `calibration.svg` (z std per dimension against the band) and `truncation.svg`
/// (truncation rate against α, per horizon, dataset vs random actions) in `dir`.
pub fn calibration_charts(dir: &Path, report: &CalibrationReport) -> anyhow::Result<()> {
    let dims = report.dimensions.len() as f64;
    let flat = |y: f32| vec![(0.0, f64::from(y)), (dims - 1.0, f64::from(y))];
    line_chart(
        &dir.join("calibration.svg"),
        "Standardised residuals on held-out data",
        "state dimension",
        "std of (s' − mean)/(Σ·sqrt(dt))",
        &[
            Series {
                name: "z std",
                points: report
                    .dimensions
                    .iter()
                    .enumerate()
                    .map(|(d, c)| (d as f64, f64::from(c.z_std)))
                    .collect(),
            },
            Series {
                name: "band low",
                points: flat(Z_STD_BAND.0),
            },
            Series {
                name: "band high",
                points: flat(Z_STD_BAND.1),
            },
        ],
    )?;
    let mut names = Vec::new();
    for h in &report.horizons {
        names.push((format!("h = {}, dataset actions", h.horizon), h, false));
        names.push((format!("h = {}, random actions", h.horizon), h, true));
    }
    let series: Vec<Series> = names
        .iter()
        .map(|(name, h, random)| Series {
            name,
            points: h
                .truncation
                .iter()
                .map(|t| {
                    let rate = if *random {
                        t.random_actions
                    } else {
                        t.dataset_actions
                    };
                    (t.alpha, f64::from(rate))
                })
                .collect(),
        })
        .collect();
    if !series.is_empty() {
        line_chart(
            &dir.join("truncation.svg"),
            "Open-loop rollouts truncated at ε(h, α), held-out windows",
            "α",
            "fraction truncated",
            &series,
        )?;
    }
    Ok(())
}
