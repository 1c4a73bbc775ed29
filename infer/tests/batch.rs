//! Batch planning and running over real files in a temporary folder.

// Point clouds are columns (SoA): one index addresses several of them.
#![allow(clippy::needless_range_loop)]

mod common;

use std::path::{Path, PathBuf};

use common::*;
use murk_infer::batch::{plan, run};
use murk_infer::{ApplyParams, BatchOptions, InferError, Severity};
use murk_io::{ReadOptions, read_cloud, write_cloud};
use murk_types::{PointCloud, PointFormat, WeatherClass};

fn scan(n: usize, salt: u64) -> PointCloud {
    let mut c = synthetic_scan(n, salt);
    c.time = None;
    c
}

/// `root/a.pcd`, `root/sub/b.bin` (KITTI scale), `root/notes.txt`.
fn tree(root: &Path) -> (PointCloud, PointCloud) {
    std::fs::create_dir_all(root.join("sub")).unwrap();
    let a = scan(5_000, 1);
    write_cloud(&root.join("a.pcd"), &a, PointFormat::Pcd).unwrap();
    let mut b = scan(3_000, 2);
    b.to_scale(murk_types::IntensityScale::KITTI);
    write_cloud(&root.join("sub/b.bin"), &b, PointFormat::KittiBin).unwrap();
    std::fs::write(root.join("notes.txt"), "not a cloud").unwrap();
    (a, b)
}

fn fog(mor: f64) -> murk_infer::Applier {
    ApplyParams::new(WeatherClass::Fog, Severity::Mor(mor))
        .near_range(true)
        .range_noise_m(0.02)
        .seed(4)
        .build(&seed_table())
        .unwrap()
}

#[test]
fn folder_is_walked_names_kept_and_non_clouds_listed() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in");
    let out = dir.path().join("out");
    tree(&input);
    let p = plan(std::slice::from_ref(&input), &out, &BatchOptions::default()).unwrap();
    let keys: Vec<&str> = p.jobs.iter().map(|j| j.key.as_str()).collect();
    assert_eq!(keys, ["a.pcd", "sub/b.bin"]);
    assert_eq!(p.skipped.len(), 1);
    assert!(p.skipped[0].path.ends_with("notes.txt"));
    let report = run(&fog(60.0), &p, &BatchOptions::default(), &|_| {}).unwrap();
    assert!(out.join("a.pcd").is_file() && out.join("sub/b.bin").is_file());
    assert_eq!(report.files.len(), 2);
    let t = &report.totals;
    assert_eq!(t.points_in, 8_000);
    assert_eq!(
        t.points_out,
        t.points_in - t.vanished + t.ghost.as_ref().unwrap().added + t.ring.as_ref().unwrap().added
    );
    let json = report.to_json();
    assert!(
        json.contains("\"format\": \"murk-apply-summary/1\""),
        "{json}"
    );
    assert!(json.contains("notes.txt"));
}

#[test]
fn same_format_keeps_the_input_scale_and_kept_points_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in");
    let out = dir.path().join("out");
    let (_, b) = tree(&input);
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(60.0))
        .build(&seed_table())
        .unwrap();
    let p = plan(&[input.join("sub/b.bin")], &out, &BatchOptions::default()).unwrap();
    run(&a, &p, &BatchOptions::default(), &|_| {}).unwrap();
    let back = read_cloud(&out.join("b.bin"), &ReadOptions::default()).unwrap();
    let b_read = read_cloud(&input.join("sub/b.bin"), &ReadOptions::default()).unwrap();
    let (expected, _) = a.apply(&b_read, "b.bin").unwrap();
    assert_eq!(
        back.intensity, expected.intensity,
        "raw KITTI intensities kept"
    );
    assert!(back.len() < b.len());
}

#[test]
fn clear_weather_writes_the_input_bytes_back() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in");
    let out = dir.path().join("out");
    tree(&input);
    let p = plan(std::slice::from_ref(&input), &out, &BatchOptions::default()).unwrap();
    run(&fog(5000.0), &p, &BatchOptions::default(), &|_| {}).unwrap();
    for name in ["a.pcd", "sub/b.bin"] {
        assert_eq!(
            std::fs::read(input.join(name)).unwrap(),
            std::fs::read(out.join(name)).unwrap(),
            "{name}"
        );
    }
}

