//! Inference speed on the CPU: the fused path ([`nuno::infer`]) against burn's
//! flex backend, at the shapes `../shared/bench/nuno_reference.py` measures
//! for its PyTorch and JAX peers (hopper sizes, paper networks):
//! - one 256×256 layer (the bulk of the work) through each candidate kernel:
//!   burn's matmul, the `gemm` crate, `matrixmultiply`, and the fused layer;
//! - the Euler–Maruyama step at batch 1, 256, 4096, 50000 (drift, σ, η, h(η));
//! - MOPO's ensemble step at rollout batches, burn and fused;
//! - a 10-step rollout with the policy (sampled actions) at batch 50000, through
//!   `agent::rollout_model`, the loop SAC and the server use;
//! - the same rollout with hopper's reward and termination written as a
//!   system file (an expression and bounds, `envs::SystemSpec`) instead of the
//!   compiled rules, and the expression alone against one model step.
//!
//! Run: `cargo bench --bench infer` (peer, same run:
//! `.bench-venv/bin/python ../shared/bench/nuno_reference.py --envs hopper`).

mod common;

use std::time::Instant;

use burn::tensor::{Device, Tensor, TensorData};
use common::{ACT, Hopper, OBS, seconds_per_call};
use nuno::agent::FusedActor;
use nuno::agent::{
    ActionMode, ActorConfig, ActorPolicy, RolloutActions, RolloutConfig, TruncatedStep,
    rollout_model,
};
use nuno::ensemble::{
    EnsembleDynamics, EnsembleFit, EnsembleUncertainty, GaussianEnsemble, Scaler,
};
use nuno::envs::{Rules, SystemReward, SystemSpec, TaskConfig, TaskName, TaskRules};
use nuno::infer::{Dense, Rows};
use nuno::sde::FusedSde;
use nuno::sde::{NeuralSde, SdeConfig};
use nuno::shared::BatchDynamics;
use nuno::shared::BatchPolicy;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn random(n: usize, rng: &mut ChaCha8Rng) -> Vec<f32> {
    (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
}

/// GFLOP/s of one `[rows, 256] × [256, 256]` layer through each kernel, one core.
fn layer_kernels(rng: &mut ChaCha8Rng) {
    const K: usize = 256;
    const N: usize = 256;
    println!("| kernel (one 256×256 layer, 1 thread) | rows | GFLOP/s |");
    println!("|---|---|---|");
    let device = Device::flex();
    let weight = random(K * N, rng);
    let layer = Dense::new(K, N, &weight, random(N, rng));
    for rows in [1usize, 4, 8, 32, 256, 4096] {
        let x = random(rows * K, rng);
        let mut out = vec![0.0f32; rows * N];
        let flops = 2.0 * (rows * K * N) as f64;
        let report = |name: &str, seconds: f64| {
            println!("| {name} | {rows} | {:.1} |", flops / seconds / 1e9);
        };
        let xt = Tensor::<2>::from_data(TensorData::new(x.clone(), [rows, K]), &device);
        let wt = Tensor::<2>::from_data(TensorData::new(weight.clone(), [K, N]), &device);
        report(
            "burn 0.22.1 flex matmul",
            seconds_per_call(|| {
                let _ = xt.clone().matmul(wt.clone()).into_data();
            }),
        );
        report(
            "gemm 0.19 (AVX-512)",
            seconds_per_call(|| unsafe {
                // SAFETY: x is [rows, K], the weight [K, N], out [rows, N], all row-major.
                gemm::gemm(
                    rows,
                    N,
                    K,
                    out.as_mut_ptr(),
                    1,
                    N as isize,
                    false,
                    x.as_ptr(),
                    1,
                    K as isize,
                    weight.as_ptr(),
                    1,
                    N as isize,
                    0.0,
                    1.0,
                    false,
                    false,
                    false,
                    gemm::Parallelism::None,
                );
            }),
        );
        report(
            "matrixmultiply 0.3.11",
            seconds_per_call(|| unsafe {
                // SAFETY: as above.
                matrixmultiply::sgemm(
                    rows,
                    K,
                    N,
                    1.0,
                    x.as_ptr(),
                    K as isize,
                    1,
                    weight.as_ptr(),
                    N as isize,
                    1,
                    0.0,
                    out.as_mut_ptr(),
                    N as isize,
                    1,
                );
            }),
        );
        report(
            "nuno fused layer (bias + x·W)",
            seconds_per_call(|| layer.forward(Rows::dense(&x, K), &mut out, None)),
        );
    }
}

/// MOPO's ensemble step (7 members of 4×200 swish, hopper sizes) at rollout
/// batches, burn against the fused path, with the GFLOP/s of the members' layers.
fn ensemble_steps(hopper: &Hopper, rng: &mut ChaCha8Rng) {
    let device = Device::flex();
    device.seed(0);
    let d_in = OBS + ACT;
    let hidden = [200usize; 4];
    let model = GaussianEnsemble::init(d_in, OBS + 1, &hidden, 7, (0.5, -10.0), &device);
    let fit = EnsembleFit {
        model,
        scaler: Scaler {
            mean: vec![0.0; d_in],
            std: vec![1.0; d_in],
        },
        elites: (0..5).collect(),
        holdout_mse: vec![0.0; 7],
        history: Vec::new(),
    };
    let burn = EnsembleDynamics::new(&fit, OBS, ACT, EnsembleUncertainty::MaxAleatoric);
    let fused = burn.on_fused_path();
    let widths = [d_in, 200, 200, 200, 200, 2 * (OBS + 1)];
    let flops_per_row: f64 = 7.0
        * widths
            .windows(2)
            .map(|w| 2.0 * (w[0] * w[1]) as f64)
            .sum::<f64>();
    println!();
    println!(
        "| ensemble step (7 × 4×200, hopper) | batch | burn flex: transitions/s | fused: transitions/s | fused GFLOP/s | fused / burn |"
    );
    println!("|---|---|---|---|---|---|");
    for batch in [256usize, 5000, 50_000] {
        let states: Vec<f32> = hopper
            .states(batch)
            .chunks_exact(OBS)
            .flat_map(|s| s.iter().copied().chain([0.0]))
            .collect();
        let actions = hopper.actions(batch);
        let noise = random(batch * (OBS + 2), rng);
        let time = |model: &EnsembleDynamics| {
            seconds_per_call(|| {
                let _ = model.step(&states, &actions, &noise);
            })
        };
        let (b, f) = (time(&burn), time(&fused));
        println!(
            "| | {batch} | {:.0} | {:.0} | {:.1} | {:.2}× |",
            batch as f64 / b,
            batch as f64 / f,
            flops_per_row * batch as f64 / f / 1e9,
            b / f
        );
    }
}

fn main() {
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    layer_kernels(&mut rng);

    let hopper = Hopper::generate();
    let device = Device::flex();
    device.seed(0);
    let burn_model = NeuralSde::init(
        hopper.spec.clone(),
        hopper.scales.clone(),
        SdeConfig::new(),
        &device,
    );
    ensemble_steps(&hopper, &mut rng);
    let fused_model = FusedSde::new(&burn_model);
    let kernels: [(&str, &dyn BatchDynamics); 2] =
        [("burn flex", &burn_model), ("fused", &fused_model)];

    em_steps(&hopper, &kernels, &mut rng);

    let actor = ActorConfig::new(OBS, ACT, vec![-1.0; ACT], vec![1.0; ACT]).init(&device);
    let burn_policy = ActorPolicy {
        actor,
        mode: ActionMode::Sampled,
    };
    let fused_policy = FusedActor::new(&burn_policy);
    let policies: [&dyn BatchPolicy; 2] = [&burn_policy, &fused_policy];
    let rules = Rules::from(TaskRules::new(
        &TaskConfig::d4rl(TaskName::Hopper),
        hopper.spec.dt,
    ));
    let batch = 50_000;
    let starts = hopper.states(batch);
    let plan = RolloutConfig {
        horizon: 10,
        particles: 1,
        penalty: 1.0,
        threshold: None,
        noise_scale: 1.0,
        halt: None,
        state_box: None,
        observation_clip: None,
        truncated_step: TruncatedStep::Drop,
    };
    println!();
    println!("| 10-step rollout with policy (hopper) | batch | transitions/s |");
    println!("|---|---|---|");
    for ((name, model), policy) in kernels.into_iter().zip(policies) {
        let start = Instant::now();
        let out = rollout_model(
            model,
            RolloutActions::Policy(policy),
            &rules,
            &starts,
            &plan,
            &mut ChaCha8Rng::seed_from_u64(0),
        );
        println!(
            "| {name} | {batch} | {:.0} |",
            out.stats.transitions as f64 / start.elapsed().as_secs_f64()
        );
    }
    system_rules(&hopper, &fused_model, &fused_policy, &starts, &plan);
}

/// One Euler–Maruyama step of each kernel at growing batch sizes.
fn em_steps(hopper: &Hopper, kernels: &[(&str, &dyn BatchDynamics)], rng: &mut ChaCha8Rng) {
    println!();
    println!("| EM step (hopper) | batch | transitions/s | µs per step |");
    println!("|---|---|---|---|");
    for batch in [1usize, 256, 4096, 50_000] {
        let states = hopper.states(batch);
        let actions = hopper.actions(batch);
        let noise = random(batch * OBS, rng);
        for &(name, model) in kernels {
            let seconds = seconds_per_call(|| {
                let _ = model.step(&states, &actions, &noise);
            });
            println!(
                "| {name} | {batch} | {:.0} | {:.1} |",
                batch as f64 / seconds,
                seconds * 1e6
            );
        }
    }
}

/// Hopper's D4RL reward and termination as a system file would write them.
const HOPPER_AS_DATA: &str = r#"
name = "hopper-as-data"
dt = 0.008
observations = ["z", "angle", "thigh", "leg", "foot", "vx", "vz", "vangle", "vthigh", "vleg", "vfoot"]
actions = ["a_thigh", "a_leg", "a_foot"]
action_low = [-1.0, -1.0, -1.0]
action_high = [1.0, 1.0, 1.0]

[reward]
expression = "next_vx + 1 - 0.001 * (a_thigh^2 + a_leg^2 + a_foot^2)"

[termination]
bounds = { z = [0.7, 1e9], angle = [-0.2, 0.2], thigh = [-100, 100], leg = [-100, 100], foot = [-100, 100], vx = [-100, 100], vz = [-100, 100], vangle = [-100, 100], vthigh = [-100, 100], vleg = [-100, 100], vfoot = [-100, 100] }
"#;

/// The rollout under compiled rules and under the system file's; the
/// expression's reward over a batch against one fused model step.
fn system_rules(
    hopper: &Hopper,
    model: &dyn BatchDynamics,
    policy: &dyn BatchPolicy,
    starts: &[f32],
    plan: &RolloutConfig,
) {
    let spec = SystemSpec::parse(HOPPER_AS_DATA, std::path::Path::new("bench")).unwrap();
    let compiled = Rules::from(TaskRules::new(
        &TaskConfig::d4rl(TaskName::Hopper),
        hopper.spec.dt,
    ));
    let as_data = Rules::System(std::sync::Arc::new(spec.clone()));
    println!();
    println!("| 10-step rollout, fused (hopper) | rules | transitions/s |");
    println!("|---|---|---|");
    for (name, rules) in [("compiled", &compiled), ("system file", &as_data)] {
        let start = Instant::now();
        let out = rollout_model(
            model,
            RolloutActions::Policy(policy),
            rules,
            starts,
            plan,
            &mut ChaCha8Rng::seed_from_u64(0),
        );
        println!(
            "| {name} | {} | {:.0} |",
            spec.name,
            out.stats.transitions as f64 / start.elapsed().as_secs_f64()
        );
    }
    let SystemReward::Expression(expression) = &spec.reward else {
        unreachable!("the file gives an expression")
    };
    println!();
    println!("| batch | expression reward µs | fused EM step µs | reward / step |");
    println!("|---|---|---|---|");
    for batch in [256usize, 4096, 50_000] {
        let (obs, actions) = (hopper.states(batch), hopper.actions(batch));
        let noise = vec![0.0; batch * OBS];
        let reward = seconds_per_call(|| {
            std::hint::black_box(expression.rewards((&obs, &actions, &obs), (OBS, ACT)));
        });
        let step = seconds_per_call(|| {
            std::hint::black_box(model.step(&obs, &actions, &noise));
        });
        println!(
            "| {batch} | {:.1} | {:.1} | {:.1} % |",
            reward * 1e6,
            step * 1e6,
            100.0 * reward / step
        );
    }
}
