//! The in-memory offline dataset: transitions `(s, a, r, s', terminal, timeout)`
//! in D4RL's flat layout, validated on construction, with trajectory
//! boundaries recovered from the flags and from state continuity.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use ndarray::{Array1, Array2, ArrayView2, Axis};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

use super::DataError;
use crate::envs::System;

/// Free-form provenance stored under D4RL's `metadata/` group (task, recipe,
/// seed, policy, generator version, ...).
pub type DatasetMetadata = BTreeMap<String, String>;

/// One trajectory: transitions `start..end` of the dataset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Trajectory {
    pub start: usize,
    pub end: usize,
}

impl Trajectory {
    pub fn len(&self) -> usize {
        self.end - self.start
    }

    pub fn is_empty(&self) -> bool {
        self.end == self.start
    }
}

/// The arrays of an offline dataset: row `i` of every array belongs to
/// transition `i`; `next_observations[i]` is the state after `actions[i]`.
/// What a reader (or a user) hands to [`Dataset::from_parts`].
#[derive(Debug, Clone, PartialEq)]
pub struct DatasetParts {
    pub observations: Array2<f32>,
    pub actions: Array2<f32>,
    pub rewards: Array1<f32>,
    pub next_observations: Array2<f32>,
    /// The episode ended because the task terminated (no bootstrapping).
    pub terminals: Vec<bool>,
    /// The episode was cut (time limit, or a boundary recovered from continuity).
    pub timeouts: Vec<bool>,
    /// Full MuJoCo state at `observations[i]` (D4RL's `infos/qpos`, `infos/qvel`), when known.
    pub qpos: Option<Array2<f32>>,
    pub qvel: Option<Array2<f32>>,
    /// log π(a|s) of the behaviour policy for each action (D4RL's
    /// `infos/action_log_probs`), when it had a density.
    pub action_log_probs: Option<Array1<f32>>,
    pub metadata: DatasetMetadata,
}

/// A validated offline dataset of `len()` transitions with its trajectory
/// boundaries. Its arrays are read through [`DatasetParts`] (`dataset.observations`, ...)
/// and cannot be changed, so the boundaries always match them.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    parts: DatasetParts,
    trajectories: Vec<Trajectory>,
}

impl std::ops::Deref for Dataset {
    type Target = DatasetParts;

    fn deref(&self) -> &DatasetParts {
        &self.parts
    }
}

impl Dataset {
    /// Validates the arrays (lengths, finiteness, non-emptiness) and recovers
    /// trajectory boundaries: a trajectory ends where `terminals` or `timeouts`
    /// is set, or where `next_observations[i] != observations[i + 1]` (a
    /// boundary the flags missed, which is then marked as a timeout).
    /// `file` names the source in errors.
    pub fn from_parts(mut parts: DatasetParts, file: &Path) -> Result<Self, DataError> {
        let DatasetParts {
            observations,
            actions,
            rewards,
            next_observations,
            terminals,
            timeouts,
            qpos,
            qvel,
            action_log_probs,
            ..
        } = &mut parts;
        let n = observations.nrows();
        if n == 0 {
            return Err(DataError::Empty {
                file: file.to_path_buf(),
            });
        }
        let rows = [
            ("actions", actions.nrows()),
            ("rewards", rewards.len()),
            ("next_observations", next_observations.nrows()),
            ("terminals", terminals.len()),
            ("timeouts", timeouts.len()),
            ("infos/qpos", qpos.as_ref().map_or(n, |a| a.nrows())),
            ("infos/qvel", qvel.as_ref().map_or(n, |a| a.nrows())),
            (
                "infos/action_log_probs",
                action_log_probs.as_ref().map_or(n, |a| a.len()),
            ),
        ];
        check_rows(file, n, &rows)?;
        if next_observations.ncols() != observations.ncols() {
            return Err(DataError::BadShape {
                file: file.to_path_buf(),
                key: "next_observations".into(),
                shape: next_observations.shape().to_vec(),
                expected: format!("[{n}, {}] like observations", observations.ncols()),
            });
        }
        check_finite(file, "observations", observations.view())?;
        check_finite(file, "actions", actions.view())?;
        check_finite(file, "rewards", rewards.view().insert_axis(Axis(1)))?;
        check_finite(file, "next_observations", next_observations.view())?;

        let mut trajectories = Vec::new();
        let mut start = 0;
        for i in 0..n {
            let last = i + 1 == n;
            let discontinuous = !last && next_observations.row(i) != observations.row(i + 1);
            if discontinuous && !terminals[i] {
                timeouts[i] = true;
            }
            if last || terminals[i] || timeouts[i] {
                trajectories.push(Trajectory { start, end: i + 1 });
                start = i + 1;
            }
        }
        Ok(Self {
            parts,
            trajectories,
        })
    }

