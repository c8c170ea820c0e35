//! The tasks' contracts beyond Gymnasium parity: state split, scores, seeding,
//! the time limit, bad input, and the evaluator's determinism.

use nuno::agent::RandomPolicy;
use nuno::envs::{
    EnvError, EvaluationConfig, Joint, JointKind, MujocoTask, ObservationClip, StateSplit,
    TaskConfig, TaskName, TaskRules, evaluate,
};
use nuno::shared::BatchPolicy;

fn random_policy(task: &MujocoTask) -> RandomPolicy {
    let (low, high) = task.action_bounds();
    let f32s = |v: Vec<f64>| v.into_iter().map(|x| x as f32).collect();
    RandomPolicy::new(task.obs_dim(), f32s(low), f32s(high))
}

#[test]
fn dimensions_and_timesteps_are_d4rl_and_neorl() {
    // (task, D4RL obs dim, NeoRL obs dim, act dim, control limit, dt), from
    // Gymnasium's documentation of each `*-v4` task and its XML's ctrlrange.
    for (name, d4rl, neorl, act, limit, dt) in [
        (TaskName::Hopper, 11, 12, 3, 1.0, 0.008),
        (TaskName::HalfCheetah, 17, 18, 6, 1.0, 0.05),
        (TaskName::Walker2d, 17, 18, 6, 1.0, 0.008),
        (TaskName::Swimmer, 8, 10, 2, 1.0, 0.04),
        (TaskName::InvertedPendulum, 4, 4, 1, 3.0, 0.04),
        (TaskName::Ant, 27, 29, 8, 1.0, 0.05),
    ] {
        let task = MujocoTask::new(&TaskConfig::d4rl(name)).unwrap();
        assert_eq!((task.obs_dim(), task.act_dim()), (d4rl, act), "{name}");
        assert!((task.dt() - dt).abs() < 1e-12, "{name} dt {}", task.dt());
        assert_eq!(task.action_bounds(), (vec![-limit; act], vec![limit; act]));
        let (qpos, qvel) = task.initial_state();
        let spec = name.spec();
        assert_eq!(
            (qpos.len(), qvel.len()),
            (spec.nq, spec.nv),
            "{name} widths"
        );
        let mut task = MujocoTask::new(&TaskConfig::neorl(name)).unwrap();
        assert_eq!(task.obs_dim(), neorl, "{name} NeoRL");
        assert_eq!(task.reset(Some(0)).len(), neorl);
    }
}

