//! Text files the subcommands write beside their artifacts (metrics, reports,
//! job scripts), each atomically.

use std::path::Path;

use anyhow::Context;
use nuno::shared::write_atomically;

/// Writes `text` to `path` atomically (temporary file, fsync, rename).
pub fn write_text(path: &Path, text: &str) -> anyhow::Result<()> {
    write_atomically(path, |tmp| std::fs::write(tmp, text), |e| e)
        .with_context(|| format!("writing {}", path.display()))
}
