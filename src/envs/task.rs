//! What defines each task: the MJCF model, frame skip, reward weights, health
//! rules, reset noise, observation layout and the state split the neural SDE
//! needs. Values are Gymnasium's `*-v4` (D4RL-v2 semantics on the modern
//! bindings); see docs/paper-map.md for the sources.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::EnvError;
use super::score::ScoreReference;

/// The three MuJoCo locomotion tasks of D4RL and NeoRL.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TaskName {
    Hopper,
    #[serde(rename = "halfcheetah")]
    HalfCheetah,
    Walker2d,
}

impl TaskName {
    pub const ALL: [TaskName; 3] = [TaskName::Hopper, TaskName::HalfCheetah, TaskName::Walker2d];

    /// The name used in dataset and preset names (`hopper`, `halfcheetah`, `walker2d`).
    pub fn as_str(self) -> &'static str {
        match self {
            TaskName::Hopper => "hopper",
            TaskName::HalfCheetah => "halfcheetah",
            TaskName::Walker2d => "walker2d",
        }
    }

    /// The task's fixed definition.
    pub fn spec(self) -> &'static TaskSpec {
        match self {
            TaskName::Hopper => &HOPPER,
            TaskName::HalfCheetah => &HALF_CHEETAH,
            TaskName::Walker2d => &WALKER2D,
        }
    }
}

impl fmt::Display for TaskName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for TaskName {
    type Err = EnvError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        TaskName::ALL
            .into_iter()
            .find(|t| t.as_str() == s.to_ascii_lowercase())
            .ok_or_else(|| EnvError::UnknownTask(s.to_string()))
    }
}

/// When an episode ends early because the robot fell (Gymnasium's `is_healthy`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HealthRule {
    /// Never terminates (halfcheetah).
    AlwaysHealthy,
    /// Healthy while `z_range.0 < qpos[1] < z_range.1`, `angle_range.0 < qpos[2] < angle_range.1`
    /// and, if set, every entry of `concat(qpos, qvel)[2..]` lies strictly inside `state_range`.
    Upright {
        z_range: (f64, f64),
        angle_range: (f64, f64),
        state_range: Option<(f64, f64)>,
    },
}

impl HealthRule {
    /// Whether a robot with root height `z`, root angle `angle` and the rest of
    /// `concat(qpos, qvel)[2..]` in `rest` is healthy.
    pub fn is_healthy(&self, z: f64, angle: f64, mut rest: impl Iterator<Item = f64>) -> bool {
        match *self {
            HealthRule::AlwaysHealthy => true,
            HealthRule::Upright {
                z_range,
                angle_range,
                state_range,
            } => {
                let inside = |x: f64, (lo, hi): (f64, f64)| lo < x && x < hi;
                let state_ok = state_range.is_none_or(|range| rest.all(|x| inside(x, range)));
                inside(z, z_range) && inside(angle, angle_range) && state_ok
            }
        }
    }
}

/// How `reset` perturbs the model's initial state (`reset_noise_scale` in Gymnasium).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ResetNoise {
    /// qpos and qvel both get `U(-scale, scale)` (hopper, walker2d).
    Uniform { scale: f64 },
    /// qpos gets `U(-scale, scale)`, qvel gets `scale · N(0, 1)` (halfcheetah).
    UniformPositionNormalVelocity { scale: f64 },
}

/// The fixed definition of one task.
#[derive(Debug, Clone, PartialEq)]
pub struct TaskSpec {
    pub name: TaskName,
    /// The MJCF model from the `gymnasium` wheel, embedded at build time.
    pub xml: &'static str,
    /// MuJoCo steps per environment step; dt = timestep · frame_skip.
    pub frame_skip: usize,
    pub forward_reward_weight: f64,
    pub ctrl_cost_weight: f64,
    /// Reward added at every step (Gymnasium v4 pays it on the terminal step too).
    pub healthy_reward: f64,
    pub health: HealthRule,
    /// Observed velocities are clipped to `[-c, c]` (hopper, walker2d: 10).
    pub velocity_clip: Option<f64>,
    pub reset_noise: ResetNoise,
    /// Time limit; reaching it is a truncation, not a termination.
    pub max_episode_steps: usize,
    /// D4RL's reference returns for the normalised score.
    pub d4rl_score: ScoreReference,
    /// The reference returns NUNO uses for NeoRL tasks (NeoRL ships none).
    pub neorl_score: ScoreReference,
}

