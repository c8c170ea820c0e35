//! What defines each task: the MJCF model, frame skip, reward weights, health
//! rules, reset noise, observation layout (each task's `[mujoco]` table in
//! `tasks/`) and the state split the neural SDE needs. Values are Gymnasium's
//! `*-v4` (D4RL-v2 semantics on the modern bindings); see docs/paper-map.md
//! for the sources.

use std::fmt;
use std::str::FromStr;
use std::sync::{Arc, Once, OnceLock};

use mujoco_rs::prelude::MjModel;
use mujoco_rs::wrappers::mj_model::MjtJoint;
use serde::{Deserialize, Serialize};

use super::EnvError;
use super::mujoco_table::{ModelSource, MujocoFile};
use super::score::ScoreReference;

/// The MuJoCo tasks nuno simulates: D4RL's and NeoRL's three locomotion
/// robots, and Gymnasium's Swimmer, InvertedPendulum and Ant.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TaskName {
    Hopper,
    #[serde(rename = "halfcheetah")]
    HalfCheetah,
    Walker2d,
    Swimmer,
    #[serde(rename = "invertedpendulum")]
    InvertedPendulum,
    Ant,
}

impl TaskName {
    pub const ALL: [TaskName; 6] = [
        TaskName::Hopper,
        TaskName::HalfCheetah,
        TaskName::Walker2d,
        TaskName::Swimmer,
        TaskName::InvertedPendulum,
        TaskName::Ant,
    ];

    /// The name used in dataset and preset names (`hopper`, `halfcheetah`, ...,
    /// `invertedpendulum`: no hyphen, as Minari spells it, so `NAME-KIND` parses).
    pub fn as_str(self) -> &'static str {
        match self {
            TaskName::Hopper => "hopper",
            TaskName::HalfCheetah => "halfcheetah",
            TaskName::Walker2d => "walker2d",
            TaskName::Swimmer => "swimmer",
            TaskName::InvertedPendulum => "invertedpendulum",
            TaskName::Ant => "ant",
        }
    }

    /// The task's fixed definition (`src/envs/tasks/<name>.toml`).
    pub fn spec(self) -> &'static TaskSpec {
        built_in(self)
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

/// A MuJoCo task: one of the built-in ones, or a system file's `[mujoco]` table.
#[derive(Debug, Clone)]
pub enum Task {
    BuiltIn(TaskName),
    File(Arc<FileTask>),
}

/// A system file's MuJoCo task, under the name the file gives its system.
#[derive(Debug)]
pub struct FileTask {
    pub name: String,
    pub spec: TaskSpec,
}

impl Task {
    /// The task's definition.
    pub fn spec(&self) -> &TaskSpec {
        match self {
            Self::BuiltIn(name) => name.spec(),
            Self::File(task) => &task.spec,
        }
    }

    pub fn name(&self) -> &str {
        match self {
            Self::BuiltIn(name) => name.as_str(),
            Self::File(task) => &task.name,
        }
    }

    /// The built-in task this is, if it is one.
    pub fn built_in(&self) -> Option<TaskName> {
        match self {
            Self::BuiltIn(name) => Some(*name),
            Self::File(_) => None,
        }
    }
}

impl From<TaskName> for Task {
    fn from(name: TaskName) -> Self {
        Self::BuiltIn(name)
    }
}

/// Built-in tasks are equal by name; a file's task only to itself (two
/// files' tasks compare through the files' texts, `System`'s equality).
impl PartialEq for Task {
    fn eq(&self, other: &Self) -> bool {
        match (self, other) {
            (Self::BuiltIn(a), Self::BuiltIn(b)) => a == b,
            (Self::File(a), Self::File(b)) => Arc::ptr_eq(a, b),
            _ => false,
        }
    }
}

impl Eq for Task {}

impl PartialEq<TaskName> for Task {
    fn eq(&self, other: &TaskName) -> bool {
        self.built_in() == Some(*other)
    }
}

impl fmt::Display for Task {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// By name. Only built-in tasks read back: a file's task is recorded as its
/// system file, whose name alone cannot rebuild it.
impl Serialize for Task {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for Task {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        TaskName::deserialize(deserializer).map(Self::BuiltIn)
    }
}

/// When an episode ends early because the robot fell (Gymnasium's `is_healthy`).
///
/// Each rule reads the state vector `concat(qpos, qvel)`; an observation that
/// omits the first `from` qpos entries is that vector from index `from` on,
/// which every rule below can still read (its qpos indices are ≥ `from`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HealthRule {
    /// Never terminates (halfcheetah, swimmer).
    AlwaysHealthy,
    /// Healthy while `z_range.0 < qpos[1] < z_range.1`, `angle_range.0 < qpos[2] < angle_range.1`
    /// and, if set, every entry of `concat(qpos, qvel)[2..]` lies strictly inside `state_range`
    /// (hopper, walker2d).
    Upright {
        z_range: (f64, f64),
        angle_range: (f64, f64),
        state_range: Option<(f64, f64)>,
    },
    /// Healthy while every entry of the state is finite and
    /// `range.0 <= qpos[qpos] <= range.1` (ant's height, the inverted pendulum's angle).
    FiniteWithin { qpos: usize, range: (f64, f64) },
}

