//! Online SAC in a real task (Haarnoja et al., 2018): how D4RL's and NeoRL's
//! behaviour policies were trained (Appendix C.1), here on the project's own
//! update ([`FusedSac`]) and MuJoCo tasks, one checkpoint interval at a time
//! so a caller can save between intervals:
//!
//! ```text
//! every step: a ~ π(·|s) (uniform on the action box for the first start_steps),
//!     step the task, record (s, a, r, s', terminal, timeout, qpos, qvel, log π(a|s))
//! after start_steps, every step: updates_per_step SAC updates on batches from the replay buffer
//! every checkpoint_every steps: cut the episode in progress (a timeout, as rlkit's
//!     epochs cut paths), evaluate tanh(μ(s)) in the task
//! ```
//!
//! An interval starts with a fresh reset drawn from the run's generator, so a
//! run resumed from a checkpoint continues exactly as an uninterrupted one
//! (on the same machine: the update's sums follow the core count and vector
//! level).

use std::time::Instant;

use burn::config::Config;
use burn::tensor::Device;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::actor::{ActionMode, ActorConfig, ActorPolicy};
use super::buffer::ReplayBuffer;
use super::fused_sac::FusedSac;
use super::policy_loop::EvalSummary;
use super::sac::{Sac, SacConfig, SacLosses};
use super::{AgentError, FusedActor};
use crate::data::Recording;
use crate::envs::{EvaluationConfig, MujocoTask, TaskConfig, evaluate};

/// Every knob of an online run; defaults are SAC's (CleanRL's `sac_continuous`
/// for the warm-up, NUNO's SAC for the update).
#[derive(Config, Debug, PartialEq)]
pub struct OnlineSacConfig {
    pub sac: SacConfig,
    /// Environment steps in all.
    #[config(default = 1_000_000)]
    pub steps: usize,
    /// Steps of uniformly random actions before the policy acts and updates
    /// begin (CleanRL's `learning_starts`).
    #[config(default = 5000)]
    pub start_steps: usize,
    /// SAC updates per environment step once they begin.
    #[config(default = 1)]
    pub updates_per_step: usize,
    /// Steps between checkpoints (evaluation, the policy and the run saved).
    #[config(default = 10_000)]
    pub checkpoint_every: usize,
    /// Deterministic evaluation episodes at each checkpoint.
    #[config(default = 10)]
    pub eval_episodes: usize,
    /// Replay capacity; `None` keeps every step, so the buffer up to any
    /// checkpoint is a prefix of the run (D4RL's medium-replay).
    pub buffer_capacity: Option<usize>,
    #[config(default = 0)]
    pub seed: u64,
}

impl OnlineSacConfig {
    /// Checks every knob before any work starts.
    pub fn validate(&self) -> Result<(), AgentError> {
        let positive = [
            ("steps", self.steps),
            ("checkpoint_every", self.checkpoint_every),
            ("batch_size", self.sac.batch_size),
            ("buffer_capacity", self.capacity()),
        ];
        match positive.iter().find(|(_, v)| *v == 0) {
            Some((name, _)) => Err(AgentError::Mismatch(format!(
                "online SAC: `{name}` must be at least 1"
            ))),
            None => Ok(()),
        }
    }

    pub fn capacity(&self) -> usize {
        self.buffer_capacity.unwrap_or(self.steps)
    }
}

/// Seconds each phase of one interval took.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct OnlineSeconds {
    /// Acting and stepping the task (recording included).
    pub environment: f64,
    /// SAC updates, their batches included.
    pub updates: f64,
    pub evaluation: f64,
}