const HOPPER: TaskSpec = TaskSpec {
    name: TaskName::Hopper,
    xml: include_str!(concat!(env!("NUNO_MJCF_DIR"), "/hopper.xml")),
    frame_skip: 4,
    forward_reward_weight: 1.0,
    ctrl_cost_weight: 1e-3,
    healthy_reward: 1.0,
    health: HealthRule::Upright {
        z_range: (0.7, f64::INFINITY),
        angle_range: (-0.2, 0.2),
        state_range: Some((-100.0, 100.0)),
    },
    velocity_clip: Some(10.0),
    reset_noise: ResetNoise::Uniform { scale: 5e-3 },
    max_episode_steps: 1000,
    d4rl_score: ScoreReference {
        random: -20.272305,
        expert: 3234.3,
    },
    neorl_score: ScoreReference {
        random: 5.0,
        expert: 3294.0,
    },
};

const HALF_CHEETAH: TaskSpec = TaskSpec {
    name: TaskName::HalfCheetah,
    xml: include_str!(concat!(env!("NUNO_MJCF_DIR"), "/half_cheetah.xml")),
    frame_skip: 5,
    forward_reward_weight: 1.0,
    ctrl_cost_weight: 0.1,
    healthy_reward: 0.0,
    health: HealthRule::AlwaysHealthy,
    velocity_clip: None,
    reset_noise: ResetNoise::UniformPositionNormalVelocity { scale: 0.1 },
    max_episode_steps: 1000,
    d4rl_score: ScoreReference {
        random: -280.178953,
        expert: 12135.0,
    },
    neorl_score: ScoreReference {
        random: -298.0,
        expert: 12284.0,
    },
};

const WALKER2D: TaskSpec = TaskSpec {
    name: TaskName::Walker2d,
    xml: include_str!(concat!(env!("NUNO_MJCF_DIR"), "/walker2d.xml")),
    frame_skip: 4,
    forward_reward_weight: 1.0,
    ctrl_cost_weight: 1e-3,
    healthy_reward: 1.0,
    health: HealthRule::Upright {
        z_range: (0.8, 2.0),
        angle_range: (-1.0, 1.0),
        state_range: None,
    },
    velocity_clip: Some(10.0),
    reset_noise: ResetNoise::Uniform { scale: 5e-3 },
    max_episode_steps: 1000,
    d4rl_score: ScoreReference {
        random: 1.629008,
        expert: 4592.3,
    },
    neorl_score: ScoreReference {
        random: 1.0,
        expert: 5143.0,
    },
};

/// Which observation variant a task reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ObservationLayout {
    /// `qpos[1..] ++ qvel`: D4RL (Gymnasium's default, root x excluded).
    #[default]
    D4rl,
    /// `qpos ++ qvel`: NeoRL, whose observations include the root x position.
    Neorl,
}

/// How an observation splits into positions and velocities for the neural SDE's
/// kinematic prior `d pos/dt = vel`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct StateSplit {
    /// Observation indices of the positions, in order.
    pub positions: Vec<usize>,
    /// Observation indices of the velocities, in order.
    pub velocities: Vec<usize>,
    /// For each position `i`, the observation index of its time derivative.
    pub position_velocity: Vec<usize>,
    /// The positions that are angles (hinge joints and the root's pitch), which
    /// a pose-aware drift sees through their cosine and sine. Splits saved
    /// before this field name none.
    #[serde(default)]
    pub angles: Vec<usize>,
}

impl StateSplit {
    /// The split for a planar robot with `nq == nv` joints, root x first.
    ///
    /// D4RL observations drop root x, so observed position `i` (qpos `i + 1`) pairs
    /// with velocity `i + 1`; NeoRL keeps root x and pairs position `i` with velocity `i`.
    /// Every qpos after root x and root z (the root's pitch and the hinges) is an angle.
    pub fn planar(nq: usize, layout: ObservationLayout) -> Self {
        let skipped = match layout {
            ObservationLayout::D4rl => 1,
            ObservationLayout::Neorl => 0,
        };
        let n_pos = nq - skipped;
        let positions: Vec<usize> = (0..n_pos).collect();
        let velocities: Vec<usize> = (n_pos..n_pos + nq).collect();
        let position_velocity = (0..n_pos).map(|i| n_pos + i + skipped).collect();
        let root_z = 1 - skipped;
        Self {
            positions,
            velocities,
            position_velocity,
            angles: (root_z + 1..n_pos).collect(),
        }
    }

    /// Width of the observation this split describes.
    pub fn obs_dim(&self) -> usize {
        self.positions.len() + self.velocities.len()
    }
}
