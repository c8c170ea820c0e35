//! `--resume` for every command that checkpoints: which checkpoint to continue,
//! and the claim that keeps two processes from writing one `--out`.

use std::fs::{File, TryLockError};
use std::path::{Path, PathBuf};

use anyhow::Context;
use nuno::artifact::latest_checkpoint;

/// The file in `--out` whose lock a writing command holds.
pub const OUTPUT_CLAIM: &str = ".writing";

/// A command's hold on its `--out` folder, released when dropped or when the process ends
/// (the operating system drops the lock of a killed process).
#[must_use = "the claim holds only while it lives"]
pub struct OutputClaim {
    _locked: Option<File>,
    out: PathBuf,
    /// Whether the claim created `out`.
    created: bool,
}

impl Drop for OutputClaim {
    /// A command refused before it wrote anything leaves nothing behind: its
    /// `--out` holds only the claim's file then, which goes, with the folder
    /// where the claim created it.
    fn drop(&mut self) {
        let only_the_claim = std::fs::read_dir(&self.out).is_ok_and(|mut entries| {
            entries.all(|e| e.is_ok_and(|e| e.file_name() == OUTPUT_CLAIM))
        });
        if only_the_claim {
            let _ = std::fs::remove_file(self.out.join(OUTPUT_CLAIM));
            if self.created {
                let _ = std::fs::remove_dir(&self.out);
            }
        }
    }
}

/// Claims `out` (created if missing) for this process, refusing it while another holds it:
/// two fits or runs into one folder (the same `--resume` started twice) would interleave
/// their checkpoints, metrics and artifact. On a file system that cannot lock (some network
/// mounts) it warns and goes on unclaimed: the claim guards against a mistake, and a run
/// should not fail for want of it.
pub fn claim_output(out: &Path) -> anyhow::Result<OutputClaim> {
    let created = !out.exists();
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let path = out.join(OUTPUT_CLAIM);
    let file = File::create(&path).with_context(|| format!("creating {}", path.display()))?;
    match file.try_lock() {
        Ok(()) => Ok(OutputClaim {
            _locked: Some(file),
            out: out.to_path_buf(),
            created,
        }),
        Err(TryLockError::WouldBlock) => anyhow::bail!(
            "{} is being written by another process; wait for it to end or choose another --out",
            out.display()
        ),
        Err(TryLockError::Error(e)) => {
            eprintln!(
                "warning: cannot lock {} ({e}); nothing stops a second process writing {}",
                path.display(),
                out.display()
            );
            Ok(OutputClaim {
                _locked: None,
                out: out.to_path_buf(),
                created,
            })
        }
    }
}

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
