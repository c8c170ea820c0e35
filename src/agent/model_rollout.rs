//! Model rollouts with NUNO's penalty and truncation (Section 4.3): from
//! dataset states, the policy acts and the neural SDE steps; each transition's
//! reward is r − λ_pen·η(s, a), and a rollout stops at a terminal state (the
//! task's rules) or once its accumulated η Σ_k η(s_k, a_k) exceeds ε(h, α).
//!
//! Particles are folded into the batch: each start state is rolled
//! `particles` times, each particle its own trajectory with its own
//! accumulated η.

use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::model_step::penalized_reward;
use crate::envs::{ObservationClip, Rules};
use crate::shared::cancel::{Cancel, Cancelled};
use crate::shared::{BatchDynamics, BatchPolicy, ModelStep, TransitionBatch, scaled_noise};

/// How model rollouts run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RolloutConfig {
    /// h, the rollout length (Table 3).
    pub horizon: usize,
    /// Trajectories per start state.
    pub particles: usize,
    /// λ_pen, the weight of η in the penalised reward (Table 3).
    pub penalty: f64,
    /// ε(h, α): a rollout stops before the step that takes its accumulated η
    /// (or the model's truncation signal) above this; `None` never truncates.
    pub threshold: Option<f32>,
    /// Multiplies ε: 1 samples the SDE, 0 follows the drift.
    pub noise_scale: f32,
    /// MOReL's HALT: a step whose own truncation signal passes the threshold
    /// is kept as a terminal transition with its reward less κ, ending the
    /// row. Absent from configurations written before it (none halted).
    #[serde(default)]
    pub halt: Option<Halt>,
    /// A step whose next observation leaves this box has diverged (dropped,
    /// the row ended); `None` judges finiteness alone. Absent from
    /// configurations written before it (none had a box).
    #[serde(default)]
    pub state_box: Option<StateBox>,
    /// Each model next observation is clipped as the task clips what it
    /// observes, before the step is judged; `None` (the paper's and NUNO's
    /// code's rollouts) leaves it as the model gives it. Absent from
    /// configurations written before it (none clipped).
    #[serde(default)]
    pub observation_clip: Option<ObservationClip>,
    /// What becomes of the step that takes the accumulated signal past the
    /// threshold. Absent from configurations written before it (dropped).
    #[serde(default)]
    pub truncated_step: TruncatedStep,
}

impl RolloutConfig {
    /// The model's own rollouts, as the analyses and thresholds measure them:
    /// no penalty, truncation, HALT or box, at the model's sampling noise.
    pub fn unpenalised(horizon: usize, particles: usize, dynamics: &dyn BatchDynamics) -> Self {
        Self {
            horizon,
            particles,
            penalty: 0.0,
            threshold: None,
            noise_scale: dynamics.sample_noise_scale(),
            halt: None,
            state_box: None,
            observation_clip: None,
            truncated_step: TruncatedStep::Drop,
        }
    }
}

/// What a rollout keeps of the step that takes its accumulated signal past
/// ε(h, α); either way the rollout ends there.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TruncatedStep {
    /// Dropped: the paper's "truncate the trajectory and do not use it for
    /// policy optimization" (Section 4.3).
    #[default]
    Drop,
    /// Kept as a terminal transition, its reward penalised as any other, so
    /// the critics bootstrap nothing past it: NUNO's and TATU's code
    /// (`FakeEnv_SDE_Trunc.step` stores the halting transition with done).
    Terminal,
}

crate::shared::named_enum!(TruncatedStep, "truncated step", TruncatedStep::Drop => "drop", TruncatedStep::Terminal => "terminal");

/// Per observation dimension, the range a model's state may reach before its
/// rollout counts as diverged: the data's range widened by a margin. nuno's
/// guard, neither the paper's nor NUNO's code's (docs/paper-map.md): a drift
/// that runs away within h steps while η stays bounded (halfcheetah-random's
/// h = 20) otherwise hands the policy rewards no state of the task can give.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StateBox {
    pub lower: Vec<f32>,
    pub upper: Vec<f32>,
}

impl StateBox {
    /// `[low − m·(high − low), high + m·(high − low)]` per dimension, from each
    /// dimension's `(low, high)` over the data.
    pub fn around(bounds: &[(f32, f32)], margin: f32) -> Self {
        Self {
            lower: bounds
                .iter()
                .map(|&(low, high)| low - margin * (high - low))
                .collect(),
            upper: bounds
                .iter()
                .map(|&(low, high)| high + margin * (high - low))
                .collect(),
        }
    }

    /// Whether every dimension of `observation` lies within the box.
    pub fn contains(&self, observation: &[f32]) -> bool {
        (observation.iter().zip(self.lower.iter().zip(&self.upper)))
            .all(|(x, (low, high))| (low..=high).contains(&x))
    }
}