    /// The same dataset with `metadata` in place of its own.
    pub fn with_metadata(mut self, metadata: DatasetMetadata) -> Self {
        self.parts.metadata = metadata;
        self
    }

    /// Number of transitions.
    pub fn len(&self) -> usize {
        self.observations.nrows()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn obs_dim(&self) -> usize {
        self.observations.ncols()
    }

    pub fn act_dim(&self) -> usize {
        self.actions.ncols()
    }

    /// Each action dimension's `(low, high)` over the dataset.
    pub fn action_bounds(&self) -> Vec<(f32, f32)> {
        column_bounds(&self.actions)
    }

    /// Each observation dimension's `(low, high)` over the dataset.
    pub fn observation_bounds(&self) -> Vec<(f32, f32)> {
        column_bounds(&self.observations)
    }

    /// The trajectories, in file order.
    pub fn trajectories(&self) -> &[Trajectory] {
        &self.trajectories
    }

    /// Checks that states and actions have `system`'s widths; `file` names the source.
    pub fn check_system(&self, system: &System, file: &Path) -> Result<(), DataError> {
        let shape = system.shape()?;
        let what = match system {
            System::Task(task) => format!("{} ({:?} layout)", task.task, task.layout),
            System::File(spec) => format!("system `{}`", spec.name),
        };
        for (key, got, expected) in [
            ("observations", self.obs_dim(), shape.obs_dim),
            ("actions", self.act_dim(), shape.act_dim),
        ] {
            if got != expected {
                return Err(DataError::WrongDimension {
                    file: file.to_path_buf(),
                    key: key.into(),
                    task: what,
                    expected,
                    got,
                });
            }
        }
        Ok(())
    }

    /// A new dataset holding only the given trajectories (by index), in that order.
    pub fn select_trajectories(&self, indices: &[usize]) -> Dataset {
        let rows: Vec<usize> = indices
            .iter()
            .flat_map(|&t| self.trajectories[t].start..self.trajectories[t].end)
            .collect();
        let pick2 = |a: &Array2<f32>| a.select(Axis(0), &rows);
        let pick_flags = |v: &[bool]| rows.iter().map(|&i| v[i]).collect::<Vec<_>>();
        let mut trajectories = Vec::with_capacity(indices.len());
        let mut start = 0;
        for &t in indices {
            let len = self.trajectories[t].len();
            trajectories.push(Trajectory {
                start,
                end: start + len,
            });
            start += len;
        }
        let parts = DatasetParts {
            observations: pick2(&self.observations),
            actions: pick2(&self.actions),
            rewards: self.rewards.select(Axis(0), &rows),
            next_observations: pick2(&self.next_observations),
            terminals: pick_flags(&self.terminals),
            timeouts: pick_flags(&self.timeouts),
            qpos: self.qpos.as_ref().map(pick2),
            qvel: self.qvel.as_ref().map(pick2),
            action_log_probs: self
                .action_log_probs
                .as_ref()
                .map(|a| a.select(Axis(0), &rows)),
            metadata: self.metadata.clone(),
        };
        Dataset {
            parts,
            trajectories,
        }
    }

    /// `datasets` one after another (D4RL's medium-expert), with `metadata`.
    /// They must agree in widths and in which of D4RL's `infos` they carry.
    pub fn concat(datasets: &[&Dataset], metadata: DatasetMetadata) -> Result<Dataset, DataError> {
        let source = Path::new("<concatenated>");
        let invalid = |message: String| DataError::Invalid {
            file: source.to_path_buf(),
            message,
        };
        let first = datasets
            .first()
            .ok_or_else(|| invalid("nothing to concatenate".into()))?;
        let shape = |d: &Dataset| {
            (
                d.obs_dim(),
                d.act_dim(),
                d.qpos.as_ref().map(|a| a.ncols()),
                d.qvel.as_ref().map(|a| a.ncols()),
                d.action_log_probs.is_some(),
            )
        };
        if let Some((i, other)) = datasets
            .iter()
            .enumerate()
            .find(|(_, d)| shape(d) != shape(first))
        {
            return Err(invalid(format!(
                "part {i} has widths and infos {:?}, part 0 has {:?}",
                shape(other),
                shape(first)
            )));
        }
        let stack = |views: Vec<ArrayView2<f32>>| {
            ndarray::concatenate(Axis(0), &views).map_err(|e| invalid(e.to_string()))
        };
        let required =
            |f: fn(&Dataset) -> &Array2<f32>| stack(datasets.iter().map(|d| f(d).view()).collect());
        // The shapes agree, so an info the first part carries, every part does.
        let optional = |f: fn(&Dataset) -> Option<&Array2<f32>>| {
            f(first)
                .map(|_| {
                    stack(
                        datasets
                            .iter()
                            .filter_map(|d| f(d))
                            .map(|a| a.view())
                            .collect(),
                    )
                })
                .transpose()
        };
        let flags =
            |f: fn(&Dataset) -> &[bool]| datasets.iter().flat_map(|d| f(d).to_vec()).collect();
        let parts = DatasetParts {
            observations: required(|d| &d.observations)?,
            actions: required(|d| &d.actions)?,
            rewards: datasets.iter().flat_map(|d| d.rewards.to_vec()).collect(),
            next_observations: required(|d| &d.next_observations)?,
            terminals: flags(|d| &d.terminals),
            timeouts: flags(|d| &d.timeouts),
            qpos: optional(|d| d.qpos.as_ref())?,
            qvel: optional(|d| d.qvel.as_ref())?,
            action_log_probs: first.action_log_probs.is_some().then(|| {
                datasets
                    .iter()
                    .flat_map(|d| d.action_log_probs.iter().flatten().copied())
                    .collect()
            }),
            metadata,
        };
        Dataset::from_parts(parts, source)
    }

    /// Splits whole trajectories into (train, validation), about `valid_fraction`
    /// of the trajectories going to validation (at least one each when there are
    /// two or more). Deterministic for a seed.
    pub fn split_by_trajectory(&self, valid_fraction: f64, seed: u64) -> (Dataset, Dataset) {
        let mut order: Vec<usize> = (0..self.trajectories.len()).collect();
        order.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
        let n = order.len();
        let n_valid = if n < 2 {
            0
        } else {
            ((n as f64 * valid_fraction).round() as usize).clamp(1, n - 1)
        };
        let (valid, train) = order.split_at(n_valid);
        let (mut train, mut valid) = (train.to_vec(), valid.to_vec());
        train.sort_unstable();
        valid.sort_unstable();
        (
            self.select_trajectories(&train),
            self.select_trajectories(&valid),
        )
    }
}

/// Checks that every `(key, rows)` has `n` rows, like `observations`.
pub(crate) fn check_rows(file: &Path, n: usize, rows: &[(&str, usize)]) -> Result<(), DataError> {
    match rows.iter().find(|(_, got)| *got != n) {
        Some(&(key, got)) => Err(DataError::LengthMismatch {
            file: file.to_path_buf(),
            key: key.into(),
            reference: "observations".into(),
            expected: n,
            got,
        }),
        None => Ok(()),
    }
}

fn check_finite(file: &Path, key: &str, values: ArrayView2<f32>) -> Result<(), DataError> {
    match values
        .outer_iter()
        .position(|row| row.iter().any(|v| !v.is_finite()))
    {
        Some(row) => Err(DataError::NonFinite {
            file: PathBuf::from(file),
            key: key.into(),
            row,
        }),
        None => Ok(()),
    }
}

/// Each column's `(low, high)`.
fn column_bounds(values: &Array2<f32>) -> Vec<(f32, f32)> {
    (values.columns().into_iter())
        .map(|column| {
            let low = column.fold(f32::INFINITY, |a, &b| a.min(b));
            (low, column.fold(low, |a, &b| a.max(b)))
        })
        .collect()
}
