//! The fused CPU inference path against burn, the training code path: the same
//! weights must give the same step and action within 1e-5 relative, and the same
//! 10-step rollout within 10 × 1e-5 (each step may add its own rounding), on
//! random inputs of freshly initialised models and on the shipped fitted model.

use std::path::Path;

use burn::tensor::Device;
use nuno::agent::{
    ActionMode, ActorConfig, ActorPolicy, RolloutActions, RolloutConfig, TruncatedStep,
    rollout_model,
};
use nuno::agent::{FusedActor, PortableActor};
use nuno::artifact::{BEST_POLICY, load_dynamics, load_policy};
use nuno::data::{Dataset, GenerateConfig, generate};
use nuno::envs::{MujocoTask, Rules, TaskConfig, TaskName, TaskRules};
use nuno::infer::{
    Dense, GEMM_MIN_ROWS, MAX_TILE_ROWS, Rows, SimdLevel, detected_simd_level, simd_level,
};
use nuno::sde::{DriftInputs, FusedSde};
use nuno::sde::{DynamicsSpec, NeuralSde, PhysicalScales, SdeConfig};
use nuno::shared::BatchDynamics;
use nuno::shared::BatchPolicy;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Relative tolerance of the issue: |fast − burn| ≤ 1e-5·(|burn| + floor), the
/// floor being the value's typical size (RMS of its output), so entries that
/// happen to be near zero are judged on the scale their errors live on.
const TOLERANCE: f64 = 1e-5;

fn assert_close(what: &str, fused: &[f32], burn: &[f32]) {
    assert_close_within(what, fused, burn, TOLERANCE);
}

fn assert_close_within(what: &str, fused: &[f32], burn: &[f32], tolerance: f64) {
    assert_eq!(fused.len(), burn.len(), "{what}: lengths");
    let rms =
        (burn.iter().map(|v| f64::from(*v).powi(2)).sum::<f64>() / burn.len().max(1) as f64).sqrt();
    let mut worst = 0.0f64;
    for (i, (f, b)) in fused.iter().zip(burn).enumerate() {
        let (f, b) = (f64::from(*f), f64::from(*b));
        let relative = (f - b).abs() / (b.abs() + rms);
        assert!(
            relative <= tolerance,
            "{what}[{i}]: fused {f}, burn {b} (relative {relative:.2e})"
        );
        worst = worst.max(relative);
    }
    eprintln!(
        "{what}: worst relative difference {worst:.2e} over {}",
        burn.len()
    );
}

fn normal(n: usize, rng: &mut ChaCha8Rng) -> Vec<f32> {
    (0..n).map(|_| rng.sample(StandardNormal)).collect()
}

fn hopper_spec() -> DynamicsSpec {
    let task = MujocoTask::new(&TaskConfig::d4rl(TaskName::Hopper)).unwrap();
    DynamicsSpec {
        obs_dim: 11,
        act_dim: 3,
        split: task.state_split(),
        dt: task.dt(),
    }
}

fn hopper_data() -> Dataset {
    let policy = nuno::agent::PortableActor::rlkit_random(11, 3, &[64, 64], 7);
    let config = GenerateConfig::new(TaskConfig::d4rl(TaskName::Hopper), "random", 2000, 7);
    generate(&config, &policy, "test", &|_| {}).unwrap()
}

fn shipped() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models/hopper-random")
}

/// Batch sizes that cover the row loop, gemm, one tile and several.
fn batches() -> [usize; 6] {
    [
        1,
        3,
        GEMM_MIN_ROWS - 1,
        GEMM_MIN_ROWS,
        MAX_TILE_ROWS + 1,
        2 * MAX_TILE_ROWS + 37,
    ]
}

