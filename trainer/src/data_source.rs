//! The dataset flags the fitting subcommands share (`--dataset`, `--format`,
//! `--task`, `--neorl`), read and checked against the task in one place.

use std::path::PathBuf;

use nuno::artifact::{DatasetInfo, sha256_file};
use nuno::data::{Dataset, DatasetFormat, read_dataset};
use nuno::envs::{TaskConfig, TaskName};

#[derive(Debug, Clone, clap::Args, serde::Serialize)]
pub struct DataSource {
    /// Dataset file (D4RL .hdf5, NeoRL .npz) or Minari directory.
    #[arg(long)]
    pub dataset: PathBuf,
    /// Reader to use (default: detected).
    #[arg(long)]
    pub format: Option<DatasetFormat>,
    #[arg(long)]
    pub task: TaskName,
    /// NeoRL's observation layout (root x included).
    #[arg(long)]
    pub neorl: bool,
}

/// `task` in D4RL's observation layout, or NeoRL's (root x included).
pub fn task_config(task: TaskName, neorl: bool) -> TaskConfig {
    if neorl {
        TaskConfig::neorl(task)
    } else {
        TaskConfig::d4rl(task)
    }
}

impl DataSource {
    pub fn task_config(&self) -> TaskConfig {
        task_config(self.task, self.neorl)
    }

    /// The dataset, checked against the task's widths.
    pub fn read(&self) -> anyhow::Result<Dataset> {
        let dataset = read_dataset(&self.dataset, self.format)?;
        dataset.check_task(&self.task_config(), &self.dataset)?;
        Ok(dataset)
    }

    /// What a model artifact records about the data it was fitted on.
    pub fn info(&self, dataset: &Dataset) -> DatasetInfo {
        DatasetInfo {
            path: self.dataset.display().to_string(),
            sha256: sha256_file(&self.dataset).unwrap_or_default(),
            transitions: dataset.len(),
            trajectories: dataset.trajectories().len(),
        }
    }
}