#[test]
fn output_bytes_do_not_depend_on_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in");
    tree(&input);
    let mut outputs = Vec::new();
    for threads in [1, 2] {
        let out = dir.path().join(format!("out{threads}"));
        let p = plan(std::slice::from_ref(&input), &out, &BatchOptions::default()).unwrap();
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| run(&fog(30.0), &p, &BatchOptions::default(), &|_| {}).unwrap());
        outputs.push(
            ["a.pcd", "sub/b.bin"]
                .map(|n| std::fs::read(out.join(n)).unwrap())
                .to_vec(),
        );
    }
    assert_eq!(outputs[0], outputs[1]);
}

/// A warning of the model (here: a MOR below the fitted range) is written
/// once, in `model.warnings`; the totals carry only what the scans raised
/// (they used to repeat the model's warnings in front of the scans').
#[test]
fn model_warnings_are_reported_once() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in");
    tree(&input);
    let a = fog(30.0);
    assert!(
        a.warnings()
            .iter()
            .any(|w| w.contains("outside the 50–200 m")),
        "{:?}",
        a.warnings()
    );
    let p = plan(
        std::slice::from_ref(&input),
        &dir.path().join("out"),
        &BatchOptions::default(),
    )
    .unwrap();
    let report = run(&a, &p, &BatchOptions::default(), &|_| {}).unwrap();
    assert_eq!(report.model.warnings, a.warnings());
    let scans: Vec<&String> = report
        .files
        .iter()
        .flat_map(|f| &f.summary.warnings)
        .collect();
    assert_eq!(report.totals.warnings.iter().collect::<Vec<_>>(), scans);
    let json = report.to_json();
    assert_eq!(json.matches("outside the 50–200 m").count(), 1, "{json}");
}

#[test]
fn format_change_renames_and_converts_intensity_scale() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in");
    let out = dir.path().join("out");
    let (_, b) = tree(&input);
    let opts = BatchOptions {
        format: Some(PointFormat::Pcd),
        ..BatchOptions::default()
    };
    let p = plan(&[input.join("sub/b.bin")], &out, &opts).unwrap();
    assert_eq!(p.jobs[0].key, "b.pcd");
    let a = fog(5000.0);
    run(&a, &p, &opts, &|_| {}).unwrap();
    let mut back = read_cloud(&out.join("b.pcd"), &ReadOptions::default()).unwrap();
    // The PCD records the KITTI scale it was written in: read back, the
    // reflectivities are the input's.
    assert_eq!(back.intensity_scale, murk_types::IntensityScale::KITTI);
    back.to_calibrated();
    let mut cal = b.clone();
    cal.to_calibrated();
    for (x, y) in back.intensity.iter().zip(&cal.intensity) {
        assert!((x - y).abs() < 1e-3, "{x} vs {y}");
    }
}

#[test]
fn output_folder_equal_to_input_folder_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    tree(dir.path());
    let e = plan(
        &[dir.path().to_path_buf()],
        dir.path(),
        &BatchOptions::default(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("output folder"), "{e}");
}

#[test]
fn output_overwriting_an_input_file_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    tree(dir.path());
    let e = plan(
        &[dir.path().join("a.pcd")],
        dir.path(),
        &BatchOptions::default(),
    )
    .unwrap_err();
    assert!(matches!(e, InferError::OutputIsInput { .. }), "{e}");
    assert!(e.to_string().contains("a.pcd"), "{e}");
}

#[test]
fn two_inputs_with_the_same_name_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (x, y) = (dir.path().join("x"), dir.path().join("y"));
    for d in [&x, &y] {
        std::fs::create_dir_all(d).unwrap();
        write_cloud(&d.join("s.pcd"), &scan(10, 1), PointFormat::Pcd).unwrap();
    }
    let e = plan(
        &[x.join("s.pcd"), y.join("s.pcd")],
        &dir.path().join("out"),
        &BatchOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("s.pcd") && e.contains("like"), "{e}");
}

#[test]
fn explicit_file_of_unknown_format_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    tree(dir.path());
    let e = plan(
        &[dir.path().join("notes.txt")],
        &dir.path().join("out"),
        &BatchOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("notes.txt") && e.contains("txt"), "{e}");
}

