//! `nuno-trainer fit-ensemble`: fit MOPO's Gaussian ensemble (OfflineRL-Kit's
//! defaults) on a dataset and write it into a model directory
//! (`ensemble.safetensors`, `ensemble.json`), with the fit's metrics and a
//! holdout-error plot; a checkpoint after every epoch in
//! `--out/ensemble-checkpoints`, which `--resume` continues.

use std::path::{Path, PathBuf};

use anyhow::Context;
use nuno::artifact::{
    EnsembleFitShape, load_ensemble_checkpoint, save_ensemble, save_ensemble_checkpoint,
};
use nuno::ensemble::{EnsembleConfig, EnsembleEpoch, EnsembleError, fit_ensemble};
use nuno::envs::System;
use nuno::infer::Kernel;
use nuno::sde::ComputeDevice;
use nuno::shared::MetricsTable;
use serde::Serialize;

use crate::data_source::DataSource;
use crate::flag_defaults::with_defaults;
use crate::output::write_text;
use crate::plot::{Series, line_chart};
use crate::resume::{checkpoint_to_resume, claim_output};
use crate::run_record::write_run_record;

#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub data: DataSource,
    /// Model directory (the ensemble's files are added to it).
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long, default_value_t = EnsembleConfig::new().members)]
    pub members: usize,
    #[arg(long, default_value_t = EnsembleConfig::new().elites)]
    pub elites: usize,
    /// Hidden sizes of each member (swish).
    #[arg(long, value_delimiter = ',', default_values_t = EnsembleConfig::new().hidden)]
    pub hidden: Vec<usize>,
    /// Weight decay per layer, hidden layers then the output (default: OfflineRL-Kit's for 4 hidden layers).
    #[arg(long, value_delimiter = ',')]
    pub weight_decay: Option<Vec<f64>>,
    #[arg(long, default_value_t = EnsembleConfig::new().batch_size)]
    pub batch_size: usize,
    /// A cap on epochs (default: until 5 epochs without a 1 % holdout improvement).
    #[arg(long)]
    pub max_epochs: Option<usize>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// What trains the members: `fused` (the CPU kernels, all cores) or `burn`
    /// (autodiff; the reference). The same loss, optimiser and data order.
    #[arg(long, default_value_t = Kernel::Fused)]
    pub kernel: Kernel,
    /// Continue the fit checkpointed in --out (either kernel's checkpoint).
    #[arg(long)]
    pub resume: bool,
}

/// What a fit-ensemble run does, validated before the data is read, written
/// to `run.json` at start.
#[derive(Debug, Serialize)]
pub struct Plan {
    pub data: DataSource,
    pub system: System,
    pub config: EnsembleConfig,
    pub kernel: Kernel,
    pub out: PathBuf,
    pub resume: bool,
}

impl Args {
    /// The flags' defaults for fitting `data` into `out`: what `fit-ensemble
    /// --dataset … --task … --out …` alone runs (the experiment runner sets its
    /// budget's fields over them).
    pub fn defaults(data: DataSource, out: PathBuf) -> Self {
        let mut args: Args = with_defaults(&[
            "fit-ensemble",
            "--dataset",
            "-",
            "--task",
            "hopper",
            "--out",
            "-",
        ]);
        (args.data, args.out) = (data, out);
        args
    }

