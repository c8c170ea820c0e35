//! SAC and NUNO's policy loop: the math against hand computations, the
//! truncation rule, the real/model batch mix, and a tiny end-to-end run that
//! checkpoints and resumes bit-exactly.

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};
use nuno::agent::{
    ActorConfig, LoopContext, MopoSettings, PRESETS, PolicyLoopConfig, PolicyTraining,
    PortableActor, RolloutActions, RolloutConfig, Sac, SacConfig, StateBox, StepOutcome,
    TruncatedStep, preset, rollout_model,
};
use nuno::artifact::{
    BEST_POLICY, collect_tensors, latest_checkpoint, load_checkpoint, load_dynamics, load_policy,
    save_checkpoint,
};
use nuno::data::{Dataset, GenerateConfig, generate};
use nuno::envs::{
    ForwardVelocity, MujocoTask, ObservationLayout, RootXReward, Rules, System, TaskConfig,
    TaskName, TaskRules,
};
use nuno::infer::Kernel;
use nuno::nn::{polyak_update, seeded_init, to_f32_vec};
use nuno::sde::DynamicsSpec;
use nuno::shared::BatchPolicy;
use nuno::shared::BatchShape;
use nuno::shared::TransitionBatch;
use nuno::shared::{BatchDynamics, ModelStep};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn tensor(values: Vec<f32>, shape: [usize; 2], device: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(values, shape), device)
}

fn small_actor(obs_dim: usize, act_dim: usize, low: f32, high: f32) -> ActorConfig {
    ActorConfig::new(obs_dim, act_dim, vec![low; act_dim], vec![high; act_dim])
        .with_hidden(vec![16, 16])
}

#[test]
fn tanh_gaussian_log_prob_matches_the_change_of_variables_by_hand() {
    let device = Device::flex();
    // A box [-2, 4]: half-width 3, centre 1.
    let actor = seeded_init(&device, 3, || small_actor(4, 3, -2.0, 4.0).init(&device));
    let obs: Vec<f32> = (0..5 * 4).map(|i| (i as f32 * 0.37).sin()).collect();
    let noise: Vec<f32> = (0..5 * 3).map(|i| (i as f32 * 0.91).cos() * 1.5).collect();
    let sample = actor.sample(
        tensor(obs.clone(), [5, 4], &device),
        tensor(noise.clone(), [5, 3], &device),
    );
    let (mean, log_std) = actor.mean_log_std(tensor(obs, [5, 4], &device));
    let (mean, log_std) = (to_f32_vec(mean), to_f32_vec(log_std));
    let actions = to_f32_vec(sample.action);
    let log_probs = to_f32_vec(sample.log_prob);
    for (row, &log_prob) in log_probs.iter().enumerate() {
        let mut expected = 0.0f64;
        for j in 0..3 {
            let k = row * 3 + j;
            let (mu, ls, eps) = (
                f64::from(mean[k]),
                f64::from(log_std[k]),
                f64::from(noise[k]),
            );
            let u = mu + ls.exp() * eps;
            // log N(u; μ, σ) − log(1 − tanh²u) − log(half-width)
            expected += -0.5 * eps * eps
                - ls
                - 0.5 * (2.0 * std::f64::consts::PI).ln()
                - (1.0 - u.tanh().powi(2)).ln()
                - 3.0f64.ln();
            let action = 1.0 + 3.0 * u.tanh();
            assert!((f64::from(actions[k]) - action).abs() < 1e-5, "action {k}");
            assert!((-2.0..=4.0).contains(&actions[k]));
        }
        assert!(
            (f64::from(log_prob) - expected).abs() < 1e-3,
            "row {row}: {log_prob} vs {expected}"
        );
    }
    // Far in the tail tanh²(u) rounds to 1 in f32; the stable form stays finite.
    let far = actor.sample(
        tensor(vec![0.0; 4], [1, 4], &device),
        tensor(vec![1e4; 3], [1, 3], &device),
    );
    assert!(to_f32_vec(far.log_prob)[0].is_finite());
}

fn sac_batch(n: usize, obs_dim: usize, act_dim: usize, terminal: f32) -> TransitionBatch {
    TransitionBatch {
        observations: (0..n * obs_dim).map(|i| (i as f32 * 0.13).sin()).collect(),
        actions: (0..n * act_dim)
            .map(|i| (i as f32 * 0.29).cos() * 0.9)
            .collect(),
        rewards: (0..n).map(|i| i as f32 * 0.5 - 1.0).collect(),
        next_observations: (0..n * obs_dim).map(|i| (i as f32 * 0.17).cos()).collect(),
        terminals: vec![terminal; n],
    }
}

#[test]
fn twin_q_target_uses_the_smaller_target_critic_and_stops_at_terminals() {
    let device = Device::flex();
    let sac = seeded_init(&device, 5, || {
        Sac::new(
            small_actor(3, 2, -1.0, 1.0),
            SacConfig::new()
                .with_critic_hidden(vec![16, 16])
                .with_initial_alpha(0.5),
            &device,
        )
    });
    let (n, plain) = (6, device.clone());
    let next_obs = tensor(
        (0..n * 3).map(|i| (i as f32).sin()).collect(),
        [n, 3],
        &plain,
    );
    let rewards: Vec<f32> = (0..n).map(|i| i as f32).collect();
    let noise = tensor(vec![0.3; n * 2], [n, 2], &plain);

    let y = |terminal: f32| {
        to_f32_vec(sac.critic_target(
            next_obs.clone(),
            tensor(rewards.clone(), [n, 1], &plain),
            tensor(vec![terminal; n], [n, 1], &plain),
            noise.clone(),
        ))
    };
    // By hand: ã' from the same ε, then r + γ(min(Q̄₁, Q̄₂) − α log π).
    let next = sac.actor.valid().sample(next_obs.clone(), noise.clone());
    let (q1, q2) = sac.target_critic.forward(next_obs.clone(), next.action);
    let (q1, q2, logp) = (to_f32_vec(q1), to_f32_vec(q2), to_f32_vec(next.log_prob));
    let live = y(0.0);
    for i in 0..n {
        let expected = rewards[i] + 0.99 * (q1[i].min(q2[i]) - 0.5 * logp[i]);
        assert!(
            (live[i] - expected).abs() < 1e-4,
            "{i}: {} vs {expected}",
            live[i]
        );
    }
    assert_eq!(y(1.0), rewards, "terminal transitions bootstrap nothing");
}

#[test]
fn temperature_moves_toward_the_target_entropy() {
    let device = Device::flex();
    let batch = sac_batch(32, 3, 2, 0.0);
    for (target_entropy, rises) in [(100.0, true), (-100.0, false)] {
        let config = SacConfig::new()
            .with_actor_hidden(vec![16, 16])
            .with_critic_hidden(vec![16, 16])
            .with_target_entropy(Some(target_entropy))
            .with_alpha_lr(0.05);
        let mut sac = seeded_init(&device, 7, || {
            Sac::new(small_actor(3, 2, -1.0, 1.0), config, &device)
        });
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let before = sac.update(&batch, &mut rng).alpha;
        let mut after = before;
        for _ in 0..5 {
            after = sac.update(&batch, &mut rng).alpha;
        }
        assert_eq!(
            after > before,
            rises,
            "H̄ = {target_entropy}: α {before} → {after}"
        );
        assert_eq!(sac.target_entropy, target_entropy);
    }
    // Default H̄ = −|A|.
    let sac = seeded_init(&device, 0, || {
        Sac::new(small_actor(3, 2, -1.0, 1.0), SacConfig::new(), &device)
    });
    assert_eq!(sac.target_entropy, -2.0);
}

