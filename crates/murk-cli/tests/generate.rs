//! `murk generate` end to end: the binary writes a campaign and its truth,
//! identically twice, refuses bad input with the file, line and field.

use std::path::Path;
use std::process::Command;

fn murk(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_murk"))
        .args(args)
        .output()
        .expect("murk runs")
}

fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().display().to_string();
                out.push((rel, std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn generate_writes_a_campaign_and_its_truth_beside_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("camp");
    let o = murk(&[
        "generate",
        "--out",
        out.to_str().unwrap(),
        "--seed",
        "7",
        "--preset",
        "small",
        "--recordings",
        "6",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("wrote 6 recordings"), "{stdout}");
    for f in ["campaign.toml", "weather.csv", "review.csv"] {
        assert!(out.join(f).is_file(), "{f}");
    }
    assert_eq!(std::fs::read_dir(out.join("lidar")).unwrap().count(), 6);
    assert_eq!(std::fs::read_dir(out.join("radar")).unwrap().count(), 6);
    let truth_path = dir.path().join("camp.truth.json");
    assert!(!out.join("camp.truth.json").exists(), "truth never inside");
    let truth: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&truth_path).unwrap()).unwrap();
    assert_eq!(truth["format"], "murk-generator-truth/1");
    assert_eq!(truth["seed"], 7);
    let recs = truth["recordings"].as_array().unwrap();
    assert_eq!(recs.len(), 6);
    // The truth's point counts are the files' point counts (PCD header).
    for r in recs {
        let id = r["id"].as_str().unwrap();
        let bytes = std::fs::read(out.join(format!("lidar/{id}.pcd"))).unwrap();
        let head = String::from_utf8_lossy(&bytes[..bytes.len().min(400)]).into_owned();
        let points = head
            .lines()
            .find_map(|l| l.strip_prefix("POINTS "))
            .unwrap()
            .trim()
            .parse::<u64>()
            .unwrap();
        assert_eq!(Some(points), r["counts"]["points"].as_u64(), "{id}");
    }
}

#[test]
fn same_seed_same_bytes_and_csv_format() {
    let dir = tempfile::tempdir().unwrap();
    let mut runs = Vec::new();
    for (name, threads) in [("a", "1"), ("b", "2")] {
        let out = dir.path().join(name);
        let o = Command::new(env!("CARGO_BIN_EXE_murk"))
            .args([
                "generate",
                "--out",
                out.to_str().unwrap(),
                "--seed",
                "3",
                "--preset",
                "small",
                "--recordings",
                "4",
                "--format",
                "csv",
            ])
            .env("RAYON_NUM_THREADS", threads)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        runs.push((
            files(&out),
            std::fs::read(dir.path().join(format!("{name}.truth.json"))).unwrap(),
        ));
    }
    assert!(runs[0] == runs[1], "two runs differ");
    let lidar: Vec<_> = runs[0]
        .0
        .iter()
        .filter(|(n, _)| n.starts_with("lidar"))
        .collect();
    assert_eq!(lidar.len(), 4);
    assert!(
        lidar
            .iter()
            .all(|(n, b)| n.ends_with(".csv") && b.starts_with(b"x,y,z,intensity,ring"))
    );
}

#[test]
fn bad_config_names_file_line_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("gen.toml");
    std::fs::write(&cfg, "[degradation.fog]\nedge_width = 0.1\n\n[[effects]]\nname = \"x\"\nobservable = \"range\"\ncovariate = \"nope\"\nfunction = { kind = \"constant\", value = 1.0 }\n").unwrap();
    let out = dir.path().join("c");
    let o = murk(&[
        "generate",
        "--out",
        out.to_str().unwrap(),
        "--seed",
        "1",
        "--config",
        cfg.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("gen.toml:7: effects[0].covariate"), "{err}");
    assert!(!out.exists(), "nothing written on error");
}

#[test]
fn existing_folder_is_not_overwritten_without_force() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("c");
    let args = |force: bool| {
        let mut a = vec![
            "generate".to_string(),
            "--out".into(),
            out.display().to_string(),
            "--seed".into(),
            "1".into(),
            "--preset".into(),
            "small".into(),
            "--recordings".into(),
            "2".into(),
        ];
        if force {
            a.push("--force".into());
        }
        a
    };
    let run = |a: Vec<String>| {
        Command::new(env!("CARGO_BIN_EXE_murk"))
            .args(a)
            .output()
            .unwrap()
    };
    assert!(run(args(false)).status.success());
    let o = run(args(false));
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("not empty"));
    assert!(run(args(true)).status.success());
}