impl HealthRule {
    /// Whether the state whose entries from index `from` on are `state` is healthy.
    pub fn is_healthy<T: Copy + Into<f64>>(&self, state: &[T], from: usize) -> bool {
        let at = |i: usize| state[i - from].into();
        match *self {
            HealthRule::AlwaysHealthy => true,
            HealthRule::Upright {
                z_range,
                angle_range,
                state_range,
            } => {
                let inside = |x: f64, (lo, hi): (f64, f64)| lo < x && x < hi;
                let rest = &state[2 - from..];
                let state_ok =
                    state_range.is_none_or(|range| rest.iter().all(|&x| inside(x.into(), range)));
                inside(at(1), z_range) && inside(at(2), angle_range) && state_ok
            }
            HealthRule::FiniteWithin { qpos, range } => {
                let x = at(qpos);
                state.iter().all(|&v| v.into().is_finite()) && range.0 <= x && x <= range.1
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

/// The fixed definition of one task: its `[mujoco]` table, checked against
/// its compiled model ([`super::mujoco_table`]).
#[derive(Debug, Clone, PartialEq)]
pub struct TaskSpec {
    /// The MJCF model, compiled once per process and shared by every instance.
    pub model: CompiledModel,
    /// The model's qpos and qvel widths.
    pub nq: usize,
    pub nv: usize,
    /// Gymnasium's default observation is `qpos[observed_qpos_from..] ++ qvel`: the
    /// root's horizontal coordinates are left out (D4RL's layout); NeoRL's keeps them all.
    pub observed_qpos_from: usize,
    /// MuJoCo steps per environment step; dt = timestep · frame_skip.
    pub frame_skip: usize,
    /// The body whose frame's x gives the forward velocity (Gymnasium's ant reads its
    /// torso, `get_body_com`); `None`: the root's qpos[0] (the planar robots, swimmer).
    pub forward_body: Option<usize>,
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
    /// The reference returns of the normalised score (D4RL's for its tasks).
    pub d4rl_score: ScoreReference,
    /// The reference returns where all of qpos is observed (NUNO's code's for
    /// NeoRL's tasks, which NeoRL ships none of); others score it as `d4rl_score`.
    pub neorl_score: ScoreReference,
}

impl TaskSpec {
    /// Seconds between observations: the model's timestep × frame skip.
    pub fn dt(&self) -> f64 {
        self.model.0.opt().timestep * self.frame_skip as f64
    }

    /// The split of the observation `qpos[qpos_from..] ++ qvel` by the model's joints.
    pub fn state_split(&self, qpos_from: usize) -> StateSplit {
        let model = &self.model.0;
        let joints: Vec<Joint> = (model.jnt_type().iter())
            .zip(model.jnt_qposadr())
            .zip(model.jnt_dofadr())
            .map(|((kind, &qpos), &dof)| Joint {
                kind: match *kind {
                    MjtJoint::mjJNT_FREE => JointKind::Free,
                    MjtJoint::mjJNT_BALL => JointKind::Ball,
                    MjtJoint::mjJNT_SLIDE => JointKind::Slide,
                    _ => JointKind::Hinge,
                },
                qpos: qpos as usize,
                dof: dof as usize,
            })
            .collect();
        StateSplit::of_joints(&joints, self.nq, self.nv, qpos_from)
    }

    /// Each actuator's control range, `None` where it has none (not ctrl-limited).
    pub fn control_ranges(&self) -> Vec<Option<(f64, f64)>> {
        let model = &self.model.0;
        (model.actuator_ctrllimited().iter())
            .zip(model.actuator_ctrlrange())
            .map(|(&limited, range)| limited.then_some((range[0], range[1])))
            .collect()
    }
}

/// A compiled MuJoCo model, shared; two are equal when they are the same one.
#[derive(Clone)]
pub struct CompiledModel(pub Arc<MjModel>);

impl PartialEq for CompiledModel {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}

impl fmt::Debug for CompiledModel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("CompiledModel")
    }
}

/// The built-in tasks' tables, in [`TaskName::ALL`]'s order.
const TABLES: [&str; TaskName::ALL.len()] = [
    include_str!("tasks/hopper.toml"),
    include_str!("tasks/halfcheetah.toml"),
    include_str!("tasks/walker2d.toml"),
    include_str!("tasks/swimmer.toml"),
    include_str!("tasks/invertedpendulum.toml"),
    include_str!("tasks/ant.toml"),
];

/// The MJCF models the tables name, from the `gymnasium` wheel (`make mujoco`).
const MODELS: [(&str, &str); TaskName::ALL.len()] = [
    (
        "hopper.xml",
        include_str!(concat!(env!("NUNO_MJCF_DIR"), "/hopper.xml")),
    ),
    (
        "half_cheetah.xml",
        include_str!(concat!(env!("NUNO_MJCF_DIR"), "/half_cheetah.xml")),
    ),
    (
        "walker2d.xml",
        include_str!(concat!(env!("NUNO_MJCF_DIR"), "/walker2d.xml")),
    ),
    (
        "swimmer.xml",
        include_str!(concat!(env!("NUNO_MJCF_DIR"), "/swimmer.xml")),
    ),
    (
        "inverted_pendulum.xml",
        include_str!(concat!(env!("NUNO_MJCF_DIR"), "/inverted_pendulum.xml")),
    ),
    (
        "ant.xml",
        include_str!(concat!(env!("NUNO_MJCF_DIR"), "/ant.xml")),
    ),
];

/// `task`'s table read and checked, once per process.
fn built_in(task: TaskName) -> &'static TaskSpec {
    static SPECS: [OnceLock<TaskSpec>; TaskName::ALL.len()] =
        [const { OnceLock::new() }; TaskName::ALL.len()];
    SPECS[task as usize].get_or_init(|| {
        let checked = MujocoFile::parse(TABLES[task as usize]).and_then(|file| {
            let table = file.table();
            let ModelSource::File(file) = table.model_source()? else {
                return Err("a built-in table names its model file".into());
            };
            let xml = MODELS.iter().find(|(name, _)| *name == file);
            let (_, xml) = xml.ok_or_else(|| format!("no embedded model `{file}`"))?;
            table.check(xml)
        });
        // Embedded at build time and read by every test of the tasks: a
        // broken one is a broken build, not bad input.
        checked.unwrap_or_else(|e| panic!("the built-in {task} table: {e}"))
    })
}

/// Routes MuJoCo's warnings to the `log` crate; it would otherwise print them
/// and append them to MUJOCO_LOG.TXT in the working directory.
pub(super) fn install_mujoco_logging() {
    static LOGGING: Once = Once::new();
    // SAFETY: called before every model is compiled (`MujocoFile::check`; Once
    // blocks other threads until the hook is in), so no thread uses MuJoCo meanwhile.
    LOGGING.call_once(|| unsafe { mujoco_rs::prelude::install_logging_hook() });
}

/// Which observation variant a task reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ObservationLayout {
    /// `qpos[k..] ++ qvel` with the task's `observed_qpos_from` k: D4RL
    /// (Gymnasium's default, the root's horizontal coordinates excluded), and
    /// a system file's task as its `[mujoco]` table observes it.
    #[default]
    D4rl,
    /// `qpos ++ qvel`: NeoRL, whose observations include the root x position.
    Neorl,
}

