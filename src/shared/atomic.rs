//! Atomic file replacement: write to a temporary sibling, fsync it, rename it
//! over the target, fsync the directory. A crash leaves either the old file or
//! the new one, never a mix; a failed write leaves nothing behind.

use std::fs::File;
use std::io;
use std::path::{Path, PathBuf};

/// Creates `path` by calling `write` on a temporary path in the same directory,
/// then publishing it atomically. The temporary file is removed if anything
/// fails; file-system errors are turned into `E` by `io_error`.
pub fn write_atomically<E>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
    io_error: impl Fn(io::Error) -> E,
) -> Result<(), E> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&dir).map_err(&io_error)?;
    let name = path.file_name().ok_or_else(|| {
        io_error(io::Error::new(
            io::ErrorKind::InvalidInput,
            "path has no file name",
        ))
    })?;
    let tmp = dir.join(format!(
        ".{}.tmp-{}",
        name.to_string_lossy(),
        std::process::id()
    ));
    let publish = || -> io::Result<()> {
        File::open(&tmp)?.sync_all()?;
        std::fs::rename(&tmp, path)?;
        File::open(&dir)?.sync_all()
    };
    let result = write(&tmp).and_then(|()| publish().map_err(&io_error));
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}
