//! Atomic file writes, shared by every crate that writes: the bytes go to a
//! temporary file in the target's folder, are synced, and the file is renamed
//! over the target, so a reader sees the old file or the new one, never half
//! of one, and a failed write leaves no temporary file behind. Batches can
//! split a write in two ([`stage_atomic`], then [`StagedFile::commit`] on
//! another thread) so that waiting for the disk does not hold up work.
//!
//! ```
//! let dir = tempfile::tempdir()?;
//! let path = dir.path().join("table.json");
//! murk_types::write_atomic(&path, b"{}")?;
//! assert_eq!(std::fs::read(&path)?, b"{}");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::path::{Path, PathBuf};

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
    stage_atomic(path, bytes)?.commit()
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
    stage_atomic_with(path, fill)?.commit()
}

/// The first half of [`write_atomic`]: `bytes` written to a temporary file
/// next to `path`, not yet synced or renamed. [`StagedFile::commit`] does
/// the rest; dropping the value instead removes the temporary file.
///
/// Why split: syncing is a wait on the disk, not work. A batch that stages
/// each output and hands it to a few committing threads keeps its workers
/// computing, and the file system can group the syncs of many files into
/// one journal commit (`murk apply` over many small scans spent most of its
/// time in one sync per file).
///
/// ```
/// let dir = tempfile::tempdir()?;
/// let path = dir.path().join("scan.bin");
/// let staged = murk_types::stage_atomic(&path, b"1234")?;
/// assert!(!path.exists()); // nothing at the target until the commit
/// staged.commit()?;
/// assert_eq!(std::fs::read(&path)?, b"1234");
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn stage_atomic(path: &Path, bytes: &[u8]) -> Result<StagedFile, AtomicWriteError> {
    // One slice: written straight to the file, no buffer in between.
    stage(path, |file| std::io::Write::write_all(file, bytes))
}

/// The first half of [`write_atomic_with`] (see [`stage_atomic`]).
pub fn stage_atomic_with(
    path: &Path,
    fill: impl FnOnce(&mut dyn std::io::Write) -> std::io::Result<()>,
) -> Result<StagedFile, AtomicWriteError> {
    stage(path, |file| {
        let mut w = std::io::BufWriter::with_capacity(1 << 20, file);
        fill(&mut w)?;
        w.into_inner()
            .map(drop)
            .map_err(std::io::IntoInnerError::into_error)
    })
}

/// An output written to its temporary file and waiting for
/// [`StagedFile::commit`]. Dropped without a commit, the temporary file is
/// removed and the target is left as it was.
#[derive(Debug)]
pub struct StagedFile {
    tmp: tempfile::NamedTempFile,
    path: PathBuf,
}

impl StagedFile {
    /// The file this will become.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Syncs the temporary file's data and renames it over the target.
    pub fn commit(self) -> Result<(), AtomicWriteError> {
        self.tmp.as_file().sync_data().map_err(err("sync"))?;
        self.tmp
            .persist(&self.path)
            .map_err(|e| err("rename temporary file")(e.error))?;
        Ok(())
    }
}

/// The temporary file and `fill` shared by [`stage_atomic`] and
/// [`stage_atomic_with`].
fn stage(
    path: &Path,
    fill: impl FnOnce(&mut std::fs::File) -> std::io::Result<()>,
) -> Result<StagedFile, AtomicWriteError> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    let prefix = format!("{TEMP_PREFIX}{}-", std::process::id());
    builder.prefix(&prefix).suffix(TEMP_SUFFIX);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let mut tmp = builder
        .tempfile_in(dir)
        .map_err(err("create temporary file"))?;
    fill(tmp.as_file_mut()).map_err(err("write"))?;
    Ok(StagedFile {
        tmp,
        path: path.to_path_buf(),
    })
}

/// Temporary files are named `.murk-<pid>-<random>.tmp`: the writing
/// process's id lets a later run tell a temporary file left by a killed
/// run (its process has ended) from one a running murk is still writing.
const TEMP_PREFIX: &str = ".murk-";
const TEMP_SUFFIX: &str = ".tmp";

/// The id of the process that created `name`, when `name` is a murk
/// temporary file (`.murk-<pid>-<random>.tmp`).
fn temp_owner(name: &str) -> Option<u32> {
    let middle = name.strip_prefix(TEMP_PREFIX)?.strip_suffix(TEMP_SUFFIX)?;
    let (pid, random) = middle.split_once('-')?;
    if random.is_empty() || !random.bytes().all(|b| b.is_ascii_alphanumeric()) {
        return None;
    }
    if pid.is_empty() || !pid.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    pid.parse().ok()
}