/// MOReL's absorbing HALT state (Kidambi et al., 2020): where the ensemble's
/// disagreement at a step passes `threshold`, the pessimistic MDP ends there.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Halt {
    pub threshold: f32,
    /// κ, subtracted from the halting step's reward (MOReL's code: 0).
    pub penalty: f32,
}

/// Where a rollout's actions come from.
#[derive(Clone, Copy)]
pub enum RolloutActions<'a> {
    /// Closed loop: the policy acts on each state.
    Policy(&'a dyn BatchPolicy),
    /// Open loop: row-major `[starts, horizon, act_dim]`, shared by a start's particles.
    Sequence(&'a [f32]),
}

/// What happened to one trajectory at one step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum StepOutcome {
    Continued,
    /// The task's rules say the robot fell; the transition is kept as terminal.
    Terminal,
    /// Accumulated η passed ε(h, α); the transition is dropped, or kept as
    /// terminal where [`RolloutConfig::truncated_step`] says so.
    Truncated,
    /// The model's next state, reward or η was not finite, or the next state
    /// left the rollout's [`StateBox`] (its drift diverged off the data); the
    /// transition is dropped.
    Diverged,
    /// The step's own signal passed MOReL's HALT threshold; the transition is
    /// kept as terminal, its reward less κ.
    Halted,
}

/// Per-step records of a batch of rollouts, row-major `[rows, horizon]`
/// where `rows = starts · particles` (particle p of start b is row b·particles + p);
/// entries after a trajectory ended are absent (`steps[row]` says how many exist).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct RolloutTrace {
    pub rows: usize,
    pub horizon: usize,
    /// Steps each trajectory kept.
    pub kept: Vec<usize>,
    /// Observations along each trajectory: the start, then one per kept step.
    pub observations: Vec<Vec<f32>>,
    /// The action of each step taken (including a truncating one).
    pub actions: Vec<Vec<f32>>,
    /// η at each step taken (including a truncating one): `[rows][..]`.
    pub eta: Vec<Vec<f32>>,
    /// Accumulated truncation signal (η, or the model's own signal, see
    /// [`ModelStep::truncation_signal`](crate::shared::ModelStep)) after each step taken.
    pub accumulated_eta: Vec<Vec<f32>>,
    /// The reward before the penalty, per step taken.
    pub rewards: Vec<Vec<f32>>,
    /// How each trajectory ended, if it did before h.
    pub outcome: Vec<StepOutcome>,
}

/// Summary of a batch of rollouts, for logging.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct RolloutStats {
    pub trajectories: usize,
    pub transitions: usize,
    pub mean_length: f32,
    pub mean_eta: f32,
    pub mean_reward: f32,
    pub mean_penalized_reward: f32,
    pub truncated: usize,
    pub terminated: usize,
    /// Absent from records written before divergence was counted.
    #[serde(default)]
    pub diverged: usize,
    /// Rows that ended in MOReL's HALT (absent from records written before it).
    #[serde(default)]
    pub halted: usize,
}

/// The transitions kept and the trace of every trajectory.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelRollout {
    /// Kept transitions, rewards penalised.
    pub transitions: TransitionBatch,
    pub trace: RolloutTrace,
    pub stats: RolloutStats,
}

/// Rolls the actions of `source` through `dynamics` from `starts` (`[batch, obs_dim]` observations).
pub fn rollout_model(
    dynamics: &dyn BatchDynamics,
    source: RolloutActions,
    rules: &Rules,
    starts: &[f32],
    config: &RolloutConfig,
    rng: &mut ChaCha8Rng,
) -> ModelRollout {
    let never = Cancel::default();
    match rollout_model_or_cancel(dynamics, source, rules, starts, config, rng, &never) {
        Ok(rollout) => rollout,
        Err(Cancelled) => unreachable!("a flag no one else holds is never cancelled"),
    }
}

/// [`rollout_model`], stopping with [`Cancelled`] before the next step once
/// `cancel` is set.
pub fn rollout_model_or_cancel(
    dynamics: &dyn BatchDynamics,
    source: RolloutActions,
    rules: &Rules,
    starts: &[f32],
    config: &RolloutConfig,
    rng: &mut ChaCha8Rng,
    cancel: &Cancel,
) -> Result<ModelRollout, Cancelled> {
    let mut rollout = Rollout::start(dynamics, starts, config);
    for k in 0..config.horizon {
        if rollout.active.is_empty() {
            break;
        }
        cancel.check()?;
        rollout.step(dynamics, (source, k), rules, config, rng);
    }
    let stats = summarize(&rollout.trace, &rollout.transitions);
    Ok(ModelRollout {
        transitions: rollout.transitions,
        trace: rollout.trace,
        stats,
    })
}

