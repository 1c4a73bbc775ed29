//! Replays the `pcap` fuzz corpus as a regression test on the stable
//! toolchain: every committed seed (`fuzz/seeds/pcap/`), and whatever a local
//! fuzzing run left in `fuzz/corpus/pcap/` and `fuzz/artifacts/pcap/` (both
//! git-ignored), goes through the body the fuzzer runs
//! (`fuzz/fuzz_targets/common/mod.rs`, included here by path).
//!
//! Beyond the files as they are, each seed is replayed under every options
//! byte the target reads (bits 0–4), cut at every length, and with each byte
//! inverted, which reaches the truncation and corruption paths the fuzzer
//! starts from.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

#[path = "../fuzz/fuzz_targets/common/mod.rs"]
mod fuzz_body;

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

/// Runs the fuzz body on `data`; a panic is recorded as a failure naming
/// `what`.
fn replay(data: &[u8], what: impl FnOnce() -> String, failures: &mut Vec<String>) {
    if catch_unwind(AssertUnwindSafe(|| fuzz_body::pcap(data))).is_err() {
        failures.push(what());
    }
}

#[test]
fn every_seed_corpus_and_artifact_capture_decodes_or_errs_without_panicking() {
    let seeds = files(&fuzz_dir().join("seeds/pcap"));
    assert!(
        seeds.len() >= 3,
        "fuzz/seeds/pcap: expected the committed seed corpus, found {} files",
        seeds.len()
    );
    let local: Vec<PathBuf> = ["corpus/pcap", "artifacts/pcap"]
        .iter()
        .flat_map(|d| files(&fuzz_dir().join(d)))
        .collect();
    if !local.is_empty() {
        println!("also replaying {} local corpus/artifact files", local.len());
    }
    let mut failures = Vec::new();
    for path in seeds.iter().chain(&local) {
        let data = std::fs::read(path).expect("readable corpus file");
        replay(&data, || path.display().to_string(), &mut failures);
    }
    for path in &seeds {
        let data = std::fs::read(path).expect("readable seed");
        let Some((_, capture)) = data.split_first() else {
            continue;
        };
        for b in 0..32u8 {
            let mut v = vec![b];
            v.extend_from_slice(capture);
            replay(
                &v,
                || format!("{} with options byte {b}", path.display()),
                &mut failures,
            );
        }
        for cut in 0..data.len() {
            replay(
                &data[..cut],
                || format!("{} cut to {cut} bytes", path.display()),
                &mut failures,
            );
        }
        for at in 1..data.len() {
            let mut v = data.clone();
            v[at] ^= 0xFF;
            replay(
                &v,
                || format!("{} with byte {at} inverted", path.display()),
                &mut failures,
            );
        }
    }
    assert!(
        failures.is_empty(),
        "the fuzz body panicked on: {failures:#?}"
    );
}
