//! The CLI under real plumbing (issue 16): a stdout closed by the reader,
//! symbolic-link loops in input folders, temporaries left by killed runs,
//! Ctrl-C in the middle of a batch, and output paths checked before the
//! work starts.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use murk_io::{ReadOptions, read_cloud, write_cloud};
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

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// The seed's fog (Table 4) and a rain conversion fitted on 0.945–100 mm/h
/// (a lower bound with a binary-fraction tail, as a fit produces them).
const TABLE: &str = r#"{
  "format": "weather-noise-coefficients/1", "campaign": "seed",
  "lidar": { "model": "VLP16", "range_scale": 1.0 },
  "weathers": {
    "fog": { "recordings": 28, "quantile": 0.99, "no_change_rate": 0.38,
      "vanishing_slope": [
        { "reflectivity_min": 0,  "reflectivity_max": 10,   "slope": 0.30286536, "points": 1 },
        { "reflectivity_min": 10, "reflectivity_max": null, "slope": 0.34634364, "points": 1 } ],
      "ghost": null, "ring": null },
    "rain": { "recordings": 11, "quantile": 0.99, "no_change_rate": 0.5,
      "vanishing_slope": [
        { "reflectivity_min": 0,  "reflectivity_max": 10,   "slope": 0.15688675, "points": 1 },
        { "reflectivity_min": 10, "reflectivity_max": null, "slope": 0.22530445, "points": 1 } ],
      "ghost": null, "ring": null,
      "mor_from_rain_rate": { "slope": -0.8308, "intercept": 159.16, "points": 42,
                              "rain_rate_min": 0.9450000000000001, "rain_rate_max": 100 } } },
  "provenance": { "tool": "test", "inputs_sha256": "", "parameters": {} }
}"#;

/// A scan: a wall of `n` points from 1 m outwards, reflectivities 5 and 50.
fn scan(n: usize) -> PointCloud {
    let mut c = PointCloud::with_capacity(n);
    for i in 0..n {
        let r = 1.0 + (i / 2) as f32 * 0.05;
        let refl = if i % 2 == 0 { 5.0 } else { 50.0 };
        c.push(r, (i % 7) as f32 * 0.1, 0.0, refl, (i % 16) as u16);
    }
    c
}

/// A table file and `in/` with `files` PCD scans of `points` points each.
fn batch(dir: &Path, files: usize, points: usize) -> (PathBuf, PathBuf) {
    let table = dir.join("t.json");
    std::fs::write(&table, TABLE).unwrap();
    let input = dir.join("in");
    std::fs::create_dir_all(&input).unwrap();
    let c = scan(points);
    for k in 0..files {
        write_cloud(&input.join(format!("s{k:05}.pcd")), &c, PointFormat::Pcd).unwrap();
    }
    (table, input)
}

/// Every file name below `dir`, relative, sorted.
fn tree(dir: &Path) -> Vec<String> {
    fn go(base: &Path, dir: &Path, out: &mut Vec<String>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() && !p.is_symlink() {
                go(base, &p, out);
            } else {
                out.push(p.strip_prefix(base).unwrap().to_string_lossy().into_owned());
            }
        }
    }
    let mut v = Vec::new();
    go(dir, dir, &mut v);
    v.sort();
    v
}

/// Runs murk with stdout a pipe whose reading end is closed at once.
fn with_closed_stdout(args: &[&str]) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_murk"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("murk runs");
    drop(child.stdout.take()); // the reader is gone before murk prints
    child.wait_with_output().unwrap()
}

fn assert_quiet_end(o: &Output, what: &str) {
    let err = text(&o.stderr);
    assert_ne!(o.status.code(), Some(101), "{what} panicked: {err}");
    assert!(!err.contains("panicked"), "{what}: {err}");
    assert!(
        !err.contains("Broken pipe"),
        "{what}: a closed pipe is not an error: {err}"
    );
    assert!(o.status.success(), "{what}: {:?} {err}", o.status);
}

