//! `--resume` for every command that checkpoints: which checkpoint to continue.

use std::path::{Path, PathBuf};

use nuno::artifact::latest_checkpoint;

/// The checkpoint in `checkpoints` to continue from: the latest when
/// `resume` is given (none, said so, when there is none yet); an error naming
/// `out` when it holds `what` already and `resume` was not given.
pub fn checkpoint_to_resume(
    checkpoints: &Path,
    resume: bool,
    out: &Path,
    what: &str,
) -> anyhow::Result<Option<PathBuf>> {
    match (latest_checkpoint(checkpoints)?, resume) {
        (Some(checkpoint), true) => Ok(Some(checkpoint)),
        (Some(_), false) => anyhow::bail!(
            "{} already holds {what}; pass --resume to continue it or choose another --out",
            out.display()
        ),
        (None, true) => {
            println!(
                "no checkpoint in {}; starting afresh",
                checkpoints.display()
            );
            Ok(None)
        }
        (None, false) => Ok(None),
    }
}