/// Whether process `pid` has certainly ended. On Linux a live process has
/// `/proc/<pid>`; where there is no `/proc` this cannot tell and says
/// `false`, so nothing is ever removed on a guess. (A recycled id looks
/// alive: the file is then kept, the safe side.)
pub fn process_ended(pid: u32) -> bool {
    let proc = Path::new("/proc");
    pid != std::process::id() && proc.join("self").exists() && !proc.join(pid.to_string()).exists()
}

/// Removes, from `dir` only (not its subfolders), the temporary files that
/// [`stage_atomic`] and friends leave when a murk process is killed before
/// it could commit or clean up: files named `.murk-<pid>-<random>.tmp`
/// whose process has ended ([`process_ended`]). Nothing else is touched:
/// not other names, not folders, not links, not the files of a murk that
/// is still running. Returns the files removed; a missing `dir` has none.
///
/// ```
/// let dir = tempfile::tempdir()?;
/// // Left by a killed run (a process id no system has).
/// let stale = dir.path().join(".murk-4294967295-AbC123.tmp");
/// std::fs::write(&stale, b"half a scan")?;
/// let mine = dir.path().join("notes.tmp");
/// std::fs::write(&mine, b"not murk's")?;
/// let removed = murk_types::remove_stale_temporaries(dir.path())?;
/// # if std::path::Path::new("/proc/self").exists() {
/// assert_eq!(removed, vec![stale.clone()]);
/// assert!(!stale.exists());
/// # }
/// assert!(mine.exists());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn remove_stale_temporaries(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(e),
    };
    let mut removed = Vec::new();
    for e in entries {
        let e = e?;
        let name = e.file_name();
        let Some(pid) = name.to_str().and_then(temp_owner) else {
            continue;
        };
        // `file_type` does not follow links: only plain files are removed.
        if !e.file_type()?.is_file() || !process_ended(pid) {
            continue;
        }
        match std::fs::remove_file(e.path()) {
            Ok(()) => removed.push(e.path()),
            // Another run cleaned it first.
            Err(err) if err.kind() == std::io::ErrorKind::NotFound => {}
            Err(err) => return Err(err),
        }
    }
    removed.sort();
    Ok(removed)
}

/// The error of a failed `action`.
fn err(action: &'static str) -> impl FnOnce(std::io::Error) -> AtomicWriteError {
    move |source| AtomicWriteError { action, source }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The names in `dir`, sorted.
    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn a_staged_file_appears_only_on_commit_and_vanishes_when_dropped() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.csv");
        std::fs::write(&path, b"old").unwrap();

        let staged = stage_atomic(&path, b"new").unwrap();
        assert_eq!(
            std::fs::read(&path).unwrap(),
            b"old",
            "target untouched before commit"
        );
        assert_eq!(
            names(dir.path()).len(),
            2,
            "the temporary file sits beside it"
        );
        drop(staged);
        assert_eq!(names(dir.path()), vec!["out.csv".to_string()]);
        assert_eq!(std::fs::read(&path).unwrap(), b"old");

        let staged = stage_atomic_with(&path, |w| w.write_all(b"streamed")).unwrap();
        assert_eq!(staged.path(), path.as_path());
        staged.commit().unwrap();
        assert_eq!(names(dir.path()), vec!["out.csv".to_string()]);
        assert_eq!(std::fs::read(&path).unwrap(), b"streamed");
    }

    #[test]
    fn temporary_names_carry_the_owner_and_nothing_else_matches() {
        let dir = tempfile::tempdir().unwrap();
        let staged = stage_atomic(&dir.path().join("a.bin"), b"x").unwrap();
        let name = names(dir.path()).remove(0);
        assert_eq!(temp_owner(&name), Some(std::process::id()), "{name}");
        // A live owner (this process): kept.
        assert!(remove_stale_temporaries(dir.path()).unwrap().is_empty());
        drop(staged);
        for other in [
            ".murk-.tmp",
            ".murk-12.tmp",
            ".murk-x1-abc.tmp",
            ".murk-1-abc.tmp.bak",
            "murk-1-abc.tmp",
            ".murk-1-a/b.tmp",
        ] {
            assert_eq!(temp_owner(other), None, "{other}");
        }
        assert_eq!(temp_owner(".murk-77-Zz9.tmp"), Some(77));
    }

    #[test]
    fn a_failed_fill_leaves_nothing_behind() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.csv");
        let e = stage_atomic_with(&path, |w| {
            w.write_all(b"half")?;
            Err(std::io::Error::other("disk on fire"))
        })
        .unwrap_err();
        assert_eq!(e.action, "write");
        assert!(names(dir.path()).is_empty());
    }
}