// ------------------------------------------------------------- closed pipe

#[test]
fn a_closed_stdout_ends_convert_and_apply_quietly_with_every_output_written() {
    let dir = tempfile::tempdir().unwrap();
    let (table, input) = batch(dir.path(), 30, 200);

    let conv = dir.path().join("conv");
    let o = with_closed_stdout(&["convert", s(&input), "--out", s(&conv), "--format", "csv"]);
    assert_quiet_end(&o, "convert");
    let written = tree(&conv);
    assert_eq!(written.len(), 30, "{written:?}");
    for name in &written {
        let c = read_cloud(&conv.join(name), &ReadOptions::default()).unwrap();
        assert_eq!(c.len(), 200, "{name} complete");
    }

    let out = dir.path().join("foggy");
    let o = with_closed_stdout(&[
        "apply",
        "--coefficients",
        s(&table),
        "--weather",
        "fog",
        "--mor",
        "60",
        s(&input),
        "--out",
        s(&out),
    ]);
    assert_quiet_end(&o, "apply");
    assert_eq!(tree(&out).len(), 30);
    // The same run with stdout read gives the same files.
    let again = dir.path().join("foggy2");
    let o2 = murk(&[
        "apply",
        "--coefficients",
        s(&table),
        "--weather",
        "fog",
        "--mor",
        "60",
        s(&input),
        "--out",
        s(&again),
    ]);
    assert!(o2.status.success());
    for name in tree(&out) {
        assert_eq!(
            std::fs::read(out.join(&name)).unwrap(),
            std::fs::read(again.join(&name)).unwrap(),
            "{name}"
        );
    }
}

/// A copy of the committed default campaign in `dir`.
fn default_campaign(dir: &Path) -> PathBuf {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/default-campaign");
    let dst = dir.join("campaign");
    copy_tree(&src, &dst);
    dst
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

#[test]
fn a_closed_stdout_ends_fit_diagnose_and_campaign_summary_quietly() {
    let dir = tempfile::tempdir().unwrap();
    let camp = default_campaign(dir.path());

    let o = with_closed_stdout(&["campaign", "summary", s(&camp)]);
    assert_quiet_end(&o, "campaign summary");
    let o = with_closed_stdout(&["campaign", "summary", s(&camp), "--json"]);
    assert_quiet_end(&o, "campaign summary --json");

    let table = dir.path().join("t.json");
    let o = with_closed_stdout(&["fit", s(&camp), "--out", s(&table), "--bootstrap", "20"]);
    assert_quiet_end(&o, "fit");
    // The table is complete: it parses and validates.
    murk_types::CoefficientTable::read(&table).expect("the table is written whole");

    let report = dir.path().join("d/report.json");
    let o = with_closed_stdout(&[
        "diagnose",
        s(&camp),
        "--weather",
        "fog",
        "--coefficients",
        s(&table),
        "--out",
        s(&report),
        "--permutations",
        "99",
        "--sims",
        "1",
    ]);
    assert_quiet_end(&o, "diagnose");
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&report).unwrap()).expect("report whole");
    assert!(r.get("findings").is_some());
}

// ------------------------------------------------------ symbolic-link loops

