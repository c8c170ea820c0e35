//! SAC update speed on the CPU at the shape `../shared/bench/nuno_reference.py`
//! measures for its PyTorch and JAX peers: obs 17, act 6, batch 256, 2×256
//! ReLU actor and twin critics, automatic α, Polyak targets.
//!
//! Run: `cargo bench --bench sac` (peer: `.bench-venv/bin/python ../shared/bench/nuno_reference.py`).

use std::time::Instant;

use burn::tensor::Device;
use nuno::agent::{ActorConfig, Sac, SacConfig};
use nuno::data::TransitionBatch;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

fn main() {
    const OBS: usize = 17;
    const ACT: usize = 6;
    const BATCH: usize = 256;
    let device = Device::flex();
    device.seed(0);
    let actor = ActorConfig::new(OBS, ACT, vec![-1.0; ACT], vec![1.0; ACT]);
    let mut sac = Sac::new(actor, SacConfig::new(), &device);
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let mut normal =
        |n: usize| -> Vec<f32> { (0..n).map(|_| rng.sample(StandardNormal)).collect() };
    let batch = TransitionBatch {
        observations: normal(BATCH * OBS),
        actions: normal(BATCH * ACT).iter().map(|x: &f32| x.tanh()).collect(),
        rewards: normal(BATCH),
        next_observations: normal(BATCH * OBS),
        terminals: vec![0.0; BATCH],
    };
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    for _ in 0..20 {
        sac.update(&batch, &mut rng);
    }
    let mut best = f64::MAX;
    for _ in 0..5 {
        let repeats = 100;
        let start = Instant::now();
        for _ in 0..repeats {
            sac.update(&batch, &mut rng);
        }
        best = best.min(start.elapsed().as_secs_f64() / repeats as f64);
    }
    println!("| benchmark (flex backend) | batch | nuno |");
    println!("|---|---|---|");
    println!(
        "| SAC update (obs {OBS}, act {ACT}), updates/s | {BATCH} | {:.1} ({:.2} ms) |",
        1.0 / best,
        best * 1e3
    );
}