    /// The validated plan.
    pub fn plan(self) -> anyhow::Result<Plan> {
        let mut config = EnsembleConfig::new()
            .with_members(self.members)
            .with_elites(self.elites)
            .with_hidden(self.hidden)
            .with_batch_size(self.batch_size)
            .with_max_epochs(self.max_epochs)
            .with_seed(self.seed);
        if let Some(decay) = self.weight_decay {
            config.weight_decay = decay;
        }
        config.validate()?;
        Ok(Plan {
            system: self.data.system()?,
            data: self.data,
            config,
            kernel: self.kernel,
            out: self.out,
            resume: self.resume,
        })
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    fit(&args.plan()?)
}

/// Fits the ensemble (from the last checkpoint under --resume) and writes it
/// with its metrics and holdout plot.
pub fn fit(plan: &Plan) -> anyhow::Result<()> {
    let _claim = claim_output(&plan.out)?;
    let dataset = plan.data.read(&plan.system)?;
    let device = ComputeDevice::Cpu.device().map_err(anyhow::Error::msg)?;
    let checkpoints = plan.out.join("ensemble-checkpoints");
    let shape = EnsembleFitShape {
        rows: dataset.len(),
        obs_dim: dataset.obs_dim(),
        act_dim: dataset.act_dim(),
    };
    let resume =
        match checkpoint_to_resume(&checkpoints, plan.resume, &plan.out, "an ensemble fit")? {
            Some(checkpoint) => {
                let state = load_ensemble_checkpoint(&checkpoint, &plan.config, &shape, &device)
                    .with_context(|| format!("resuming from {}", checkpoint.display()))?;
                println!(
                    "resumed from {} (epoch {})",
                    checkpoint.display(),
                    state.history.len()
                );
                Some(state)
            }
            None => None,
        };
    write_run_record(&plan.out, "fit-ensemble", plan, &[&plan.data.dataset])?;
    let fit = fit_ensemble(
        &dataset,
        &plan.config,
        plan.kernel,
        &device,
        resume,
        &mut |state| {
            print_epoch(state.history.last().expect("an epoch behind the state"));
            save_ensemble_checkpoint(&checkpoints, &plan.config, &shape, state)
                .map(|_| ())
                .map_err(|e| EnsembleError::Checkpoint(e.to_string()))
        },
    )?;
    let info = plan.data.info(&dataset);
    save_ensemble(&plan.out, &fit, &plan.config, &plan.system, Some(info))?;
    write_metrics(&plan.out, &fit.history, plan.config.members)?;
    println!(
        "{} epochs; elites {:?} (holdout MSE {:?}); written to {}",
        fit.history.len(),
        fit.elites,
        fit.elites
            .iter()
            .map(|&e| fit.holdout_mse[e])
            .collect::<Vec<_>>(),
        plan.out.display()
    );
    Ok(())
}

fn print_epoch(epoch: &EnsembleEpoch) {
    let best = epoch
        .holdout_mse
        .iter()
        .copied()
        .fold(f32::INFINITY, f32::min);
    let improved = if epoch.improved {
        ""
    } else {
        " (no improvement)"
    };
    println!(
        "epoch {:>4}: train loss {:.4}, best member's holdout MSE {best:.5}{improved}",
        epoch.epoch, epoch.train_loss
    );
}

/// ensemble_metrics.csv (an epoch a row, each member's holdout MSE a column)
/// and its plot.
fn write_metrics(out: &Path, history: &[EnsembleEpoch], members: usize) -> anyhow::Result<()> {
    let mut table = MetricsTable::new()
        .column("epoch", |e: &EnsembleEpoch| e.epoch.into())
        .column("train_loss", |e: &EnsembleEpoch| e.train_loss.into())
        .column("improved", |e: &EnsembleEpoch| e.improved.into());
    for m in 0..members {
        table = table.column(format!("holdout_mse/{m}"), move |e: &EnsembleEpoch| {
            e.holdout_mse[m].into()
        });
    }
    write_text(&out.join("ensemble_metrics.csv"), &table.csv(history))?;
    let names: Vec<String> = (0..members).map(|m| format!("member {m}")).collect();
    let series: Vec<Series> = names
        .iter()
        .enumerate()
        .map(|(m, name)| Series {
            name,
            points: history
                .iter()
                .map(|e| (e.epoch as f64, f64::from(e.holdout_mse[m])))
                .collect(),
        })
        .collect();
    line_chart(
        &out.join("ensemble_holdout.svg"),
        "Gaussian ensemble: holdout MSE",
        "epoch",
        "holdout MSE of (s' − s, r)",
        &series,
    )
}
