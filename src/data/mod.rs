//! Offline datasets: readers for D4RL (HDF5), NeoRL (`.npz`), Minari (HDF5
//! episodes) and a described system's CSV log, a writer in D4RL's exact
//! layout, the random-policy generator, the per-dimension normaliser, and the
//! samplers that fitting and policy optimisation draw from.

mod behaviour;
mod csv_log;
mod d4rl;
mod dataset;
mod format;
mod generate;
mod minari;
mod neorl;
mod normalizer;
mod recording;
mod sampler;
mod system_check;

use std::path::PathBuf;

pub use behaviour::{BehaviourLevel, BehaviourPick, LEVEL_TOLERANCE, select_behaviour};
pub use csv_log::read_csv_log;
pub use d4rl::{read_d4rl, write_d4rl};
pub use dataset::{Dataset, DatasetMetadata, DatasetParts, Trajectory};
pub use format::{DatasetFormat, read_dataset, read_system_dataset};
pub use generate::{Budget, GenerateConfig, generate, generator};
pub use minari::read_minari;
pub use neorl::{read_neorl, write_neorl};
pub use normalizer::{Normalizer, NormalizerConfig, Stats};
pub use recording::Recording;
pub use sampler::{StartStateSampler, TransitionSampler, WindowBatch, WindowSampler};
pub use system_check::{ColumnRange, PAIR_ERROR_LIMIT, PairCheck, SystemCheck, check_system};

use crate::envs::EnvError;

/// Everything that can be wrong with a dataset file or a request on a dataset.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    #[error("{file}: {source}")]
    Io {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{file}: not a readable HDF5 file or dataset: {message}")]
    Hdf5 { file: PathBuf, message: String },
    #[error("{file}: not a readable .npz archive: {message}")]
    Npz { file: PathBuf, message: String },
    #[error("{file}: missing key `{key}`")]
    MissingKey { file: PathBuf, key: String },
    #[error("{file}: `{key}` has {got} rows, expected {expected} (as `{reference}`)")]
    LengthMismatch {
        file: PathBuf,
        key: String,
        reference: String,
        expected: usize,
        got: usize,
    },
    #[error("{file}: `{key}` has shape {shape:?}, expected {expected}")]
    BadShape {
        file: PathBuf,
        key: String,
        shape: Vec<usize>,
        expected: String,
    },
    #[error("{file}: `{key}` rows are {got} wide, but {task} expects {expected}")]
    WrongDimension {
        file: PathBuf,
        key: String,
        task: String,
        expected: usize,
        got: usize,
    },
    #[error("{file}: `{key}` row {row} holds NaN or Inf")]
    NonFinite {
        file: PathBuf,
        key: String,
        row: usize,
    },
    #[error("{file}: {message}")]
    Invalid { file: PathBuf, message: String },
    #[error("behaviour policy: {0}")]
    Behaviour(String),
    #[error("{file}: the dataset has no transitions")]
    Empty { file: PathBuf },
    #[error("the dataset has no window of {horizon} steps inside one trajectory")]
    NoWindows { horizon: usize },
    #[error("dataset generation failed: {0}")]
    Env(#[from] EnvError),
}
