//! Replays the fuzz corpora of `fuzz/` as regression tests on the stable
//! toolchain: every committed seed (`fuzz/seeds/<target>/`), and whatever a
//! local fuzzing run left in `fuzz/corpus/<target>/` and
//! `fuzz/artifacts/<target>/` (both git-ignored), goes through the body the
//! fuzzer runs (`fuzz/fuzz_targets/common/mod.rs`, included here by path).
//!
//! Beyond the files as they are, each seed is replayed under every options
//! byte the targets read (bits 0–2) and cut at every length, which reaches
//! the truncation paths the fuzzer starts from.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

use murk_types::PointFormat;

#[path = "../fuzz/fuzz_targets/common/mod.rs"]
mod fuzz_body;

const TARGETS: [(PointFormat, &str); 4] = [
    (PointFormat::Pcd, "pcd"),
    (PointFormat::KittiBin, "kitti_bin"),
    (PointFormat::NuscenesBin, "nuscenes_bin"),
    (PointFormat::Csv, "csv"),
];

fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz")
}

/// The files of `dir`, sorted; none when it does not exist.
fn files(dir: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut v: Vec<PathBuf> = entries
        .map(|e| e.expect("readable folder entry").path())
        .filter(|p| p.is_file())
        .collect();
    v.sort();
    v
}

/// Runs the body of `format`'s target on `data`; a panic is returned as a
/// failure naming `what`.
fn replay(
    format: PointFormat,
    data: &[u8],
    what: impl FnOnce() -> String,
    failures: &mut Vec<String>,
) {
    if catch_unwind(AssertUnwindSafe(|| fuzz_body::run(format, data))).is_err() {
        failures.push(what());
    }
}

#[test]
fn every_seed_corpus_and_artifact_input_parses_or_errs_without_panicking() {
    let mut failures = Vec::new();
    for (format, name) in TARGETS {
        let seeds = files(&fuzz_dir().join("seeds").join(name));
        assert!(
            seeds.len() >= 2,
            "fuzz/seeds/{name}: expected the committed seed corpus, found {} files",
            seeds.len()
        );
        let local: Vec<PathBuf> = ["corpus", "artifacts"]
            .iter()
            .flat_map(|d| files(&fuzz_dir().join(d).join(name)))
            .collect();
        if !local.is_empty() {
            println!(
                "{name}: also replaying {} local corpus/artifact files",
                local.len()
            );
        }
        for path in seeds.iter().chain(&local) {
            let data = std::fs::read(path).expect("readable corpus file");
            replay(format, &data, || path.display().to_string(), &mut failures);
        }
        for path in &seeds {
            let data = std::fs::read(path).expect("readable seed");
            let Some((&opts, file)) = data.split_first() else {
                continue;
            };
            for b in 0..8u8 {
                let mut v = vec![b];
                v.extend_from_slice(file);
                replay(
                    format,
                    &v,
                    || format!("{} with options byte {b}", path.display()),
                    &mut failures,
                );
            }
            for cut in 0..data.len() {
                replay(
                    format,
                    &data[..cut],
                    || format!("{} cut to {cut} bytes", path.display()),
                    &mut failures,
                );
            }
            // Options byte unchanged, one byte flipped at each position.
            for at in 1..data.len() {
                let mut v = data.clone();
                v[at] ^= 0xFF;
                replay(
                    format,
                    &v,
                    || {
                        format!(
                            "{} with byte {at} inverted (options {opts})",
                            path.display()
                        )
                    },
                    &mut failures,
                );
            }
        }
    }
    assert!(
        failures.is_empty(),
        "the fuzz body panicked on: {failures:#?}"
    );
}
