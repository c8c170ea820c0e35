//! Helpers shared by the integration tests: the Python peer from `make venv`,
//! and bounded waits on what a test starts.

pub mod bounded;

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The workspace root (these helpers are shared with the trainer's tests,
/// whose crate sits one folder down).
fn workspace_root() -> &'static Path {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    manifest
        .ancestors()
        .find(|dir| dir.join("Cargo.lock").is_file())
        .unwrap_or(manifest)
}

/// The test venv's interpreter, created by `make venv` (part of `make test`).
pub fn python() -> PathBuf {
    let python = workspace_root().join(".venv/bin/python");
    assert!(
        python.is_file(),
        "{} is missing: run `make venv` (or `make test`, which creates it)",
        python.display()
    );
    python
}

/// Runs `tests/python/<script>` with `args` in the test venv, inside `workdir`
/// (Python's MuJoCo writes MUJOCO_LOG.TXT there); panics with its stderr if it fails.
pub fn run_python<A: AsRef<OsStr>>(script: &str, args: &[A], workdir: &Path) {
    let script = workspace_root().join("tests/python").join(script);
    let mut command = Command::new(python());
    command.arg(&script).args(args).current_dir(workdir);
    let output = bounded::output_within(&mut command, &script.display().to_string());
    assert!(
        output.status.success(),
        "{} failed:\n{}",
        script.display(),
        String::from_utf8_lossy(&output.stderr)
    );
}