#[test]
fn state_split_pairs_each_position_with_its_velocity() {
    // Hopper: root x and z slide, the root's pitch and three joints hinge.
    let joint = |kind, i| Joint {
        kind,
        qpos: i,
        dof: i,
    };
    let kinds = [JointKind::Slide, JointKind::Slide].into_iter();
    let hopper: Vec<Joint> = (kinds.chain([JointKind::Hinge; 4]).enumerate())
        .map(|(i, kind)| joint(kind, i))
        .collect();
    let d4rl = StateSplit::of_joints(&hopper, 6, 6, 1);
    assert_eq!(d4rl.positions, vec![0, 1, 2, 3, 4]);
    assert_eq!(d4rl.velocities, vec![5, 6, 7, 8, 9, 10]);
    assert_eq!(d4rl.position_velocity, vec![6, 7, 8, 9, 10]);
    assert_eq!(d4rl.angles, vec![1, 2, 3, 4]);
    let neorl = StateSplit::of_joints(&hopper, 6, 6, 0);
    assert_eq!(neorl.position_velocity, vec![6, 7, 8, 9, 10, 11]);
    // Ant: a free root (x y z, quaternion; 6 velocities) then 8 hinges. Its
    // height pairs with the root's z velocity; the quaternion has no velocity
    // of its own, so pairing stops there and the hinges are left to the drift.
    let ant: Vec<Joint> = std::iter::once(joint(JointKind::Free, 0))
        .chain((0..8).map(|i| Joint {
            kind: JointKind::Hinge,
            qpos: 7 + i,
            dof: 6 + i,
        }))
        .collect();
    let ant = StateSplit::of_joints(&ant, 15, 14, 2);
    assert_eq!(ant.positions, vec![0]);
    assert_eq!(ant.position_velocity, vec![13 + 2]);
    assert_eq!(ant.velocities, (1..27).collect::<Vec<_>>());
    assert!(ant.angles.is_empty());

    // The angles are the paired positions MuJoCo's model moves by hinge joints,
    // in both layouts: hopper 4, halfcheetah and walker2d 7, swimmer 3 (its
    // root rotation and two joints), the pendulum's 1, the ant's none.
    for (name, angles) in [
        (TaskName::Hopper, 4),
        (TaskName::HalfCheetah, 7),
        (TaskName::Walker2d, 7),
        (TaskName::Swimmer, 3),
        (TaskName::InvertedPendulum, 1),
        (TaskName::Ant, 0),
    ] {
        for config in [TaskConfig::d4rl(name), TaskConfig::neorl(name)] {
            let from = config.layout.qpos_from(name.spec());
            let task = MujocoTask::new(&config).unwrap();
            let split = task.state_split();
            let hinges: Vec<usize> = (task.hinge_qpos().iter())
                .filter(|&&q| q >= from && q - from < split.positions.len())
                .map(|q| q - from)
                .collect();
            assert_eq!(split.angles, hinges, "{name}");
            assert_eq!(hinges.len(), angles, "{name}: {hinges:?}");
        }
    }

    // The pairing is physical: along a trajectory, each observed position's finite
    // difference correlates best, and strongly, with its paired velocity.
    for name in TaskName::ALL {
        let mut task = MujocoTask::new(&TaskConfig::d4rl(name)).unwrap();
        let split = task.state_split();
        let mut observations = vec![task.reset(Some(3))];
        for t in 0..40 {
            let action: Vec<f64> = (0..task.act_dim())
                .map(|i| ((t + i) as f64).sin())
                .collect();
            observations.push(task.step(&action).unwrap().observation);
        }
        let steps = observations.windows(2);
        for (&p, &paired) in split.positions.iter().zip(&split.position_velocity) {
            let finite_difference: Vec<f64> = steps
                .clone()
                .map(|w| (w[1][p] - w[0][p]) / task.dt())
                .collect();
            let best = split
                .velocities
                .iter()
                .map(|&v| {
                    let velocity: Vec<f64> =
                        steps.clone().map(|w| 0.5 * (w[0][v] + w[1][v])).collect();
                    (v, correlation(&finite_difference, &velocity))
                })
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .unwrap();
            assert_eq!(
                best.0, paired,
                "{name}: position {p} tracks velocity {}",
                best.0
            );
            assert!(best.1 > 0.9, "{name}: position {p} correlation {}", best.1);
        }
    }
}

fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len() as f64;
    let (ma, mb) = (mean(a), mean(b));
    let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
    let var = |x: &[f64], m: f64| x.iter().map(|v| (v - m).powi(2)).sum::<f64>();
    cov / (var(a, ma) * var(b, mb)).sqrt()
}

#[test]
fn normalised_scores_use_d4rl_reference_returns() {
    for (name, random, expert) in [
        (TaskName::Hopper, -20.272305, 3234.3),
        (TaskName::HalfCheetah, -280.178953, 12135.0),
        (TaskName::Walker2d, 1.629008, 4592.3),
    ] {
        let reference = TaskConfig::d4rl(name).score_reference();
        assert_eq!(reference.normalize(random), 0.0);
        assert!((reference.normalize(expert) - 100.0).abs() < 1e-12);
        let midpoint = 0.5 * (random + expert);
        assert!((reference.normalize(midpoint) - 50.0).abs() < 1e-9);
    }
    let neorl = TaskConfig::neorl(TaskName::Hopper).score_reference();
    assert!((neorl.normalize(3294.0) - 100.0).abs() < 1e-12);
}

#[test]
fn resets_are_seeded_and_noisy() {
    let mut a = MujocoTask::new(&TaskConfig::d4rl(TaskName::HalfCheetah)).unwrap();
    let mut b = MujocoTask::new(&TaskConfig::d4rl(TaskName::HalfCheetah)).unwrap();
    assert_eq!(a.reset(Some(7)), b.reset(Some(7)));
    assert_ne!(a.reset(Some(7)), a.reset(Some(8)));
    // Without a seed the generator moves on: each reset draws a new start
    // state, and the draws continue the seeded stream (the same on a twin).
    let seeded = a.reset(Some(9));
    let (first, second) = (a.reset(None), a.reset(None));
    assert!(first != seeded && second != first && second != seeded);
    b.reset(Some(9));
    assert_eq!((b.reset(None), b.reset(None)), (first, second));
    let (init_qpos, _) = a.initial_state();
    let deviation = a
        .qpos()
        .iter()
        .zip(init_qpos)
        .map(|(q, q0)| (q - q0).abs())
        .fold(0.0, f64::max);
    assert!(
        deviation > 0.0 && deviation <= 0.1,
        "reset noise {deviation}"
    );
}

