//! What the model benchmarks share: the hopper set-up at the peer's shapes
//! (`../shared/bench/nuno_reference.py`) and the timing helpers.
// Each bench compiles this module on its own and uses part of it.
#![allow(dead_code)]

use std::time::Instant;

use nuno::agent::PortableActor;
use nuno::data::{Dataset, GenerateConfig, generate};
use nuno::envs::{MujocoTask, TaskConfig, TaskName};
use nuno::sde::{DynamicsSpec, PhysicalScales};

/// Hopper sizes: 11 observed dimensions, 3 actions.
pub const OBS: usize = 11;
pub const ACT: usize = 3;

/// A generated hopper-random dataset and what a model needs from it.
pub struct Hopper {
    pub spec: DynamicsSpec,
    pub dataset: Dataset,
    pub scales: PhysicalScales,
}

impl Hopper {
    /// 20,000 transitions of a random network policy, seed 0.
    pub fn generate() -> Self {
        let task = MujocoTask::new(&TaskConfig::d4rl(TaskName::Hopper)).expect("task");
        let spec = DynamicsSpec {
            obs_dim: OBS,
            act_dim: ACT,
            split: task.state_split(),
            dt: task.dt(),
        };
        let policy = PortableActor::rlkit_random(OBS, ACT, &[256, 256], 0);
        let config = GenerateConfig::new(TaskConfig::d4rl(TaskName::Hopper), "random", 20_000, 0);
        let dataset = generate(&config, &policy, "bench", &|_| {}).expect("dataset");
        let scales = PhysicalScales::measure(&dataset, &spec, &Default::default());
        Self {
            spec,
            dataset,
            scales,
        }
    }

    /// The first `batch` observations, repeated as often as needed, flattened.
    pub fn states(&self, batch: usize) -> Vec<f32> {
        cycled(&self.dataset.observations, batch * OBS)
    }

    /// The first `batch` actions, repeated as often as needed, flattened.
    pub fn actions(&self, batch: usize) -> Vec<f32> {
        cycled(&self.dataset.actions, batch * ACT)
    }
}

fn cycled(values: &ndarray::Array2<f32>, n: usize) -> Vec<f32> {
    values.iter().cycle().take(n).copied().collect()
}

/// Seconds per call of `f`: the best of 5 rounds of enough calls for ~0.2 s.
pub fn seconds_per_call(mut f: impl FnMut()) -> f64 {
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