/// A batch of rollouts in progress.
struct Rollout {
    obs_dim: usize,
    act_dim: usize,
    /// Each row's current observation, `[rows, obs_dim]`.
    observations: Vec<f32>,
    trace: RolloutTrace,
    transitions: TransitionBatch,
    /// Each row's accumulated truncation signal.
    accumulated: Vec<f32>,
    /// The rows still running.
    active: Vec<usize>,
}

impl Rollout {
    /// Every start state repeated `config.particles` times, nothing taken yet.
    fn start(dynamics: &dyn BatchDynamics, starts: &[f32], config: &RolloutConfig) -> Self {
        let (obs_dim, act_dim) = (dynamics.obs_dim(), dynamics.act_dim());
        let rows = starts.len() / obs_dim * config.particles;
        let observations: Vec<f32> = starts
            .chunks_exact(obs_dim)
            .flat_map(|row| {
                std::iter::repeat_n(row, config.particles)
                    .flatten()
                    .copied()
            })
            .collect();
        let trace = RolloutTrace {
            rows,
            horizon: config.horizon,
            kept: vec![0; rows],
            observations: observations
                .chunks_exact(obs_dim)
                .map(|o| o.to_vec())
                .collect(),
            actions: vec![Vec::new(); rows],
            eta: vec![Vec::new(); rows],
            accumulated_eta: vec![Vec::new(); rows],
            rewards: vec![Vec::new(); rows],
            outcome: vec![StepOutcome::Continued; rows],
        };
        Self {
            obs_dim,
            act_dim,
            observations,
            trace,
            // Grown as steps are kept: sized for every step, it would reserve the
            // largest rollout a server accepts (hundreds of MB) for runs that truncate early.
            transitions: TransitionBatch::with_capacity(0, obs_dim, act_dim),
            accumulated: vec![0.0; rows],
            active: (0..rows).collect(),
        }
    }

    /// Step `k` of every active row: act, step the model, judge and keep each row.
    fn step(
        &mut self,
        dynamics: &dyn BatchDynamics,
        (source, k): (RolloutActions, usize),
        rules: &Rules,
        config: &RolloutConfig,
        rng: &mut ChaCha8Rng,
    ) {
        let (obs_dim, act_dim) = (self.obs_dim, self.act_dim);
        let obs: Vec<f32> = (self.active.iter())
            .flat_map(|&r| {
                self.observations[r * obs_dim..(r + 1) * obs_dim]
                    .iter()
                    .copied()
            })
            .collect();
        let actions = match source {
            RolloutActions::Policy(policy) => policy.act(&obs, rng),
            RolloutActions::Sequence(sequence) => (self.active.iter())
                .flat_map(|&r| {
                    let at = ((r / config.particles) * config.horizon + k) * act_dim;
                    sequence[at..at + act_dim].iter().copied()
                })
                .collect(),
        };
        let states = dynamics.states_from_observations(&obs);
        let noise = scaled_noise(
            self.active.len() * dynamics.noise_dim(),
            config.noise_scale,
            rng,
        );
        let mut step = dynamics.step(&states, &actions, &noise);
        if let Some(clip) = &config.observation_clip {
            let state_dim = dynamics.state_dim();
            for next_state in step.next_states.chunks_exact_mut(state_dim) {
                clip.apply(&mut next_state[..obs_dim]);
            }
        }

        let active = std::mem::take(&mut self.active);
        for (i, &r) in active.iter().enumerate() {
            let from = &obs[i * obs_dim..(i + 1) * obs_dim];
            let action = &actions[i * act_dim..(i + 1) * act_dim];
            let row = judge_row(
                dynamics,
                rules,
                &step,
                i,
                (from, action),
                &mut self.accumulated[r],
                (config.threshold, config.halt, config.state_box.as_ref()),
            );
            if self.record(r, (from, action), &row, config) {
                self.active.push(r);
            }
        }
    }

