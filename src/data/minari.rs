//! Minari datasets: an HDF5 file (`main_data.hdf5`) with one group per episode,
//! `episode_<id>/{observations [T+1], actions [T], rewards [T], terminations [T],
//! truncations [T]}`. Only flat (Box) observation spaces are read.

use std::path::{Path, PathBuf};

use ndarray::{Array1, Array2, Axis, concatenate, s};

use super::d4rl::{h5_error, read_column, read_flags, read_matrix};
use super::dataset::DatasetParts;
use super::{DataError, Dataset, DatasetMetadata};

/// Reads a Minari dataset from its `main_data.hdf5`, or from the dataset
/// directory holding `data/main_data.hdf5`.
pub fn read_minari(path: &Path) -> Result<Dataset, DataError> {
    let file_path: PathBuf = if path.is_dir() {
        path.join("data").join("main_data.hdf5")
    } else {
        path.to_path_buf()
    };
    let path = file_path.as_path();
    let file = hdf5::File::open(path).map_err(h5_error(path))?;
    let episodes = episode_groups(&file, path)?
        .iter()
        .map(|name| read_episode(&file, name, path))
        .collect::<Result<Vec<_>, _>>()?;
    let stack = |part: fn(&Episode) -> &Array2<f32>, key: &str| {
        let views: Vec<_> = episodes.iter().map(|e| part(e).view()).collect();
        concatenate(Axis(0), &views).map_err(|_| DataError::Invalid {
            file: path.to_path_buf(),
            message: format!("episodes disagree on the width of `{key}`"),
        })
    };
    let mut metadata = DatasetMetadata::new();
    metadata.insert("source".into(), path.display().to_string());
    metadata.insert("format".into(), "minari".into());
    let parts = DatasetParts {
        observations: stack(|e| &e.observations, "observations")?,
        next_observations: stack(|e| &e.next_observations, "observations")?,
        actions: stack(|e| &e.actions, "actions")?,
        rewards: episodes
            .iter()
            .flat_map(|e| e.rewards.iter().copied())
            .collect(),
        terminals: episodes.iter().flat_map(|e| e.terminals.clone()).collect(),
        timeouts: episodes.iter().flat_map(|e| e.timeouts.clone()).collect(),
        qpos: None,
        qvel: None,
        action_log_probs: None,
        metadata,
    };
    Dataset::from_parts(parts, path)
}

/// The file's `episode_<id>` groups, in the order of their ids.
fn episode_groups(file: &hdf5::File, path: &Path) -> Result<Vec<String>, DataError> {
    let mut episodes: Vec<(u64, String)> = file
        .member_names()
        .map_err(h5_error(path))?
        .into_iter()
        .filter_map(|name| {
            let id = name.strip_prefix("episode_")?.parse().ok()?;
            Some((id, name))
        })
        .collect();
    if episodes.is_empty() {
        return Err(DataError::Empty {
            file: path.to_path_buf(),
        });
    }
    episodes.sort();
    Ok(episodes.into_iter().map(|(_, name)| name).collect())
}

/// One episode as transitions.
struct Episode {
    observations: Array2<f32>,
    next_observations: Array2<f32>,
    actions: Array2<f32>,
    rewards: Array1<f32>,
    terminals: Vec<bool>,
    timeouts: Vec<bool>,
}

/// Reads the group `name`, checking every key's length against its T actions.
fn read_episode(file: &hdf5::File, name: &str, path: &Path) -> Result<Episode, DataError> {
    let group = file.group(name).map_err(h5_error(path))?;
    let key = |k: &str| format!("{name}/{k}");
    let observations = read_matrix(&group, "observations", path).map_err(|e| rename(e, name))?;
    let actions = read_matrix(&group, "actions", path).map_err(|e| rename(e, name))?;
    let steps = actions.nrows();
    if observations.nrows() != steps + 1 {
        return Err(DataError::LengthMismatch {
            file: path.to_path_buf(),
            key: key("observations"),
            reference: format!("{} plus one", key("actions")),
            expected: steps + 1,
            got: observations.nrows(),
        });
    }
    let rewards = read_column(&group, "rewards", path).map_err(|e| rename(e, name))?;
    let terminals = read_flags(&group, "terminations", path).map_err(|e| rename(e, name))?;
    let mut timeouts = read_flags(&group, "truncations", path).map_err(|e| rename(e, name))?;
    for (k, len) in [
        ("rewards", rewards.len()),
        ("terminations", terminals.len()),
        ("truncations", timeouts.len()),
    ] {
        if len != steps {
            return Err(DataError::LengthMismatch {
                file: path.to_path_buf(),
                key: key(k),
                reference: key("actions"),
                expected: steps,
                got: len,
            });
        }
    }
    // An episode always ends: if neither flag is set on its last step, it was cut.
    if let (Some(last_t), Some(last_c)) = (terminals.last(), timeouts.last_mut()) {
        *last_c |= !*last_t;
    }
    Ok(Episode {
        observations: observations.slice(s![..steps, ..]).to_owned(),
        next_observations: observations.slice(s![1.., ..]).to_owned(),
        actions,
        rewards,
        terminals,
        timeouts,
    })
}

/// Prefixes the key of a per-episode error with its episode group.
fn rename(error: DataError, episode: &str) -> DataError {
    match error {
        DataError::MissingKey { file, key } => DataError::MissingKey {
            file,
            key: format!("{episode}/{key}"),
        },
        DataError::BadShape {
            file,
            key,
            shape,
            expected,
        } => DataError::BadShape {
            file,
            key: format!("{episode}/{key}"),
            shape,
            expected,
        },
        other => other,
    }
}
