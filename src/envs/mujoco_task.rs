//! One running copy of a task on MuJoCo: reset, set the state, step, observe.
//!
//! `step` reproduces Gymnasium's `*-v4` `step` operation for operation (the
//! parity test checks this to 1e-9 against Python): write the action to
//! `ctrl`, `mj_step` `frame_skip` times, then reward, termination and
//! observation from the new state.

use std::sync::Arc;

use mujoco_rs::prelude::{MjData, MjModel};
use mujoco_rs::wrappers::mj_model::MjtJoint;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use super::EnvError;
use super::score::ScoreReference;
use super::task::{FileTask, ObservationLayout, ResetNoise, StateSplit, Task, TaskName, TaskSpec};

/// Which task to run, in which variant.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct TaskConfig {
    #[serde(rename = "name")]
    pub task: Task,
    pub layout: ObservationLayout,
    /// Steps after which an episode is truncated.
    pub max_episode_steps: usize,
}

impl TaskConfig {
    /// The D4RL variant (root x not observed, 1000-step limit).
    pub fn d4rl(name: TaskName) -> Self {
        Self::own_layout(Task::BuiltIn(name))
    }

    /// A system file's task, observed as its table says.
    pub fn of_file(task: Arc<FileTask>) -> Self {
        Self::own_layout(Task::File(task))
    }

    fn own_layout(task: Task) -> Self {
        Self {
            max_episode_steps: task.spec().max_episode_steps,
            task,
            layout: ObservationLayout::D4rl,
        }
    }

    /// The NeoRL variant (root x observed, 1000-step limit).
    pub fn neorl(name: TaskName) -> Self {
        Self {
            layout: ObservationLayout::Neorl,
            ..Self::d4rl(name)
        }
    }

    /// Whether the observations hold root x, qpos[0] (NeoRL's layout).
    pub fn observes_root_x(&self) -> bool {
        self.layout.qpos_from(self.task.spec()) == 0
    }

    /// The reference returns that define this variant's normalised score.
    pub fn score_reference(&self) -> ScoreReference {
        let spec = self.task.spec();
        match self.layout {
            ObservationLayout::D4rl => spec.d4rl_score,
            ObservationLayout::Neorl => spec.neorl_score,
        }
    }
}

/// What one environment step returns.
#[derive(Debug, Clone, PartialEq)]
pub struct Transition {
    pub observation: Vec<f64>,
    pub reward: f64,
    /// The robot fell (health rule broken): the episode ends, no bootstrapping.
    pub terminated: bool,
    /// The time limit was reached: the episode ends, bootstrapping is still valid.
    pub truncated: bool,
    /// Root x (ant: its torso's x) after the step.
    pub x_position: f64,
    /// `(x_after − x_before) / dt`, the forward-velocity reward term.
    pub x_velocity: f64,
}

/// A task instance: one MuJoCo `MjData` over the task's shared model.
pub struct MujocoTask {
    config: TaskConfig,
    data: MjData<Arc<MjModel>>,
    init_qpos: Vec<f64>,
    init_qvel: Vec<f64>,
    dt: f64,
    elapsed_steps: usize,
    rng: ChaCha8Rng,
}

impl std::fmt::Debug for MujocoTask {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MujocoTask")
            .field("config", &self.config)
            .field("elapsed_steps", &self.elapsed_steps)
            .finish_non_exhaustive()
    }
}

impl MujocoTask {
    /// A new instance in the model's initial state (call [`reset`](Self::reset) before stepping).
    pub fn new(config: &TaskConfig) -> Result<Self, EnvError> {
        let spec = config.task.spec();
        let model = spec.model.0.clone();
        let dt = model.opt().timestep * spec.frame_skip as f64;
        let data = MjData::try_new(model).map_err(|e| EnvError::Model {
            task: config.task.to_string(),
            message: e.to_string(),
        })?;
        Ok(Self {
            config: config.clone(),
            init_qpos: data.qpos().to_vec(),
            init_qvel: data.qvel().to_vec(),
            data,
            dt,
            elapsed_steps: 0,
            rng: ChaCha8Rng::seed_from_u64(0),
        })
    }

    pub fn config(&self) -> &TaskConfig {
        &self.config
    }

    pub fn spec(&self) -> &TaskSpec {
        self.config.task.spec()
    }

