//! `.npz` datasets: NeoRL's (e.g. `Hopper-v3-low-1000-train-noise.npz`, keys
//! `obs`, `next_obs`, `action`, `reward`, `done` and `index`, the first row of
//! each trajectory; NeoRL observations include the root x position), or any
//! `.npz` with D4RL's keys (`observations`, `actions`, `rewards`,
//! `terminals`, optional `timeouts` and `next_observations`), as `np.savez`
//! of a D4RL dict writes. The writer produces NeoRL files it reads back.

use std::fs::File;
use std::path::Path;

use ndarray::{Array1, Array2, ArrayD, Ix2};
use ndarray_npy::{NpzReader, NpzWriter};

use super::d4rl::next_states_from_successors;
use super::dataset::DatasetParts;
use super::{DataError, Dataset, DatasetMetadata};
use crate::shared::write_atomically;

/// Reads a NeoRL `.npz` file. Trajectory `k` spans `index[k]..index[k + 1]`;
/// its last transition is a terminal if `done` says so, else a timeout.
pub fn read_neorl(path: &Path) -> Result<Dataset, DataError> {
    let npz_error = |message: String| DataError::Npz {
        file: path.to_path_buf(),
        message,
    };
    let file = File::open(path).map_err(|source| DataError::Io {
        file: path.to_path_buf(),
        source,
    })?;
    let mut npz = NpzReader::new(file).map_err(|e| npz_error(e.to_string()))?;
    let names = npz.names().map_err(|e| npz_error(e.to_string()))?;
    if names.iter().any(|n| n == "observations") {
        return read_d4rl_keys(npz, &names, path);
    }
    let mut array = |key: &str| -> Result<ArrayD<f32>, DataError> {
        if !names.iter().any(|n| n == key) {
            return Err(DataError::MissingKey {
                file: path.to_path_buf(),
                key: key.into(),
            });
        }
        read_as_f32(&mut npz, key).map_err(|e| npz_error(format!("`{key}`: {e}")))
    };
    let observations = matrix(array("obs")?, "obs", path)?;
    let next_observations = matrix(array("next_obs")?, "next_obs", path)?;
    let actions = matrix(array("action")?, "action", path)?;
    let rewards = column(array("reward")?, "reward", path)?;
    let done: Vec<bool> = column(array("done")?, "done", path)?
        .iter()
        .map(|&d| d != 0.0)
        .collect();
    // Trajectory starts; f32 holds integers exactly up to 2^24 rows, far above
    // NeoRL's largest files (about 1M transitions).
    let index = column(array("index")?, "index", path)?;

    let n = observations.nrows();
    let mut timeouts = vec![false; n];
    let starts: Vec<usize> = index.iter().map(|&i| i as usize).collect();
    for (k, &start) in starts.iter().enumerate() {
        let end = starts.get(k + 1).copied().unwrap_or(n);
        if start >= end || end > n {
            return Err(DataError::Invalid {
                file: path.to_path_buf(),
                message: format!(
                    "`index` must increase strictly below {n}, found trajectory {k} at {start}..{end}"
                ),
            });
        }
        if done.len() == n && !done[end - 1] {
            timeouts[end - 1] = true;
        }
    }
    let mut metadata = DatasetMetadata::new();
    metadata.insert("source".into(), path.display().to_string());
    metadata.insert("format".into(), "neorl".into());
    let parts = DatasetParts {
        observations,
        actions,
        rewards,
        next_observations,
        terminals: done,
        timeouts,
        qpos: None,
        qvel: None,
        action_log_probs: None,
        metadata,
    };
    Dataset::from_parts(parts, path)
}