#[test]
fn polyak_update_blends_every_parameter() {
    let device = Device::flex();
    let (a, b) = seeded_init(&device, 0, || {
        let init = || small_actor(3, 2, -1.0, 1.0).init(&device);
        (init(), init())
    });
    let (ta, tb) = (collect_tensors(&a), collect_tensors(&b));
    let blended = collect_tensors(&polyak_update(a, &b, 0.25));
    assert_eq!(blended.len(), 6);
    for (name, (_, values)) in &blended {
        for ((v, old), new) in values.iter().zip(&ta[name].1).zip(&tb[name].1) {
            assert!((v - (0.75 * old + 0.25 * new)).abs() < 1e-6, "{name}");
        }
    }
}

/// Dynamics with a known answer: s' = s + 0.01·(a, a, ...), η = 0.3 everywhere.
struct ConstantEta {
    spec: DynamicsSpec,
}

impl BatchDynamics for ConstantEta {
    fn shape(&self) -> BatchShape {
        BatchShape {
            obs_dim: self.spec.obs_dim,
            act_dim: self.spec.act_dim,
            learns_reward: false,
            dt: self.spec.dt,
        }
    }
    fn step(&self, states: &[f32], actions: &[f32], _noise: &[f32]) -> ModelStep {
        let (o, a) = (self.spec.obs_dim, self.spec.act_dim);
        let n = states.len() / o;
        let next: Vec<f32> = (0..n * o)
            .map(|i| states[i] + 0.01 * actions[(i / o) * a])
            .collect();
        ModelStep {
            next_states: next.clone(),
            means: next,
            sigma: vec![0.0; n * o],
            h_eta: vec![0.0; n * o],
            eta: vec![0.3; n],
            truncation_signal: None,
        }
    }
}

/// [`ConstantEta`] until its second call, then not finite on rows whose last
/// observation is marked (≥ 0.5): NaN states where the first is above 1.2, an
/// infinite η on the others.
struct DivergesWhereMarked {
    inner: ConstantEta,
    calls: std::sync::atomic::AtomicUsize,
}

impl BatchDynamics for DivergesWhereMarked {
    fn shape(&self) -> BatchShape {
        self.inner.shape()
    }
    fn step(&self, states: &[f32], actions: &[f32], noise: &[f32]) -> ModelStep {
        let mut step = self.inner.step(states, actions, noise);
        let call = self.calls.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        let o = self.inner.spec.obs_dim;
        if call >= 1 {
            for (row, state) in states.chunks_exact(o).enumerate() {
                if state[o - 1] < 0.5 {
                    continue;
                }
                if state[0] > 1.2 {
                    step.next_states[row * o + 3] = f32::NAN;
                } else {
                    step.eta[row] = f32::INFINITY;
                }
            }
        }
        step
    }
}

#[test]
fn a_diverging_model_ends_its_rollouts_and_keeps_nothing_that_is_not_finite() {
    let hopper = HopperRollouts::new();
    let spec = &hopper.spec;
    let dynamics = DivergesWhereMarked {
        inner: ConstantEta { spec: spec.clone() },
        calls: Default::default(),
    };
    // Upright hoppers; even rows marked, rows 0, 4 higher up (NaN states).
    let starts: Vec<f32> = (0..8)
        .flat_map(|row| {
            let mut start = vec![0.0f32; spec.obs_dim];
            start[0] = if row % 4 == 0 { 1.25 } else { 1.15 };
            start[spec.obs_dim - 1] = if row % 2 == 0 { 1.0 } else { 0.0 };
            start
        })
        .collect();
    let out = hopper.roll(&dynamics, &starts, &plain_rollouts(4, 1, 1.0));
    let diverged = StepOutcome::Diverged;
    for row in 0..8 {
        if row % 2 == 0 {
            assert_eq!(out.trace.kept[row], 1, "row {row}");
            assert_eq!(out.trace.outcome[row], diverged, "row {row}");
        } else {
            assert_eq!(out.trace.kept[row], 4, "row {row}");
            assert_eq!(out.trace.outcome[row], StepOutcome::Continued, "row {row}");
        }
    }
    assert_eq!(out.stats.diverged, 4);
    assert_eq!(out.transitions.len(), 4 + 4 * 4);
    let b = &out.transitions;
    let all = [
        &b.observations,
        &b.actions,
        &b.rewards,
        &b.next_observations,
    ];
    assert!(all.iter().all(|v| v.iter().all(|x| x.is_finite())));
    assert!(out.trace.eta.iter().flatten().all(|e| e.is_finite()));
}

#[test]
fn the_state_box_widens_the_datas_range_by_its_margin() {
    // Hand computation: (0, 1) widened by 0.5 × 1, (−2, 2) by 0.5 × 4.
    let b = StateBox::around(&[(0.0, 1.0), (-2.0, 2.0)], 0.5);
    assert_eq!(
        (b.lower.as_slice(), b.upper.as_slice()),
        (&[-0.5, -4.0][..], &[1.5, 4.0][..])
    );
    assert!(b.contains(&[1.5, -4.0]) && b.contains(&[0.2, 0.0]));
    assert!(!b.contains(&[1.51, 0.0]) && !b.contains(&[0.0, -4.01]));
}

#[test]
fn a_rollout_that_leaves_the_state_box_ends_as_diverged_without_the_step() {
    let hopper = HopperRollouts::new();
    let spec = &hopper.spec;
    let dynamics = ConstantEta { spec: spec.clone() };
    // s' = s + 0.01·0.5 on every dimension: observation 2 reads 0.005, 0.010, 0.015, …
    let starts: Vec<f32> = [0.0f32, -1.0]
        .iter()
        .flat_map(|&thigh| {
            let mut start = vec![0.0f32; spec.obs_dim];
            (start[0], start[2]) = (1.25, thigh);
            start
        })
        .collect();
    let mut upper = vec![10.0; spec.obs_dim];
    upper[2] = 0.012;
    let config = RolloutConfig {
        state_box: Some(StateBox {
            lower: vec![-10.0; spec.obs_dim],
            upper,
        }),
        ..plain_rollouts(4, 1, 1.0)
    };
    let out = hopper.roll(&dynamics, &starts, &config);
    // Row 0 keeps its steps to 0.010 and drops the one to 0.015; row 1 (from −1) stays in.
    assert_eq!(out.trace.kept, vec![2, 4]);
    assert_eq!(
        out.trace.outcome,
        vec![StepOutcome::Diverged, StepOutcome::Continued]
    );
    assert_eq!((out.stats.diverged, out.transitions.len()), (1, 6));
    let o = spec.obs_dim;
    let thighs: Vec<f32> = (out.transitions.next_observations.chunks_exact(o))
        .map(|s| s[2])
        .collect();
    assert!(thighs.iter().all(|&x| x <= 0.012), "{thighs:?}");
}