#[test]
fn time_limit_truncates_without_terminating() {
    let mut task = MujocoTask::new(&TaskConfig::d4rl(TaskName::HalfCheetah)).unwrap();
    task.reset(Some(0));
    let action = vec![0.1; task.act_dim()];
    for step in 1..=1000 {
        let t = task.step(&action).unwrap();
        assert!(!t.terminated, "halfcheetah never terminates");
        assert_eq!(t.truncated, step == 1000, "truncated at step {step}");
    }
}

#[test]
fn bad_actions_and_states_are_refused_with_what_was_wrong() {
    let mut task = MujocoTask::new(&TaskConfig::d4rl(TaskName::Hopper)).unwrap();
    task.reset(Some(0));
    let err = task.step(&[0.0, 0.0]).unwrap_err();
    assert!(matches!(
        err,
        EnvError::Dimension {
            what: "action",
            expected: 3,
            got: 2
        }
    ));
    assert_eq!(err.to_string(), "action has 2 entries, the task expects 3");
    let err = task.step(&[0.0, f64::NAN, 0.0]).unwrap_err();
    assert!(matches!(
        err,
        EnvError::NonFinite {
            what: "action",
            index: 1
        }
    ));
    let err = task.set_state(&[0.0; 5], &[0.0; 6]).unwrap_err();
    assert!(matches!(
        err,
        EnvError::Dimension {
            what: "qpos",
            expected: 6,
            got: 5
        }
    ));
    let err = "humanoid".parse::<TaskName>().unwrap_err();
    assert!(err.to_string().contains("unknown task `humanoid`"));
    assert_eq!(
        "HalfCheetah".parse::<TaskName>().unwrap(),
        TaskName::HalfCheetah
    );
}

#[test]
fn evaluator_is_deterministic_and_independent_of_thread_count() {
    let config = EvaluationConfig::new(TaskConfig::d4rl(TaskName::Hopper), 13, 5);
    let task = MujocoTask::new(&config.task).unwrap();
    let policy = random_policy(&task);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| evaluate(&policy, &config).unwrap())
    };
    let one = run(1);
    let two = run(2);
    assert_eq!(one, two);
    assert_eq!(one.returns.len(), 13);
    assert!(one.lengths.iter().all(|&l| (1..=1000).contains(&l)));
    let reference = config.task.score_reference();
    for (r, s) in one.returns.iter().zip(&one.normalized_scores) {
        assert_eq!(*s, reference.normalize(*r));
    }
    let mean = one.returns.iter().sum::<f64>() / 13.0;
    assert!((one.mean_return - mean).abs() < 1e-9);
    // Random hopper scores about 1 (D4RL's hopper-random sits near 1.2).
    assert!(one.mean_normalized_score > -1.0 && one.mean_normalized_score < 5.0);
    let other_seed = evaluate(&policy, &EvaluationConfig { seed: 6, ..config }).unwrap();
    assert_ne!(one.returns, other_seed.returns);
}

/// Hopper's zero action whatever the state: episodes depend on their reset seed alone.
struct Still;

impl BatchPolicy for Still {
    fn obs_dim(&self) -> usize {
        11
    }
    fn act_dim(&self) -> usize {
        3
    }
    fn act(&self, observations: &[f32], _: &mut dyn rand::RngCore) -> Vec<f32> {
        vec![0.0; observations.len() / 11 * 3]
    }
}

#[test]
fn episode_seeds_wrap_around_the_largest_seed() {
    // Episode i resets with seed + i mod 2⁶⁴: from u64::MAX the second episode is seed 0's.
    let hopper = TaskConfig::d4rl(TaskName::Hopper);
    let last = evaluate(&Still, &EvaluationConfig::new(hopper.clone(), 2, u64::MAX)).unwrap();
    let zero = evaluate(&Still, &EvaluationConfig::new(hopper.clone(), 1, 0)).unwrap();
    assert_eq!(last.returns[1], zero.returns[0]);
    assert_ne!(last.returns[0], last.returns[1]);
}