/// Steps `burn` and its fused copy on dataset-like rows plus noise.
fn compare_steps(name: &str, burn: &NeuralSde, data: &Dataset, seed: u64) {
    let fused = FusedSde::new(burn);
    let state_dim = burn.state_dim();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for batch in batches() {
        let rows: Vec<usize> = (0..batch)
            .map(|_| rng.random_range(0..data.len()))
            .collect();
        let obs: Vec<f32> = rows
            .iter()
            .flat_map(|&i| data.observations.row(i).to_vec())
            .collect();
        let states = burn.states_from_observations(&obs);
        assert_eq!(states.len(), batch * state_dim);
        // Actions off the data too: the model must agree away from it.
        let actions: Vec<f32> = normal(batch * 3, &mut rng);
        let noise = normal(batch * state_dim, &mut rng);
        let (a, b) = (
            fused.step(&states, &actions, &noise),
            BatchDynamics::step(burn, &states, &actions, &noise),
        );
        let label = |field: &str| format!("{name} batch {batch} {field}");
        assert_close(&label("next_states"), &a.next_states, &b.next_states);
        assert_close(&label("means"), &a.means, &b.means);
        assert_close(&label("sigma"), &a.sigma, &b.sigma);
        assert_close(&label("h_eta"), &a.h_eta, &b.h_eta);
        assert_close(&label("eta"), &a.eta, &b.eta);
        assert_eq!(a.eta.len(), batch);
    }
}

#[test]
fn fused_step_matches_burn_on_random_models() {
    let data = hopper_data();
    let spec = hopper_spec();
    let device = Device::flex();
    let scales = PhysicalScales::measure(&data, &spec, &Default::default());
    for (reward_model, drift_inputs) in [
        (false, DriftInputs::ZScores),
        (true, DriftInputs::ZScores),
        (false, DriftInputs::Pose),
    ] {
        let mut config = SdeConfig::new();
        config.reward_model = reward_model;
        config.drift_inputs = drift_inputs;
        let model = NeuralSde::init(spec.clone(), scales.clone(), config, &device);
        compare_steps(
            &format!("random (reward model {reward_model}, drift inputs {drift_inputs})"),
            &model,
            &data,
            1,
        );
    }
}

#[test]
fn fused_step_matches_burn_on_the_shipped_model() {
    let (model, _) = load_dynamics(&shipped(), &Device::flex()).unwrap();
    compare_steps("shipped hopper-random", &model, &hopper_data(), 2);
}

/// `make test` runs this file once per vector level (`NUNO_SIMD`), so the
/// portable and AVX2 variants are checked on machines that have AVX-512 too.
#[test]
fn the_requested_vector_level_is_the_one_used() {
    let used = simd_level();
    eprintln!(
        "fused kernels on {used:?} (CPU: {:?})",
        detected_simd_level()
    );
    if let Some(cap) = std::env::var("NUNO_SIMD")
        .ok()
        .and_then(|v| SimdLevel::parse(&v))
    {
        assert_eq!(used, cap.min(detected_simd_level()));
    }
}

/// The panic message of `work`, which must panic.
fn panic_message(work: impl FnOnce()) -> String {
    let payload = std::panic::catch_unwind(std::panic::AssertUnwindSafe(work))
        .expect_err("a batch of the wrong shape was accepted");
    payload
        .downcast_ref::<String>()
        .cloned()
        .or_else(|| payload.downcast_ref::<&str>().map(|s| s.to_string()))
        .unwrap_or_default()
}

/// Rows of the wrong width are a caller's bug: both kernels refuse them at the
/// interface, with the same message, instead of truncating (the fused tiles
/// would silently drop the partial row) or failing deep inside burn.
#[test]
fn both_kernels_refuse_batches_of_the_wrong_shape_the_same_way() {
    let device = Device::flex();
    let data = hopper_data();
    let spec = hopper_spec();
    let scales = PhysicalScales::measure(&data, &spec, &Default::default());
    let model = NeuralSde::init(spec, scales, SdeConfig::new(), &device);
    let burn = ActorPolicy {
        actor: ActorConfig::new(11, 3, vec![-1.0; 3], vec![1.0; 3]).init(&device),
        mode: ActionMode::Deterministic,
    };
    let fused_sde = FusedSde::new(&model);
    let fused_actor = FusedActor::new(&burn);
    let dynamics: [&dyn BatchDynamics; 2] = [&model, &fused_sde];
    let policies: [&dyn BatchPolicy; 2] = [&burn, &fused_actor];
    let (states, actions, noise) = (vec![0.0; 2 * 11], vec![0.0; 2 * 3], vec![0.0; 2 * 11]);
    let mut step_messages = Vec::new();
    for d in dynamics {
        // A short state row, a missing action row, a short noise buffer.
        for (s, a, n) in [
            (&states[1..], &actions[..], &noise[1..]),
            (&states[..], &actions[3..], &noise[..]),
            (&states[..], &actions[..], &noise[1..]),
        ] {
            step_messages.push(panic_message(|| {
                d.step(s, a, n);
            }));
        }
    }
    let (burn_messages, fused_messages) = step_messages.split_at(3);
    assert_eq!(burn_messages, fused_messages);
    assert_eq!(
        burn_messages[0],
        "BatchDynamics::step: 21 state, 6 action and 21 noise values are not [batch, 11], \
         [batch, 3] and [batch, 11] rows of one batch"
    );
    let act_messages: Vec<String> = policies
        .iter()
        .map(|p| {
            panic_message(|| {
                p.act(&states[1..], &mut ChaCha8Rng::seed_from_u64(0));
            })
        })
        .collect();
    assert_eq!(act_messages[0], act_messages[1]);
    assert_eq!(
        act_messages[0],
        "BatchPolicy::act: 21 observation values are not [batch, 11] rows"
    );
}