/// With the task's clip, a model's joint velocity past ±10 is observed at ±10:
/// the kept next state, the next step's start and the reward all read the
/// clipped value; positions are never clipped. Without it they pass 10.
#[test]
fn a_rollout_with_the_tasks_clip_keeps_velocities_where_the_task_observes_them() {
    let hopper = HopperRollouts::new();
    let spec = &hopper.spec;
    let dynamics = ConstantEta { spec: spec.clone() };
    let Rules::Task(rules) = &hopper.rules else {
        unreachable!("hopper's rules are a task's")
    };
    // D4RL hopper: observations 0..5 are qpos[1..], 5..11 qvel; the model adds 0.005 a step.
    let mut start = hopper.upright();
    start[4] = 9.998;
    start[5..].fill(9.998);
    let clipped = RolloutConfig {
        observation_clip: rules.observation_clip(),
        truncated_step: TruncatedStep::Drop,
        ..plain_rollouts(2, 1, 0.0)
    };
    let out = hopper.roll(&dynamics, &start, &clipped);
    assert_eq!(out.transitions.len(), 2);
    let o = spec.obs_dim;
    for (k, next) in out
        .transitions
        .next_observations
        .chunks_exact(o)
        .enumerate()
    {
        let foot = 9.998 + 0.005 * (k + 1) as f32;
        assert!(
            (next[4] - foot).abs() < 1e-5,
            "step {k}: the foot angle {}",
            next[4]
        );
        assert_eq!(&next[5..], &[10.0; 6], "step {k}");
    }
    // Step 2 starts where step 1's clip left it.
    assert_eq!(&out.transitions.observations[o + 5..2 * o], &[10.0; 6]);
    for k in 0..2 {
        let at = k * o..(k + 1) * o;
        let by_hand = hopper.rules.reward(
            &out.transitions.observations[at.clone()],
            &HOPPER_ACTION,
            &out.transitions.next_observations[at],
        );
        assert_eq!(out.transitions.rewards[k], by_hand);
    }
    // Forward velocity 10 + healthy 1 − 1e-3·|a|², the hopper's reward at the clip.
    let control: f32 = HOPPER_ACTION.iter().map(|a| a * a).sum();
    assert!((out.transitions.rewards[0] - (11.0 - 1e-3 * control)).abs() < 1e-5);
    let free = hopper.roll(&dynamics, &start, &plain_rollouts(2, 1, 0.0));
    assert!(free.transitions.next_observations[5] > 10.0);
}

struct Constant(Vec<f32>, usize);

impl BatchPolicy for Constant {
    fn obs_dim(&self) -> usize {
        self.1
    }
    fn act_dim(&self) -> usize {
        self.0.len()
    }
    fn act(&self, observations: &[f32], _rng: &mut dyn rand::RngCore) -> Vec<f32> {
        let n = observations.len() / self.1;
        self.0.repeat(n)
    }
}

fn hopper() -> (TaskConfig, DynamicsSpec) {
    let task = TaskConfig::d4rl(TaskName::Hopper);
    let probe = MujocoTask::new(&task).unwrap();
    let spec = DynamicsSpec {
        obs_dim: probe.obs_dim(),
        act_dim: probe.act_dim(),
        split: probe.state_split(),
        dt: probe.dt(),
    };
    (task, spec)
}

/// The action of every hopper rollout test's policy.
const HOPPER_ACTION: [f32; 3] = [0.5, -0.5, 0.25];

/// What the hopper rollout tests share: the task's rules and a policy that
/// always takes [`HOPPER_ACTION`].
struct HopperRollouts {
    spec: DynamicsSpec,
    rules: Rules,
    policy: Constant,
}

impl HopperRollouts {
    fn new() -> Self {
        let (task, spec) = hopper();
        Self {
            rules: Rules::from(TaskRules::new(&task, spec.dt)),
            policy: Constant(HOPPER_ACTION.to_vec(), spec.obs_dim),
            spec,
        }
    }

    /// An upright hopper (z = 1.25, everything else 0).
    fn upright(&self) -> Vec<f32> {
        let mut start = vec![0.0f32; self.spec.obs_dim];
        start[0] = 1.25;
        start
    }

    fn roll(
        &self,
        dynamics: &dyn BatchDynamics,
        starts: &[f32],
        config: &RolloutConfig,
    ) -> nuno::agent::ModelRollout {
        self.roll_with(dynamics, starts, config, &mut ChaCha8Rng::seed_from_u64(0))
    }

    fn roll_with(
        &self,
        dynamics: &dyn BatchDynamics,
        starts: &[f32],
        config: &RolloutConfig,
        rng: &mut ChaCha8Rng,
    ) -> nuno::agent::ModelRollout {
        let actions = RolloutActions::Policy(&self.policy);
        rollout_model(dynamics, actions, &self.rules, starts, config, rng)
    }

    /// Every transition's reward is the task's known reward of its step at
    /// the constant action, less `penalty` (λ·η: r̃ = r − λ·η).
    fn assert_penalised_by(&self, transitions: &TransitionBatch, penalty: f32) {
        let obs_dim = self.spec.obs_dim;
        for i in 0..transitions.len() {
            let at = i * obs_dim..(i + 1) * obs_dim;
            let reward = self.rules.reward(
                &transitions.observations[at.clone()],
                &HOPPER_ACTION,
                &transitions.next_observations[at],
            );
            assert!(
                (transitions.rewards[i] - (reward - penalty)).abs() < 1e-5,
                "transition {i}"
            );
        }
    }
}

/// Rollouts with no truncation, HALT or state box, at the sampler's own noise.
fn plain_rollouts(horizon: usize, particles: usize, penalty: f64) -> RolloutConfig {
    RolloutConfig {
        horizon,
        particles,
        penalty,
        threshold: None,
        noise_scale: 1.0,
        halt: None,
        state_box: None,
        observation_clip: None,
        truncated_step: TruncatedStep::Drop,
    }
}

/// MOReL's HALT compares each step's own signal (η = 0.3 here), not the sum:
/// under 0.35 nothing halts though the sum passes it; under 0.25 the first
/// step halts, kept as terminal with its reward less κ.
#[test]
fn morels_halt_keeps_the_halting_step_as_terminal_less_kappa() {
    let hopper = HopperRollouts::new();
    let (spec, rules) = (&hopper.spec, &hopper.rules);
    let dynamics = ConstantEta { spec: spec.clone() };
    let start = hopper.upright();
    let starts = start.repeat(4);
    let run = |threshold: f32| {
        let config = RolloutConfig {
            halt: Some(nuno::agent::Halt {
                threshold,
                penalty: 5.0,
            }),
            ..plain_rollouts(10, 1, 0.0)
        };
        hopper.roll(&dynamics, &starts, &config)
    };
    let out = run(0.35);
    assert_eq!(out.transitions.len(), 40);
    assert_eq!((out.stats.halted, out.stats.terminated), (0, 0));
    let out = run(0.25);
    assert_eq!(out.trace.kept, vec![1; 4]);
    assert!(out.trace.outcome.iter().all(|&o| o == StepOutcome::Halted));
    assert_eq!(out.stats.halted, 4);
    assert_eq!(out.transitions.terminals, vec![1.0; 4]);
    for i in 0..4 {
        let next = &out.transitions.next_observations[i * spec.obs_dim..(i + 1) * spec.obs_dim];
        let reward = rules.reward(&start, &HOPPER_ACTION, next);
        assert!((out.transitions.rewards[i] - (reward - 5.0)).abs() < 1e-5);
    }
}

