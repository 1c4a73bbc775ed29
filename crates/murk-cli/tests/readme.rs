//! Every command of README.md's ```sh blocks, in order, on a fresh copy of
//! the committed default campaign: what a new user types must run.
//!
//! `murk` and `cargo run --release -p murk-cli --` become the binary under
//! test (through `PATH`). A command is skipped, with the reason printed,
//! only when it needs what this machine cannot have: the test suite itself,
//! Python packages, an ONNX generator file that is not in the repository, a
//! second (native) build, or `../shared` when it is absent — and then also
//! every later command that reads what a skipped one would have written.
//! Any other command that exits non-zero fails the test.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The commands of the ```sh blocks, continuation lines joined.
fn readme_commands(readme: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut in_sh = false;
    let mut pending = String::new();
    for line in readme.lines() {
        let t = line.trim();
        if !in_sh {
            in_sh = t == "```sh";
            continue;
        }
        if t == "```" {
            in_sh = false;
            continue;
        }
        if let Some(head) = t.strip_suffix('\\') {
            pending.push_str(head.trim_end());
            pending.push(' ');
            continue;
        }
        pending.push_str(t);
        let cmd = std::mem::take(&mut pending);
        let code = cmd.split(" #").next().unwrap_or("").trim();
        if !code.is_empty() && !code.starts_with('#') {
            out.push(cmd);
        }
    }
    out
}

/// The value of every `--out` of `cmd`, without a trailing `/`.
fn outputs(cmd: &str) -> Vec<String> {
    let words: Vec<&str> = cmd.split_whitespace().collect();
    words
        .windows(2)
        .filter(|w| w[0] == "--out")
        .map(|w| w[1].trim_end_matches('/').to_string())
        .collect()
}

fn mentions(cmd: &str, path: &str) -> bool {
    cmd.split_whitespace()
        .any(|w| w.trim_end_matches('/') == path)
}

/// Why `cmd` cannot run here, if it cannot.
fn why_skip(cmd: &str, work: &Path, shared: bool, skipped_outputs: &[String]) -> Option<String> {
    let c = cmd.trim();
    if c.starts_with("cargo test") {
        return Some("the test suite itself".into());
    }
    if c.starts_with("pip ") || c.contains("python3") {
        return Some("needs Python packages (and a PyTorch checkpoint)".into());
    }
    if c.starts_with("cargo build") || c.contains("$LIB") || c.contains("--ort-lib") {
        return Some("needs the native ONNX Runtime build".into());
    }
    if let Some(onnx) = c
        .split_whitespace()
        .find(|w| w.ends_with(".onnx") && !work.join(w).exists())
    {
        return Some(format!(
            "needs the ONNX generator {onnx}, which is not in the repository"
        ));
    }
    if c.contains("../shared") && !shared {
        return Some("../shared is absent".into());
    }
    skipped_outputs
        .iter()
        .find(|o| mentions(c, o))
        .map(|o| format!("reads {o}, which a skipped command would have written"))
}

fn copy_tree(src: &Path, dst: &Path) {
    std::fs::create_dir_all(dst).unwrap();
    for e in std::fs::read_dir(src).unwrap() {
        let p = e.unwrap().path();
        let to = dst.join(p.file_name().unwrap());
        if p.is_dir() {
            copy_tree(&p, &to);
        } else {
            std::fs::copy(&p, &to).unwrap();
        }
    }
}

#[cfg(unix)]
#[test]
fn every_readme_command_runs_in_order_on_a_fresh_copy() {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    let repo = manifest.join("../..");
    let readme = std::fs::read_to_string(repo.join("README.md")).unwrap();
    let commands = readme_commands(&readme);

    // root/checkout is the clone, root/shared the shared folder beside it,
    // root/bin holds `murk`.
    let root = tempfile::tempdir().unwrap();
    let work = root.path().join("checkout");
    copy_tree(
        &repo.join("fixtures/default-campaign"),
        &work.join("fixtures/default-campaign"),
    );
    let real: PathBuf = murk_types::real_data::real_data_path(env!("CARGO_MANIFEST_DIR"));
    let shared = real.is_dir();
    if shared {
        let dir = real.join("../..").canonicalize().unwrap();
        std::os::unix::fs::symlink(dir, root.path().join("shared")).unwrap();
    } else if murk_types::real_data::real_data_required() {
        panic!("MURK_REQUIRE_REAL_DATA=1 but {} is absent", real.display());
    }
    let bin = root.path().join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    std::os::unix::fs::symlink(env!("CARGO_BIN_EXE_murk"), bin.join("murk")).unwrap();
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );

    let mut ran = 0;
    let mut skipped_outputs: Vec<String> = Vec::new();
    for raw in &commands {
        let cmd = raw.replace("cargo run --release -p murk-cli --", "murk");
        if let Some(why) = why_skip(&cmd, &work, shared, &skipped_outputs) {
            println!("skipping `{cmd}`: {why}");
            skipped_outputs.extend(outputs(&cmd));
            continue;
        }
        let started = std::time::Instant::now();
        let o = Command::new("sh")
            .args(["-c", &cmd])
            .current_dir(&work)
            .env("PATH", &path)
            .output()
            .unwrap();
        println!(
            "ran `{cmd}` in {:.1} s: {}",
            started.elapsed().as_secs_f64(),
            String::from_utf8_lossy(&o.stdout)
                .lines()
                .last()
                .unwrap_or("")
        );
        assert!(
            o.status.success(),
            "README command failed ({:?}): {cmd}\nstdout:\n{}\nstderr:\n{}",
            o.status,
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        );
        ran += 1;
    }
    // The README's murk commands that need nothing from outside.
    assert!(ran >= 8, "only {ran} README commands ran: {commands:#?}");
}

#[test]
fn readme_parsing_joins_continuations_and_drops_comments() {
    let md = "text\n```sh\n# a comment\nmurk a \\\n   --b c   # note\n\nmurk d\n```\n```text\nmurk e\n```\n";
    assert_eq!(readme_commands(md), vec!["murk a --b c   # note", "murk d"]);
    assert_eq!(outputs("murk x --out frames/ --y"), vec!["frames"]);
    assert!(mentions("murk apply frames/ --out f", "frames"));
    assert!(!mentions("murk apply foggy-frames/", "frames"));
}
