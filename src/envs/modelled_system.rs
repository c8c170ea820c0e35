//! What a model is of: one of the built-in MuJoCo tasks (simulated, in
//! D4RL's or NeoRL's layout) or a system described in a file (no
//! simulator). The trainer's `--task`/`--system`, the artifacts and the
//! server all carry one.

use std::sync::Arc;

use serde::ser::{SerializeMap, Serializer};

use super::EnvError;
use super::mujoco_task::{MujocoTask, TaskConfig};
use super::rules::{Rules, TaskRules};
use super::system::SystemSpec;
use super::task::StateSplit;

/// A built-in task, or a system described as data.
#[derive(Debug, Clone)]
pub enum System {
    Task(TaskConfig),
    File(Arc<SystemSpec>),
}

/// What a dynamics model of a system is built from, and the box its
/// actions live in.
#[derive(Debug, Clone, PartialEq)]
pub struct SystemShape {
    pub obs_dim: usize,
    pub act_dim: usize,
    pub split: StateSplit,
    /// Seconds between consecutive observations.
    pub dt: f64,
    pub action_low: Vec<f64>,
    pub action_high: Vec<f64>,
}

impl SystemShape {
    /// The action box as `(low, high)` pairs in f32, the actions' precision.
    pub fn action_space(&self) -> Vec<(f32, f32)> {
        self.action_low
            .iter()
            .zip(&self.action_high)
            .map(|(&l, &h)| (l as f32, h as f32))
            .collect()
    }
}

impl System {
    /// The task's name (`hopper`), or the name the file gives.
    pub fn name(&self) -> String {
        match self {
            Self::Task(task) => task.task.to_string(),
            Self::File(spec) => spec.name.clone(),
        }
    }

    /// The observations' names, where the system gives them (a file's; the
    /// built-in tasks name none).
    pub fn observation_names(&self) -> Option<&[String]> {
        match self {
            Self::Task(_) => None,
            Self::File(spec) => Some(&spec.observations),
        }
    }

    /// The task to simulate, where there is one: a built-in task, or the
    /// `[mujoco]` table of a system's file.
    pub fn simulator(&self) -> Option<TaskConfig> {
        match self {
            Self::Task(task) => Some(task.clone()),
            Self::File(spec) => spec.simulation.clone(),
        }
    }

    /// The built-in task, which artifacts record by name (a file's system
    /// is recorded as its file's text).
    pub fn task(&self) -> Option<TaskConfig> {
        match self {
            Self::Task(task) => Some(task.clone()),
            Self::File(_) => None,
        }
    }

    /// Widths, the state split, dt and the action box (a task's read from its
    /// MuJoCo model).
    pub fn shape(&self) -> Result<SystemShape, EnvError> {
        match self {
            Self::Task(task) => {
                let probe = MujocoTask::new(task)?;
                let (action_low, action_high) = probe.action_bounds();
                Ok(SystemShape {
                    obs_dim: probe.obs_dim(),
                    act_dim: probe.act_dim(),
                    split: probe.state_split(),
                    dt: probe.dt(),
                    action_low,
                    action_high,
                })
            }
            Self::File(spec) => Ok(SystemShape {
                obs_dim: spec.obs_dim(),
                act_dim: spec.act_dim(),
                split: spec.split.clone(),
                dt: spec.dt,
                action_low: spec.action_low.clone(),
                action_high: spec.action_high.clone(),
            }),
        }
    }

    /// The rules on a model whose states are `dt` apart (a neural SDE's own;
    /// a file's system has one dt).
    pub fn rules_on(&self, dt: f64) -> Rules {
        match self {
            Self::Task(task) => TaskRules::new(task, dt).into(),
            Self::File(spec) => Rules::System(spec.clone()),
        }
    }

    /// The rules on the system's own observations and step (what a model that
    /// steps once per system step, like an ensemble, follows).
    pub fn rules(&self) -> Result<Rules, EnvError> {
        match self {
            Self::Task(task) => Ok(TaskRules::of_task(task)?.into()),
            Self::File(spec) => Ok(Rules::System(spec.clone())),
        }
    }

    /// The system a model records: its file's text where it has one
    /// (re-checked here, `what` naming the record for messages), else its task.
    pub fn recorded(
        task: Option<TaskConfig>,
        file: Option<&str>,
        what: &std::path::Path,
    ) -> Result<Option<Self>, EnvError> {
        match (file, task) {
            (Some(text), _) => Ok(Some(Self::File(Arc::new(SystemSpec::parse(text, what)?)))),
            (None, Some(task)) => Ok(Some(Self::Task(task))),
            (None, None) => Ok(None),
        }
    }

    /// The file's text, for an artifact to record; none for a built-in task.
    pub fn file_text(&self) -> Option<String> {
        match self {
            Self::Task(_) => None,
            Self::File(spec) => Some(spec.source.clone()),
        }
    }
}

/// Two built-in tasks are equal in the same layout; two files' systems when
/// their files say the same.
impl PartialEq for System {
    fn eq(&self, other: &Self) -> bool {
        match (self, other) {
            (Self::Task(a), Self::Task(b)) => a == b,
            (Self::File(a), Self::File(b)) => a.source == b.source,
            _ => false,
        }
    }
}

/// `{"task": {...}}` or `{"system": {"name": ..., "file": "<the TOML>"}}`,
/// as plans record it in `run.json`.
impl serde::Serialize for System {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(Some(1))?;
        match self {
            Self::Task(task) => map.serialize_entry("task", task)?,
            Self::File(spec) => map.serialize_entry(
                "system",
                &serde_json::json!({ "name": spec.name, "file": spec.source }),
            )?,
        }
        map.end()
    }
}