/// What one checkpoint interval did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OnlineRecord {
    /// Environment steps taken by the end of the interval.
    pub step: usize,
    /// SAC updates taken by the end of the interval.
    pub updates: usize,
    /// Episodes finished (or cut) by the end of the interval.
    pub episodes: usize,
    /// Mean return of the interval's training episodes (cut ones included).
    pub train_return: f64,
    /// Mean SAC losses over the interval's updates (zeros before they begin).
    pub losses: SacLosses,
    /// The deterministic policy in the task.
    pub eval: EvalSummary,
    pub seconds: OnlineSeconds,
    /// Environment steps per second of acting and stepping.
    pub env_steps_per_second: f64,
    /// SAC updates per second of updating.
    pub updates_per_second: f64,
}

/// An online run's whole state: what a checkpoint saves (the replay buffer is
/// rebuilt from the recorded intervals).
pub struct OnlineSac {
    pub config: OnlineSacConfig,
    pub task: TaskConfig,
    /// The agent as burn modules, current at every interval's end.
    pub sac: Sac,
    pub buffer: ReplayBuffer,
    /// The steps of the interval in progress, with what D4RL records beside them.
    pub recording: Recording,
    pub rng: ChaCha8Rng,
    pub step: usize,
    pub updates: usize,
    pub episodes: usize,
    pub history: Vec<OnlineRecord>,
    /// Updates run from the step after this one: `start_steps`, or later in a
    /// run continued with an emptied replay buffer (see
    /// [`crate::artifact::load_online_checkpoint`]), so the buffer refills first.
    pub updates_after: usize,
}

impl OnlineSac {
    /// A fresh run in `task`.
    pub fn new(
        config: OnlineSacConfig,
        task: TaskConfig,
        device: &Device,
    ) -> Result<Self, AgentError> {
        config.validate()?;
        let env = MujocoTask::new(&task)?;
        let (low, high) = env.action_bounds();
        let mut actor = ActorConfig::new(
            env.obs_dim(),
            env.act_dim(),
            low.iter().map(|&x| x as f32).collect(),
            high.iter().map(|&x| x as f32).collect(),
        );
        actor.hidden = config.sac.actor_hidden.clone();
        actor.log_std_min = config.sac.log_std_min;
        actor.log_std_max = config.sac.log_std_max;
        let sac = crate::nn::seeded_init(device, config.seed, || {
            Sac::new(actor, config.sac.clone(), device)
        });
        Ok(Self {
            buffer: ReplayBuffer::new(config.capacity(), env.obs_dim(), env.act_dim()),
            recording: Recording::for_task(&env),
            rng: ChaCha8Rng::seed_from_u64(config.seed),
            step: 0,
            updates: 0,
            episodes: 0,
            history: Vec::new(),
            updates_after: config.start_steps,
            sac,
            task,
            config,
        })
    }

    pub fn is_finished(&self) -> bool {
        self.step >= self.config.steps
    }