#[test]
fn truncation_drops_the_step_that_passes_epsilon_and_penalises_rewards() {
    let hopper = HopperRollouts::new();
    let spec = &hopper.spec;
    let dynamics = ConstantEta { spec: spec.clone() };
    let start = hopper.upright();
    let starts = start.repeat(4);
    let config = RolloutConfig {
        threshold: Some(1.0),
        ..plain_rollouts(10, 2, 2.0)
    };
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let out = hopper.roll_with(&dynamics, &starts, &config, &mut rng);
    // η = 0.3 per step: 0.3, 0.6, 0.9 are kept, 1.2 > ε truncates.
    assert_eq!(out.trace.rows, 8);
    assert_eq!(out.trace.kept, vec![3; 8]);
    assert!(
        out.trace
            .outcome
            .iter()
            .all(|&o| o == StepOutcome::Truncated)
    );
    assert_eq!(out.transitions.len(), 24);
    assert_eq!(out.stats.truncated, 8);
    for (row, acc) in out.trace.accumulated_eta.iter().enumerate() {
        let kept = out.trace.kept[row];
        assert!(acc[..kept].iter().all(|&a| a <= 1.0));
        assert!(acc[kept] > 1.0);
    }
    // r̃ = r − λ·η = r − 2 · 0.3 with the task's known reward on the next observation.
    hopper.assert_penalised_by(&out.transitions, 0.6);
    assert_eq!(out.transitions.terminals, vec![0.0; 24]);
    // Without a threshold every step is kept; a fallen start ends at once as terminal.
    let free = RolloutConfig {
        threshold: None,
        ..config
    };
    let out = hopper.roll_with(&dynamics, &starts, &free, &mut rng);
    assert_eq!(out.transitions.len(), 80);
    let mut fallen = start.clone();
    fallen[0] = 0.5;
    let out = hopper.roll_with(&dynamics, &fallen, &free, &mut rng);
    assert_eq!(out.trace.kept, vec![1, 1]);
    assert_eq!(out.transitions.terminals, vec![1.0, 1.0]);
    assert_eq!(out.stats.terminated, 2);
}

/// NUNO's code's form: the step that takes accumulated η past ε is kept as a
/// terminal transition, its reward penalised like the others, and the row
/// still ends there; the steps before it are what the dropping form keeps.
#[test]
fn a_truncated_step_kept_as_terminal_ends_its_row_with_a_terminal_transition() {
    let hopper = HopperRollouts::new();
    let spec = &hopper.spec;
    let dynamics = ConstantEta { spec: spec.clone() };
    let starts = hopper.upright().repeat(4);
    let config = RolloutConfig {
        threshold: Some(1.0),
        truncated_step: TruncatedStep::Terminal,
        ..plain_rollouts(10, 2, 2.0)
    };
    let out = hopper.roll(&dynamics, &starts, &config);
    // η = 0.3 per step: 0.3, 0.6, 0.9 continue, 1.2 > ε is kept as terminal.
    assert_eq!(out.trace.kept, vec![4; 8]);
    assert!(
        out.trace
            .outcome
            .iter()
            .all(|&o| o == StepOutcome::Truncated)
    );
    assert_eq!(out.stats.truncated, 8);
    assert_eq!(out.transitions.len(), 32);
    // Transitions go step by step over the rows: the 8 truncating steps come last.
    let terminals: Vec<f32> = [vec![0.0; 24], vec![1.0; 8]].concat();
    assert_eq!(out.transitions.terminals, terminals);
    // r̃ = r − λ·η = r − 2 · 0.3 on the truncating step as on the others.
    hopper.assert_penalised_by(&out.transitions, 0.6);
    let dropped = hopper.roll(
        &dynamics,
        &starts,
        &RolloutConfig {
            truncated_step: TruncatedStep::Drop,
            ..config
        },
    );
    assert_eq!(dropped.transitions.len(), 24);
    assert_eq!(dropped.transitions.terminals, vec![0.0; 24]);
    assert_eq!(
        dropped.transitions.next_observations,
        out.transitions.next_observations[..24 * spec.obs_dim]
    );
}

/// Steps `task` 3000 times with random actions, checking the known terminal rule
/// on every step; returns the mean |known reward − simulator reward|.
fn known_rules_against_the_simulator(task: TaskConfig) -> f64 {
    let mut sim = MujocoTask::new(&task).unwrap();
    let rules = Rules::from(TaskRules::new(&task, sim.dt()));
    let mut obs = sim.reset(Some(1));
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let (mut steps, mut reward_error) = (0, 0.0f64);
    let mut terminals = 0;
    while steps < 3000 {
        let action: Vec<f64> = (0..sim.act_dim())
            .map(|_| rand::Rng::random_range(&mut rng, -1.0..1.0))
            .collect();
        let t = sim.step(&action).unwrap();
        let before: Vec<f32> = obs.iter().map(|&x| x as f32).collect();
        let next: Vec<f32> = t.observation.iter().map(|&x| x as f32).collect();
        let a32: Vec<f32> = action.iter().map(|&x| x as f32).collect();
        assert_eq!(rules.terminal(&next), t.terminated, "step {steps}");
        reward_error += (f64::from(rules.reward(&before, &a32, &next)) - t.reward).abs();
        terminals += usize::from(t.terminated);
        steps += 1;
        obs = if t.terminated || t.truncated {
            sim.reset(Some(steps as u64))
        } else {
            t.observation
        };
    }
    // halfcheetah never terminates; the others' random policy falls often.
    let falls = task.task != nuno::envs::Task::BuiltIn(TaskName::HalfCheetah);
    assert!(
        !falls || terminals > 10,
        "the random policy should fall often ({terminals})"
    );
    reward_error / steps as f64
}

#[test]
fn known_rules_agree_with_the_simulator() {
    // D4RL observations omit root x: the velocity after the step stands in for
    // (x' − x)/dt, close on average (measured under random actions: hopper 0.04,
    // walker2d 0.11, halfcheetah 0.21); the termination rule is exact in every task.
    for (task, bound) in [
        (TaskName::Hopper, 0.1),
        (TaskName::Walker2d, 0.15),
        (TaskName::HalfCheetah, 0.3),
    ] {
        let d4rl = known_rules_against_the_simulator(TaskConfig::d4rl(task));
        assert!(d4rl < bound, "D4RL {task}: mean |Δr| = {d4rl}");
    }
    // NeoRL observations hold root x: (x' − x)/dt is Gymnasium's own reward, up
    // to the f32 rounding of x; the same for every NeoRL task.
    for task in [TaskName::Hopper, TaskName::Walker2d, TaskName::HalfCheetah] {
        let neorl = known_rules_against_the_simulator(TaskConfig::neorl(task));
        assert!(neorl < 1e-3, "NeoRL {task}: mean |Δr| = {neorl}");
    }
}

#[test]
fn presets_are_table_3() {
    assert_eq!(PRESETS.len(), 21);
    let p = preset("hopper-random").unwrap();
    assert_eq!((p.horizon, p.cvar_alpha, p.penalty), (10, 1.0, 0.001));
    let p = preset("walker2d-medium-replay").unwrap();
    assert_eq!((p.horizon, p.cvar_alpha, p.penalty), (10, 0.95, 1.0));
    let p = preset("neorl-hopper-medium").unwrap();
    assert_eq!(
        (p.horizon, p.cvar_alpha, p.penalty, p.layout),
        (5, 0.9, 0.1, ObservationLayout::Neorl)
    );
    let err = preset("hopper-expert").unwrap_err().to_string();
    assert!(
        err.contains("hopper-expert") && err.contains("hopper-medium-expert"),
        "{err}"
    );
}

fn tiny_config(seed: u64) -> PolicyLoopConfig {
    let sac = SacConfig::new()
        .with_actor_hidden(vec![16, 16])
        .with_critic_hidden(vec![16, 16])
        .with_batch_size(32);
    let mut config = PolicyLoopConfig::from_preset(preset("hopper-random").unwrap(), sac);
    config.horizon = 5;
    config.rollout_freq = 10;
    config.rollout_batch = 64;
    config.steps_per_epoch = 15;
    config.epochs = 2;
    config.eval_episodes = 1;
    config.eta_probe_states = 50;
    config.seed = seed;
    config
}

fn shipped_model() -> (nuno::sde::NeuralSde, nuno::artifact::DynamicsMetadata) {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models/hopper-random");
    load_dynamics(&dir, &Device::flex()).unwrap()
}