impl ObservationLayout {
    /// The first qpos entry this layout observes of a task defined by `spec`.
    pub fn qpos_from(self, spec: &TaskSpec) -> usize {
        match self {
            ObservationLayout::D4rl => spec.observed_qpos_from,
            ObservationLayout::Neorl => 0,
        }
    }
}

/// What one MuJoCo joint adds to qpos and qvel, and where.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Joint {
    pub kind: JointKind,
    /// Its first entry in qpos (`jnt_qposadr`) and in qvel (`jnt_dofadr`).
    pub qpos: usize,
    pub dof: usize,
}

/// MuJoCo's joint types, by what their coordinates are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointKind {
    /// Position (3) and orientation quaternion (4); linear (3) and angular (3) velocity.
    Free,
    /// An orientation quaternion (4); angular velocity (3).
    Ball,
    Slide,
    Hinge,
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
    /// The split of the observation `qpos[from..] ++ qvel` of a model with
    /// these joints: a slide or hinge coordinate, or a free joint's position,
    /// pairs with its velocity (a free joint's linear velocity is its
    /// position's derivative in the world frame); hinges are angles.
    ///
    /// The SDE needs its positions first (`DynamicsSpec::validate`), so pairing
    /// stops at the first observed qpos entry without a velocity of its own (a
    /// quaternion): the entries from there on are learned by the drift's
    /// networks alone, as unpaired observations of a system file are.
    pub fn of_joints(joints: &[Joint], nq: usize, nv: usize, from: usize) -> Self {
        let mut paired = vec![None; nq];
        let mut angles = Vec::new();
        for joint in joints {
            let translations = match joint.kind {
                JointKind::Free => 3,
                JointKind::Ball => 0,
                JointKind::Slide | JointKind::Hinge => 1,
            };
            for k in 0..translations {
                paired[joint.qpos + k] = Some(joint.dof + k);
            }
            if joint.kind == JointKind::Hinge {
                angles.push(joint.qpos);
            }
        }
        let observed_qpos = nq - from;
        let dofs: Vec<usize> = paired[from..].iter().map_while(|v| *v).collect();
        let n_pos = dofs.len();
        Self {
            positions: (0..n_pos).collect(),
            velocities: (n_pos..observed_qpos + nv).collect(),
            position_velocity: dofs.iter().map(|d| observed_qpos + d).collect(),
            angles: angles
                .into_iter()
                .filter(|&q| q >= from && q < from + n_pos)
                .map(|q| q - from)
                .collect(),
        }
    }

    /// Width of the observation this split describes.
    pub fn obs_dim(&self) -> usize {
        self.positions.len() + self.velocities.len()
    }
}
