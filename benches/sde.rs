//! Neural SDE speed on the CPU, at the shapes `../shared/bench/nuno_reference.py`
//! measures for its PyTorch and JAX peers (hopper sizes, paper networks):
//! batched Euler–Maruyama step throughput (batch 1, 256, 4096, 50000), a
//! 10-step open-loop rollout at batch 50000, and fit steps/s (horizon-2 NLL +
//! η losses, batch 128). burn's flex backend, one model code path.
//!
//! Run: `cargo bench --bench sde` (peer: `.bench-venv/bin/python ../shared/bench/nuno_reference.py --envs hopper`).

use std::time::Instant;

use burn::tensor::{Device, Tensor, TensorData};
use nuno::agent::RandomNetworkPolicy;
use nuno::data::{GenerateConfig, generate};
use nuno::envs::{MujocoTask, TaskConfig, TaskName};
use nuno::sde::{
    DynamicsSpec, FitConfig, LossConfig, NeuralSde, OpenLoop, PhysicalScales, SdeConfig, fit,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The first `n` values of `values`, repeated as often as needed.
fn cycled(values: &ndarray::Array2<f32>, n: usize) -> Vec<f32> {
    values.iter().cycle().take(n).copied().collect()
}

fn main() {
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
    let scales = PhysicalScales::measure(&dataset, &spec, &Default::default());
    let model = NeuralSde::init(spec.clone(), scales, SdeConfig::new(), &device);

    println!("| benchmark (hopper, flex backend) | batch | nuno |");
    println!("|---|---|---|");
    for batch in [1usize, 256, 4096, 50_000] {
        let states = cycled(&dataset.observations, batch * 11);
        let actions = cycled(&dataset.actions, batch * 3);
        let s = Tensor::<2>::from_data(TensorData::new(states, [batch, 11]), &device);
        let a = Tensor::<2>::from_data(TensorData::new(actions, [batch, 3]), &device);
        let repeats = (200_000 / batch).clamp(3, 2000);
        let mut best = f64::MAX;
        for _ in 0..3 {
            let start = Instant::now();
            for _ in 0..repeats {
                let noise = Tensor::<2>::zeros([batch, 11], &device);
                let (next, _) = model.step(s.clone(), a.clone(), noise);
                let _ = next.into_data();
            }
            best = best.min(start.elapsed().as_secs_f64() / repeats as f64);
        }
        println!(
            "| EM step, transitions/s | {batch} | {:.0} |",
            batch as f64 / best
        );
    }

    let batch = 50_000;
    let starts = cycled(&dataset.observations, batch * 11);
    let actions = cycled(&dataset.actions, batch * 10 * 3);
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

    let (train, valid) = dataset.split_by_trajectory(0.1, 0);
    let mut fit_config = FitConfig::new(SdeConfig::new(), LossConfig::new());
    fit_config.max_steps = 200;
    fit_config.eval_every = 1_000_000;
    let start = Instant::now();
    let (_, summary) = fit(&train, &valid, spec, &fit_config, &device, &mut |_| {}).expect("fit");
    println!(
        "| fit step (NLL h=2 + η losses), steps/s | 128 | {:.1} |",
        summary.steps as f64 / start.elapsed().as_secs_f64()
    );
}