/// A policy whose output width is wrong, to check the evaluator refuses it.
struct Broken;

impl BatchPolicy for Broken {
    fn obs_dim(&self) -> usize {
        11
    }
    fn act_dim(&self) -> usize {
        3
    }
    fn act(&self, observations: &[f32], _: &mut dyn rand::RngCore) -> Vec<f32> {
        vec![0.0; observations.len() / 11]
    }
}

#[test]
fn evaluator_refuses_mismatched_policies() {
    let hopper = TaskConfig::d4rl(TaskName::Hopper);
    let walker = MujocoTask::new(&TaskConfig::d4rl(TaskName::Walker2d)).unwrap();
    let err = evaluate(
        &random_policy(&walker),
        &EvaluationConfig::new(hopper.clone(), 2, 0),
    )
    .unwrap_err();
    assert!(
        matches!(
            err,
            EnvError::PolicyMismatch {
                policy: 17,
                task: 11,
                ..
            }
        ),
        "{err}"
    );
    let err = evaluate(&Broken, &EvaluationConfig::new(hopper.clone(), 2, 0)).unwrap_err();
    assert!(
        matches!(
            err,
            EnvError::PolicyOutput {
                batch: 2,
                expected: 6,
                got: 2
            }
        ),
        "{err}"
    );
    let err = evaluate(&Broken, &EvaluationConfig::new(hopper.clone(), 0, 0)).unwrap_err();
    assert!(matches!(err, EnvError::NoEpisodes));
}

/// Plays each episode its own open-loop actions, counting its steps: state
/// per episode, as model-predictive control keeps its last plan.
struct OpenLoop {
    steps: std::collections::HashMap<usize, usize>,
}

/// Episode `episode`'s action at step `t` (distinct per episode, in hopper's box).
fn scripted(episode: usize, t: usize) -> [f64; 3] {
    let phase = episode as f64 + 0.3 * t as f64;
    [phase.sin(), (1.7 * phase).cos(), (0.5 * phase).sin()]
}

impl nuno::envs::EpisodeController for OpenLoop {
    fn obs_dim(&self) -> usize {
        11
    }
    fn act_dim(&self) -> usize {
        3
    }
    fn act(
        &mut self,
        episodes: &[usize],
        _: &[f32],
        _: &mut rand_chacha::ChaCha8Rng,
        _: &nuno::shared::Cancel,
    ) -> Result<Vec<f32>, EnvError> {
        let mut actions = Vec::new();
        for &episode in episodes {
            let t = self.steps.entry(episode).or_default();
            actions.extend(scripted(episode, *t).map(|a| a as f32));
            *t += 1;
        }
        Ok(actions)
    }
}

#[test]
fn a_controller_is_told_which_episode_each_row_is() {
    // 11 episodes: two groups, whose episodes fall at different steps, so
    // the rows a step sees are a shrinking subset of each group.
    let config = EvaluationConfig::new(TaskConfig::d4rl(TaskName::Hopper), 11, 3);
    let make = || OpenLoop {
        steps: Default::default(),
    };
    let cancel = nuno::shared::Cancel::default();
    let report = nuno::envs::evaluate_controlled(&make, &config, &cancel).unwrap();
    // The reference: each episode's script played alone in a fresh task.
    for episode in 0..11 {
        let mut task = MujocoTask::new(&config.task).unwrap();
        let seed = nuno::shared::derive_seed(3, nuno::shared::SeedStream::Episode(episode as u64));
        task.reset(Some(seed));
        let (mut total, mut length) = (0.0, 0);
        loop {
            let step = task
                .step(&scripted(episode, length).map(|a| a as f32 as f64))
                .unwrap();
            total += step.reward;
            length += 1;
            if step.terminated || step.truncated {
                break;
            }
        }
        assert_eq!(report.returns[episode], total, "episode {episode}");
        assert_eq!(report.lengths[episode], length, "episode {episode}");
    }
    let lengths: std::collections::HashSet<_> = report.lengths.iter().collect();
    assert!(
        lengths.len() > 1,
        "every episode lasted as long: {lengths:?}"
    );
}

