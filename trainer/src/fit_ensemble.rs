//! `nuno-trainer fit-ensemble`: fit MOPO's Gaussian ensemble (OfflineRL-Kit's
//! defaults) on a dataset and write it into a model directory
//! (`ensemble.safetensors`, `ensemble.json`), with the fit's metrics and a
//! holdout-error plot; a checkpoint after every epoch in
//! `--out/ensemble-checkpoints`, which `--resume` continues.

use std::path::PathBuf;

use anyhow::Context;
use nuno::artifact::{
    EnsembleFitShape, load_ensemble_checkpoint, save_ensemble, save_ensemble_checkpoint,
};
use nuno::ensemble::{EnsembleConfig, EnsembleEpoch, EnsembleError, fit_ensemble};
use nuno::infer::Kernel;
use nuno::sde::ComputeDevice;
use nuno::shared::MetricsTable;

use crate::data_source::DataSource;

use crate::output::write_text;
use crate::plot::{Series, line_chart};
use crate::resume::checkpoint_to_resume;

#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    data: DataSource,
    /// Model directory (the ensemble's files are added to it).
    #[arg(long)]
    out: PathBuf,
    #[arg(long, default_value_t = 7)]
    members: usize,
    #[arg(long, default_value_t = 5)]
    elites: usize,
    /// Hidden sizes of each member (swish).
    #[arg(long, value_delimiter = ',', default_value = "200,200,200,200")]
    hidden: Vec<usize>,
    /// Weight decay per layer, hidden layers then the output (default: OfflineRL-Kit's for 4 hidden layers).
    #[arg(long, value_delimiter = ',')]
    weight_decay: Option<Vec<f64>>,
    #[arg(long, default_value_t = 256)]
    batch_size: usize,
    /// A cap on epochs (default: until 5 epochs without a 1 % holdout improvement).
    #[arg(long)]
    max_epochs: Option<usize>,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// What trains the members: `fused` (the CPU kernels, all cores) or `burn`
    /// (autodiff; the reference). The same loss, optimiser and data order.
    #[arg(long, default_value_t = Kernel::Fused)]
    kernel: Kernel,
    /// Continue the fit checkpointed in --out (either kernel's checkpoint).
    #[arg(long)]
    resume: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let task = args.data.task_config();
    let mut config = EnsembleConfig::new()
        .with_members(args.members)
        .with_elites(args.elites)
        .with_hidden(args.hidden.clone())
        .with_batch_size(args.batch_size)
        .with_max_epochs(args.max_epochs)
        .with_seed(args.seed);
    if let Some(decay) = &args.weight_decay {
        config.weight_decay = decay.clone();
    }
    config.validate()?;
    let dataset = args.data.read()?;
    let device = ComputeDevice::Cpu.device().map_err(anyhow::Error::msg)?;

    let checkpoints = args.out.join("ensemble-checkpoints");
    let shape = EnsembleFitShape {
        rows: dataset.len(),
        obs_dim: dataset.obs_dim(),
        act_dim: dataset.act_dim(),
    };
    let resume =
        match checkpoint_to_resume(&checkpoints, args.resume, &args.out, "an ensemble fit")? {
            Some(checkpoint) => {
                let state = load_ensemble_checkpoint(&checkpoint, &config, &shape, &device)
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

    let fit = fit_ensemble(
        &dataset,
        &config,
        args.kernel,
        &device,
        resume,
        &mut |state| {
            let epoch = state.history.last().expect("an epoch behind the state");
            let best = epoch
                .holdout_mse
                .iter()
                .copied()
                .fold(f32::INFINITY, f32::min);
            println!(
                "epoch {:>4}: train loss {:.4}, best member's holdout MSE {best:.5}{}",
                epoch.epoch,
                epoch.train_loss,
                if epoch.improved {
                    ""
                } else {
                    " (no improvement)"
                }
            );
            save_ensemble_checkpoint(&checkpoints, &config, &shape, state)
                .map(|_| ())
                .map_err(|e| EnsembleError::Checkpoint(e.to_string()))
        },
    )?;
    save_ensemble(
        &args.out,
        &fit,
        &config,
        task,
        Some(args.data.info(&dataset)),
    )?;

    let mut table = MetricsTable::new()
        .column("epoch", |e: &EnsembleEpoch| e.epoch.into())
        .column("train_loss", |e: &EnsembleEpoch| e.train_loss.into())
        .column("improved", |e: &EnsembleEpoch| e.improved.into());
    for m in 0..config.members {
        table = table.column(format!("holdout_mse/{m}"), move |e: &EnsembleEpoch| {
            e.holdout_mse[m].into()
        });
    }
    let csv = table.csv(&fit.history);
    let path = args.out.join("ensemble_metrics.csv");
    write_text(&path, &csv)?;
    let names: Vec<String> = (0..config.members).map(|m| format!("member {m}")).collect();
    let series: Vec<Series> = names
        .iter()
        .enumerate()
        .map(|(m, name)| Series {
            name,
            points: fit
                .history
                .iter()
                .map(|e| (e.epoch as f64, f64::from(e.holdout_mse[m])))
                .collect(),
        })
        .collect();
    line_chart(
        &args.out.join("ensemble_holdout.svg"),
        "Gaussian ensemble: holdout MSE",
        "epoch",
        "holdout MSE of (s' − s, r)",
        &series,
    )?;
    println!(
        "{} epochs; elites {:?} (holdout MSE {:?}); written to {}",
        fit.history.len(),
        fit.elites,
        fit.elites
            .iter()
            .map(|&e| fit.holdout_mse[e])
            .collect::<Vec<_>>(),
        args.out.display()
    );
    Ok(())
}