/// The shipped policy is the one models/README.md documents (the best of a
/// 57-epoch run in the shipped model: 2×256, normalised 53.2 at epoch 49), not
/// a tiny run saved over it by mistake, as commit 1d8ed12 once did: its
/// deterministic episodes still score far above a random policy's ≈ 1.
#[test]
fn the_shipped_policy_is_the_documented_one() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models/hopper-random");
    let (actor, metadata) = load_policy(&dir, BEST_POLICY, &Device::flex()).unwrap();
    assert_eq!(metadata.actor.hidden, [256, 256]);
    assert_eq!(
        (metadata.provenance.epoch, metadata.provenance.step),
        (49, 49_000)
    );
    let sha = nuno::artifact::sha256_file(&dir.join("dynamics.safetensors")).unwrap();
    assert_eq!(metadata.provenance.dynamics_sha256.as_deref(), Some(&*sha));
    let policy = Kernel::Fused.policy(nuno::agent::ActorPolicy {
        actor,
        mode: nuno::agent::ActionMode::Deterministic,
    });
    let config = nuno::envs::EvaluationConfig::new(TaskConfig::d4rl(TaskName::Hopper), 2, 100);
    let report = nuno::envs::evaluate(policy.as_ref(), &config).unwrap();
    assert!(
        report.mean_normalized_score > 40.0,
        "the shipped policy scores {:.1}",
        report.mean_normalized_score
    );
}

fn small_dataset() -> Dataset {
    let policy = PortableActor::rlkit_random(11, 3, &[64, 64], 4);
    let config = GenerateConfig::new(TaskConfig::d4rl(TaskName::Hopper), "random", 3000, 4);
    generate(&config, &policy, "test", &|_| {}).unwrap()
}

/// The loop's context for D4RL hopper.
fn hopper_context<'a>(model: &'a nuno::sde::NeuralSde, dataset: &'a Dataset) -> LoopContext<'a> {
    let system = System::Task(TaskConfig::d4rl(TaskName::Hopper));
    LoopContext {
        dataset,
        dynamics: model,
        rules: system.rules_on(model.constants.spec.dt),
        system,
        // burn throughout, like the dynamics (the fused path: tests/infer.rs, the CLI test).
        kernel: Kernel::Burn,
        ensemble: None,
    }
}

/// The loop's box is the dataset's own range per dimension, widened by the margin.
#[test]
fn the_loops_state_box_is_the_datasets_range_widened_by_its_margin() {
    let (model, metadata) = shipped_model();
    let dataset = small_dataset();
    let ctx = hopper_context(&model, &dataset);
    let mut config = tiny_config(0);
    config.state_box_margin = Some(0.25);
    let threshold = (config.threshold_from(metadata.provenance.thresholds.as_ref())).unwrap();
    let training = PolicyTraining::new(config, &ctx, threshold, &Device::flex()).unwrap();
    let state_box = training.state_box.expect("a margin makes a box");
    for j in 0..dataset.obs_dim() {
        let column: Vec<f32> = dataset.observations.column(j).to_vec();
        let low = column.iter().copied().fold(f32::INFINITY, f32::min);
        let high = column.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        let widening = 0.25 * (high - low);
        assert_eq!(state_box.lower[j], low - widening, "dimension {j}");
        assert_eq!(state_box.upper[j], high + widening, "dimension {j}");
    }
}

/// NUNO's code keeps 10× as many model transitions (D3): the buffer holds
/// `model_buffer_factor` × rollout batch × h × particles × retained rollouts.
#[test]
fn the_model_buffer_holds_its_factor_of_rollouts() {
    let (model, metadata) = shipped_model();
    let dataset = small_dataset();
    let ctx = hopper_context(&model, &dataset);
    let held = |factor: usize| {
        let mut config = tiny_config(0);
        config.model_buffer_factor = factor;
        // 64 starts × h = 5 × 1 particle × 5 rollouts = 1600 per factor.
        let threshold = config
            .threshold_from(metadata.provenance.thresholds.as_ref())
            .unwrap();
        let mut training = PolicyTraining::new(config, &ctx, threshold, &Device::flex()).unwrap();
        let rows = 2500;
        training.model_buffer.push(&TransitionBatch {
            observations: vec![0.0; rows * 11],
            actions: vec![0.0; rows * 3],
            rewards: vec![0.0; rows],
            next_observations: vec![0.0; rows * 11],
            terminals: vec![0.0; rows],
        });
        training.model_buffer.len()
    };
    assert_eq!(held(1), 1600);
    assert_eq!(held(2), 2500);
}

/// NUNO's code rewards the mean x-velocity over the step (D6); by hand on
/// hopper's D4RL observation (x-velocity at index 5, healthy reward 1,
/// control cost 1e-3·‖a‖²).
#[test]
fn the_known_reward_reads_the_velocity_it_is_told() {
    let rules = Rules::from(TaskRules::of_task(&TaskConfig::d4rl(TaskName::Hopper)).unwrap());
    let mut obs = vec![0.0f32; 11];
    obs[0] = 1.25;
    obs[5] = 1.0;
    let mut next = obs.clone();
    next[5] = 3.0;
    let action = [0.5f32, 0.0, 0.0];
    let cost = 1e-3 * 0.25;
    let after = rules.reward(&obs, &action, &next);
    assert!((after - (3.0 + 1.0 - cost)).abs() < 1e-6, "{after}");
    let mean = rules
        .with_forward_reward(ForwardVelocity::Mean, RootXReward::Difference)
        .reward(&obs, &action, &next);
    assert!((mean - (2.0 + 1.0 - cost)).abs() < 1e-6, "{mean}");
    // D4RL's observations hold no root x: asking for its velocity changes nothing.
    let no_root_x = rules.with_forward_reward(ForwardVelocity::Mean, RootXReward::Velocity);
    assert_eq!(no_root_x.reward(&obs, &action, &next), mean);
    // NeoRL's hold root x (entry 0; its velocity at 6, dt 0.008): the finite
    // difference, 0.016 / 0.008 = 2, whatever velocity is named, unless the run
    // asks for the velocity itself (4 before the step, 6 after).
    let neorl = Rules::from(TaskRules::of_task(&TaskConfig::neorl(TaskName::Hopper)).unwrap());
    let (mut x, mut x_next) = (vec![0.0f32; 12], vec![0.0f32; 12]);
    (x[1], x_next[1], x_next[0]) = (1.25, 1.25, 0.016);
    (x[6], x_next[6]) = (4.0, 6.0);
    let reward = |velocity, root_x| {
        neorl
            .with_forward_reward(velocity, root_x)
            .reward(&x, &action, &x_next)
    };
    let by_hand = [
        (ForwardVelocity::Next, RootXReward::Difference, 2.0),
        (ForwardVelocity::Mean, RootXReward::Difference, 2.0),
        (ForwardVelocity::Next, RootXReward::Velocity, 6.0),
        (ForwardVelocity::Mean, RootXReward::Velocity, 5.0),
    ];
    for (velocity, root_x, forward) in by_hand {
        let got = reward(velocity, root_x);
        assert!(
            (got - (forward + 1.0 - cost)).abs() < 1e-5,
            "{velocity} {root_x}: {got}"
        );
    }
    assert_eq!(
        neorl.reward(&x, &action, &x_next),
        reward(ForwardVelocity::Next, RootXReward::Difference)
    );
}

