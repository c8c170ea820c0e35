//! The Rust tasks (hopper, halfcheetah, walker2d, swimmer, inverted pendulum,
//! ant) against Python Gymnasium `*-v4` on `mujoco==3.17.0`: the same
//! start states and actions must give the same observations, rewards,
//! terminated and truncated flags (to 1e-9), across falls, resets, the time
//! limit and NeoRL's observation layout.

mod common;

use nuno::envs::{MujocoTask, ObservationLayout, TaskConfig, TaskName};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

const TOLERANCE: f64 = 1e-9;
/// Actions go 30 % beyond each task's control range so MuJoCo's clamping and
/// the control cost on the unclamped action are both exercised.
const ACTION_OVERSHOOT: f64 = 1.3;

#[derive(Serialize)]
struct Episode {
    task: TaskName,
    layout: ObservationLayout,
    max_episode_steps: usize,
    qpos: Vec<f64>,
    qvel: Vec<f64>,
    actions: Vec<Vec<f64>>,
}

#[derive(Serialize, Deserialize, Debug, Default)]
struct Outcome {
    init_qpos: Vec<f64>,
    init_qvel: Vec<f64>,
    first_observation: Vec<f64>,
    observations: Vec<Vec<f64>>,
    rewards: Vec<f64>,
    terminated: Vec<bool>,
    truncated: Vec<bool>,
}

#[derive(Serialize, Deserialize)]
struct Episodes<T> {
    episodes: T,
}

/// Runs one seeded random-action episode in Rust and records it.
fn run_episode(config: TaskConfig, seed: u64) -> (Episode, Outcome) {
    let mut task = MujocoTask::new(&config).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let first_observation = task.reset(Some(seed));
    let (init_qpos, init_qvel) = task.initial_state();
    let mut outcome = Outcome {
        init_qpos: init_qpos.to_vec(),
        init_qvel: init_qvel.to_vec(),
        first_observation,
        ..Outcome::default()
    };
    let mut episode = Episode {
        task: config.task.built_in().expect("a built-in task"),
        layout: config.layout,
        max_episode_steps: config.max_episode_steps,
        qpos: task.qpos().to_vec(),
        qvel: task.qvel().to_vec(),
        actions: Vec::new(),
    };
    let (_, high) = task.action_bounds();
    loop {
        let action: Vec<f64> = (high.iter())
            .map(|h| ACTION_OVERSHOOT * h * rng.random_range(-1.0..1.0))
            .collect();
        let step = task.step(&action).unwrap();
        episode.actions.push(action);
        outcome.observations.push(step.observation);
        outcome.rewards.push(step.reward);
        outcome.terminated.push(step.terminated);
        outcome.truncated.push(step.truncated);
        if step.terminated || step.truncated {
            return (episode, outcome);
        }
    }
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len(), "vector lengths differ");
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
#[cfg_attr(
    not(feature = "external-tests"),
    ignore = "needs the Python venv (`make venv`); `make test` runs it"
)]
fn rust_tasks_match_gymnasium_v4() {
    let mut runs: Vec<(Episode, Outcome)> = Vec::new();
    for name in TaskName::ALL {
        // At least 1000 steps per task: many short falling episodes, or one full one.
        let mut steps = 0;
        for seed in 0.. {
            let run = run_episode(TaskConfig::d4rl(name), seed);
            steps += run.1.rewards.len();
            runs.push(run);
            if steps >= 1000 {
                break;
            }
        }
        // A short time limit, so truncation is checked for the falling tasks too.
        let short = TaskConfig {
            max_episode_steps: 7,
            ..TaskConfig::d4rl(name)
        };
        runs.push(run_episode(short, 1000));
        runs.push(run_episode(TaskConfig::neorl(name), 2000));
    }
    let (episodes, ours): (Vec<Episode>, Vec<Outcome>) = runs.into_iter().unzip();

    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("episodes.json");
    let output = dir.path().join("gymnasium.json");
    std::fs::write(
        &input,
        serde_json::to_vec(&Episodes {
            episodes: &episodes[..],
        })
        .unwrap(),
    )
    .unwrap();
    common::run_python("gymnasium_replay.py", &[&input, &output], dir.path());
    let theirs: Episodes<Vec<Outcome>> =
        serde_json::from_slice(&std::fs::read(&output).unwrap()).unwrap();

    assert_eq!(theirs.episodes.len(), ours.len());
    let (mut steps, mut terminations, mut truncations) = (0, 0, 0);
    for (i, (ours, theirs)) in ours.iter().zip(&theirs.episodes).enumerate() {
        let what = format!(
            "episode {i} ({:?}, {:?})",
            episodes[i].task, episodes[i].layout
        );
        assert!(
            max_abs_diff(&ours.init_qpos, &theirs.init_qpos) == 0.0,
            "{what}: init_qpos"
        );
        assert!(
            max_abs_diff(&ours.init_qvel, &theirs.init_qvel) == 0.0,
            "{what}: init_qvel"
        );
        assert!(
            max_abs_diff(&ours.first_observation, &theirs.first_observation) <= TOLERANCE,
            "{what}: first observation"
        );
        assert_eq!(
            ours.observations.len(),
            theirs.observations.len(),
            "{what}: length"
        );
        for t in 0..ours.observations.len() {
            let diff = max_abs_diff(&ours.observations[t], &theirs.observations[t]);
            assert!(
                diff <= TOLERANCE,
                "{what} step {t}: observations differ by {diff}"
            );
            let diff = (ours.rewards[t] - theirs.rewards[t]).abs();
            assert!(
                diff <= TOLERANCE,
                "{what} step {t}: rewards differ by {diff}"
            );
        }
        assert_eq!(
            ours.terminated, theirs.terminated,
            "{what}: terminated flags"
        );
        assert_eq!(ours.truncated, theirs.truncated, "{what}: truncated flags");
        steps += ours.observations.len();
        terminations += ours.terminated.iter().filter(|&&t| t).count();
        truncations += ours.truncated.iter().filter(|&&t| t).count();
    }
    // The replay must have exercised what it claims to.
    assert!(steps >= 3000, "only {steps} steps compared");
    assert!(terminations >= 10, "only {terminations} falls compared");
    assert!(
        truncations >= 4,
        "only {truncations} time-limit truncations compared"
    );
}