/// The fused actor, and the portable one datasets are generated with, against burn.
#[test]
fn fused_and_portable_actions_match_burn_deterministic_and_sampled() {
    let device = Device::flex();
    let random = ActorConfig::new(11, 3, vec![-1.0, -0.5, 0.0], vec![1.0, 2.0, 0.5]).init(&device);
    let (shipped, _) = load_policy(&shipped(), BEST_POLICY, &device).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for (name, actor) in [("random", random), ("shipped", shipped)] {
        for mode in [ActionMode::Deterministic, ActionMode::Sampled] {
            let burn = ActorPolicy {
                actor: actor.clone(),
                mode,
            };
            let fused = FusedActor::new(&burn);
            let portable = PortableActor::new(&burn);
            for batch in batches() {
                let obs = normal(batch * 11, &mut rng);
                let seed = rng.random();
                let b = burn.act(&obs, &mut ChaCha8Rng::seed_from_u64(seed));
                // log π(a|s) as D4RL records it: the scalar formula against
                // burn's tensor graph (`Actor::sample`).
                let b_logged = burn.act_logged(&obs, &mut ChaCha8Rng::seed_from_u64(seed));
                let kernels: [(&str, &dyn BatchPolicy); 2] =
                    [("fused", &fused), ("portable", &portable)];
                for (kernel, policy) in kernels {
                    let what = format!("{kernel} {name} {mode:?} batch {batch}");
                    let a = policy.act(&obs, &mut ChaCha8Rng::seed_from_u64(seed));
                    assert_close(&what, &a, &b);
                    let a = policy.act_logged(&obs, &mut ChaCha8Rng::seed_from_u64(seed));
                    assert_close(&format!("{what} logged"), &a.actions, &b_logged.actions);
                    match (a.log_probs, b_logged.log_probs.clone(), mode) {
                        (None, None, ActionMode::Deterministic) => {}
                        (Some(a), Some(b), ActionMode::Sampled) => {
                            assert_eq!(a.len(), batch);
                            assert_close(&format!("{what} log π"), &a, &b);
                        }
                        other => panic!("{what}: log-probabilities {other:?}"),
                    }
                }
            }
        }
    }
}

