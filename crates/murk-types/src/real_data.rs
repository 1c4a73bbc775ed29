//! Test support: where the tests of every murk crate find the real sample
//! data (`shared/data/real/`: a VLP-16 pcap, KITTI and nuScenes scans,
//! RADIATE fog frames), so that they agree and none looks at an absolute
//! path that exists on one machine only.
//!
//! The data sits beside the checkout: `<workspace root>/../shared/data/real`,
//! the workspace root being the first folder above the calling crate's
//! `CARGO_MANIFEST_DIR` whose `Cargo.toml` has a `[workspace]` table. It is
//! not part of the repository, so a test that needs a file skips (saying
//! so) when it is absent — unless `MURK_REQUIRE_REAL_DATA=1` is set (CI sets
//! it whenever `../shared/data/real` exists): then a missing folder or file
//! fails the test, so a real-data test cannot skip unnoticed.
//!
//! It lives here, in the crate every other crate depends on, because six
//! test suites in four crates need the same rule; a copy per suite is how
//! the absolute paths came about.

use std::path::{Path, PathBuf};

/// The environment variable that turns a skip into a failure.
pub const REQUIRE_REAL_DATA: &str = "MURK_REQUIRE_REAL_DATA";

/// The workspace root above `manifest_dir` (the first folder whose
/// `Cargo.toml` declares `[workspace]`), if any.
fn workspace_root(manifest_dir: &Path) -> Option<PathBuf> {
    manifest_dir
        .ancestors()
        .find(|d| {
            std::fs::read_to_string(d.join("Cargo.toml"))
                .is_ok_and(|t| t.lines().any(|l| l.trim() == "[workspace]"))
        })
        .map(Path::to_path_buf)
}

/// Where the real sample data of the checkout holding `manifest_dir` would
/// be (`<workspace root>/../shared/data/real`), whether or not it exists.
/// Pass `env!("CARGO_MANIFEST_DIR")`.
pub fn real_data_path(manifest_dir: &str) -> PathBuf {
    let m = Path::new(manifest_dir);
    workspace_root(m)
        .unwrap_or_else(|| m.to_path_buf())
        .join("../shared/data/real")
}

/// Whether a missing real-data file must fail the test
/// ([`REQUIRE_REAL_DATA`] is `1`).
pub fn real_data_required() -> bool {
    std::env::var(REQUIRE_REAL_DATA).is_ok_and(|v| v == "1")
}

/// The real sample file `name` (a path below `shared/data/real/`), or
/// `None` after printing `skipping: …` when it is absent.
///
/// # Panics
///
/// When the file is absent and [`real_data_required`]: the test then fails
/// naming the file, instead of skipping.
pub fn real_data_file(manifest_dir: &str, name: &str) -> Option<PathBuf> {
    let dir = real_data_path(manifest_dir);
    let path = dir.join(name);
    if path.exists() {
        return Some(path);
    }
    let why = if dir.is_dir() {
        format!("{} is missing from {}", name, dir.display())
    } else {
        format!("{} is absent", dir.display())
    };
    if real_data_required() {
        panic!("{REQUIRE_REAL_DATA}=1 but {why}: a real-data test would skip");
    }
    println!("skipping: {why}");
    None
}
