//! `nuno-trainer`: the offline command line. One file per subcommand, each a
//! thin layer that parses flags, calls the library and reports; no algorithm
//! code lives here.

// A subcommand is flags → a plan → one library call: no function grows long.
#![warn(clippy::too_many_lines)]

mod analyze;
mod collect;
mod data_source;
mod dataset;
mod dataset_check;
mod eta_report;
mod evaluate;
mod experiment;
mod export;
mod fit_ensemble;
mod fit_model;
mod fit_policy;
mod flag_defaults;
mod output;
mod plot;
mod resume;
mod run_record;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

#[derive(Debug, Parser)]
#[command(name = "nuno-trainer", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Compare models (SDEs, ensembles): prediction error in and out of
    /// distribution, uncertainty by action source, a policy's exploitation (Figures 3–5).
    Analyze(analyze::Args),
    /// Train behaviour policies online in the MuJoCo tasks and pick their levels.
    #[command(subcommand)]
    Collect(collect::Command),
    /// Generate or inspect offline datasets.
    #[command(subcommand)]
    Dataset(dataset::Command),
    /// Fit MOPO's Gaussian ensemble on a dataset and write it into a model directory.
    FitEnsemble(fit_ensemble::Args),
    /// Fit the neural SDE on a dataset and write the model artifact.
    FitModel(fit_model::Args),
    /// Train a policy offline: NUNO's SAC on a model's penalised, truncated rollouts, or one
    /// of the paper's baselines (--algo).
    FitPolicy(fit_policy::Args),
    /// Run, follow and report grids of datasets × methods × seeds, locally or on Slurm.
    #[command(subcommand)]
    Experiment(experiment::Command),
    /// Run a policy in the real MuJoCo task and print returns and D4RL normalised scores.
    Evaluate(evaluate::Args),
    /// Write a model folder's SDE step and policy as ONNX graphs with their contract.
    Export(export::Args),
    /// How well a model's η separates a dataset from random actions and perturbed data.
    EtaReport(eta_report::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Analyze(args) => analyze::run(args),
        Command::Collect(command) => collect::run(command),
        Command::Dataset(command) => dataset::run(command),
        Command::Evaluate(args) => evaluate::run(args),
        Command::Export(args) => export::run(args),
        Command::Experiment(command) => experiment::run(command),
        Command::EtaReport(args) => eta_report::run(args),
        Command::FitEnsemble(args) => fit_ensemble::run(args),
        Command::FitModel(args) => fit_model::run(args),
        Command::FitPolicy(args) => fit_policy::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}