/// OfflineRL-Kit's MOPO: actor and α at 1e-4, the actor's rate cosine-annealed
/// per epoch (PyTorch's `CosineAnnealingLR(T_max = epochs)`, by hand), 50 000 starts.
#[test]
fn mopo_follows_offlinerl_kits_settings_unless_told_nuno() {
    let mut config = tiny_config(0);
    config.epochs = 4;
    config.apply_mopo_settings(MopoSettings::OfflinerlKit);
    assert_eq!((config.sac.actor_lr, config.sac.alpha_lr), (1e-4, 1e-4));
    assert_eq!(config.rollout_batch, 50_000);
    let lr: Vec<f64> = (0..4).map(|e| config.actor_lr_at(e)).collect();
    let by_hand = [1e-4, 0.853_553_4e-4, 0.5e-4, 0.146_446_6e-4];
    for (got, want) in lr.iter().zip(by_hand) {
        assert!((got - want).abs() < 1e-11, "{lr:?}");
    }
    config.apply_mopo_settings(MopoSettings::Nuno);
    assert_eq!((config.sac.actor_lr, config.sac.alpha_lr), (3e-4, 3e-4));
    assert_eq!((config.actor_lr_at(0), config.actor_lr_at(3)), (3e-4, 3e-4));
    assert_eq!(config.rollout_batch, 5000);
}

#[test]
fn batches_mix_real_and_model_data_at_beta() {
    let (model, metadata) = shipped_model();
    let dataset = small_dataset();
    let ctx = hopper_context(&model, &dataset);
    let mut config = tiny_config(0);
    config.sac.batch_size = 256;
    config.real_ratio = 0.05;
    let device = Device::flex();
    let threshold = config
        .threshold_from(metadata.provenance.thresholds.as_ref())
        .unwrap();
    let mut training = PolicyTraining::new(config, &ctx, threshold, &device).unwrap();
    // Empty model buffer: all real.
    let batch = training.mixed_batch(&dataset);
    assert_eq!(batch.len(), 256);
    let marker = 1234.5f32;
    let o = dataset.obs_dim();
    training.model_buffer.push(&TransitionBatch {
        observations: vec![marker; o],
        actions: vec![0.0; 3],
        rewards: vec![0.0],
        next_observations: vec![marker; o],
        terminals: vec![0.0],
    });
    let batch = training.mixed_batch(&dataset);
    let from_model: Vec<bool> = batch
        .observations
        .chunks(o)
        .map(|row| row[0] == marker)
        .collect();
    assert_eq!(batch.len(), 256);
    assert!(
        from_model[..12].iter().all(|m| !m),
        "int(0.05·256) = 12 real rows first (NUNO's code), not 13"
    );
    assert!(from_model[12..].iter().all(|&m| m), "then 244 model rows");
}

#[test]
fn the_loop_runs_checkpoints_and_resumes_bit_exactly_with_burn() {
    runs_checkpoints_and_resumes_bit_exactly(Kernel::Burn);
}

#[test]
fn the_loop_runs_checkpoints_and_resumes_bit_exactly_with_the_fused_kernel() {
    runs_checkpoints_and_resumes_bit_exactly(Kernel::Fused);
}

fn runs_checkpoints_and_resumes_bit_exactly(kernel: Kernel) {
    let (model, metadata) = shipped_model();
    let dataset = small_dataset();
    let ctx = LoopContext {
        kernel,
        ..hopper_context(&model, &dataset)
    };
    let thresholds = metadata.provenance.thresholds.as_ref();
    let threshold = tiny_config(0).threshold_from(thresholds).unwrap();
    let device = Device::flex();

    // Two epochs straight through. Its initial state is saved too: burn draws
    // initial weights from a process-wide generator that tests running in
    // parallel share, so a second `new` would not start from the same weights.
    let mut straight = PolicyTraining::new(tiny_config(9), &ctx, threshold, &device).unwrap();
    assert_eq!(straight.threshold, thresholds.unwrap().get(5, 1.0));
    let initial = tempfile::tempdir().unwrap();
    save_checkpoint(initial.path(), &straight).unwrap();
    for _ in 0..2 {
        straight.run_epoch(&ctx).unwrap();
    }
    assert_eq!((straight.epoch, straight.step), (2, 30));
    let last = straight.history.last().unwrap();
    assert!(last.losses.qf1_loss.is_finite() && last.losses.actor_loss.is_finite());
    assert!(last.eval.mean_return.is_finite() && last.rollout.transitions > 0);
    assert!(!straight.model_buffer.is_empty());

    // One epoch, a checkpoint, a fresh process state, the second epoch.
    let dir = tempfile::tempdir().unwrap();
    let mut first = PolicyTraining::new(tiny_config(9), &ctx, threshold, &device).unwrap();
    let start = latest_checkpoint(initial.path()).unwrap().unwrap();
    load_checkpoint(&start, &mut first).unwrap();
    assert_eq!((first.epoch, first.step), (0, 0));
    first.run_epoch(&ctx).unwrap();
    save_checkpoint(dir.path(), &first).unwrap();
    drop(first);
    let mut resumed = PolicyTraining::new(tiny_config(9), &ctx, threshold, &device).unwrap();
    let checkpoint = latest_checkpoint(dir.path()).unwrap().unwrap();
    load_checkpoint(&checkpoint, &mut resumed).unwrap();
    assert_eq!((resumed.epoch, resumed.step), (1, 15));
    resumed.run_epoch(&ctx).unwrap();

    assert_eq!(
        collect_tensors(&resumed.sac.actor),
        collect_tensors(&straight.sac.actor)
    );
    assert_eq!(
        collect_tensors(&resumed.sac.critic),
        collect_tensors(&straight.sac.critic)
    );
    assert_eq!(resumed.sac.adam, straight.sac.adam);
    assert_eq!(resumed.model_buffer, straight.model_buffer);
    let strip = |h: &[nuno::agent::EpochRecord]| -> Vec<String> {
        h.iter()
            .map(|r| format!("{:?} {:?} {:?}", r.losses, r.eval, r.eta))
            .collect()
    };
    assert_eq!(strip(&resumed.history), strip(&straight.history));

    // A checkpoint from other settings is refused by name.
    let mut other = PolicyTraining::new(tiny_config(10), &ctx, threshold, &device).unwrap();
    let err = load_checkpoint(&checkpoint, &mut other)
        .unwrap_err()
        .to_string();
    assert!(err.contains("different configuration"), "{err}");
}

/// Every network parameter and Adam moment of `a` within `tolerance` (relative,
/// or absolute near zero) of `b`'s.
fn assert_agents_close(a: &PolicyTraining, b: &PolicyTraining, tolerance: f32) {
    let close = |what: &str, x: &[f32], y: &[f32]| {
        assert_eq!(x.len(), y.len(), "{what}");
        for (i, (x, y)) in x.iter().zip(y).enumerate() {
            assert!(
                (x - y).abs() <= tolerance * y.abs().max(1e-2),
                "{what}[{i}]: {x} vs {y}"
            );
        }
    };
    for (name, (x, y)) in [
        (
            "actor",
            (collect_tensors(&a.sac.actor), collect_tensors(&b.sac.actor)),
        ),
        (
            "critic",
            (
                collect_tensors(&a.sac.critic),
                collect_tensors(&b.sac.critic),
            ),
        ),
        (
            "temperature",
            (
                collect_tensors(&a.sac.temperature),
                collect_tensors(&b.sac.temperature),
            ),
        ),
    ] {
        for (path, (_, values)) in &x {
            close(&format!("{name}.{path}"), values, &y[path].1);
        }
    }
    for (x, y) in [
        (&a.sac.adam.actor, &b.sac.adam.actor),
        (&a.sac.adam.critic, &b.sac.adam.critic),
    ] {
        assert_eq!(x.time, y.time);
        for (path, m) in &x.moments {
            close(path, &m.first, &y.moments[path].first);
        }
    }
}

