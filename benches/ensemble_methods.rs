//! Update speed of the methods that train in MOPO's ensemble and pay for it
//! at every update, beside SAC's fused update on the same shape (hopper: obs
//! 11, act 3, batch 256, 2×256 networks; the ensemble 7 members of 4×200
//! Swish, 5 elites): MOBILE's update is SAC's plus its Bellman penalty on the
//! batch's 244 model rows (5 elites × 10 sampled next states each through the
//! ensemble, the actor and both target critics), all on the fused kernels.
//! RAMBO's adversarial model step, on burn's autodiff through the ensemble and
//! on the fused kernels: x̂ drawn from the elites for 256 (s, a), its advantage
//! under the critics, and one Adam step on w_adv·mean(log p(x̂)·A) + L_sl on
//! 256 real rows; one adversarial phase takes `adversary_steps` of them.
//! (COMBO's update is CQL's on the mixed batch: `cargo bench --bench model_free`.)
//!
//! Run: `cargo bench --bench ensemble_methods`.

use std::time::Instant;

use burn::tensor::Device;
use nuno::agent::{
    ActorConfig, BellmanPenalty, FusedSac, RAMBO_PRESETS, Sac, SacConfig, advantages, standardise,
};
use nuno::ensemble::{
    AdversarialConfig, AdversarialEnsemble, EnsembleDynamics, EnsembleFit, EnsembleUncertainty,
    GaussianEnsemble, Scaler,
};
use nuno::infer::Kernel;
use nuno::nn::seeded_init;
use nuno::shared::TransitionBatch;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

const OBS: usize = 11;
const ACT: usize = 3;
const BATCH: usize = 256;
/// OfflineRL-Kit's real ratio 0.05 of 256.
const REAL_ROWS: usize = 12;

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

fn main() {
    let device = Device::flex();
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
    let ensemble = hopper_ensemble(&device);
    let actor = ActorConfig::new(OBS, ACT, vec![-1.0; ACT], vec![1.0; ACT]);
    let sac = seeded_init(&device, 0, || Sac::new(actor, SacConfig::new(), &device));
    let penalty = BellmanPenalty::new(1.0);

    println!("| update, hopper's shape, batch {BATCH} | updates/s | ms | × SAC's |");
    println!("|---|---|---|---|");
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let mut fused = FusedSac::from_sac(&sac);
    let sac_seconds = time(200, || {
        fused.update(&batch, &mut rng);
    });
    let row = |name: &str, seconds: f64| {
        println!(
            "| {name} | {:.1} | {:.2} | {:.2} |",
            1.0 / seconds,
            seconds * 1e3,
            sac_seconds / seconds
        );
    };
    row("SAC (fused)", sac_seconds);
    let mut fused = FusedSac::from_sac(&sac);
    let mut values_rng = ChaCha8Rng::seed_from_u64(3);
    let penalty_seconds = time(20, || {
        let mut penalised = batch.clone();
        let mut target = |obs: &[f32], rng: &mut ChaCha8Rng| fused.target_values(obs, rng);
        penalty.penalize(
            &mut penalised,
            REAL_ROWS,
            &ensemble,
            &mut target,
            &mut values_rng,
        );
    });
    row("MOBILE's penalty alone", penalty_seconds);
    let mut fused = FusedSac::from_sac(&sac);
    let mobile_seconds = time(20, || {
        let mut penalised = batch.clone();
        let mut target = |obs: &[f32], rng: &mut ChaCha8Rng| fused.target_values(obs, rng);
        penalty.penalize(
            &mut penalised,
            REAL_ROWS,
            &ensemble,
            &mut target,
            &mut values_rng,
        );
        fused.update(&penalised, &mut rng);
    });
    row("MOBILE (penalty + SAC)", mobile_seconds);

    for kernel in [Kernel::Burn, Kernel::Fused] {
        let seconds = rambo_step_seconds(&batch, &ensemble, &sac, (kernel, &device));
        row(
            &format!("RAMBO's adversarial model step ({kernel})"),
            seconds,
        );
    }
}

/// MOPO's ensemble at hopper's shape (7 members of 4×200, 5 elites), seeded,
/// on the fused path.
fn hopper_ensemble(device: &Device) -> EnsembleDynamics {
    let model = seeded_init(device, 1, || {
        GaussianEnsemble::init(OBS + ACT, OBS + 1, &[200; 4], 7, (0.5, -10.0), device)
    });
    let fit = EnsembleFit {
        model,
        scaler: Scaler {
            mean: vec![0.0; OBS + ACT],
            std: vec![1.0; OBS + ACT],
        },
        elites: (0..5).collect(),
        holdout_mse: vec![0.0; 7],
        history: Vec::new(),
    };
    EnsembleDynamics::new(&fit, OBS, ACT, EnsembleUncertainty::MaxAleatoric).on_fused_path()
}

/// Seconds per RAMBO adversarial model step on `batch`'s 256 rows.
fn rambo_step_seconds(
    batch: &TransitionBatch,
    ensemble: &EnsembleDynamics,
    sac: &Sac,
    (kernel, device): (Kernel, &Device),
) -> f64 {
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    // hopper-medium's w_adv (the weight does not change the work).
    let adv_weight = RAMBO_PRESETS[1].2;
    let mut adversary =
        AdversarialEnsemble::new(ensemble, AdversarialConfig::new(adv_weight), kernel, device);
    let no_terminals = vec![0.0; BATCH];
    let real = (
        &batch.observations[..],
        &batch.actions[..],
        &batch.next_observations[..],
        &batch.rewards[..],
    );
    time(10, || {
        let sample = adversary.sample(&batch.observations, &batch.actions, &mut rng);
        let drawn = (
            &sample.next_observations[..],
            &sample.rewards[..],
            &no_terminals[..],
        );
        let mut advantage = advantages(sac, (&batch.observations, &batch.actions), drawn);
        standardise(&mut advantage);
        adversary.step(&sample, &advantage, real);
    })
}
