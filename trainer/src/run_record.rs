//! `run.json`: a run's whole resolved configuration (every setting with its
//! defaults filled in, the seed, the build, each dataset's SHA-256), written
//! to its output folder before any work starts and printed, so that a run can
//! be repeated, or told apart from another, from its own record.

use std::path::{Path, PathBuf};

use anyhow::Context;
use nuno::artifact::sha256_file;
use serde::Serialize;

use crate::output::write_text;

/// The record's file name in a run's output folder.
pub const RUN_RECORD: &str = "run.json";

/// A dataset a run reads, named as given and by its content (`None` for a
/// folder, such as a Minari dataset, which has no one file to hash).
#[derive(Serialize)]
struct DatasetHash {
    path: PathBuf,
    sha256: Option<String>,
}

#[derive(Serialize)]
struct RunRecord<'a, P> {
    /// The subcommand, as typed: `fit-policy`, `dataset generate`, …
    command: &'a str,
    nuno_version: &'static str,
    /// The running binary's SHA-256: the exact build, where a version names many.
    binary_sha256: String,
    /// The process's command line (a grid's cell runs its fits in the runner's process).
    invoked_as: Vec<String>,
    datasets: Vec<DatasetHash>,
    /// The validated plan: what the run does, every default resolved.
    plan: &'a P,
}

/// The binary this process runs, to hash or to start again: on Linux
/// `/proc/self/exe`, which still opens it after a rebuild replaced its file
/// (where [`std::env::current_exe`] names a path ending in " (deleted)"), so a
/// grid's cells keep running the build that started them.
pub fn running_binary() -> anyhow::Result<PathBuf> {
    let own = Path::new("/proc/self/exe");
    if own.exists() {
        return Ok(own.to_path_buf());
    }
    std::env::current_exe().context("locating the running binary")
}

/// Writes `out/run.json` for `plan` (atomically) and prints it.
pub fn write_run_record<P: Serialize>(
    out: &Path,
    command: &str,
    plan: &P,
    datasets: &[&Path],
) -> anyhow::Result<()> {
    let exe = running_binary()?;
    let datasets = datasets
        .iter()
        .map(|&path| {
            Ok(DatasetHash {
                path: path.to_path_buf(),
                sha256: path.is_file().then(|| sha256_file(path)).transpose()?,
            })
        })
        .collect::<anyhow::Result<_>>()?;
    let record = RunRecord {
        command,
        nuno_version: env!("CARGO_PKG_VERSION"),
        binary_sha256: sha256_file(&exe)?,
        invoked_as: std::env::args().collect(),
        datasets,
        plan,
    };
    let json = serde_json::to_string_pretty(&record)?;
    let path = out.join(RUN_RECORD);
    write_text(&path, &json)?;
    println!(
        "{command}: the run's settings ({}):\n{json}",
        path.display()
    );
    Ok(())
}
