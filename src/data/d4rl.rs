//! D4RL's HDF5 layout: `observations`, `actions`, `rewards`, `terminals`,
//! `timeouts`, optional `next_observations`, `infos/qpos`, `infos/qvel`,
//! `infos/action_log_probs`, and a
//! `metadata/` group. The reader takes real D4RL files; the writer produces
//! files that h5py and D4RL-style loaders read unchanged.

use std::path::Path;

use hdf5::types::VarLenUnicode;
use ndarray::{Array1, Array2, Axis, s};

use super::dataset::{DatasetParts, check_rows};
use super::{DataError, Dataset, DatasetMetadata};
use crate::shared::write_atomically;

/// gzip level of written datasets (h5py's and D4RL's default).
const GZIP_LEVEL: u8 = 4;

/// Wraps an HDF5 error with the file it came from.
pub(crate) fn h5_error(file: &Path) -> impl Fn(hdf5::Error) -> DataError + '_ {
    move |e| DataError::Hdf5 {
        file: file.to_path_buf(),
        message: e.to_string(),
    }
}

/// Opens a member dataset, or names the missing key.
pub(crate) fn member(
    group: &hdf5::Group,
    key: &str,
    file: &Path,
) -> Result<hdf5::Dataset, DataError> {
    if !group.link_exists(key) {
        return Err(DataError::MissingKey {
            file: file.to_path_buf(),
            key: key.into(),
        });
    }
    group.dataset(key).map_err(h5_error(file))
}

/// A 2-D float array (any float or integer type on disk).
pub(crate) fn read_matrix(
    group: &hdf5::Group,
    key: &str,
    file: &Path,
) -> Result<Array2<f32>, DataError> {
    let ds = member(group, key, file)?;
    if ds.ndim() != 2 {
        return Err(DataError::BadShape {
            file: file.to_path_buf(),
            key: key.into(),
            shape: ds.shape(),
            expected: "2 dimensions [transitions, width]".into(),
        });
    }
    ds.read_2d::<f32>().map_err(h5_error(file))
}

/// A per-transition scalar column, stored as `[n]` or `[n, 1]`.
pub(crate) fn read_column(
    group: &hdf5::Group,
    key: &str,
    file: &Path,
) -> Result<Array1<f32>, DataError> {
    let ds = member(group, key, file)?;
    let shape = ds.shape();
    if !(shape.len() == 1 || (shape.len() == 2 && shape[1] == 1)) {
        return Err(DataError::BadShape {
            file: file.to_path_buf(),
            key: key.into(),
            shape,
            expected: "[transitions] or [transitions, 1]".into(),
        });
    }
    Ok(Array1::from(ds.read_raw::<f32>().map_err(h5_error(file))?))
}

/// A per-transition flag column: h5py's bool enum, or numbers (non-zero = set).
pub(crate) fn read_flags(
    group: &hdf5::Group,
    key: &str,
    file: &Path,
) -> Result<Vec<bool>, DataError> {
    let ds = member(group, key, file)?;
    match ds.read_raw::<bool>() {
        Ok(flags) => Ok(flags),
        Err(_) => Ok(read_column(group, key, file)?
            .iter()
            .map(|&v| v != 0.0)
            .collect()),
    }
}

/// Reads a D4RL HDF5 file.
///
/// Next states come from `next_observations` when present. Without it, the
/// next state of transition `i` is `observations[i + 1]` inside a trajectory,
/// and the last transition of each trajectory, whose next state was never
/// recorded, is dropped (its predecessor then ends the trajectory as a
/// timeout); the count goes to `metadata["dropped_without_next_observation"]`.
pub fn read_d4rl(path: &Path) -> Result<Dataset, DataError> {
    let file = hdf5::File::open(path).map_err(h5_error(path))?;
    let observations = read_matrix(&file, "observations", path)?;
    let actions = read_matrix(&file, "actions", path)?;
    let rewards = read_column(&file, "rewards", path)?;
    let terminals = read_flags(&file, "terminals", path)?;
    let n = observations.nrows();
    let timeouts = if file.link_exists("timeouts") {
        read_flags(&file, "timeouts", path)?
    } else {
        vec![false; n]
    };
    let infos = |key: &str| -> Result<Option<Array2<f32>>, DataError> {
        let full = format!("infos/{key}");
        if file.link_exists("infos") && file.link_exists(&full) {
            read_matrix(&file, &full, path).map(Some)
        } else {
            Ok(None)
        }
    };
    let infos_column = |key: &str| -> Result<Option<Array1<f32>>, DataError> {
        let full = format!("infos/{key}");
        if file.link_exists("infos") && file.link_exists(&full) {
            read_column(&file, &full, path).map(Some)
        } else {
            Ok(None)
        }
    };
    let mut metadata = read_metadata(&file, path)?;
    metadata.insert("source".into(), path.display().to_string());
    let mut parts = DatasetParts {
        qpos: infos("qpos")?,
        qvel: infos("qvel")?,
        action_log_probs: infos_column("action_log_probs")?,
        next_observations: Array2::zeros((0, observations.ncols())),
        observations,
        actions,
        rewards,
        terminals,
        timeouts,
        metadata,
    };
    if file.link_exists("next_observations") {
        parts.next_observations = read_matrix(&file, "next_observations", path)?;
    } else {
        parts = next_states_from_successors(parts, path)?;
    }
    Dataset::from_parts(parts, path)
}

