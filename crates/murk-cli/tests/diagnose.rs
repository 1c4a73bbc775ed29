//! `murk diagnose` end to end on generated campaigns: a hidden survival
//! effect is found, the extended table it writes is used by `murk apply`,
//! reports are byte-identical for the same seed, and bad flags are refused.

use std::path::Path;
use std::process::{Command, Output};

fn murk(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_murk"))
        .args(args)
        .output()
        .expect("murk runs")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A 48-recording fog campaign whose dark returns (reflectivity < 25)
/// vanish 30 % sooner than the rest.
fn campaign(dir: &Path) -> std::path::PathBuf {
    let cfg = dir.join("effects.toml");
    std::fs::write(
        &cfg,
        r#"
[campaign]
recordings = 48
[weather.mix]
clear = 0.25
fog = 0.75
rain = 0.0
snow = 0.0
[review.reject]
clear = 0.05
fog = 0.05
rain = 0.05
snow = 0.05
[[effects]]
name = "dark returns drop first"
observable = "survival"
covariate = "reflectivity"
weathers = ["fog"]
function = { kind = "step", threshold = 25.0, below = 0.7, above = 1.0 }
"#,
    )
    .unwrap();
    let out = dir.join("camp");
    let o = murk(&[
        "generate",
        "--preset",
        "small",
        "--seed",
        "5",
        "--config",
        s(&cfg),
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    out
}

#[test]
fn finds_the_hidden_effect_and_writes_a_table_apply_uses() {
    let dir = tempfile::tempdir().unwrap();
    let camp = campaign(dir.path());
    let report = dir.path().join("out/report.json");
    let figs = dir.path().join("figs");
    let o = murk(&[
        "diagnose",
        s(&camp),
        "--weather",
        "fog",
        "--out",
        s(&report),
        "--figures",
        s(&figs),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(r["format"], "weather-noise-diagnosis/1");
    assert_eq!(r["weather"], "fog");
    let top = &r["findings"][0];
    assert_eq!(top["significant"], true, "{top}");
    assert_eq!(
        (top["observable"].as_str(), top["covariate"].as_str()),
        (Some("survival"), Some("reflectivity"))
    );
    let g = &r["gain"];
    assert!(g["relative"].as_f64().unwrap() > 0.0, "{g}");
    // Every test says what it could have found: a positive number, or why
    // it cannot tell; the tests that found nothing say so on stdout.
    for f in r["findings"].as_array().unwrap() {
        match f["detectable"].as_f64() {
            Some(x) => assert!(x.is_finite() && x > 0.0, "{f}"),
            None => assert!(f["detectable_reason"].is_string(), "{f}"),
        }
    }
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("effect larger than") && stdout.contains("(80 % power)"),
        "{stdout}"
    );
    assert!(
        r["baseline"]["metrics"]["voxel_global_difference"]
            .as_f64()
            .is_some()
    );
    // Figures: the finding's profile and the bird's-eye view.
    assert!(figs.join("residual-survival-reflectivity.png").is_file());
    assert!(
        std::fs::read_dir(&figs).unwrap().any(|e| e
            .unwrap()
            .file_name()
            .to_string_lossy()
            .starts_with("bev-"))
    );

    // The extended table drives murk apply: with the term, more dark
    // returns vanish than with the baseline.
    let ext = dir.path().join("out/report.extended.json");
    assert!(ext.is_file());
    let clear = std::fs::read_dir(camp.join("lidar"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .min()
        .unwrap();
    let mut kept = Vec::new();
    for flag in [None, Some("--no-extensions")] {
        let out = dir.path().join(format!("applied-{}", kept.len()));
        let mut args = vec![
            "apply",
            "--coefficients",
            s(&ext),
            "--weather",
            "fog",
            "--mor",
            "60",
            s(&clear),
            "--out",
            s(&out),
        ];
        args.extend(flag);
        let o = murk(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let f = std::fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.extension().is_some_and(|e| e == "pcd"))
            .unwrap();
        kept.push(std::fs::metadata(f).unwrap().len());
    }
    assert!(
        kept[0] < kept[1],
        "extended keeps fewer bytes than baseline: {kept:?}"
    );

    // Same seed, same report bytes, whatever the thread count.
    let again = dir.path().join("again.json");
    // (on one thread: the bytes must not depend on the thread count)
    let o = Command::new(env!("CARGO_BIN_EXE_murk"))
        .args(["diagnose", s(&camp), "--weather", "fog", "--out", s(&again)])
        .env("RAYON_NUM_THREADS", "1")
        .output()
        .unwrap();
    assert!(o.status.success());
    assert!(
        std::fs::read(&report).unwrap() == std::fs::read(&again).unwrap(),
        "the same seed gave different report bytes"
    );
}

#[test]
fn bad_flags_are_refused_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let o = murk(&[
        "diagnose",
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../fixtures/default-campaign"
        ),
        "--weather",
        "clear",
        "--out",
        s(&dir.path().join("r.json")),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("clear"), "{err}");
    let o = murk(&[
        "diagnose",
        "/nonexistent/campaign",
        "--weather",
        "fog",
        "--out",
        s(&dir.path().join("r.json")),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("/nonexistent/campaign"));
}