#[test]
fn either_kernel_resumes_the_others_checkpoint() {
    let (model, metadata) = shipped_model();
    let dataset = small_dataset();
    let thresholds = metadata.provenance.thresholds.as_ref();
    let threshold = tiny_config(0).threshold_from(thresholds).unwrap();
    let device = Device::flex();
    let context = |kernel| LoopContext {
        kernel,
        ..hopper_context(&model, &dataset)
    };
    for (first, second) in [(Kernel::Burn, Kernel::Fused), (Kernel::Fused, Kernel::Burn)] {
        // One epoch with `first`, checkpointed.
        let dir = tempfile::tempdir().unwrap();
        let mut training =
            PolicyTraining::new(tiny_config(11), &context(first), threshold, &device).unwrap();
        training.run_epoch(&context(first)).unwrap();
        save_checkpoint(dir.path(), &training).unwrap();
        let checkpoint = latest_checkpoint(dir.path()).unwrap().unwrap();
        // The second epoch by both kernels from the same files.
        let resume = |kernel| {
            let mut t =
                PolicyTraining::new(tiny_config(11), &context(kernel), threshold, &device).unwrap();
            load_checkpoint(&checkpoint, &mut t).unwrap();
            t.run_epoch(&context(kernel)).unwrap();
            t
        };
        let (same, other) = (resume(first), resume(second));
        assert_eq!(other.step, 30);
        // 15 updates apart only by float rounding between the kernels.
        assert_agents_close(&other, &same, 1e-3);
    }
}

