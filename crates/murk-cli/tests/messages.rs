//! The CLI's messages as a user reads them (issue 16): numbers with sensible
//! precision, hints that name the real flag, an OS error or a position said
//! once, "listed above" where the list is above, singular for one, and
//! values the table cannot place refused instead of silently defaulted.

use std::path::Path;
use std::process::{Command, Output};

use murk_io::write_cloud;
use murk_types::{PointCloud, PointFormat};

fn murk(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_murk"))
        .args(args)
        .output()
        .expect("murk runs")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Fog with one extension term on the categorical `Road state`, and rain
/// converted on 0.945…–100 mm/h (a lower bound with a binary tail).
const TABLE: &str = r#"{
  "format": "weather-noise-coefficients/1", "campaign": "seed",
  "lidar": { "model": "VLP16", "range_scale": 1.0 },
  "weathers": {
    "fog": { "recordings": 28, "quantile": 0.99, "no_change_rate": 0.38,
      "vanishing_slope": [
        { "reflectivity_min": 0,  "reflectivity_max": 10,   "slope": 0.30286536, "points": 1 },
        { "reflectivity_min": 10, "reflectivity_max": null, "slope": 0.34634364, "points": 1 } ],
      "ghost": null, "ring": null,
      "extensions": [ { "observable": "survival", "covariate": "Road state",
        "function": { "kind": "categories", "values": { "dry": 1.0, "wet": 0.8 } },
        "default": 1.0, "description": "test" } ] },
    "rain": { "recordings": 11, "quantile": 0.99, "no_change_rate": 0.5,
      "vanishing_slope": [
        { "reflectivity_min": 0,  "reflectivity_max": 10,   "slope": 0.15688675, "points": 1 },
        { "reflectivity_min": 10, "reflectivity_max": null, "slope": 0.22530445, "points": 1 } ],
      "ghost": null, "ring": null,
      "mor_from_rain_rate": { "slope": -0.8308, "intercept": 159.16, "points": 42,
                              "rain_rate_min": 0.9450000000000001, "rain_rate_max": 100 } } },
  "provenance": { "tool": "test", "inputs_sha256": "", "parameters": {} }
}"#;

fn setup() -> (tempfile::TempDir, std::path::PathBuf, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let table = dir.path().join("t.json");
    std::fs::write(&table, TABLE).unwrap();
    let scan = dir.path().join("a.pcd");
    let mut c = PointCloud::with_capacity(20);
    for r in 1..=20 {
        c.push(r as f32, 0.0, 0.0, 30.0, 0);
    }
    write_cloud(&scan, &c, PointFormat::Pcd).unwrap();
    (dir, table, scan)
}

#[test]
fn a_rain_rate_outside_the_range_prints_short_bounds_and_names_clamp() {
    let (dir, table, scan) = setup();
    let out = dir.path().join("out");
    let base = [
        "apply",
        "--coefficients",
        s(&table),
        "--weather",
        "rain",
        "--rain-rate",
        "0.5",
        s(&scan),
        "--out",
        s(&out),
    ];
    let o = murk(&base);
    let err = stderr(&o);
    assert!(!o.status.success());
    assert!(!err.contains("0.9450000000000001"), "{err}");
    // Rounded up: 0.945 itself is below the bound.
    assert!(err.contains("[0.9451, 100] mm/h"), "{err}");
    assert!(err.contains("`--clamp`"), "the real flag: {err}");
    assert!(!err.contains("ask for a clamp"), "{err}");

    let mut clamped = base.to_vec();
    clamped.push("--clamp");
    let o = murk(&clamped);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("clamped to 0.945 mm/h"), "{err}");
    assert!(!err.contains("0.9450000000000001"), "{err}");
}

#[test]
fn an_unknown_category_is_refused_naming_the_known_ones() {
    let (dir, table, scan) = setup();
    let out = dir.path().join("out");
    let run = |cov: &str| {
        murk(&[
            "apply",
            "--coefficients",
            s(&table),
            "--weather",
            "fog",
            "--mor",
            "60",
            "--covariate",
            cov,
            s(&scan),
            "--out",
            s(&out),
        ])
    };
    let o = run("Road state=slushy");
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("\"slushy\" is not a category"), "{err}");
    assert!(err.contains("\"dry\", \"wet\""), "names the known: {err}");
    assert!(!out.join("a.pcd").exists(), "nothing written");
    // A known category applies; a covariate no term uses is said, not silent.
    let o = run("Road state=wet");
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run("Wind=3");
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("covariate \"Wind\" given, but no extension term"),
        "{err}"
    );
}

#[test]
fn nothing_to_apply_says_the_list_is_above_and_counts_in_the_singular() {
    let (dir, table, scan) = setup();
    let only_text = dir.path().join("docs");
    std::fs::create_dir_all(&only_text).unwrap();
    std::fs::write(only_text.join("readme.txt"), b"hi").unwrap();
    let o = murk(&[
        "apply",
        "--coefficients",
        s(&table),
        "--weather",
        "fog",
        "--mor",
        "60",
        s(&only_text),
        "--out",
        s(&dir.path().join("out")),
    ]);
    let err = stderr(&o);
    let skipped = err.find("skipped").expect("the list is printed");
    let summary = err.find("listed above").expect("and pointed at");
    assert!(skipped < summary, "the list comes first: {err}");
    assert!(
        err.contains("1 other entry listed above was left out"),
        "{err}"
    );
    assert!(!err.contains("listed below"), "{err}");

    let o = murk(&[
        "apply",
        "--coefficients",
        s(&table),
        "--weather",
        "fog",
        "--mor",
        "60",
        s(&scan),
        "--out",
        s(&dir.path().join("out")),
    ]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success());
    assert!(out.contains(" to 1 file → "), "{out}");
    assert!(!out.contains("1 files"), "{out}");
}

