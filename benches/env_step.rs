//! Task stepping speed: environment steps per second on one core for each task
//! (random actions, resets on episode end), next to Python Gymnasium `*-v4`
//! stepping the same task in the same run, and the parallel evaluator's
//! throughput over all cores.
//!
//! Run: `make bench` (or `cargo bench --bench env_step`); needs `make venv` for the peer.

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use nuno::agent::RandomPolicy;
use nuno::envs::{EvaluationConfig, MujocoTask, TaskConfig, TaskName, evaluate};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const STEPS: usize = 100_000;
const EVAL_EPISODES: usize = 64;

fn rust_steps_per_second(name: TaskName) -> f64 {
    let mut task = MujocoTask::new(&TaskConfig::d4rl(name)).expect("task");
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let actions: Vec<Vec<f64>> = (0..STEPS)
        .map(|_| {
            (0..task.act_dim())
                .map(|_| rng.random_range(-1.0..1.0))
                .collect()
        })
        .collect();
    task.reset(Some(0));
    let start = Instant::now();
    for action in &actions {
        let t = task.step(action).expect("step");
        if t.terminated || t.truncated {
            task.reset(None);
        }
    }
    STEPS as f64 / start.elapsed().as_secs_f64()
}

fn gymnasium_steps_per_second(name: TaskName) -> Option<f64> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let output = Command::new(root.join(".venv/bin/python"))
        .arg(root.join("benches/gymnasium_step_speed.py"))
        .args([name.as_str(), &STEPS.to_string()])
        .output()
        .ok()?;
    String::from_utf8(output.stdout).ok()?.trim().parse().ok()
}

fn evaluator_steps_per_second(name: TaskName) -> f64 {
    let config = EvaluationConfig::new(TaskConfig::d4rl(name), EVAL_EPISODES, 0);
    let task = MujocoTask::new(&config.task).expect("task");
    let (low, high) = task.action_bounds();
    let f32s = |v: Vec<f64>| v.into_iter().map(|x| x as f32).collect();
    let policy = RandomPolicy::new(task.obs_dim(), f32s(low), f32s(high));
    let start = Instant::now();
    let report = evaluate(&policy, &config).expect("evaluate");
    report.lengths.iter().sum::<usize>() as f64 / start.elapsed().as_secs_f64()
}

fn main() {
    println!("cores: {}", rayon::current_num_threads());
    println!(
        "| task | nuno steps/s (1 core) | Gymnasium v4 steps/s (1 core) | ratio | nuno evaluator steps/s (all cores) |"
    );
    println!("|---|---|---|---|---|");
    for name in TaskName::ALL {
        let ours = rust_steps_per_second(name);
        let peer = gymnasium_steps_per_second(name);
        let evaluator = evaluator_steps_per_second(name);
        let (peer_text, ratio) = match peer {
            Some(p) => (format!("{p:.0}"), format!("{:.2}x", ours / p)),
            None => ("(no .venv: run make venv)".into(), "-".into()),
        };
        println!("| {name} | {ours:.0} | {peer_text} | {ratio} | {evaluator:.0} |");
    }
}
