//! Neural SDE speed on the CPU, at the shapes `../shared/bench/nuno_reference.py`
//! measures for its PyTorch and JAX peers (hopper sizes, paper networks):
//! batched Euler–Maruyama step throughput (batch 1, 256, 4096, 50000), a
//! 10-step open-loop rollout at batch 50000, and fit steps/s (horizon-2 NLL +
//! η losses, batch 128) on burn's autodiff and on the fused kernel. burn's flex
//! backend for the rest, one model code path.
//!
//! Run: `cargo bench --bench sde` (peer: `.bench-venv/bin/python ../shared/bench/nuno_reference.py --envs hopper`).

use std::time::Instant;

mod common;

use burn::tensor::{Device, Tensor, TensorData};
use common::{ACT, Hopper, OBS, seconds_per_call};
use nuno::infer::Kernel;
use nuno::sde::{FitConfig, LossConfig, NeuralSde, OpenLoop, SdeConfig, fit};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn main() {
    let hopper = Hopper::generate();
    let device = Device::flex();
    let model = NeuralSde::init(
        hopper.spec.clone(),
        hopper.scales.clone(),
        SdeConfig::new(),
        &device,
    );

    println!("| benchmark (hopper, flex backend) | batch | nuno |");
    println!("|---|---|---|");
    for batch in [1usize, 256, 4096, 50_000] {
        let s =
            Tensor::<2>::from_data(TensorData::new(hopper.states(batch), [batch, OBS]), &device);
        let a = Tensor::<2>::from_data(
            TensorData::new(hopper.actions(batch), [batch, ACT]),
            &device,
        );
        let best = seconds_per_call(|| {
            let noise = Tensor::<2>::zeros([batch, OBS], &device);
            let (next, _) = model.step(s.clone(), a.clone(), noise);
            let _ = next.into_data();
        });
        println!(
            "| EM step, transitions/s | {batch} | {:.0} |",
            batch as f64 / best
        );
    }

    let batch = 50_000;
    let starts = hopper.states(batch);
    let actions = hopper.actions(batch * 10);
    let plan = OpenLoop {
        horizon: 10,
        particles: 1,
        noise_scale: 1.0,
    };
    let start = Instant::now();
    let _ = model.rollout_open_loop(
        &starts,
        &actions,
        plan,
        &mut ChaCha8Rng::seed_from_u64(0),
        &device,
    );
    println!(
        "| 10-step open-loop rollout, transitions/s | {batch} | {:.0} |",
        (batch * 10) as f64 / start.elapsed().as_secs_f64()
    );

    let (train, valid) = hopper.dataset.split_by_trajectory(0.1, 0);
    for kernel in [Kernel::Burn, Kernel::Fused] {
        let mut fit_config = FitConfig::new(SdeConfig::new(), LossConfig::new());
        fit_config.kernel = kernel;
        fit_config.max_steps = match kernel {
            Kernel::Burn => 200,
            Kernel::Fused => 1000,
        };
        fit_config.eval_every = 1_000_000;
        let start = Instant::now();
        let (_, summary) = fit(
            &train,
            &valid,
            hopper.spec.clone(),
            &fit_config,
            &device,
            &mut |_| {},
        )
        .expect("fit");
        println!(
            "| fit step (NLL h=2 + η losses), {kernel}, steps/s | 128 | {:.1} |",
            summary.steps as f64 / start.elapsed().as_secs_f64()
        );
    }
}