#[test]
fn an_os_error_and_a_json_position_are_said_once() {
    let (dir, _table, scan) = setup();
    let o = murk(&["campaign", "summary", s(&dir.path().join("nowhere"))]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(err.matches("(os error 2)").count(), 1, "{err}");

    let bad = dir.path().join("bad.json");
    std::fs::write(
        &bad,
        "{\n  \"format\": \"weather-noise-coefficients/1\",\n  oops\n}\n",
    )
    .unwrap();
    let o = murk(&[
        "apply",
        "--coefficients",
        s(&bad),
        "--weather",
        "fog",
        "--mor",
        "60",
        s(&scan),
        "--out",
        s(&dir.path().join("out")),
    ]);
    let err = stderr(&o);
    assert!(err.contains("line 3 column 3"), "{err}");
    assert_eq!(err.matches("line 3 column 3").count(), 1, "{err}");
}

#[test]
fn convert_prints_one_line_for_the_whole_batch() {
    let (dir, _table, scan) = setup();
    let input = dir.path().join("many");
    std::fs::create_dir_all(&input).unwrap();
    for k in 0..12 {
        std::fs::copy(&scan, input.join(format!("s{k}.pcd"))).unwrap();
    }
    let out = dir.path().join("conv");
    let o = murk(&["convert", s(&input), "--out", s(&out), "--format", "bin"]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        text.lines().collect::<Vec<_>>(),
        vec![format!(
            "converted 12 inputs into 12 bin files (240 points; intensity calibrated → kitti) in {}",
            out.display()
        )]
    );
    let o = murk(&["convert", s(&scan), "--out", s(&out), "--format", "csv"]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.starts_with("converted 1 input into 1 csv file (20 points; intensity calibrated)"),
        "{text}"
    );
}

/// `--no-law-comparison`: the table says the laws were not compared (and
/// the parameter is in its provenance); with `--bend` it is refused by
/// name.
#[test]
fn no_law_comparison_is_said_in_the_table_and_refused_with_bend() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/default-campaign");
    let out = dir.path().join("t.json");
    let o = murk(&[
        "fit",
        s(&campaign),
        "--out",
        s(&out),
        "--bootstrap",
        "0",
        "--no-law-comparison",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let t: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(t["provenance"]["parameters"]["compare_laws"], false);
    let fog = &t["weathers"]["fog"]["law_choice"];
    assert_eq!(fog["chosen"], "linear", "{fog}");
    assert!(
        fog["reason"].as_str().unwrap().contains("not compared"),
        "{fog}"
    );
    let o = murk(&[
        "fit",
        s(&campaign),
        "--out",
        s(&out),
        "--bend",
        "--no-law-comparison",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--no-law-comparison"), "{}", stderr(&o));
}

/// `--reflectivity-law` puts the reflectivity term's comparison in the
/// table (on a campaign whose truth has one distance per band: compared,
/// not chosen, no term written) and its edges in the parameters; with
/// `--no-law-comparison` it is refused.
#[test]
fn reflectivity_law_is_compared_and_refused_without_the_law_comparison() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/default-campaign");
    let out = dir.path().join("t.json");
    let o = murk(&[
        "fit",
        s(&campaign),
        "--out",
        s(&out),
        "--bootstrap",
        "0",
        "--bend",
        "--reflectivity-law",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let t: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(
        t["provenance"]["parameters"]["reflectivity_law_edges"][0],
        1.0
    );
    let mut compared = 0;
    for (w, c) in t["weathers"].as_object().unwrap() {
        if c["law_choice"].is_null() {
            continue;
        }
        compared += 1;
        let r = &c["law_choice"]["reflectivity"];
        assert_eq!(r["chosen"], false, "{w}: {r}");
        assert!(r["p_value"].as_f64().unwrap() > 0.01, "{w}: {r}");
        for b in c["vanishing_slope"].as_array().unwrap() {
            assert!(b["law"]["reflectivity"].is_null(), "{w}: {b}");
        }
    }
    assert!(compared >= 2, "{compared} weathers compared");
    let o = murk(&[
        "fit",
        s(&campaign),
        "--out",
        s(&out),
        "--reflectivity-law",
        "--no-law-comparison",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--no-law-comparison"), "{}", stderr(&o));
}

/// `--clear-memory-mb 0` spills every clear image and gives the same table
/// bytes; a negative budget and a spill folder that does not exist are
/// refused naming the flag or the folder.
#[test]
fn spilled_clear_images_give_the_same_table_and_bad_budgets_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/default-campaign");
    let fit = |out: &Path, extra: &[&str]| {
        let mut args = vec!["fit", s(&campaign), "--out", s(out), "--bootstrap", "0"];
        args.extend_from_slice(extra);
        murk(&args)
    };
    let (a, b) = (dir.path().join("a.json"), dir.path().join("b.json"));
    let o = fit(&a, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let spill = dir.path().join("spill");
    std::fs::create_dir(&spill).unwrap();
    let o = fit(&b, &["--clear-memory-mb", "0", "--spill-dir", s(&spill)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap());
    // The file is anonymous: nothing is left in the folder.
    assert_eq!(std::fs::read_dir(&spill).unwrap().count(), 0);
    let o = fit(&b, &["--clear-memory-mb=-1"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--clear-memory-mb"), "{}", stderr(&o));
    let missing = dir.path().join("no-such-folder");
    let o = fit(&b, &["--clear-memory-mb", "0", "--spill-dir", s(&missing)]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains(s(&missing)) && e.contains("temporary file of the clear images"),
        "{e}"
    );
}