#[test]
fn missing_input_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let e = plan(
        &[PathBuf::from("/definitely/not/here.pcd")],
        &dir.path().join("out"),
        &BatchOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("/definitely/not/here.pcd"), "{e}");
}

#[test]
fn bad_file_error_names_the_file() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("broken.bin"), [0u8; 7]).unwrap();
    let p = plan(
        &[dir.path().join("broken.bin")],
        &dir.path().join("out"),
        &BatchOptions::default(),
    )
    .unwrap();
    let e = run(&fog(50.0), &p, &BatchOptions::default(), &|_| {})
        .unwrap_err()
        .to_string();
    assert!(e.contains("broken.bin"), "{e}");
    assert!(!dir.path().join("out/broken.bin").exists());
}

#[test]
fn output_folder_inside_the_input_folder_is_not_read_back() {
    let dir = tempfile::tempdir().unwrap();
    tree(dir.path());
    let out = dir.path().join("degraded");
    let p = plan(&[dir.path().to_path_buf()], &out, &BatchOptions::default()).unwrap();
    run(&fog(50.0), &p, &BatchOptions::default(), &|_| {}).unwrap();
    // A second run over the same folder ignores the outputs of the first.
    let p2 = plan(&[dir.path().to_path_buf()], &out, &BatchOptions::default()).unwrap();
    assert_eq!(p2.jobs.len(), 2);
    assert!(p2.skipped.iter().any(|s| s.reason == "the output folder"));
}

/// A CSV scan the way other tools write one: extra columns around murk's,
/// `54.0`-style numbers, CRLF line breaks.
fn foreign_csv(cloud: &PointCloud) -> String {
    let mut s = String::from("id,x,y,z,intensity,ring,label\r\n");
    for i in 0..cloud.len() {
        s.push_str(&format!(
            "{i},{:.6},{:.6},{:.6},{:.1},{},p{i}\r\n",
            cloud.x[i], cloud.y[i], cloud.z[i], cloud.intensity[i], cloud.ring[i]
        ));
    }
    s
}

#[test]
fn csv_to_csv_keeps_the_rows_the_model_keeps_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("scan.csv");
    // ~1.6 MB: several parse pieces.
    let text = foreign_csv(&scan(30_000, 5));
    std::fs::write(&input, &text).unwrap();
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(60.0))
        .build(&seed_table())
        .unwrap();
    let out = dir.path().join("out");
    let p = plan(std::slice::from_ref(&input), &out, &BatchOptions::default()).unwrap();
    let report = run(&a, &p, &BatchOptions::default(), &|_| {}).unwrap();
    // The model's own decision on the cloud as read.
    let cloud = read_cloud(&input, &ReadOptions::default()).unwrap();
    let mut mask = Vec::new();
    let kept = a.mask(&cloud, "scan.csv", &mut mask).unwrap();
    assert!(
        kept > 1_000 && (kept as usize) < cloud.len() - 1_000,
        "{kept}"
    );
    let mut want = String::from("id,x,y,z,intensity,ring,label\r\n");
    for (line, &m) in text.split_inclusive("\r\n").skip(1).zip(&mask) {
        if m == 1 {
            want.push_str(line);
        }
    }
    assert_eq!(std::fs::read_to_string(out.join("scan.csv")).unwrap(), want);
    let t = &report.totals;
    assert_eq!((t.points_in, t.points_out), (30_000, kept));
}

#[test]
fn csv_to_csv_with_near_range_and_noise_equals_the_general_path() {
    // A murk-written CSV (with time): the row-preserving path must give the
    // bytes the general path (read, apply, write) gives.
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("scan.csv");
    let cloud = synthetic_scan(20_000, 9);
    write_cloud(&input, &cloud, PointFormat::Csv).unwrap();
    let a = fog(40.0);
    let out = dir.path().join("out");
    let p = plan(std::slice::from_ref(&input), &out, &BatchOptions::default()).unwrap();
    let report = run(&a, &p, &BatchOptions::default(), &|_| {}).unwrap();
    let (general, summary) = a
        .apply(
            &read_cloud(&input, &ReadOptions::default()).unwrap(),
            "scan.csv",
        )
        .unwrap();
    let want = dir.path().join("general.csv");
    write_cloud(&want, &general, PointFormat::Csv).unwrap();
    assert_eq!(
        std::fs::read_to_string(out.join("scan.csv")).unwrap(),
        std::fs::read_to_string(&want).unwrap()
    );
    assert_eq!(report.files[0].summary, summary);
    let g = summary.ghost.as_ref().unwrap();
    assert!(g.replaced + g.added > 0, "{g:?}");
}