/// The rules' observation clip is the simulator's own: at a state whose joint
/// velocities pass ±10 both ways, the raw qpos/qvel clipped by the rules is
/// what the task observes (hopper and walker2d, both layouts); halfcheetah
/// observes its velocities unclipped, and its rules have no clip.
#[test]
fn the_rules_observation_clip_is_what_the_task_observes() {
    for config in [
        TaskConfig::d4rl(TaskName::Hopper),
        TaskConfig::neorl(TaskName::Hopper),
        TaskConfig::d4rl(TaskName::Walker2d),
        TaskConfig::neorl(TaskName::HalfCheetah),
    ] {
        let name = config.task.name().to_string();
        let mut task = MujocoTask::new(&config).unwrap();
        let qpos = task.initial_state().0.to_vec();
        // ±(12 + j): every joint velocity outside ±10, alternately above and below.
        let qvel: Vec<f64> = (0..task.qvel().len())
            .map(|j| {
                if j % 2 == 0 {
                    12.0 + j as f64
                } else {
                    -12.0 - j as f64
                }
            })
            .collect();
        let observed: Vec<f32> = (task.set_state(&qpos, &qvel).unwrap())
            .iter()
            .map(|&x| x as f32)
            .collect();
        let observed_qpos = observed.len() - qvel.len();
        let raw: Vec<f32> = (observed[..observed_qpos].iter().copied())
            .chain(qvel.iter().map(|&v| v as f32))
            .collect();
        let clip = TaskRules::of_task(&config).unwrap().observation_clip();
        if name == "halfcheetah" {
            assert_eq!(clip, None);
            assert_eq!(observed, raw, "halfcheetah observes velocities unclipped");
            continue;
        }
        let mut clipped = raw.clone();
        clip.expect("hopper and walker2d clip").apply(&mut clipped);
        assert_eq!(clipped, observed, "{name}");
        assert_ne!(
            raw, observed,
            "{name}: the state's velocities pass the clip"
        );
    }
}

/// Only entries from `from` on are clipped; a non-finite one is left as it is,
/// so a step that diverged still reads as diverged.
#[test]
fn an_observation_clip_leaves_positions_and_non_finite_entries() {
    let clip = ObservationClip {
        from: 1,
        limit: 10.0,
    };
    let mut observation = [50.0, 12.0, -15.0, 3.0, f32::INFINITY];
    clip.apply(&mut observation);
    assert_eq!(observation, [50.0, 10.0, -10.0, 3.0, f32::INFINITY]);
    let mut nan = [0.0, f32::NAN];
    clip.apply(&mut nan);
    assert!(nan[1].is_nan());
}

/// A simulator put in the state an observation shows steps as the one that
/// showed it: D4RL's root x (not observed) matters to none of the robots'
/// dynamics, so the next observation agrees to rounding; NeoRL's observation
/// is the whole state, which comes back exactly.
#[test]
fn a_simulator_set_to_an_observation_steps_as_the_one_that_showed_it() {
    for config in [
        TaskConfig::d4rl(TaskName::Hopper),
        TaskConfig::d4rl(TaskName::Walker2d),
        TaskConfig::neorl(TaskName::HalfCheetah),
    ] {
        let name = config.task.name().to_string();
        let mut walked = MujocoTask::new(&config).unwrap();
        walked.reset(Some(3));
        let action: Vec<f64> = (0..walked.act_dim())
            .map(|j| 0.3 - 0.2 * j as f64)
            .collect();
        for _ in 0..20 {
            walked.step(&action).unwrap();
        }
        let shown = walked.observation();
        let next = walked.step(&action).unwrap().observation;
        let mut set = MujocoTask::new(&config).unwrap();
        assert_eq!(set.set_observation(&shown).unwrap(), shown, "{name}");
        let stepped = set.step(&action).unwrap().observation;
        for (i, (got, want)) in stepped.iter().zip(&next).enumerate() {
            assert!(
                (got - want).abs() < 1e-9,
                "{name}, entry {i}: {got} against {want}"
            );
        }
        let error = set.set_observation(&shown[1..]).unwrap_err();
        assert!(error.to_string().contains("observation"), "{name}: {error}");
    }
}