    /// Seconds of simulated time per step.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    pub fn obs_dim(&self) -> usize {
        self.state_split().obs_dim()
    }

    pub fn act_dim(&self) -> usize {
        self.data.ctrl().len()
    }

    /// Per-dimension action bounds `(low, high)` (the actuators' control ranges).
    pub fn action_bounds(&self) -> (Vec<f64>, Vec<f64>) {
        self.data
            .model()
            .actuator_ctrlrange()
            .iter()
            .map(|r| (r[0], r[1]))
            .unzip()
    }

    /// Which observation entries are positions and velocities.
    pub fn state_split(&self) -> StateSplit {
        self.spec().state_split(self.qpos_from())
    }

    /// The first qpos entry the observation holds.
    fn qpos_from(&self) -> usize {
        self.config.layout.qpos_from(self.spec())
    }

    /// The qpos indices of the model's hinge joints (angles, in radians).
    pub fn hinge_qpos(&self) -> Vec<usize> {
        let model = self.data.model();
        let types = model.jnt_type().iter();
        types
            .zip(model.jnt_qposadr())
            .filter(|(t, _)| **t == MjtJoint::mjJNT_HINGE)
            .map(|(_, &adr)| adr as usize)
            .collect()
    }

    /// The model's default pose and velocity, before reset noise.
    pub fn initial_state(&self) -> (&[f64], &[f64]) {
        (&self.init_qpos, &self.init_qvel)
    }

    pub fn qpos(&self) -> &[f64] {
        self.data.qpos()
    }

    pub fn qvel(&self) -> &[f64] {
        self.data.qvel()
    }

    /// Steps taken since the last reset.
    pub fn elapsed_steps(&self) -> usize {
        self.elapsed_steps
    }

    /// Starts an episode from the initial state plus the task's reset noise and
    /// returns the first observation. `Some(seed)` reseeds the noise generator.
    pub fn reset(&mut self, seed: Option<u64>) -> Vec<f64> {
        if let Some(seed) = seed {
            self.rng = ChaCha8Rng::seed_from_u64(seed);
        }
        let (scale, normal_velocity) = match self.spec().reset_noise {
            ResetNoise::Uniform { scale } => (scale, false),
            ResetNoise::UniformPositionNormalVelocity { scale } => (scale, true),
        };
        let rng = &mut self.rng;
        let qpos: Vec<f64> = self
            .init_qpos
            .iter()
            .map(|q| q + rng.random_range(-scale..scale))
            .collect();
        let qvel: Vec<f64> = self
            .init_qvel
            .iter()
            .map(|v| {
                if normal_velocity {
                    v + scale * rng.sample::<f64, _>(StandardNormal)
                } else {
                    v + rng.random_range(-scale..scale)
                }
            })
            .collect();
        self.data.reset();
        self.write_state(&qpos, &qvel);
        self.elapsed_steps = 0;
        self.observation()
    }

    /// Puts the simulator in the full state (qpos, qvel), like Gymnasium's
    /// `set_state`, and returns the observation there. The step counter is kept.
    pub fn set_state(&mut self, qpos: &[f64], qvel: &[f64]) -> Result<Vec<f64>, EnvError> {
        check_vector("qpos", qpos, self.init_qpos.len())?;
        check_vector("qvel", qvel, self.init_qvel.len())?;
        self.write_state(qpos, qvel);
        Ok(self.observation())
    }

    /// Puts the simulator in the state `observation` shows, the qpos entries
    /// the layout omits (root x, D4RL's) at 0: the robots' dynamics do not
    /// depend on where along the floor they stand. Returns the observation there.
    pub fn set_observation(&mut self, observation: &[f64]) -> Result<Vec<f64>, EnvError> {
        check_vector("observation", observation, self.obs_dim())?;
        let (nq, from) = (self.init_qpos.len(), self.qpos_from());
        let (observed_qpos, qvel) = observation.split_at(nq - from);
        let qpos: Vec<f64> = std::iter::repeat_n(0.0, from)
            .chain(observed_qpos.iter().copied())
            .collect();
        self.set_state(&qpos, qvel)
    }

    fn write_state(&mut self, qpos: &[f64], qvel: &[f64]) {
        self.data.qpos_mut().copy_from_slice(qpos);
        self.data.qvel_mut().copy_from_slice(qvel);
        self.data.forward();
    }

    /// Applies `action` for `frame_skip` physics steps.
    pub fn step(&mut self, action: &[f64]) -> Result<Transition, EnvError> {
        check_vector("action", action, self.act_dim())?;
        let x_before = self.forward_position();
        self.data.ctrl_mut().copy_from_slice(action);
        for _ in 0..self.spec().frame_skip {
            self.data.step();
        }
        self.elapsed_steps += 1;
        let x_after = self.forward_position();
        let x_velocity = (x_after - x_before) / self.dt;

        // Same operation order as Gymnasium, so rewards agree to the last bit; a
        // term whose weight is 0 is left out, as Gymnasium's inverted pendulum has none.
        let weighted = |weight: f64, value: f64| if weight == 0.0 { 0.0 } else { weight * value };
        let control = action.iter().map(|a| a * a).sum::<f64>();
        let ctrl_cost = weighted(self.spec().ctrl_cost_weight, control);
        let forward_reward = weighted(self.spec().forward_reward_weight, x_velocity);
        let reward = (forward_reward + self.spec().healthy_reward) - ctrl_cost;
        Ok(Transition {
            observation: self.observation(),
            reward,
            terminated: !self.is_healthy(),
            truncated: self.elapsed_steps >= self.config.max_episode_steps,
            x_position: x_after,
            x_velocity,
        })
    }

    /// Where the forward velocity is measured: the forward body's frame x
    /// (MuJoCo's `xpos`, as of the last kinematics pass, as Gymnasium reads it), or qpos[0].
    fn forward_position(&self) -> f64 {
        match self.spec().forward_body {
            Some(body) => self.data.xpos()[body][0],
            None => self.data.qpos()[0],
        }
    }

    /// The current observation in the configured layout.
    pub fn observation(&self) -> Vec<f64> {
        let clip = self.spec().velocity_clip.unwrap_or(f64::INFINITY);
        let qpos = &self.data.qpos()[self.qpos_from()..];
        let qvel = self.data.qvel().iter().map(|v| v.clamp(-clip, clip));
        qpos.iter().copied().chain(qvel).collect()
    }

    /// Gymnasium's `is_healthy` on the simulator state.
    pub fn is_healthy(&self) -> bool {
        let state: Vec<f64> = self
            .data
            .qpos()
            .iter()
            .chain(self.data.qvel())
            .copied()
            .collect();
        self.spec().health.is_healthy(&state, 0)
    }
}

fn check_vector(what: &'static str, values: &[f64], expected: usize) -> Result<(), EnvError> {
    if values.len() != expected {
        return Err(EnvError::Dimension {
            what,
            expected,
            got: values.len(),
        });
    }
    if let Some(index) = values.iter().position(|v| !v.is_finite()) {
        return Err(EnvError::NonFinite { what, index });
    }
    Ok(())
}
