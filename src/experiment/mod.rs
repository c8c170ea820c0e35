//! Experiments: a grid of datasets × methods × seeds under one budget
//! ([`grid`]), each cell's result and the Table 1/2-style aggregate
//! ([`results`]), the paper's published tables and nuno's cells laid out as
//! them ([`paper_tables`]), and the paper's model analyses ([`analysis`]) and the models' answer to the
//! action against the task's ([`action_sensitivity`]). Running cells (locally or as a Slurm array) is the
//! trainer's `experiment` subcommand; it calls the other subcommands per cell.

mod action_sensitivity;
pub mod analysis;
pub mod grid;
mod linear_model;
pub mod paper_tables;
pub mod results;

use std::path::PathBuf;

pub use action_sensitivity::{ActionSensitivity, SensitivityConfig, action_sensitivity};
pub use analysis::{
    ActionSource, Exploitation, ExploitationConfig, PredictionConfig, PredictionError,
    exploitation, prediction_error, uncertainty_by_action,
};
pub use grid::{Budget, Cell, CellSelection, Grid, GridDataset, MopoRow};
pub use linear_model::LinearModel;
pub use paper_tables::{PaperScore, paper_layout_table, paper_score};
pub use results::{
    CellResult, CellStatus, MeanCurve, Summary, cell_dir, cell_status, check_fitted_sde,
    collect_results, fit_changes, markdown_table, mean_curves, policy_time_left, read_result,
    results_csv, summarize, summarize_run, write_result,
};

/// Everything that can be wrong with an experiment.
#[derive(Debug, thiserror::Error)]
pub enum ExperimentError {
    #[error("{file}: {message}")]
    Grid { file: PathBuf, message: String },
    #[error("{file}: {source}")]
    Io {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{0}")]
    Invalid(String),
    #[error(transparent)]
    Artifact(#[from] crate::artifact::ArtifactError),
}