    /// Records row `r`'s judged step in its trace and, where the step is kept,
    /// as a transition (reward penalised); returns whether the row goes on.
    fn record(
        &mut self,
        r: usize,
        (from, action): (&[f32], &[f32]),
        row: &JudgedRow,
        config: &RolloutConfig,
    ) -> bool {
        let trace = &mut self.trace;
        trace.actions[r].extend_from_slice(action);
        trace.outcome[r] = row.fate;
        if row.fate == StepOutcome::Diverged {
            return false;
        }
        trace.eta[r].push(row.eta);
        trace.accumulated_eta[r].push(self.accumulated[r]);
        trace.rewards[r].push(row.reward);
        let terminal = match row.fate {
            StepOutcome::Truncated if config.truncated_step == TruncatedStep::Drop => return false,
            StepOutcome::Terminal | StepOutcome::Halted | StepOutcome::Truncated => true,
            StepOutcome::Continued | StepOutcome::Diverged => false,
        };
        let t = &mut self.transitions;
        t.observations.extend_from_slice(from);
        t.actions.extend_from_slice(action);
        // Penalised reward r − λ_pen·η(s, a).
        t.rewards
            .push(penalized_reward(row.reward, config.penalty, row.eta));
        t.next_observations.extend_from_slice(row.next_obs);
        t.terminals.push(if terminal { 1.0 } else { 0.0 });
        trace.kept[r] += 1;
        trace.observations[r].extend_from_slice(row.next_obs);
        let obs_dim = self.obs_dim;
        self.observations[r * obs_dim..(r + 1) * obs_dim].copy_from_slice(row.next_obs);
        !terminal
    }
}

/// One row of a model step as NUNO's rollouts take it (Section 4.3).
#[derive(Debug, Clone, Copy)]
pub struct JudgedRow<'a> {
    pub next_obs: &'a [f32],
    /// The model's own reward (NUNO^R), else the rules'.
    pub reward: f32,
    pub eta: f32,
    /// `Continued` or `Terminal` keep the step; `Truncated` (the accumulated
    /// signal passed ε(h, α)) and `Diverged` (a non-finite next state, reward,
    /// η or signal, or a next state outside the box: the drift left the data)
    /// drop it and end the row.
    pub fate: StepOutcome,
}

/// Row `i` of `step`, taken from `(observation, action)`: its reward, η and
/// fate, its truncation signal added to `accumulated` unless it diverged and
/// compared with `threshold` so, or alone with `halt`'s. The one rule for
/// every model rollout (the policy loop's, the server's, the planners' scores).
pub fn judge_row<'a>(
    dynamics: &dyn BatchDynamics,
    rules: &Rules,
    step: &'a ModelStep,
    i: usize,
    (observation, action): (&[f32], &[f32]),
    accumulated: &mut f32,
    (threshold, halt, state_box): (Option<f32>, Option<Halt>, Option<&StateBox>),
) -> JudgedRow<'a> {
    let (obs_dim, state_dim) = (dynamics.obs_dim(), dynamics.state_dim());
    let next_state = &step.next_states[i * state_dim..(i + 1) * state_dim];
    let next_obs = &next_state[..obs_dim];
    let reward = if dynamics.learns_reward() {
        next_state[obs_dim]
    } else {
        rules.reward(observation, action, next_obs)
    };
    let (eta, signal) = (step.eta[i], step.truncation_at(i));
    // Finite, and inside the box where there is one.
    let sound = eta.is_finite()
        && signal.is_finite()
        && reward.is_finite()
        && next_state.iter().all(|x| x.is_finite())
        && state_box.is_none_or(|b| b.contains(next_obs));
    let halted = halt.filter(|h| sound && signal > h.threshold);
    let fate = if !sound {
        StepOutcome::Diverged
    } else if halted.is_some() {
        StepOutcome::Halted
    } else {
        // TATU+MOPO accumulates the ensemble's disagreement, the others η.
        *accumulated += signal;
        // Truncation: Σ_k η(s_k, a_k) > ε(h, α) drops this step and ends the rollout.
        if threshold.is_some_and(|e| *accumulated > e) {
            StepOutcome::Truncated
        } else if rules.terminal(next_obs) {
            StepOutcome::Terminal
        } else {
            StepOutcome::Continued
        }
    };
    JudgedRow {
        next_obs,
        reward: reward - halted.map_or(0.0, |h| h.penalty),
        eta,
        fate,
    }
}

fn summarize(trace: &RolloutTrace, transitions: &TransitionBatch) -> RolloutStats {
    let mean = |values: &mut dyn Iterator<Item = f32>| {
        let (sum, n) = values.fold((0.0f64, 0usize), |(s, n), v| (s + f64::from(v), n + 1));
        if n == 0 { 0.0 } else { (sum / n as f64) as f32 }
    };
    let count = |o: StepOutcome| trace.outcome.iter().filter(|&&x| x == o).count();
    RolloutStats {
        trajectories: trace.rows,
        transitions: transitions.len(),
        mean_length: mean(&mut trace.kept.iter().map(|&k| k as f32)),
        mean_eta: mean(&mut trace.eta.iter().flatten().copied()),
        mean_reward: mean(&mut trace.rewards.iter().flatten().copied()),
        mean_penalized_reward: mean(&mut transitions.rewards.iter().copied()),
        truncated: count(StepOutcome::Truncated),
        terminated: count(StepOutcome::Terminal),
        diverged: count(StepOutcome::Diverged),
        halted: count(StepOutcome::Halted),
    }
}
