//! The one folder walk of murk: every command that takes a folder of inputs
//! (`murk apply`, `murk convert`) lists its files through [`walk_folder`],
//! so they agree on order, hidden files and symbolic links.
//!
//! - Entries are visited in name order, depth first (a folder's files
//!   where its name sorts), so a batch's order does not depend on the file
//!   system.
//! - Hidden entries (names starting with `.`) are left out and listed, as
//!   are folders the caller excludes (an output folder inside the input).
//! - Symbolic links are followed: a link to a file is that file, a link to
//!   a folder is walked, **unless** the folder it leads to is already being
//!   walked or was walked (compared by canonical path). Such a link (`sub/up
//!   -> ..`) would make the walk go round forever, or read the same files
//!   twice under other names; it is left out and listed with the folder it
//!   points to. Broken links are listed too.
//!
//! ```
//! let dir = tempfile::tempdir()?;
//! std::fs::create_dir(dir.path().join("sub"))?;
//! std::fs::write(dir.path().join("sub/a.pcd"), b"")?;
//! std::fs::write(dir.path().join(".hidden.pcd"), b"")?;
//! let w = murk_types::walk_folder(dir.path(), &[])?;
//! assert_eq!(w.files.len(), 1);
//! assert_eq!(w.files[0].key, "sub/a.pcd");
//! assert_eq!(w.left_out.len(), 1);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use crate::TypesError;

/// A file found by [`walk_folder`].
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub struct WalkedFile {
    /// The file, as the walk reached it (the root joined with `key`).
    pub path: PathBuf,
    /// Its path relative to the root, with `/` separators.
    pub key: String,
}

/// An entry [`walk_folder`] did not follow, and why.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub struct LeftOut {
    /// The entry.
    pub path: PathBuf,
    /// Why it was left out.
    pub reason: String,
}

/// What [`walk_folder`] found.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
#[non_exhaustive]
pub struct Walk {
    /// Every file below the root, in name order, depth first.
    pub files: Vec<WalkedFile>,
    /// Hidden entries, excluded folders, looping and broken links.
    pub left_out: Vec<LeftOut>,
}

/// Walks `root` recursively (see the module docs); folders whose canonical
/// path is in `exclude` are left out. Fails only when a folder cannot be
/// listed or resolved.
pub fn walk_folder(root: &Path, exclude: &[PathBuf]) -> Result<Walk, TypesError> {
    let canon = root.canonicalize().map_err(|source| TypesError::Folder {
        path: root.to_path_buf(),
        action: "resolve",
        source,
    })?;
    let mut visited = HashSet::from([canon.clone()]);
    let mut walk = Walk::default();
    visit(root, "", exclude, &mut visited, &mut walk)?;
    Ok(walk)
}

fn visit(
    dir: &Path,
    prefix: &str,
    exclude: &[PathBuf],
    visited: &mut HashSet<PathBuf>,
    walk: &mut Walk,
) -> Result<(), TypesError> {
    let list_err = |source| TypesError::Folder {
        path: dir.to_path_buf(),
        action: "list",
        source,
    };
    let mut entries = Vec::new();
    for e in std::fs::read_dir(dir).map_err(list_err)? {
        entries.push(e.map_err(list_err)?.path());
    }
    entries.sort();
    for p in entries {
        let name = p
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let key = if prefix.is_empty() {
            name.clone()
        } else {
            format!("{prefix}/{name}")
        };
        let left_out = |reason: String| LeftOut {
            path: p.clone(),
            reason,
        };
        if name.starts_with('.') {
            walk.left_out.push(left_out("hidden file or folder".into()));
            continue;
        }
        let is_link = p.symlink_metadata().is_ok_and(|m| m.is_symlink());
        // `metadata` follows links: a broken link has none.
        let Ok(meta) = p.metadata() else {
            walk.left_out.push(left_out(if is_link {
                "symbolic link to nothing".into()
            } else {
                "vanished while listed".into()
            }));
            continue;
        };
        if !meta.is_dir() {
            walk.files.push(WalkedFile { path: p, key });
            continue;
        }
        let canon = p.canonicalize().map_err(|source| TypesError::Folder {
            path: p.clone(),
            action: "resolve",
            source,
        })?;
        if exclude.contains(&canon) {
            walk.left_out.push(left_out("the output folder".into()));
            continue;
        }
        if !visited.insert(canon.clone()) {
            walk.left_out.push(left_out(if is_link {
                format!(
                    "symbolic link to {}, a folder this walk already covers (a loop or a \
                     second way in): not followed",
                    canon.display()
                )
            } else {
                "folder already walked through a symbolic link".into()
            }));
            continue;
        }
        visit(&p, &key, exclude, visited, walk)?;
    }
    Ok(())
}