#[test]
fn sde_rollouts_with_truncation_keep_nothing_past_epsilon() {
    let (model, metadata) = shipped_model();
    let dataset = small_dataset();
    let (task, spec) = hopper();
    let rules = Rules::from(TaskRules::new(&task, spec.dt));
    let device = Device::flex();
    let actor = seeded_init(&device, 1, || {
        Sac::new(
            small_actor(11, 3, -1.0, 1.0),
            SacConfig::new().with_actor_hidden(vec![16, 16]),
            &device,
        )
    })
    .actor
    .valid();
    let policy = nuno::agent::ActorPolicy {
        actor,
        mode: nuno::agent::ActionMode::Sampled,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let starts = nuno::data::StartStateSampler::new(&dataset).sample(256, &mut rng);
    // ε at the median accumulated η so truncation really happens.
    let table = metadata.provenance.thresholds.unwrap();
    let epsilon = table.get(10, 0.9).unwrap() * 0.5;
    let config = RolloutConfig {
        horizon: 10,
        particles: 2,
        penalty: 0.001,
        threshold: Some(epsilon),
        noise_scale: 1.0,
        halt: None,
        state_box: None,
        observation_clip: None,
        truncated_step: TruncatedStep::Drop,
    };
    let out = rollout_model(
        &model,
        RolloutActions::Policy(&policy),
        &rules,
        &starts,
        &config,
        &mut rng,
    );
    assert!(
        out.stats.truncated > 0,
        "ε = {epsilon} should truncate some rollouts"
    );
    assert_eq!(out.trace.kept.iter().sum::<usize>(), out.transitions.len());
    for (row, acc) in out.trace.accumulated_eta.iter().enumerate() {
        assert!(
            acc[..out.trace.kept[row]].iter().all(|&a| a <= epsilon),
            "row {row}"
        );
    }
}

/// The networks run once per item; particles must still be the model's own EM
/// step of each (s, a) with that particle's ε: compared with both kernels'
/// `step` on the rows repeated once per particle (the path before the change),
/// with the same ε.
#[test]
fn particles_equal_the_model_step_on_repeated_rows() {
    use nuno::agent::{ParticleConfig, step_particles};
    use rand::Rng;
    let (model, metadata) = shipped_model();
    let rules = Rules::from(TaskRules::new(
        &TaskConfig::d4rl(TaskName::Hopper),
        metadata.spec.dt,
    ));
    let (batch, particles, obs_dim, act_dim) = (5, 7, 11, 3);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let dataset = small_dataset();
    let observations: Vec<f32> = dataset
        .observations
        .iter()
        .take(batch * obs_dim)
        .copied()
        .collect();
    let actions: Vec<f32> = (0..batch * act_dim)
        .map(|_| rng.random_range(-1.0..1.0))
        .collect();
    let config = ParticleConfig {
        particles,
        penalty: 0.5,
        noise_scale: 1.5,
    };
    for kernel in [Kernel::Fused, Kernel::Burn] {
        let dynamics = kernel.dynamics(&model);
        let got = step_particles(
            &*dynamics,
            &rules,
            &observations,
            &actions,
            config,
            &mut ChaCha8Rng::seed_from_u64(9),
        );
        let repeat = |values: &[f32], width: usize| -> Vec<f32> {
            values
                .chunks_exact(width)
                .flat_map(|row| row.repeat(particles))
                .collect()
        };
        let mut noise_rng = ChaCha8Rng::seed_from_u64(9);
        let noise: Vec<f32> = (0..batch * particles * obs_dim)
            .map(|_| noise_rng.sample::<f32, _>(rand_distr::StandardNormal) * 1.5)
            .collect();
        let row_observations = repeat(&observations, obs_dim);
        let row_actions = repeat(&actions, act_dim);
        let want = dynamics.step(&row_observations, &row_actions, &noise);
        assert_eq!(got.next_states.len(), want.next_states.len());
        for (i, (g, w)) in got.next_states.iter().zip(&want.next_states).enumerate() {
            assert!(
                (g - w).abs() <= 1e-5 * w.abs().max(1.0),
                "{kernel:?} row {} dim {}: {g} vs {w}",
                i / obs_dim,
                i % obs_dim
            );
        }
        for row in 0..batch * particles {
            let b = row / particles;
            // Batches of different sizes may take different matrix kernels.
            let close = |g: f32, w: f32| (g - w).abs() <= 1e-5 * w.abs().max(1.0);
            assert!(close(got.eta[b], want.eta[row]), "{kernel:?} η of item {b}");
            let next = &want.next_states[row * obs_dim..(row + 1) * obs_dim];
            let reward = rules.reward(
                &observations[b * obs_dim..(b + 1) * obs_dim],
                &actions[b * act_dim..(b + 1) * act_dim],
                next,
            );
            assert!((got.rewards[row] - reward).abs() <= 1e-5 * reward.abs().max(1.0));
            let penalised = reward - 0.5 * want.eta[row];
            assert!(
                (got.penalized_rewards[row] - penalised).abs() <= 1e-5 * penalised.abs().max(1.0)
            );
            assert_eq!(got.terminals[row], rules.terminal(next));
        }
        for (g, w) in got.mean.iter().zip(
            want.means
                .chunks_exact(obs_dim)
                .step_by(particles)
                .flatten(),
        ) {
            assert!((g - w).abs() <= 1e-5 * w.abs().max(1.0), "{kernel:?} mean");
        }
    }
}

/// A policy that sets `cancel` on its `at`-th call and counts its calls.
struct CancelAt {
    cancel: nuno::shared::cancel::Cancel,
    at: usize,
    calls: std::sync::atomic::AtomicUsize,
}

impl BatchPolicy for CancelAt {
    fn obs_dim(&self) -> usize {
        11
    }
    fn act_dim(&self) -> usize {
        3
    }
    fn act(&self, observations: &[f32], _rng: &mut dyn rand::RngCore) -> Vec<f32> {
        let calls = self.calls.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1;
        if calls == self.at {
            self.cancel.cancel();
        }
        vec![0.0; observations.len() / 11 * 3]
    }
}

/// Cancelled rollouts and evaluations stop before their next step: the
/// policy is asked for exactly as many steps as ran before the flag was set.
#[test]
fn cancelled_rollouts_and_evaluations_stop_at_the_next_step() {
    use nuno::agent::rollout_model_or_cancel;
    use nuno::envs::{EnvError, EvaluationConfig, evaluate_or_cancel};
    use nuno::shared::cancel::Cancelled;
    let (model, metadata) = shipped_model();
    let rules = Rules::from(TaskRules::new(
        &TaskConfig::d4rl(TaskName::Hopper),
        metadata.spec.dt,
    ));
    let policy = CancelAt {
        cancel: Default::default(),
        at: 3,
        calls: Default::default(),
    };
    let dataset = small_dataset();
    let starts: Vec<f32> = dataset.observations.iter().take(4 * 11).copied().collect();
    let config = RolloutConfig {
        horizon: 20,
        particles: 2,
        penalty: 0.0,
        threshold: None,
        noise_scale: 0.0,
        halt: None,
        state_box: None,
        observation_clip: None,
        truncated_step: TruncatedStep::Drop,
    };
    let dynamics = Kernel::Fused.dynamics(&model);
    let out = rollout_model_or_cancel(
        &*dynamics,
        RolloutActions::Policy(&policy),
        &rules,
        &starts,
        &config,
        &mut ChaCha8Rng::seed_from_u64(0),
        &policy.cancel,
    );
    assert_eq!(out.err(), Some(Cancelled));
    assert_eq!(policy.calls.load(std::sync::atomic::Ordering::SeqCst), 3);

    let policy = CancelAt {
        cancel: Default::default(),
        at: 5,
        calls: Default::default(),
    };
    let mut evaluation = EvaluationConfig::new(TaskConfig::d4rl(TaskName::Hopper), 2, 0);
    evaluation.episodes_per_group = 2;
    let err = evaluate_or_cancel(&policy, &evaluation, &policy.cancel).unwrap_err();
    assert!(matches!(err, EnvError::Cancelled(Cancelled)), "{err}");
    assert_eq!(policy.calls.load(std::sync::atomic::Ordering::SeqCst), 5);
}

/// [`ConstantEta`] with a known σ (3, 4, 0, …: ‖σ‖ = 5) and a truncation
/// signal of 1.0 per step beside its η of 0.3 (TATU+MOPO's shape).
struct TwoSignals {
    inner: ConstantEta,
}

impl BatchDynamics for TwoSignals {
    fn shape(&self) -> BatchShape {
        self.inner.shape()
    }
    fn step(&self, states: &[f32], actions: &[f32], noise: &[f32]) -> ModelStep {
        let mut step = self.inner.step(states, actions, noise);
        let o = self.inner.spec.obs_dim;
        for sigma in step.sigma.chunks_exact_mut(o) {
            (sigma[0], sigma[1]) = (3.0, 4.0);
        }
        step.truncation_signal = Some(vec![1.0; step.eta.len()]);
        step
    }
}

#[test]
fn rollouts_penalise_eta_but_truncate_on_the_models_own_signal() {
    let hopper = HopperRollouts::new();
    let spec = &hopper.spec;
    let dynamics = TwoSignals {
        inner: ConstantEta { spec: spec.clone() },
    };
    let config = RolloutConfig {
        threshold: Some(2.5),
        ..plain_rollouts(10, 1, 2.0)
    };
    let start = hopper.upright();
    let out = hopper.roll(&dynamics, &start.repeat(3), &config);
    // The signal adds 1.0 a step: 1, 2 kept, 3 > 2.5 truncates (η's 0.3s would allow 8).
    assert_eq!(out.trace.kept, vec![2; 3]);
    assert_eq!(out.stats.truncated, 3);
    assert_eq!(out.trace.accumulated_eta[0], vec![1.0, 2.0, 3.0]);
    // ... while the penalty is still λ·η = 2·0.3.
    hopper.assert_penalised_by(&out.transitions, 0.6);

    // NUNO^al: the same model reporting ‖σ‖ = 5 as η penalises by λ·5.
    let aleatoric = nuno::agent::AleatoricAsEta::new(&dynamics.inner);
    let step = aleatoric.step(&start, &HOPPER_ACTION, &vec![0.0; spec.obs_dim]);
    assert_eq!(step.eta, vec![0.0], "ConstantEta's σ is zero");
    let aleatoric = nuno::agent::AleatoricAsEta::new(&dynamics);
    let step = aleatoric.step(
        &start.repeat(2),
        &HOPPER_ACTION.repeat(2),
        &vec![0.0; 2 * spec.obs_dim],
    );
    assert_eq!(step.eta, vec![5.0, 5.0]);
}

/// η = the first observation coordinate (a known function for thresholds).
struct EtaIsFirstCoordinate {
    inner: ConstantEta,
}

impl BatchDynamics for EtaIsFirstCoordinate {
    fn shape(&self) -> BatchShape {
        self.inner.shape()
    }
    fn step(&self, states: &[f32], actions: &[f32], noise: &[f32]) -> ModelStep {
        let mut step = self.inner.step(states, actions, noise);
        let o = self.inner.spec.obs_dim;
        step.eta = states.chunks_exact(o).map(|s| s[0]).collect();
        step
    }
}

#[test]
fn tatus_threshold_is_the_datasets_largest_signal_over_the_pessimism() {
    let (_, spec) = hopper();
    let dataset = small_dataset();
    let dynamics = EtaIsFirstCoordinate {
        inner: ConstantEta { spec },
    };
    let largest = dataset
        .observations
        .column(0)
        .iter()
        .copied()
        .fold(f32::NEG_INFINITY, f32::max);
    // Chunks that do not divide the dataset reach its last rows too.
    for chunk in [7, 1000, 10_000] {
        let threshold =
            nuno::agent::dataset_max_threshold(&dynamics, &dataset, 2.0, chunk).unwrap();
        assert!((threshold - largest / 2.0).abs() < 1e-6, "chunk {chunk}");
    }
    let error = nuno::agent::dataset_max_threshold(&dynamics, &dataset, 0.0, 7).unwrap_err();
    assert!(error.to_string().contains("pessimism"), "{error}");
}

#[test]
fn a_threshold_computed_through_rollouts_agrees_with_the_models_own_table() {
    // Two implementations of ε(h, α) (sde::compute_thresholds on OpenLoop,
    // agent::rollout_threshold on rollout_model) on the same windows' recipe:
    // the same statistic of independently drawn noise.
    let (model, _) = shipped_model();
    let dataset = small_dataset();
    let (task, spec) = hopper();
    let rules = Rules::from(TaskRules::new(&task, spec.dt));
    let config = nuno::sde::ThresholdConfig::new()
        .with_horizons(vec![5])
        .with_alphas(vec![0.5, 0.9])
        .with_max_windows(400)
        .with_seed(3);
    let table = nuno::sde::compute_thresholds(&model, &dataset, &config, &Device::flex()).unwrap();
    for alpha in [0.5, 0.9] {
        let reference = table.get(5, alpha).unwrap();
        let ours = nuno::agent::rollout_threshold(
            &model,
            &rules,
            &dataset,
            5,
            alpha,
            &config.clone().with_seed(4),
        )
        .unwrap();
        assert!(
            (ours / reference - 1.0).abs() < 0.15,
            "α = {alpha}: {ours} through rollouts, {reference} in the table"
        );
    }
}