#[cfg(unix)]
#[test]
fn a_symlink_loop_in_an_input_folder_is_named_and_not_followed() {
    use std::os::unix::fs::symlink;
    let dir = tempfile::tempdir().unwrap();
    let (table, input) = batch(dir.path(), 1, 50);
    std::fs::create_dir_all(input.join("sub")).unwrap();
    write_cloud(&input.join("sub/b.pcd"), &scan(40), PointFormat::Pcd).unwrap();
    symlink("..", input.join("sub/up")).unwrap();
    // A link to a file elsewhere is followed.
    let other = dir.path().join("elsewhere");
    std::fs::create_dir_all(&other).unwrap();
    write_cloud(&other.join("c.pcd"), &scan(30), PointFormat::Pcd).unwrap();
    symlink(other.join("c.pcd"), input.join("linked.pcd")).unwrap();

    let out = dir.path().join("out");
    let o = murk(&[
        "apply",
        "--coefficients",
        s(&table),
        "--weather",
        "fog",
        "--mor",
        "3000",
        s(&input),
        "--out",
        s(&out),
    ]);
    let err = text(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert_eq!(
        tree(&out),
        vec!["linked.pcd", "s00000.pcd", "sub/b.pcd"],
        "{err}"
    );
    let loop_line = err
        .lines()
        .find(|l| l.contains("sub/up"))
        .unwrap_or_else(|| panic!("the looping link is named: {err}"));
    assert!(loop_line.contains("not followed"), "{loop_line}");
    assert!(loop_line.contains("loop"), "{loop_line}");
    assert!(
        loop_line.contains(s(&input.canonicalize().unwrap())),
        "says where it leads: {loop_line}"
    );
    let linked = read_cloud(&out.join("linked.pcd"), &ReadOptions::default()).unwrap();
    assert_eq!(linked.len(), 30);

    let conv = dir.path().join("conv");
    let o = murk(&["convert", s(&input), "--out", s(&conv), "--format", "bin"]);
    let err = text(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert_eq!(
        tree(&conv),
        vec!["linked.bin", "s00000.bin", "sub/b.bin"],
        "{err}"
    );
    assert!(
        err.contains("sub/up") && err.contains("not followed"),
        "{err}"
    );
}

// ------------------------------------------------- killed runs and Ctrl-C

/// The id of a process that has ended: a child that exited and was reaped.
fn dead_pid() -> u32 {
    let mut c = Command::new("true").spawn().unwrap();
    let pid = c.id();
    c.wait().unwrap();
    pid
}

#[cfg(target_os = "linux")]
#[test]
fn a_rerun_removes_the_temporaries_of_a_killed_run_and_nothing_else() {
    let dir = tempfile::tempdir().unwrap();
    let (table, input) = batch(dir.path(), 3, 50);
    let out = dir.path().join("out");
    std::fs::create_dir_all(out.join("deeper")).unwrap();
    let dead = dead_pid();
    // What a `kill -9` of `murk apply` leaves: half-written outputs under
    // murk's temporary name, the killed process's id in it.
    let stale = out.join(format!(".murk-{dead}-Qx81Zb.tmp"));
    std::fs::write(&stale, b"half a scan").unwrap();
    // A live process's temporary (this test's own id), and files that are
    // not murk's: all kept.
    let live = out.join(format!(".murk-{}-Ab12Cd.tmp", std::process::id()));
    std::fs::write(&live, b"being written").unwrap();
    let keep = [
        out.join("notes.tmp"),
        out.join(".murk-cache.tmp"),
        out.join(format!(".murk-{dead}-Qx81Zb.tmp.bak")),
        out.join(format!("deeper/.murk-{dead}-Qx81Zb.tmp")), // not an output folder
    ];
    for k in &keep {
        std::fs::write(k, b"mine").unwrap();
    }
    let o = murk(&[
        "apply",
        "--coefficients",
        s(&table),
        "--weather",
        "fog",
        "--mor",
        "60",
        s(&input),
        "--out",
        s(&out),
    ]);
    let err = text(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(!stale.exists(), "the stale temporary is removed");
    assert!(
        err.contains(&format!(".murk-{dead}-Qx81Zb.tmp"))
            && err.contains("left by an interrupted murk run"),
        "and said: {err}"
    );
    assert!(live.exists(), "a live run's temporary is kept");
    for k in &keep {
        assert_eq!(std::fs::read(k).unwrap(), b"mine", "{} kept", k.display());
    }

    // `murk convert` cleans the same way.
    let stale = out.join(format!(".murk-{dead}-Zz00Yy.tmp"));
    std::fs::write(&stale, b"half").unwrap();
    let o = murk(&["convert", s(&input), "--out", s(&out), "--format", "csv"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(!stale.exists());
    assert!(live.exists());
}

#[cfg(target_os = "linux")]
#[test]
fn a_rerun_of_generate_removes_the_folder_a_killed_run_left() {
    let dir = tempfile::tempdir().unwrap();
    let dead = dead_pid();
    let stale = dir.path().join(format!(".camp.tmp-{dead}"));
    std::fs::create_dir_all(stale.join("lidar")).unwrap();
    std::fs::write(stale.join("lidar/r1.pcd"), b"half").unwrap();
    // Not this target's, not murk's naming, or possibly the only copy of a
    // previous campaign: kept.
    let keep = [
        dir.path().join(format!(".other.tmp-{dead}")),
        dir.path().join(format!(".camp.old-{dead}")),
        dir.path().join(format!(".camp.tmp-{}", std::process::id())),
        dir.path().join(".camp.tmp-x1"),
    ];
    for k in &keep {
        std::fs::create_dir_all(k).unwrap();
    }
    let out = dir.path().join("camp");
    let o = murk(&[
        "generate",
        "--preset",
        "small",
        "--recordings",
        "4",
        "--seed",
        "1",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(out.join("campaign.toml").is_file());
    assert!(!stale.exists(), "the killed run's folder is removed");
    for k in &keep {
        assert!(k.is_dir(), "{} kept", k.display());
    }
}

#[cfg(unix)]
#[test]
fn ctrl_c_stops_a_batch_with_every_written_output_complete_and_no_temporary_left() {
    let dir = tempfile::tempdir().unwrap();
    let files = 3000;
    let (table, input) = batch(dir.path(), files, 300);
    let out = dir.path().join("out");
    let child = Command::new(env!("CARGO_BIN_EXE_murk"))
        .args([
            "apply",
            "--coefficients",
            s(&table),
            "--weather",
            "fog",
            "--mor",
            "3000", // clear: every output equals its input, byte for byte
            s(&input),
            "--out",
            s(&out),
        ])
        .env("RAYON_NUM_THREADS", "1")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until the batch is under way, then press Ctrl-C.
    let started = std::time::Instant::now();
    while std::fs::read_dir(&out).map_or(0, |d| d.count()) < 5 {
        assert!(started.elapsed().as_secs() < 120, "the batch did not start");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let o = child.wait_with_output().unwrap();
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(130), "exit 130 after Ctrl-C: {err}");
    assert!(!err.contains("panicked"), "{err}");
    let written = tree(&out);
    assert!(
        written.len() < files,
        "stopped before the end ({} files)",
        written.len()
    );
    assert!(
        err.contains(&format!(
            "interrupted: {} of {files} files written",
            written.len()
        )),
        "says what is done: {err}"
    );
    for name in &written {
        assert!(!name.contains(".murk-"), "temporary file left: {name}");
        assert_eq!(
            std::fs::read(out.join(name)).unwrap(),
            std::fs::read(input.join(name)).unwrap(),
            "{name} is complete"
        );
    }
}

// --------------------------------------------- paths checked before work

#[test]
fn output_paths_that_cannot_be_written_fail_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let camp = default_campaign(dir.path());
    let a_file = dir.path().join("a-file");
    std::fs::write(&a_file, b"x").unwrap();
    let a_dir = dir.path().join("a-dir");
    std::fs::create_dir_all(&a_dir).unwrap();

    // fit --out FOLDER: refused at once, nothing written.
    let o = murk(&["fit", s(&camp), "--out", s(&a_dir)]);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        err.contains("--out") && err.contains("is a folder"),
        "{err}"
    );
    assert!(o.stdout.is_empty(), "no summary printed before the refusal");
    // fit --figures FILE: refused before the table is written.
    let table = dir.path().join("t.json");
    let o = murk(&["fit", s(&camp), "--out", s(&table), "--figures", s(&a_file)]);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        err.contains("--figures") && err.contains("is not a folder"),
        "{err}"
    );
    assert!(!table.exists(), "no table written before the refusal");
    // diagnose --out below a file.
    let o = murk(&[
        "diagnose",
        s(&camp),
        "--weather",
        "fog",
        "--out",
        s(&a_file.join("r.json")),
    ]);
    let err = text(&o.stderr);
    assert!(err.contains("is a file, not a folder"), "{err}");
    // apply --out FILE.
    std::fs::write(&table, TABLE).unwrap();
    let o = murk(&[
        "apply",
        "--coefficients",
        s(&table),
        "--weather",
        "fog",
        "--mor",
        "60",
        s(&camp.join("lidar")),
        "--out",
        s(&a_file),
    ]);
    let err = text(&o.stderr);
    assert!(
        err.contains("--out") && err.contains("is not a folder"),
        "{err}"
    );
    assert_eq!(std::fs::read(&a_file).unwrap(), b"x");
}

// ------------------------------------------------------ silent acceptance

const EMPTY_PCD: &str = "\
# .PCD v0.7 - Point Cloud Data file format
VERSION 0.7
FIELDS x y z intensity ring
SIZE 4 4 4 4 2
TYPE F F F F U
COUNT 1 1 1 1 1
WIDTH 0
HEIGHT 1
VIEWPOINT 0 0 0 1 0 0 0
POINTS 0
DATA ascii
";

/// Removes the rows of `id` from a CSV file of the campaign.
fn drop_rows(path: &Path, id: &str) {
    let text = std::fs::read_to_string(path).unwrap();
    let kept: String = text
        .lines()
        .filter(|l| l.split(',').next() != Some(id))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(path, kept).unwrap();
}

fn fit_json(camp: &Path, out: &Path) -> serde_json::Value {
    let o = murk(&["fit", s(camp), "--out", s(out), "--bootstrap", "20"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    serde_json::from_slice(&std::fs::read(out).unwrap()).unwrap()
}

#[test]
fn a_recording_without_points_is_excluded_and_listed_as_if_it_were_absent() {
    let dir = tempfile::tempdir().unwrap();
    // r0003 is clear, r0004 fog in the committed campaign (both selected).
    let empty = default_campaign(dir.path());
    std::fs::write(empty.join("lidar/r0003.pcd"), EMPTY_PCD).unwrap();
    std::fs::write(empty.join("lidar/r0004.pcd"), EMPTY_PCD).unwrap();
    let with_empty = fit_json(&empty, &dir.path().join("empty.json"));

    let absent_dir = dir.path().join("absent");
    std::fs::create_dir_all(&absent_dir).unwrap();
    let absent = default_campaign(&absent_dir);
    for id in ["r0003", "r0004"] {
        std::fs::remove_file(absent.join(format!("lidar/{id}.pcd"))).unwrap();
        let _ = std::fs::remove_file(absent.join(format!("radar/{id}.csv")));
        drop_rows(&absent.join("weather.csv"), id);
        drop_rows(&absent.join("review.csv"), id);
    }
    let without = fit_json(&absent, &dir.path().join("absent.json"));

    let excluded = with_empty["excluded_recordings"].as_array().unwrap();
    for (id, weather) in [("r0003", "clear"), ("r0004", "fog")] {
        let e = excluded
            .iter()
            .find(|e| e["recording"] == id)
            .unwrap_or_else(|| panic!("{id} not excluded: {excluded:?}"));
        assert_eq!(e["weather"], weather);
        assert!(
            e["reason"].as_str().unwrap().contains("holds no point"),
            "{e}"
        );
    }
    // Known answer: excluded means the fit is the fit without them.
    assert_eq!(with_empty["clear"], without["clear"], "clear coefficients");
    assert_eq!(
        with_empty["weathers"]["fog"]["vanishing_slope"],
        without["weathers"]["fog"]["vanishing_slope"]
    );
}