/// Reads an `.npz` holding D4RL's keys, as [`super::read_d4rl`] reads them
/// from HDF5 (next states from the following rows where `next_observations`
/// is missing).
fn read_d4rl_keys(
    mut npz: NpzReader<File>,
    names: &[String],
    path: &Path,
) -> Result<Dataset, DataError> {
    let has = |key: &str| names.iter().any(|n| n == key);
    let mut array = |key: &str| -> Result<ArrayD<f32>, DataError> {
        if !has(key) {
            return Err(DataError::MissingKey {
                file: path.to_path_buf(),
                key: key.into(),
            });
        }
        read_as_f32(&mut npz, key).map_err(|e| DataError::Npz {
            file: path.to_path_buf(),
            message: format!("`{key}`: {e}"),
        })
    };
    let flags = |values: Array1<f32>| values.iter().map(|&v| v != 0.0).collect::<Vec<bool>>();
    let observations = matrix(array("observations")?, "observations", path)?;
    let n = observations.nrows();
    let mut metadata = DatasetMetadata::new();
    metadata.insert("source".into(), path.display().to_string());
    metadata.insert("format".into(), "npz with D4RL keys".into());
    let mut parts = DatasetParts {
        actions: matrix(array("actions")?, "actions", path)?,
        rewards: column(array("rewards")?, "rewards", path)?,
        terminals: flags(column(array("terminals")?, "terminals", path)?),
        timeouts: if has("timeouts") {
            flags(column(array("timeouts")?, "timeouts", path)?)
        } else {
            vec![false; n]
        },
        next_observations: Array2::zeros((0, observations.ncols())),
        observations,
        qpos: None,
        qvel: None,
        action_log_probs: None,
        metadata,
    };
    if has("next_observations") {
        parts.next_observations = matrix(array("next_observations")?, "next_observations", path)?;
    } else {
        parts = next_states_from_successors(parts, path)?;
    }
    Dataset::from_parts(parts, path)
}

/// Writes `dataset` as a NeoRL `.npz` (float32 `obs`, `next_obs`, `action`,
/// `reward` and `done` as `[n, 1]`, int64 `index`), atomically. Timeouts are
/// where a trajectory ends without `done`, as NeoRL keeps them.
pub fn write_neorl(dataset: &Dataset, path: &Path) -> Result<(), DataError> {
    let npz_error = |message: String| DataError::Npz {
        file: path.to_path_buf(),
        message,
    };
    let n = dataset.len();
    let column = |v: Vec<f32>| Array2::from_shape_vec((n, 1), v);
    let reward = column(dataset.rewards.to_vec()).map_err(|e| npz_error(e.to_string()))?;
    let done = column(
        dataset
            .terminals
            .iter()
            .map(|&d| f32::from(u8::from(d)))
            .collect(),
    )
    .map_err(|e| npz_error(e.to_string()))?;
    let index = Array1::from_iter(dataset.trajectories().iter().map(|t| t.start as i64));
    write_atomically(
        path,
        |tmp| {
            let file = File::create(tmp).map_err(|source| DataError::Io {
                file: path.to_path_buf(),
                source,
            })?;
            let mut npz = NpzWriter::new_compressed(file);
            npz.add_array("obs", &dataset.observations)
                .and_then(|()| npz.add_array("next_obs", &dataset.next_observations))
                .and_then(|()| npz.add_array("action", &dataset.actions))
                .and_then(|()| npz.add_array("reward", &reward))
                .and_then(|()| npz.add_array("done", &done))
                .and_then(|()| npz.add_array("index", &index))
                .and_then(|()| npz.finish().map(drop))
                .map_err(|e| npz_error(e.to_string()))
        },
        |source| DataError::Io {
            file: path.to_path_buf(),
            source,
        },
    )
}

/// Reads any numeric or bool `.npy` member as f32.
fn read_as_f32(npz: &mut NpzReader<File>, key: &str) -> Result<ArrayD<f32>, String> {
    macro_rules! try_type {
        ($t:ty, $cast:expr) => {
            if let Ok(a) = npz.by_name::<ndarray::OwnedRepr<$t>, ndarray::IxDyn>(key) {
                return Ok(a.mapv($cast));
            }
        };
    }
    try_type!(f32, |v| v);
    try_type!(f64, |v| v as f32);
    try_type!(i64, |v| v as f32);
    try_type!(i32, |v| v as f32);
    try_type!(bool, |v| if v { 1.0 } else { 0.0 });
    try_type!(u8, f32::from);
    Err("unsupported dtype (expected float, integer or bool)".into())
}

fn matrix(a: ArrayD<f32>, key: &str, path: &Path) -> Result<Array2<f32>, DataError> {
    let shape = a.shape().to_vec();
    a.into_dimensionality::<Ix2>()
        .map_err(|_| DataError::BadShape {
            file: path.to_path_buf(),
            key: key.into(),
            shape,
            expected: "2 dimensions [transitions, width]".into(),
        })
}

fn column(a: ArrayD<f32>, key: &str, path: &Path) -> Result<Array1<f32>, DataError> {
    let shape = a.shape().to_vec();
    if shape.len() == 1 || (shape.len() == 2 && shape[1] == 1) {
        Ok(Array1::from_iter(a.iter().copied()))
    } else {
        Err(DataError::BadShape {
            file: path.to_path_buf(),
            key: key.into(),
            shape,
            expected: "[transitions] or [transitions, 1]".into(),
        })
    }
}
