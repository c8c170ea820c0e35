//! Inference speed on the CPU: the fused path ([`nuno::infer`]) against burn's
//! flex backend, at the shapes `../shared/bench/nuno_reference.py` measures
//! for its PyTorch and JAX peers (hopper sizes, paper networks):
//! - one 256×256 layer (the bulk of the work) through each candidate kernel:
//!   burn's matmul, the `gemm` crate, `matrixmultiply`, and the fused layer;
//! - the Euler–Maruyama step at batch 1, 256, 4096, 50000 (drift, σ, η, h(η));
//! - a 10-step rollout with the policy (sampled actions) at batch 50000, through
//!   `agent::rollout_model`, the loop SAC and the server use.
//!
//! Run: `cargo bench --bench infer` (peer, same run:
//! `.bench-venv/bin/python ../shared/bench/nuno_reference.py --envs hopper`).

use std::time::Instant;

use burn::tensor::{Device, Tensor, TensorData};
use nuno::agent::{
    ActionMode, ActorConfig, ActorPolicy, BatchPolicy, RandomNetworkPolicy, RolloutActions,
    RolloutConfig, rollout_model,
};
use nuno::data::{GenerateConfig, generate};
use nuno::envs::{MujocoTask, TaskConfig, TaskName, TaskRules};
use nuno::infer::{Dense, FusedActor, FusedSde, Rows};
use nuno::sde::{BatchDynamics, DynamicsSpec, NeuralSde, PhysicalScales, SdeConfig};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Seconds per call of `f`: the best of 5 rounds of enough calls for ~0.2 s.
fn seconds_per_call(mut f: impl FnMut()) -> f64 {
    f();
    let start = Instant::now();
    f();
    let once = start.elapsed().as_secs_f64().max(1e-7);
    let repeats = ((0.2 / once) as usize).clamp(1, 100_000);
    (0..5)
        .map(|_| {
            let start = Instant::now();
            for _ in 0..repeats {
                f();
            }
            start.elapsed().as_secs_f64() / repeats as f64
        })
        .fold(f64::MAX, f64::min)
}

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
            seconds_per_call(|| layer.forward(Rows::dense(&x, K), &mut out)),
        );
    }
}

fn main() {
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    layer_kernels(&mut rng);

    let task = MujocoTask::new(TaskConfig::d4rl(TaskName::Hopper)).expect("task");
    let spec = DynamicsSpec {
        obs_dim: 11,
        act_dim: 3,
        split: task.state_split(),
        dt: task.dt(),
    };
    let policy = RandomNetworkPolicy::new(11, 3, &[256, 256], 0);
    let config = GenerateConfig::new(TaskConfig::d4rl(TaskName::Hopper), "random", 20_000, 0);
    let dataset = generate(&config, &policy, "bench", &|_| {}).expect("dataset");
    let device = Device::flex();
    device.seed(0);
    let scales = PhysicalScales::measure(&dataset, &spec, &Default::default());
    let burn_model = NeuralSde::init(spec.clone(), scales, SdeConfig::new(), &device);
    let fused_model = FusedSde::new(&burn_model);
    let cycled = |values: &ndarray::Array2<f32>, n: usize| -> Vec<f32> {
        values.iter().cycle().take(n).copied().collect()
    };
    let kernels: [(&str, &dyn BatchDynamics); 2] =
        [("burn flex", &burn_model), ("fused", &fused_model)];

    println!();
    println!("| EM step (hopper) | batch | transitions/s | µs per step |");
    println!("|---|---|---|---|");
    for batch in [1usize, 256, 4096, 50_000] {
        let states = cycled(&dataset.observations, batch * 11);
        let actions = cycled(&dataset.actions, batch * 3);
        let noise = random(batch * 11, &mut rng);
        for (name, model) in kernels {
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

    let actor = ActorConfig::new(11, 3, vec![-1.0; 3], vec![1.0; 3]).init(&device);
    let burn_policy = ActorPolicy {
        actor,
        mode: ActionMode::Sampled,
    };
    let fused_policy = FusedActor::new(&burn_policy);
    let policies: [&dyn BatchPolicy; 2] = [&burn_policy, &fused_policy];
    let rules = TaskRules::new(TaskConfig::d4rl(TaskName::Hopper), &task.state_split());
    let batch = 50_000;
    let starts = cycled(&dataset.observations, batch * 11);
    let plan = RolloutConfig {
        horizon: 10,
        particles: 1,
        penalty: 1.0,
        threshold: None,
        noise_scale: 1.0,
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
}
