//! MOPO's ensemble fit on the CPU: the fused trainer against burn's autodiff,
//! one epoch each from the same initial weights over the same batches
//! (OfflineRL-Kit's model: 7 members of 4×200 swish, batch 256), on 20 000
//! generated hopper-random transitions (1000 held out).
//!
//! Run: `cargo bench --bench ensemble_fit` (peak, same run:
//! `.bench-venv/bin/python ../shared/bench/nuno_reference.py --envs hopper --frameworks jax --quick`).

mod common;

use std::time::Instant;

use burn::tensor::Device;
use common::{ACT, Hopper, OBS};
use nuno::ensemble::{EnsembleConfig, fit_ensemble};
use nuno::infer::Kernel;

fn main() {
    let hopper = Hopper::generate();
    let config = EnsembleConfig::new().with_max_epochs(Some(1));
    let train_rows = hopper.dataset.len() - config.max_holdout;
    let steps = train_rows.div_ceil(config.batch_size);
    // FLOPs of one step: per member and row, 2·m·n per layer forward, as much
    // again for each weight gradient, and for each input gradient but the first.
    let mut widths = vec![OBS + ACT];
    widths.extend(&config.hidden);
    widths.push(2 * (OBS + 1));
    let layer_flops: Vec<f64> = widths
        .windows(2)
        .map(|w| 2.0 * (w[0] * w[1]) as f64)
        .collect();
    let per_row = 3.0 * layer_flops.iter().sum::<f64>() - layer_flops[0];
    let flops_per_step = per_row * (config.members * config.batch_size) as f64;

    println!(
        "| ensemble fit (7 × 4×200 swish, batch 256, hopper) | steps/s | transitions/s (all members) | GFLOP/s | fused / burn |"
    );
    println!("|---|---|---|---|---|");
    let mut burn_seconds = 0.0;
    for kernel in [Kernel::Burn, Kernel::Fused] {
        let start = Instant::now();
        let fit = fit_ensemble(
            &hopper.dataset,
            &config,
            kernel,
            &Device::flex(),
            None,
            &mut |_| Ok(()),
        )
        .expect("fit");
        let seconds = start.elapsed().as_secs_f64();
        assert_eq!(fit.history.len(), 1);
        if kernel == Kernel::Burn {
            burn_seconds = seconds;
        }
        println!(
            "| {kernel} | {:.1} | {:.0} | {:.1} | {:.2}× |",
            steps as f64 / seconds,
            (steps * config.batch_size * config.members) as f64 / seconds,
            flops_per_step * steps as f64 / seconds / 1e9,
            burn_seconds / seconds
        );
    }
}
