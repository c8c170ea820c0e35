//! SAC update speed on the CPU at the shape `../shared/bench/nuno_reference.py`
//! measures for its PyTorch and JAX peers: obs 17, act 6, batch 256, 2×256
//! ReLU actor and twin critics, automatic α, Polyak targets; both kernels;
//! then hopper's own shape (obs 11, act 3).
//!
//! Run: `cargo bench --bench sac` (peer: `.bench-venv/bin/python ../shared/bench/nuno_reference.py`).

use std::time::Instant;

use burn::tensor::Device;
use nuno::agent::{ActorConfig, FusedSac, Sac, SacConfig};
use nuno::nn::seeded_init;
use nuno::shared::TransitionBatch;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// (observation, action) widths: the peers' shape, then hopper's.
const SHAPES: [(usize, usize); 2] = [(17, 6), (11, 3)];
const BATCH: usize = 256;
const HIDDEN: usize = 256;

/// Multiply-adds ×2 of one update: critic target (actor + 2 target critics
/// forward), critic step (2 critics forward + backward with weight and input
/// gradients), actor step (actor forward + backward, 2 critics forward +
/// input-gradient backward).
fn flops_per_update(obs: usize, act: usize) -> f64 {
    let mlp = |d_in: usize, d_out: usize| (d_in * HIDDEN + HIDDEN * HIDDEN + HIDDEN * d_out) as f64;
    let (actor, critic) = (mlp(obs, 2 * act), mlp(obs + act, 1));
    let forward = |weights: f64| 2.0 * BATCH as f64 * weights;
    let target = forward(actor) + 2.0 * forward(critic);
    let critic_step = 2.0 * 3.0 * forward(critic);
    let actor_step = 3.0 * forward(actor) + 2.0 * 2.0 * forward(critic);
    target + critic_step + actor_step
}

/// Best seconds per update over 5 rounds of 100, after 20 warm-up updates.
fn time(mut update: impl FnMut()) -> f64 {
    for _ in 0..20 {
        update();
    }
    let mut best = f64::MAX;
    for _ in 0..5 {
        let start = Instant::now();
        for _ in 0..100 {
            update();
        }
        best = best.min(start.elapsed().as_secs_f64() / 100.0);
    }
    best
}

fn main() {
    println!("| SAC update, batch {BATCH} | kernel | updates/s | ms | GFLOP/s |");
    println!("|---|---|---|---|---|");
    for (obs, act) in SHAPES {
        bench_shape(obs, act);
    }
}

/// Both kernels on the same weights and batch of one shape.
fn bench_shape(obs: usize, act: usize) {
    let device = Device::flex();
    let actor = ActorConfig::new(obs, act, vec![-1.0; act], vec![1.0; act]);
    let mut sac = seeded_init(&device, 0, || Sac::new(actor, SacConfig::new(), &device));
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let mut normal =
        |n: usize| -> Vec<f32> { (0..n).map(|_| rng.sample(StandardNormal)).collect() };
    let batch = TransitionBatch {
        observations: normal(BATCH * obs),
        actions: normal(BATCH * act).iter().map(|x: &f32| x.tanh()).collect(),
        rewards: normal(BATCH),
        next_observations: normal(BATCH * obs),
        terminals: vec![0.0; BATCH],
    };
    let mut fused = FusedSac::from_sac(&sac);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let fused_seconds = time(|| {
        fused.update(&batch, &mut rng);
    });
    let burn_seconds = time(|| {
        sac.update(&batch, &mut rng);
    });
    let gflop = flops_per_update(obs, act) / 1e9;
    for (kernel, seconds) in [("fused", fused_seconds), ("burn (flex)", burn_seconds)] {
        println!(
            "| obs {obs}, act {act}, {gflop:.2} GFLOP | {kernel} | {:.1} | {:.2} | {:.1} |",
            1.0 / seconds,
            seconds * 1e3,
            gflop / seconds
        );
    }
}