/// Fills `next_observations` from the following row and drops the transitions
/// that end a trajectory (their next state is unknown).
pub(super) fn next_states_from_successors(
    mut parts: DatasetParts,
    path: &Path,
) -> Result<DatasetParts, DataError> {
    let n = parts.observations.nrows();
    // Checked here as well as in `Dataset::from_parts`: the rows are indexed below.
    check_rows(
        path,
        n,
        &[
            ("actions", parts.actions.nrows()),
            ("terminals", parts.terminals.len()),
            ("timeouts", parts.timeouts.len()),
        ],
    )?;
    let ends = |i: usize| i + 1 == n || parts.terminals[i] || parts.timeouts[i];
    let keep: Vec<usize> = (0..n).filter(|&i| !ends(i)).collect();
    let next_rows: Vec<usize> = keep.iter().map(|&i| i + 1).collect();
    // A kept transition whose successor was dropped now ends its trajectory.
    let cut: Vec<bool> = keep.iter().map(|&i| ends(i + 1)).collect();
    let dropped = n - keep.len();
    parts.next_observations = parts.observations.select(Axis(0), &next_rows);
    parts.observations = parts.observations.select(Axis(0), &keep);
    parts.actions = parts.actions.select(Axis(0), &keep);
    parts.rewards = parts.rewards.select(Axis(0), &keep);
    parts.terminals = keep.iter().map(|&i| parts.terminals[i]).collect();
    parts.timeouts = keep
        .iter()
        .zip(&cut)
        .map(|(&i, &c)| parts.timeouts[i] || c)
        .collect();
    parts.qpos = parts.qpos.map(|a| a.select(Axis(0), &keep));
    parts.qvel = parts.qvel.map(|a| a.select(Axis(0), &keep));
    parts.action_log_probs = parts.action_log_probs.map(|a| a.select(Axis(0), &keep));
    parts.metadata.insert(
        "dropped_without_next_observation".into(),
        dropped.to_string(),
    );
    Ok(parts)
}

/// Scalar members of `metadata/` as strings (nested groups and arrays, such as
/// D4RL's stored policy weights, are skipped).
fn read_metadata(file: &hdf5::File, path: &Path) -> Result<DatasetMetadata, DataError> {
    let mut metadata = DatasetMetadata::new();
    if !file.link_exists("metadata") {
        return Ok(metadata);
    }
    let group = file.group("metadata").map_err(h5_error(path))?;
    for name in group.member_names().map_err(h5_error(path))? {
        let Ok(ds) = group.dataset(&name) else {
            continue;
        };
        if !ds.is_scalar() {
            continue;
        }
        let value = ds
            .read_scalar::<VarLenUnicode>()
            .map(|s| s.as_str().to_string())
            .or_else(|_| ds.read_scalar::<f64>().map(|v| v.to_string()));
        if let Ok(value) = value {
            metadata.insert(name, value);
        }
    }
    Ok(metadata)
}

/// Writes `dataset` in D4RL's layout (gzip-compressed, float32 arrays, bool
/// flags, `metadata/` as scalar strings), atomically.
pub fn write_d4rl(dataset: &Dataset, path: &Path) -> Result<(), DataError> {
    write_atomically(
        path,
        |tmp| write_file(dataset, tmp, path),
        |source| DataError::Io {
            file: path.to_path_buf(),
            source,
        },
    )
}

fn write_file(dataset: &Dataset, tmp: &Path, path: &Path) -> Result<(), DataError> {
    let err = h5_error(path);
    let file = hdf5::File::create(tmp).map_err(&err)?;
    let matrix = |group: &hdf5::Group, key: &str, a: &Array2<f32>| {
        group
            .new_dataset_builder()
            .with_data(a.view())
            .deflate(GZIP_LEVEL)
            .create(key)
            .map(|_| ())
    };
    matrix(&file, "observations", &dataset.observations).map_err(&err)?;
    matrix(&file, "actions", &dataset.actions).map_err(&err)?;
    matrix(&file, "next_observations", &dataset.next_observations).map_err(&err)?;
    let rewards = dataset.rewards.slice(s![..]);
    file.new_dataset_builder()
        .with_data(rewards)
        .deflate(GZIP_LEVEL)
        .create("rewards")
        .map_err(&err)?;
    for (key, flags) in [
        ("terminals", &dataset.terminals),
        ("timeouts", &dataset.timeouts),
    ] {
        file.new_dataset_builder()
            .with_data(flags.as_slice())
            .deflate(GZIP_LEVEL)
            .create(key)
            .map_err(&err)?;
    }
    let has_infos =
        dataset.qpos.is_some() || dataset.qvel.is_some() || dataset.action_log_probs.is_some();
    if has_infos {
        let infos = file.create_group("infos").map_err(&err)?;
        if let Some(log_probs) = &dataset.action_log_probs {
            infos
                .new_dataset_builder()
                .with_data(log_probs.view())
                .deflate(GZIP_LEVEL)
                .create("action_log_probs")
                .map_err(&err)?;
        }
        if let Some(qpos) = &dataset.qpos {
            matrix(&infos, "qpos", qpos).map_err(&err)?;
        }
        if let Some(qvel) = &dataset.qvel {
            matrix(&infos, "qvel", qvel).map_err(&err)?;
        }
    }
    let metadata = file.create_group("metadata").map_err(&err)?;
    for (key, value) in &dataset.metadata {
        let value: VarLenUnicode = value.parse().map_err(|e| DataError::Invalid {
            file: path.to_path_buf(),
            message: format!("metadata `{key}` cannot be stored: {e}"),
        })?;
        metadata
            .new_dataset::<VarLenUnicode>()
            .create(key.as_str())
            .and_then(|ds| ds.write_scalar(&value))
            .map_err(&err)?;
    }
    file.close().map_err(&err)
}
