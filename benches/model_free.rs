//! Update speed of the model-free baselines (BC, TD3+BC, CQL, EDAC with 10 and
//! 50 critics) at hopper's shape (obs 11, act 3), batch 256, each at its
//! reference settings, beside SAC's burn update on the same shape: on burn's
//! kernels, and CQL's and EDAC's also on the fused kernel
//! (`FusedSac::update_conservative`, `FusedSac::update_edac`).
//!
//! Run: `cargo bench --bench model_free`.

use std::time::Instant;

use burn::tensor::Device;
use nuno::agent::{ActorConfig, FusedSac, Learner, LearnerConfig, Method, Sac, SacConfig};
use nuno::infer::Kernel;
use nuno::nn::seeded_init;
use nuno::shared::TransitionBatch;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

const OBS: usize = 11;
const ACT: usize = 3;
const BATCH: usize = 256;

/// Best seconds per update over 3 rounds of `n`, after `n / 5 + 1` warm-up updates.
fn time(n: usize, mut update: impl FnMut()) -> f64 {
    for _ in 0..n / 5 + 1 {
        update();
    }
    let mut best = f64::MAX;
    for _ in 0..3 {
        let start = Instant::now();
        for _ in 0..n {
            update();
        }
        best = best.min(start.elapsed().as_secs_f64() / n as f64);
    }
    best
}

/// Each baseline's row: name, method, the dataset whose per-task settings it
/// takes (none: the method's defaults), timed updates per round, kernel.
const BASELINES: [(&str, Method, Option<&str>, usize, Kernel); 8] = [
    ("BC", Method::Bc, None, 50, Kernel::Burn),
    ("TD3+BC", Method::Td3Bc, None, 50, Kernel::Burn),
    ("CQL", Method::Cql, None, 10, Kernel::Burn),
    ("CQL (fused)", Method::Cql, None, 20, Kernel::Fused),
    ("EDAC, N = 10", Method::Edac, None, 10, Kernel::Burn),
    (
        "EDAC, N = 50 (hopper)",
        Method::Edac,
        Some("hopper-medium"),
        3,
        Kernel::Burn,
    ),
    (
        "EDAC, N = 10 (fused)",
        Method::Edac,
        None,
        20,
        Kernel::Fused,
    ),
    (
        "EDAC, N = 50 (hopper, fused)",
        Method::Edac,
        Some("hopper-medium"),
        5,
        Kernel::Fused,
    ),
];

fn actor() -> ActorConfig {
    ActorConfig::new(OBS, ACT, vec![-1.0; ACT], vec![1.0; ACT])
}

/// One fixed batch of hopper-shaped transitions.
fn batch() -> TransitionBatch {
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let mut normal =
        |n: usize| -> Vec<f32> { (0..n).map(|_| rng.sample(StandardNormal)).collect() };
    TransitionBatch {
        observations: normal(BATCH * OBS),
        actions: normal(BATCH * ACT).iter().map(|x: &f32| x.tanh()).collect(),
        rewards: normal(BATCH),
        next_observations: normal(BATCH * OBS),
        terminals: vec![0.0; BATCH],
    }
}

fn main() {
    let device = Device::flex();
    let batch = batch();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    println!("| update, hopper's shape, batch {BATCH} | networks | updates/s | ms | × SAC's |");
    println!("|---|---|---|---|---|");
    let mut sac = seeded_init(&device, 0, || Sac::new(actor(), SacConfig::new(), &device));
    let sac_seconds = time(50, || {
        sac.update(&batch, &mut rng);
    });
    let row = |name: &str, networks: &str, seconds: f64| {
        println!(
            "| {name} | {networks} | {:.1} | {:.2} | {:.2} |",
            1.0 / seconds,
            seconds * 1e3,
            sac_seconds / seconds
        );
    };
    row("SAC (burn)", "2×256, 2 critics", sac_seconds);
    let mut fused_sac = FusedSac::from_sac(&sac);
    let fused_seconds = time(50, || {
        fused_sac.update(&batch, &mut rng);
    });
    row("SAC (fused)", "2×256, 2 critics", fused_seconds);
    for (name, method, dataset, n, kernel) in BASELINES {
        let config = match dataset {
            Some(dataset) => LearnerConfig::for_dataset(method, dataset),
            None => LearnerConfig::for_method(method),
        };
        let config = config.expect("a model-free method");
        let hidden = config.hidden();
        let critics = match &config {
            LearnerConfig::Bc(_) => 0,
            LearnerConfig::Edac(c) => c.num_critics,
            _ => 2,
        };
        let mut learner = seeded_init(&device, 0, || Learner::new(actor(), &config, &device));
        let mut fused = learner.fused(kernel);
        let seconds = time(n, || {
            learner.update(fused.as_mut(), &batch, &mut rng);
        });
        row(
            name,
            &format!("{}×{}, {critics} critics", hidden.len(), hidden[0]),
            seconds,
        );
    }
}
