//! Transitions recorded in a real task, row by row, with what D4RL keeps
//! beside them: the MuJoCo state at each observation and the behaviour
//! policy's log π(a|s). Dataset generation and online SAC both record into a
//! [`Recording`] and turn it into a [`Dataset`].

use std::path::Path;

use ndarray::{Array1, Array2};

use super::dataset::DatasetParts;
use super::{DataError, Dataset, DatasetMetadata};
use crate::envs::{MujocoTask, Transition};

/// Row-major columns of recorded transitions, widths fixed by the task.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    pub obs_dim: usize,
    pub act_dim: usize,
    pub nq: usize,
    pub nv: usize,
    pub observations: Vec<f32>,
    pub actions: Vec<f32>,
    pub rewards: Vec<f32>,
    pub next_observations: Vec<f32>,
    pub terminals: Vec<bool>,
    pub timeouts: Vec<bool>,
    pub qpos: Vec<f32>,
    pub qvel: Vec<f32>,
    pub log_probs: Vec<f32>,
    /// Whether every action came with its log π(a|s).
    pub logged: bool,
}

impl Recording {
    /// An empty recording with `task`'s widths.
    pub fn for_task(task: &MujocoTask) -> Self {
        Self {
            obs_dim: task.obs_dim(),
            act_dim: task.act_dim(),
            nq: task.qpos().len(),
            nv: task.qvel().len(),
            observations: Vec::new(),
            actions: Vec::new(),
            rewards: Vec::new(),
            next_observations: Vec::new(),
            terminals: Vec::new(),
            timeouts: Vec::new(),
            qpos: Vec::new(),
            qvel: Vec::new(),
            log_probs: Vec::new(),
            logged: true,
        }
    }

    pub fn len(&self) -> usize {
        self.rewards.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rewards.is_empty()
    }

    /// Records one step of `task`: `obs` and the MuJoCo state `(qpos, qvel)`
    /// before it, the action and its log-probability, and what the step gave.
    pub fn push(
        &mut self,
        obs: &[f32],
        (qpos, qvel): (&[f64], &[f64]),
        action: &[f32],
        log_prob: Option<f32>,
        step: &Transition,
    ) {
        self.observations.extend_from_slice(obs);
        self.qpos.extend(qpos.iter().map(|&x| x as f32));
        self.qvel.extend(qvel.iter().map(|&x| x as f32));
        self.actions.extend_from_slice(action);
        match log_prob {
            Some(l) => self.log_probs.push(l),
            None => self.logged = false,
        }
        self.rewards.push(step.reward as f32);
        self.next_observations
            .extend(step.observation.iter().map(|&x| x as f32));
        self.terminals.push(step.terminated);
        self.timeouts.push(step.truncated && !step.terminated);
    }

    /// Ends the trajectory in progress at the last row as a timeout, unless
    /// it already ended there (a cut that is not a time limit: the end of a
    /// budget, a checkpoint).
    pub fn cut(&mut self) {
        if let (Some(&t), Some(c)) = (self.terminals.last(), self.timeouts.last_mut()) {
            *c = !t;
        }
    }

    /// Keeps the first `keep` transitions, the last of them now ending its trajectory.
    pub fn truncate(&mut self, keep: usize) {
        self.observations.truncate(keep * self.obs_dim);
        self.actions.truncate(keep * self.act_dim);
        self.rewards.truncate(keep);
        self.next_observations.truncate(keep * self.obs_dim);
        self.terminals.truncate(keep);
        self.timeouts.truncate(keep);
        self.qpos.truncate(keep * self.nq);
        self.qvel.truncate(keep * self.nv);
        self.log_probs.truncate(keep);
        self.cut();
    }

    /// Appends `other`'s rows after this recording's.
    pub fn append(&mut self, other: Recording) {
        self.observations.extend(other.observations);
        self.actions.extend(other.actions);
        self.rewards.extend(other.rewards);
        self.next_observations.extend(other.next_observations);
        self.terminals.extend(other.terminals);
        self.timeouts.extend(other.timeouts);
        self.qpos.extend(other.qpos);
        self.qvel.extend(other.qvel);
        self.log_probs.extend(other.log_probs);
        self.logged &= other.logged;
    }

    /// The recorded rows as a validated dataset; `source` names it in errors.
    pub fn into_dataset(
        self,
        metadata: DatasetMetadata,
        source: &Path,
    ) -> Result<Dataset, DataError> {
        let n = self.len();
        let matrix = |v: Vec<f32>, width: usize| {
            Array2::from_shape_vec((n, width), v).map_err(|e| DataError::Invalid {
                file: source.to_path_buf(),
                message: format!("recorded rows do not form [{n}, {width}]: {e}"),
            })
        };
        let parts = DatasetParts {
            observations: matrix(self.observations, self.obs_dim)?,
            actions: matrix(self.actions, self.act_dim)?,
            rewards: Array1::from(self.rewards),
            next_observations: matrix(self.next_observations, self.obs_dim)?,
            terminals: self.terminals,
            timeouts: self.timeouts,
            qpos: Some(matrix(self.qpos, self.nq)?),
            qvel: Some(matrix(self.qvel, self.nv)?),
            action_log_probs: self.logged.then(|| Array1::from(self.log_probs)),
            metadata,
        };
        Dataset::from_parts(parts, source)
    }
}
