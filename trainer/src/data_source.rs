//! The dataset flags the fitting subcommands share (`--dataset`, `--format`,
//! `--task` or `--system`, `--neorl`), read and checked against the system in
//! one place.

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::Context;

use nuno::artifact::{DatasetInfo, sha256_file};
use nuno::data::{Dataset, DatasetFormat, read_system_dataset};
use nuno::envs::{System, SystemSpec, TaskConfig, TaskName};

#[derive(Debug, Clone, clap::Args, serde::Serialize)]
pub struct DataSource {
    /// Dataset file (D4RL .hdf5, .npz with NeoRL or D4RL keys, a CSV log of a --system) or Minari directory.
    #[arg(long)]
    pub dataset: PathBuf,
    /// Reader to use (default: detected).
    #[arg(long)]
    pub format: Option<DatasetFormat>,
    /// A built-in task: hopper, halfcheetah, walker2d, swimmer, invertedpendulum or ant.
    #[arg(long, required_unless_present = "system", conflicts_with = "system")]
    pub task: Option<TaskName>,
    /// A system described in a TOML file (docs/your-own-system.md), in place of --task.
    #[arg(long)]
    pub system: Option<PathBuf>,
    /// NeoRL's observation layout (root x included).
    #[arg(long, conflicts_with = "system")]
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

/// The system `--task` (with `--neorl`) or `--system FILE` names; the file
/// read and checked.
pub fn system_of(
    task: Option<TaskName>,
    file: Option<&std::path::Path>,
    neorl: bool,
) -> anyhow::Result<System> {
    match (task, file) {
        (_, Some(file)) => Ok(System::File(Arc::new(SystemSpec::read(file)?))),
        (Some(task), None) => Ok(System::Task(task_config(task, neorl))),
        (None, None) => anyhow::bail!("give --task or --system"),
    }
}

/// The MuJoCo task that simulates `system`: a built-in task, or its file's
/// `[mujoco]` table.
pub fn simulation_of(system: &System) -> anyhow::Result<TaskConfig> {
    system.simulator().with_context(|| {
        format!(
            "`{}` has no [mujoco] table: nothing simulates it (docs/your-own-system.md)",
            system.name()
        )
    })
}

impl DataSource {
    /// The system the data is of.
    pub fn system(&self) -> anyhow::Result<System> {
        system_of(self.task, self.system.as_deref(), self.neorl)
    }

    /// The dataset, checked against the system's widths.
    pub fn read(&self, system: &System) -> anyhow::Result<Dataset> {
        Ok(read_system_dataset(&self.dataset, self.format, system)?)
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
