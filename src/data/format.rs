//! Which reader a dataset file needs, chosen by the user or detected.

use std::path::Path;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::{DataError, Dataset, read_csv_log, read_d4rl, read_minari, read_neorl};
use crate::envs::System;

/// The on-disk dataset formats nuno reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DatasetFormat {
    /// D4RL's flat HDF5 layout (also what nuno writes).
    D4rl,
    /// `.npz`: NeoRL's keys, or D4RL's.
    Neorl,
    /// Minari's per-episode HDF5.
    Minari,
    /// A CSV time series whose columns a system file names ([`super::read_csv_log`]).
    Csv,
}

impl FromStr for DatasetFormat {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "d4rl" => Ok(Self::D4rl),
            "neorl" => Ok(Self::Neorl),
            "minari" => Ok(Self::Minari),
            "csv" => Ok(Self::Csv),
            other => Err(format!(
                "unknown dataset format `{other}` (expected d4rl, neorl, minari or csv)"
            )),
        }
    }
}

impl DatasetFormat {
    /// Guesses the format: a directory or an HDF5 file with `episode_*` groups
    /// is Minari, `.npz` is NeoRL, `.csv` a CSV log, any other file is D4RL.
    pub fn detect(path: &Path) -> Self {
        if path.is_dir() {
            return Self::Minari;
        }
        let extension = |e: &str| path.extension().is_some_and(|x| x.eq_ignore_ascii_case(e));
        if extension("npz") {
            return Self::Neorl;
        }
        if extension("csv") {
            return Self::Csv;
        }
        let minari = hdf5::File::open(path)
            .and_then(|f| f.member_names())
            .is_ok_and(|names| names.iter().any(|n| n.starts_with("episode_")));
        if minari { Self::Minari } else { Self::D4rl }
    }
}

/// Reads `path` with the reader for `format`, or the detected one.
pub fn read_dataset(path: &Path, format: Option<DatasetFormat>) -> Result<Dataset, DataError> {
    if !path.exists() {
        return Err(DataError::Io {
            file: path.to_path_buf(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such file or directory"),
        });
    }
    match format.unwrap_or_else(|| DatasetFormat::detect(path)) {
        DatasetFormat::D4rl => read_d4rl(path),
        DatasetFormat::Neorl => read_neorl(path),
        DatasetFormat::Minari => read_minari(path),
        DatasetFormat::Csv => Err(DataError::Invalid {
            file: path.to_path_buf(),
            message: "a CSV log is read by the names of its system: give a system file (--system)"
                .into(),
        }),
    }
}

/// Reads `path` as a dataset of `system`, checked against its widths: a CSV
/// log by the names its file gives, any other format as [`read_dataset`].
pub fn read_system_dataset(
    path: &Path,
    format: Option<DatasetFormat>,
    system: &System,
) -> Result<Dataset, DataError> {
    let format = format.unwrap_or_else(|| DatasetFormat::detect(path));
    let dataset = match (format, system) {
        (DatasetFormat::Csv, System::File(spec)) => read_csv_log(path, spec)?,
        _ => read_dataset(path, Some(format))?,
    };
    dataset.check_system(system, path)?;
    Ok(dataset)
}