    /// Steps to the next checkpoint (or the end of the run), then evaluates.
    /// The interval's transitions are left in `self.recording` for the caller
    /// to save; the next call starts a new recording.
    pub fn run_interval(&mut self) -> Result<OnlineRecord, AgentError> {
        let c = &self.config;
        let end = (self.step + c.checkpoint_every).min(c.steps);
        let mut env = MujocoTask::new(&self.task)?;
        self.recording = Recording::for_task(&env);
        let (low, high) = env.action_bounds();
        // A uniform action's log-density on the box.
        let uniform_log_prob = -low
            .iter()
            .zip(&high)
            .map(|(l, h)| (h - l).ln())
            .sum::<f64>();
        let mut fused = FusedSac::from_sac(&self.sac);
        let mut seconds = OnlineSeconds::default();
        let mut losses = Vec::new();
        let mut returns = Vec::new();
        let mut episode_return = 0.0;
        let mut obs: Vec<f32> = to_f32(&env.reset(Some(self.rng.random())));
        let steps_before = self.step;
        while self.step < end {
            let acting = Instant::now();
            let (action, log_prob) =
                self.act(&mut fused, &obs, (&low, &high), uniform_log_prob as f32);
            let state = (env.qpos().to_vec(), env.qvel().to_vec());
            let step = env.step(&action.iter().map(|&a| f64::from(a)).collect::<Vec<_>>())?;
            let next = to_f32(&step.observation);
            self.recording
                .push(&obs, (&state.0, &state.1), &action, Some(log_prob), &step);
            let done = if step.terminated { 1.0 } else { 0.0 };
            self.buffer
                .push_row(&obs, &action, step.reward as f32, &next, done);
            episode_return += step.reward;
            self.step += 1;
            if step.terminated || step.truncated {
                returns.push(episode_return);
                episode_return = 0.0;
                self.episodes += 1;
                obs = to_f32(&env.reset(Some(self.rng.random())));
            } else {
                obs = next;
            }
            seconds.environment += acting.elapsed().as_secs_f64();

            if self.step > self.updates_after {
                let updating = Instant::now();
                self.update(&mut fused, &mut losses);
                seconds.updates += updating.elapsed().as_secs_f64();
            }
        }
        // The episode in progress ends with the interval (a timeout).
        if self.recording.timeouts.last() == Some(&false)
            && self.recording.terminals.last() == Some(&false)
        {
            self.recording.cut();
            returns.push(episode_return);
            self.episodes += 1;
        }
        fused.write_to(&mut self.sac);

        let evaluating = Instant::now();
        let eval = self.evaluate()?;
        seconds.evaluation = evaluating.elapsed().as_secs_f64();
        let steps = self.step - steps_before;
        let record = OnlineRecord {
            step: self.step,
            updates: self.updates,
            episodes: self.episodes,
            train_return: mean(&returns),
            losses: SacLosses::mean(&losses),
            eval,
            seconds,
            env_steps_per_second: steps as f64 / seconds.environment.max(1e-9),
            updates_per_second: losses.len() as f64 / seconds.updates.max(1e-9),
        };
        self.history.push(record.clone());
        Ok(record)
    }

    /// The step's action and its log-density: uniform on the box `bounds`
    /// during the warm-up, then a ~ π(·|s).
    fn act(
        &mut self,
        fused: &mut FusedSac,
        obs: &[f32],
        (low, high): (&[f64], &[f64]),
        uniform_log_prob: f32,
    ) -> (Vec<f32>, f32) {
        if self.step < self.config.start_steps {
            let action = low
                .iter()
                .zip(high)
                .map(|(&l, &h)| self.rng.random_range(l..h) as f32)
                .collect();
            return (action, uniform_log_prob);
        }
        let logged = fused.act_logged(obs, &mut self.rng);
        let log_prob = logged.log_probs.map_or(f32::NAN, |l| l[0]);
        (logged.actions, log_prob)
    }

    /// `updates_per_step` SAC updates on batches from the replay buffer.
    fn update(&mut self, fused: &mut FusedSac, losses: &mut Vec<SacLosses>) {
        for _ in 0..self.config.updates_per_step {
            let batch = self
                .buffer
                .sample(self.config.sac.batch_size, &mut self.rng);
            losses.push(fused.update(&batch, &mut self.rng));
            self.updates += 1;
        }
    }

    /// The current actor, choosing actions by `mode`.
    pub fn policy(&self, mode: ActionMode) -> ActorPolicy {
        ActorPolicy {
            actor: self.sac.actor.clone(),
            mode,
        }
    }

    /// tanh(μ(s)) in the task, from the same start states at every checkpoint
    /// so that checkpoints compare.
    fn evaluate(&self) -> Result<EvalSummary, AgentError> {
        if self.config.eval_episodes == 0 {
            return Ok(EvalSummary::default());
        }
        let config = EvaluationConfig::new(
            self.task.clone(),
            self.config.eval_episodes,
            self.config.seed,
        );
        let policy = FusedActor::new(&self.policy(ActionMode::Deterministic));
        Ok(EvalSummary::from(&evaluate(&policy, &config)?))
    }
}

fn to_f32(values: &[f64]) -> Vec<f32> {
    values.iter().map(|&x| x as f32).collect()
}

fn mean(values: &[f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.iter().sum::<f64>() / values.len() as f64
}
