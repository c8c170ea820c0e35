//! Which reader a dataset file needs, chosen by the user or detected.

use std::path::Path;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::{DataError, Dataset, read_d4rl, read_minari, read_neorl};

/// The on-disk dataset formats nuno reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DatasetFormat {
    /// D4RL's flat HDF5 layout (also what nuno writes).
    D4rl,
    /// NeoRL's `.npz`.
    Neorl,
    /// Minari's per-episode HDF5.
    Minari,
}

impl FromStr for DatasetFormat {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "d4rl" => Ok(Self::D4rl),
            "neorl" => Ok(Self::Neorl),
            "minari" => Ok(Self::Minari),
            other => Err(format!(
                "unknown dataset format `{other}` (expected d4rl, neorl or minari)"
            )),
        }
    }
}

impl DatasetFormat {
    /// Guesses the format: a directory or an HDF5 file with `episode_*` groups
    /// is Minari, `.npz` is NeoRL, any other file is D4RL.
    pub fn detect(path: &Path) -> Self {
        if path.is_dir() {
            return Self::Minari;
        }
        if path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("npz"))
        {
            return Self::Neorl;
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
    }
}
