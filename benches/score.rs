//! Scoring a planner's population in process, beside the EM step it is made
//! of, on the shipped `models/hopper-random` (fused kernel): 400 random
//! candidates × horizon 30 from one start, at 1 and 5 particles (issue 33's
//! sizes). The step's throughput is measured at the rollout's first batch
//! (400 and 2000 rows); the score's counts the steps its particles actually
//! took (a hopper falls, and its particle stops). With `NUNO_SCORE_BODIES=DIR`
//! the same starts, candidates and seeds are written as the `score` route's
//! safetensors bodies (`score-400x30-p{1,5}.bin`, and iCEM's 200 × 10 at one
//! particle, `score-200x10-p1.bin`), so
//! `benches/server_planning.sh` measures the same work over HTTP.
//!
//! Run: `cargo bench --bench score`.

mod common;

use std::collections::HashMap;
use std::path::Path;

use burn::tensor::Device;
use common::seconds_per_call;
use nuno::agent::{RolloutActions, RolloutConfig, TruncatedStep, rollout_model};
use nuno::artifact::{NamedTensors, load_dynamics, safetensors_bytes};
use nuno::envs::{Rules, TaskConfig, TaskName, TaskRules};
use nuno::planning::{Candidates, Cost, ScoreConfig, score_sequences};
use nuno::sde::FusedSde;
use nuno::shared::{BatchDynamics, Cancel};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const CANDIDATES: usize = 400;
const HORIZON: usize = 30;
const SEED: u64 = 0;

fn main() {
    let (model, _) = load_dynamics(Path::new("models/hopper-random"), &Device::flex())
        .expect("the shipped models/hopper-random");
    let fused = FusedSde::new(&model);
    let (obs_dim, act_dim) = (fused.obs_dim(), fused.act_dim());
    let rules = Rules::from(TaskRules::new(
        &TaskConfig::d4rl(TaskName::Hopper),
        fused.dt(),
    ));
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut start = vec![0.0f32; obs_dim];
    start[0] = 1.25;
    let candidates: Vec<f32> = (0..CANDIDATES * HORIZON * act_dim)
        .map(|_| rng.random_range(-1.0..1.0))
        .collect();

    println!(
        "| in process (fused, hopper-random) | particles | rows | transitions/s | steps a call |"
    );
    println!("|---|---|---|---|---|");
    for particles in [1, 5] {
        let rows = CANDIDATES * particles;
        let states = start.repeat(rows);
        let actions: Vec<f32> = candidates[..act_dim].repeat(rows);
        let noise = vec![0.5f32; rows * fused.noise_dim()];
        let step = seconds_per_call(|| {
            let _ = fused.step(&states, &actions, &noise);
        });
        println!(
            "| EM step | {particles} | {rows} | {:.0} | {rows} |",
            rows as f64 / step
        );
        let config = ScoreConfig {
            horizon: HORIZON,
            particles,
            discount: 1.0,
            penalty: 1.0,
            cvar_alpha: None,
            threshold: None,
            noise_scale: fused.sample_noise_scale(),
            cost: Cost::default(),
        };
        let given = Candidates {
            starts: &start,
            sequences: &candidates,
            per_start: CANDIDATES,
        };
        let score = seconds_per_call(|| {
            let mut rng = ChaCha8Rng::seed_from_u64(SEED);
            score_sequences(
                &fused,
                &rules,
                &given,
                &config,
                &mut rng,
                &Cancel::default(),
            )
            .expect("scores");
        });
        // The rollout behind the scores, with the same noise: its steps taken.
        let steps = steps_taken(&fused, &rules, &start, &candidates, &config);
        println!(
            "| `score_sequences` | {particles} | {rows} | {:.0} | {steps} |",
            steps as f64 / score
        );
        if let Ok(dir) = std::env::var("NUNO_SCORE_BODIES") {
            let shape = [CANDIDATES, HORIZON, act_dim];
            write_body(Path::new(&dir), &start, &candidates, shape, particles);
        }
    }
    // iCEM's size (200 × H 10, 1 particle): small requests, for the batcher.
    if let Ok(dir) = std::env::var("NUNO_SCORE_BODIES") {
        let small = &candidates[..200 * 10 * act_dim];
        write_body(Path::new(&dir), &start, small, [200, 10, act_dim], 1);
    }
}

/// The steps the particles of the scored candidates take (kept or dropped).
fn steps_taken(
    dynamics: &dyn BatchDynamics,
    rules: &Rules,
    start: &[f32],
    candidates: &[f32],
    config: &ScoreConfig,
) -> usize {
    let starts = start.repeat(CANDIDATES);
    let rollout = RolloutConfig {
        horizon: config.horizon,
        particles: config.particles,
        penalty: config.penalty,
        threshold: config.threshold,
        noise_scale: config.noise_scale,
        halt: None,
        state_box: None,
        observation_clip: None,
        truncated_step: TruncatedStep::Drop,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(SEED);
    let actions = RolloutActions::Sequence(candidates);
    let trace = rollout_model(dynamics, actions, rules, &starts, &rollout, &mut rng).trace;
    trace.eta.iter().map(Vec::len).sum::<usize>()
        + (trace.outcome.iter())
            .filter(|o| **o == nuno::agent::StepOutcome::Diverged)
            .count()
}

/// The same work as a `score` request: safetensors, `[candidates, horizon,
/// act_dim]` shared, written as `score-{candidates}x{horizon}-p{particles}.bin`.
fn write_body(dir: &Path, start: &[f32], candidates: &[f32], shape: [usize; 3], particles: usize) {
    let tensors = NamedTensors::from([
        ("states".to_string(), (vec![1, start.len()], start.to_vec())),
        (
            "shared_actions".to_string(),
            (shape.to_vec(), candidates.to_vec()),
        ),
    ]);
    let metadata = HashMap::from([
        ("particles".to_string(), particles.to_string()),
        ("seed".to_string(), SEED.to_string()),
    ]);
    let bytes = safetensors_bytes(&tensors, Some(metadata)).expect("body");
    std::fs::create_dir_all(dir).expect("bodies folder");
    let name = format!("score-{}x{}-p{particles}.bin", shape[0], shape[1]);
    std::fs::write(dir.join(name), bytes).expect("body");
}