#[test]
fn csv_output_bytes_do_not_depend_on_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in");
    std::fs::create_dir_all(&input).unwrap();
    std::fs::write(input.join("a.csv"), foreign_csv(&scan(25_000, 3))).unwrap();
    write_cloud(
        &input.join("b.csv"),
        &synthetic_scan(25_000, 4),
        PointFormat::Csv,
    )
    .unwrap();
    let mut outputs = Vec::new();
    for threads in [1, 2] {
        let out = dir.path().join(format!("out{threads}"));
        let p = plan(std::slice::from_ref(&input), &out, &BatchOptions::default()).unwrap();
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| run(&fog(30.0), &p, &BatchOptions::default(), &|_| {}).unwrap());
        outputs.push(["a.csv", "b.csv"].map(|n| std::fs::read(out.join(n)).unwrap()));
    }
    assert!(outputs[0][0].len() > 10_000);
    assert_eq!(outputs[0], outputs[1]);
}

#[test]
fn csv_bad_row_error_names_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bad.csv");
    let mut text = foreign_csv(&scan(20_000, 6));
    text = text.replacen("\r\n12345,", "\r\n12345,oops", 1);
    std::fs::write(&input, &text).unwrap();
    let out = dir.path().join("out");
    let p = plan(std::slice::from_ref(&input), &out, &BatchOptions::default()).unwrap();
    let e = run(&fog(30.0), &p, &BatchOptions::default(), &|_| {}).unwrap_err();
    let msg = e.to_string();
    // Header on line 1: point 12345 is on line 12347.
    assert!(
        msg.contains("bad.csv") && msg.contains("line 12347") && msg.contains("column x"),
        "{msg}"
    );
    assert!(!out.join("bad.csv").exists());
}

#[test]
fn many_files_commit_once_each_before_progress_and_leave_no_temporary_files() {
    // More files than the staged-output bound, so workers wait on the
    // committing threads; one unreadable file among them.
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in");
    let out = dir.path().join("out");
    std::fs::create_dir_all(&input).unwrap();
    for i in 0..150u64 {
        let c = scan(200, 10 + i);
        let format = if i % 2 == 0 {
            PointFormat::Csv
        } else {
            PointFormat::KittiBin
        };
        let name = format!("{i:03}.{}", if i % 2 == 0 { "csv" } else { "bin" });
        write_cloud(&input.join(name), &c, format).unwrap();
    }
    std::fs::write(input.join("077.bin"), b"not a multiple of 16").unwrap();
    let p = plan(std::slice::from_ref(&input), &out, &BatchOptions::default()).unwrap();
    assert_eq!(p.jobs.len(), 150);
    let seen = std::sync::Mutex::new(Vec::new());
    let e = run(&fog(40.0), &p, &BatchOptions::default(), &|f| {
        assert!(
            f.output.is_file(),
            "{} reported before it exists",
            f.output.display()
        );
        seen.lock().unwrap().push(f.output.clone());
    })
    .unwrap_err();
    assert!(e.to_string().contains("077.bin"), "{e}");
    let mut seen = seen.into_inner().unwrap();
    seen.sort();
    let before = seen.len();
    seen.dedup();
    assert_eq!(seen.len(), before, "a file reported twice");
    assert_eq!(seen.len(), 149, "every good file written and reported once");
    let left: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".tmp"))
        .collect();
    assert!(left.is_empty(), "temporary files left: {left:?}");
    // The written files are the ones a single-file run gives.
    let j = &p.jobs[4];
    let single = dir.path().join("single");
    std::fs::create_dir_all(&single).unwrap();
    let mut one = j.clone();
    one.output = single.join("004.csv");
    murk_infer::batch::run_job(&fog(40.0), &one, &BatchOptions::default()).unwrap();
    assert_eq!(
        std::fs::read(&one.output).unwrap(),
        std::fs::read(out.join("004.csv")).unwrap()
    );
}