#[test]
fn fused_ten_step_rollouts_match_burn_with_fixed_noise() {
    let device = Device::flex();
    let (model, _) = load_dynamics(&shipped(), &device).unwrap();
    let (actor, _) = load_policy(&shipped(), BEST_POLICY, &device).unwrap();
    let burn_policy = ActorPolicy {
        actor,
        mode: ActionMode::Sampled,
    };
    let fused_policy = FusedActor::new(&burn_policy);
    let fused_model = FusedSde::new(&model);
    let rules = Rules::from(TaskRules::new(
        &TaskConfig::d4rl(TaskName::Hopper),
        model.spec().dt,
    ));
    let data = hopper_data();
    let starts: Vec<f32> = (0..40)
        .flat_map(|i| data.observations.row(i * 37).to_vec())
        .collect();
    let config = RolloutConfig {
        horizon: 10,
        particles: 3,
        penalty: 1.0,
        threshold: None,
        noise_scale: 1.0,
        halt: None,
        state_box: None,
        observation_clip: None,
        truncated_step: TruncatedStep::Drop,
    };
    let run = |model: &dyn BatchDynamics, policy: &dyn BatchPolicy| {
        rollout_model(
            model,
            RolloutActions::Policy(policy),
            &rules,
            &starts,
            &config,
            &mut ChaCha8Rng::seed_from_u64(5),
        )
    };
    let fused = run(&fused_model, &fused_policy);
    let burn = run(&model, &burn_policy);
    assert_eq!(fused.trace.kept, burn.trace.kept, "trajectory lengths");
    assert!(
        burn.stats.transitions > 200,
        "rollouts too short to compare"
    );
    let flat = |v: &Vec<Vec<f32>>| v.iter().flatten().copied().collect::<Vec<f32>>();
    let (f, b) = (&fused.trace, &burn.trace);
    // Each of the 10 steps is within TOLERANCE; their rounding compounds along the rollout.
    let within = TOLERANCE * config.horizon as f64;
    let close = |what: &str, fused: &[f32], burn: &[f32]| {
        assert_close_within(what, fused, burn, within);
    };
    close(
        "rollout observations",
        &flat(&f.observations),
        &flat(&b.observations),
    );
    close("rollout actions", &flat(&f.actions), &flat(&b.actions));
    close("rollout eta", &flat(&f.eta), &flat(&b.eta));
    close(
        "rollout rewards",
        &fused.transitions.rewards,
        &burn.transitions.rewards,
    );
}

#[test]
fn dense_layer_reads_a_column_window_of_wider_rows() {
    // y = x[:, 1..3]·W + b on 9 rows (gemm) and 2 rows (row loop), by hand.
    let layer = Dense::new(2, 3, &[1.0, 2.0, 3.0, -1.0, 0.5, 4.0], vec![0.1, 0.2, 0.3]);
    for rows in [2usize, 9] {
        let x: Vec<f32> = (0..rows * 4).map(|i| i as f32).collect();
        let mut out = vec![0.0; rows * 3];
        layer.forward(Rows::columns(&x, 4, 1, 2), &mut out, None);
        for r in 0..rows {
            let (a, b) = (x[r * 4 + 1], x[r * 4 + 2]);
            let want = [
                0.1 + a - b,
                0.2 + 2.0 * a + 0.5 * b,
                0.3 + 3.0 * a + 4.0 * b,
            ];
            assert_close(
                &format!("window rows {rows} row {r}"),
                &out[r * 3..r * 3 + 3],
                &want,
            );
        }
    }
}

/// A row's output must not depend on the rows beside it: the row loop (fewer
/// than GEMM_MIN_ROWS rows) and gemm (more) give the bits of one chain of
/// fused multiply-adds by hand where the CPU has FMA (gemm's kernels then use
/// it), of plain multiply-then-add otherwise, at whatever level NUNO_SIMD
/// caps. The server's dynamic batching answers a request batched with others
/// as it does alone only because of this.
#[test]
fn a_layers_rows_do_not_depend_on_the_batch_around_them() {
    let mut rng = ChaCha8Rng::seed_from_u64(41);
    let has_fma = detected_simd_level() >= SimdLevel::Avx2;
    for (k, n) in [(14usize, 256usize), (256, 256), (200, 17)] {
        let w: Vec<f32> = (0..k * n).map(|_| rng.random_range(-0.1..0.1)).collect();
        let layer = Dense::new(k, n, &w, vec![0.0; n]);
        let x: Vec<f32> = (0..2 * GEMM_MIN_ROWS * k)
            .map(|_| rng.random_range(-1.0..1.0))
            .collect();
        let chain = |r: usize, j: usize| {
            (0..k).fold(0.0f32, |acc, i| {
                let (a, b) = (x[r * k + i], w[i * n + j]);
                if has_fma {
                    a.mul_add(b, acc)
                } else {
                    acc + a * b
                }
            })
        };
        for rows in [1, GEMM_MIN_ROWS - 1, GEMM_MIN_ROWS, 2 * GEMM_MIN_ROWS] {
            let mut out = vec![0.0; rows * n];
            layer.forward(Rows::dense(&x[..rows * k], k), &mut out, None);
            for r in 0..rows {
                for j in 0..n {
                    assert_eq!(
                        out[r * n + j].to_bits(),
                        chain(r, j).to_bits(),
                        "{k}×{n}, {rows} rows: row {r} column {j} at {:?}",
                        simd_level()
                    );
                }
            }
        }
    }
}
