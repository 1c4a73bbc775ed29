//! Atomic file writes, shared by every crate that writes: the bytes go to a
//! temporary file in the target's folder, are synced, and the file is renamed
//! over the target, so a reader sees the old file or the new one, never half
//! of one, and a failed write leaves no temporary file behind.
//!
//! ```
//! let dir = tempfile::tempdir()?;
//! let path = dir.path().join("table.json");
//! murk_types::write_atomic(&path, b"{}")?;
//! assert_eq!(std::fs::read(&path)?, b"{}");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::path::Path;

/// Why an atomic write failed: the step that failed and the system's error.
/// Each crate wraps it in its own error with the path.
#[derive(Debug, thiserror::Error)]
#[error("cannot {action}: {source}")]
pub struct AtomicWriteError {
    /// What was being done ("create temporary file", "write", "sync",
    /// "rename temporary file").
    pub action: &'static str,
    /// The system's error.
    #[source]
    pub source: std::io::Error,
}

/// Writes `bytes` to `path` atomically (temporary file in the same folder,
/// synced, renamed). The file gets the mode of a plainly created file (0666
/// less the umask on Unix), not the 0600 of a temporary file.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), AtomicWriteError> {
    // One slice: written straight to the file, no buffer in between.
    persist_atomic(path, |file| std::io::Write::write_all(file, bytes))
}

/// Like [`write_atomic`], but `fill` streams the contents into the
/// temporary file (through a 1 MiB buffer) instead of taking them as one
/// slice, so a large output need not be assembled in memory first. An error
/// from `fill` is reported as a failed "write" and leaves no file behind.
///
/// ```
/// use std::io::Write as _;
/// let dir = tempfile::tempdir()?;
/// let path = dir.path().join("rows.csv");
/// murk_types::write_atomic_with(&path, |w| {
///     w.write_all(b"x,y\n")?;
///     w.write_all(b"1,2\n")
/// })?;
/// assert_eq!(std::fs::read(&path)?, b"x,y\n1,2\n");
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn write_atomic_with(
    path: &Path,
    fill: impl FnOnce(&mut dyn std::io::Write) -> std::io::Result<()>,
) -> Result<(), AtomicWriteError> {
    persist_atomic(path, |file| {
        let mut w = std::io::BufWriter::with_capacity(1 << 20, file);
        fill(&mut w)?;
        w.into_inner()
            .map(drop)
            .map_err(std::io::IntoInnerError::into_error)
    })
}

/// The temporary file, `fill`, sync and rename shared by [`write_atomic`]
/// and [`write_atomic_with`].
fn persist_atomic(
    path: &Path,
    fill: impl FnOnce(&mut std::fs::File) -> std::io::Result<()>,
) -> Result<(), AtomicWriteError> {
    let err = |action: &'static str| move |source| AtomicWriteError { action, source };
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    builder.prefix(".murk-").suffix(".tmp");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let mut tmp = builder
        .tempfile_in(dir)
        .map_err(err("create temporary file"))?;
    fill(tmp.as_file_mut()).map_err(err("write"))?;
    tmp.as_file().sync_data().map_err(err("sync"))?;
    tmp.persist(path)
        .map_err(|e| err("rename temporary file")(e.error))?;
    Ok(())
}
