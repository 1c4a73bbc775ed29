//! `murk convert` end to end: a generated scan through every writable format
//! and back, folder walking, pcap frames, and refusing to overwrite inputs.

use std::path::Path;
use std::process::{Command, Output};

use murk_io::{ReadOptions, read_cloud, write_cloud};
use murk_types::{IntensityScale, LidarSpec, PointCloud, PointFormat};

fn murk(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_murk"))
        .args(args)
        .output()
        .expect("run murk")
}

fn ok(args: &[&str]) -> String {
    let out = murk(args);
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "murk {args:?} failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

fn fails(args: &[&str]) -> String {
    let out = murk(args);
    assert!(!out.status.success(), "murk {args:?} should fail");
    String::from_utf8_lossy(&out.stderr).to_string()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A scan whose points lie on the VLP-16 rings (so KITTI, which stores no
/// ring, gives the same rings back from elevation), with times.
fn scan(n: usize) -> PointCloud {
    let el = LidarSpec::vlp16().elevation_deg;
    let mut c = PointCloud::with_capacity(n);
    for i in 0..n {
        let ring = (i % 16) as u16;
        let e = el[ring as usize].to_radians();
        let a = i as f64 * 0.37;
        let r = 3.0 + (i % 50) as f64;
        c.push_timed(
            (r * e.cos() * a.cos()) as f32,
            (r * e.cos() * a.sin()) as f32,
            (r * e.sin()) as f32,
            (i % 256) as f32,
            ring,
            i as f32 * 1e-4,
        );
    }
    c
}

fn same_points(a: &PointCloud, b: &PointCloud, what: &str) {
    assert_eq!(a.x, b.x, "{what}: x");
    assert_eq!(a.y, b.y, "{what}: y");
    assert_eq!(a.z, b.z, "{what}: z");
    assert_eq!(a.intensity, b.intensity, "{what}: intensity");
    assert_eq!(a.ring, b.ring, "{what}: ring");
}

#[test]
fn a_scan_survives_every_writable_format_and_back() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("scan.pcd");
    let cloud = scan(3_000);
    write_cloud(&src, &cloud, PointFormat::Pcd).unwrap();

    let cases: [(&str, &[&str], &str); 7] = [
        ("pcd", &["--pcd-data", "ascii"], "pcd"),
        ("pcd", &["--pcd-data", "binary"], "pcd"),
        ("pcd", &["--pcd-data", "binary_compressed"], "pcd"),
        ("bin", &[], "bin"),
        ("nuscenes", &[], "pcd.bin"),
        ("csv", &[], "csv"),
        ("parquet", &[], "parquet"),
    ];
    for (k, (format, extra, ext)) in cases.iter().enumerate() {
        let out = dir.path().join(format!("out-{k}"));
        let mut args = vec!["convert", s(&src), "--out", s(&out), "--format", format];
        args.extend(extra.iter());
        let stdout = ok(&args);
        assert!(stdout.contains("3000 points"), "{stdout}");
        let path = out.join(format!("scan.{ext}"));
        let mut back = read_cloud(&path, &ReadOptions::default()).unwrap();
        if *format == "bin" {
            // A KITTI `.bin` holds 0–1 intensity: read back, the
            // reflectivities are the input's (to rounding), not the bits.
            assert_eq!(back.intensity_scale, IntensityScale::KITTI);
            back.to_calibrated();
            for (a, b) in back.intensity.iter().zip(&cloud.intensity) {
                assert!((a - b).abs() < 1e-3, "bin: intensity {a} vs {b}");
            }
            back.intensity.clone_from(&cloud.intensity);
        }
        same_points(&back, &cloud, &format!("{format} {extra:?}"));
        let keeps_time = !matches!(*format, "bin" | "nuscenes");
        assert_eq!(back.time.is_some(), keeps_time, "{format}: time");
        if keeps_time {
            assert_eq!(back.time, cloud.time, "{format}: time");
        }
    }
}

#[test]
fn folders_are_walked_recursively_and_keep_their_layout() {
    let dir = tempfile::tempdir().unwrap();
    let inp = dir.path().join("in");
    std::fs::create_dir_all(inp.join("b")).unwrap();
    write_cloud(&inp.join("a.csv"), &scan(5), PointFormat::Csv).unwrap();
    write_cloud(&inp.join("b/a.csv"), &scan(7), PointFormat::Csv).unwrap();
    write_cloud(
        &inp.join("b/run.v2.pcd.bin"),
        &scan(9),
        PointFormat::NuscenesBin,
    )
    .unwrap();
    std::fs::write(inp.join("notes.txt"), "not a cloud").unwrap();
    let out = dir.path().join("out");
    let stdout = ok(&["convert", s(&inp), "--out", s(&out), "--format", "pcd"]);
    assert!(
        stdout.contains("converted 3 inputs into 3 pcd files (21 points; intensity calibrated)"),
        "{stdout}"
    );
    let n = |p: &str| {
        read_cloud(&out.join(p), &ReadOptions::default())
            .unwrap()
            .len()
    };
    assert_eq!((n("a.pcd"), n("b/a.pcd"), n("b/run.v2.pcd")), (5, 7, 9));
    assert!(!out.join("notes.pcd").exists());
}

#[test]
fn intensity_scale_converts_kitti_to_calibrated() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("000000.bin");
    let mut c = scan(4);
    c.time = None;
    c.intensity = vec![0.0, 0.2, 0.5, 1.0];
    write_cloud(&src, &c, PointFormat::KittiBin).unwrap();
    let out = dir.path().join("out");
    ok(&[
        "convert",
        s(&src),
        "--out",
        s(&out),
        "--format",
        "csv",
        "--intensity-scale",
        "calibrated",
    ]);
    let back = read_cloud(&out.join("000000.csv"), &ReadOptions::default()).unwrap();
    let want: Vec<f32> = c.intensity.iter().map(|v| v * 255.0).collect();
    assert_eq!(back.intensity, want);
    assert_eq!(back.intensity_scale, IntensityScale::Calibrated);
}

#[test]
fn converting_onto_an_input_is_refused_and_leaves_it_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("scan.pcd");
    write_cloud(&src, &scan(10), PointFormat::Pcd).unwrap();
    let before = std::fs::read(&src).unwrap();
    let err = fails(&[
        "convert",
        s(&src),
        "--out",
        s(dir.path()),
        "--format",
        "pcd",
    ]);
    assert!(err.contains("refusing to overwrite an input"), "{err}");
    assert_eq!(std::fs::read(&src).unwrap(), before);
}

#[test]
fn two_inputs_landing_on_one_output_are_refused_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("scan.csv");
    let b = dir.path().join("scan.parquet");
    write_cloud(&a, &scan(3), PointFormat::Csv).unwrap();
    write_cloud(&b, &scan(3), PointFormat::Parquet).unwrap();
    let out = dir.path().join("out");
    let err = fails(&["convert", s(&a), s(&b), "--out", s(&out), "--format", "pcd"]);
    assert!(err.contains("would both be written to"), "{err}");
    assert!(!out.exists());
}

#[test]
fn pcap_is_not_an_output_format() {
    let err = fails(&["convert", "x.pcd", "--out", "o", "--format", "pcap"]);
    assert!(err.contains("not a format murk writes"), "{err}");
}

#[test]
fn a_bad_input_stops_with_its_name() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("bad.bin");
    std::fs::write(&src, [0u8; 17]).unwrap();
    let err = fails(&[
        "convert",
        s(&src),
        "--out",
        s(dir.path()),
        "--format",
        "csv",
    ]);
    assert!(
        err.contains("bad.bin") && err.contains("1 trailing bytes"),
        "{err}"
    );
}

/// The real VLP-16 capture, when present.
fn real_capture() -> Option<std::path::PathBuf> {
    murk_types::real_data::real_data_file(
        env!("CARGO_MANIFEST_DIR"),
        "vlp16-test-90deg-1-50-frames.pcap",
    )
}

#[test]
fn a_pcap_becomes_one_file_per_frame() {
    let Some(pcap) = real_capture() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let names_in = |d: &Path| {
        let mut names: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        names.sort();
        names
    };
    // By default the partial first and last revolutions are left out,
    // named, and the frames keep their capture numbers.
    let out = dir.path().join("frames");
    let stdout = ok(&["convert", s(&pcap), "--out", s(&out), "--format", "pcd"]);
    let frames_dir = out.join("vlp16-test-90deg-1-50-frames");
    let names = names_in(&frames_dir);
    let want: Vec<String> = (2..=51).map(|k| format!("frame-{k:06}.pcd")).collect();
    assert_eq!(names, want);
    assert!(stdout.contains("(50 frames)"), "{stdout}");
    assert!(
        stdout.contains("left out 2 partial revolutions: frame-000001.pcd")
            && stdout.contains("frame-000052.pcd"),
        "{stdout}"
    );

    // --keep-partial: every revolution, holding every point of the capture.
    let out = dir.path().join("all");
    let stdout = ok(&[
        "convert",
        s(&pcap),
        "--out",
        s(&out),
        "--format",
        "pcd",
        "--keep-partial",
    ]);
    let frames_dir = out.join("vlp16-test-90deg-1-50-frames");
    let names = names_in(&frames_dir);
    let want: Vec<String> = (1..=52).map(|k| format!("frame-{k:06}.pcd")).collect();
    assert_eq!(names, want);
    let all = read_cloud(&pcap, &ReadOptions::default()).unwrap();
    let total: usize = names
        .iter()
        .map(|n| {
            read_cloud(&frames_dir.join(n), &ReadOptions::default())
                .unwrap()
                .len()
        })
        .sum();
    assert_eq!(total, all.len());
    assert!(
        stdout.contains(&format!(
            "split into one file per frame) into {} pcd files",
            names.len()
        )) && stdout.contains("(52 frames)")
            && stdout.contains("2 of the 52 frames written are partial"),
        "{stdout}"
    );
}

#[test]
fn pcap_return_selects_a_return_the_capture_recorded() {
    let Some(pcap) = real_capture() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    // The real capture is single-return, strongest: asking for its
    // strongest returns writes what it recorded, asking for the last ones
    // stops, naming the file and the packet.
    let as_recorded = dir.path().join("recorded");
    ok(&[
        "convert",
        s(&pcap),
        "--out",
        s(&as_recorded),
        "--format",
        "bin",
    ]);
    let strongest = dir.path().join("strongest");
    ok(&[
        "convert",
        s(&pcap),
        "--out",
        s(&strongest),
        "--format",
        "bin",
        "--pcap-return",
        "strongest",
    ]);
    let stem = "vlp16-test-90deg-1-50-frames";
    for k in [2, 30, 51] {
        let name = format!("frame-{k:06}.bin");
        let a = std::fs::read(as_recorded.join(stem).join(&name)).unwrap();
        let b = std::fs::read(strongest.join(stem).join(&name)).unwrap();
        assert!(a == b && !a.is_empty(), "{name}");
    }
    let err = fails(&[
        "convert",
        s(&pcap),
        "--out",
        s(&dir.path().join("last")),
        "--format",
        "bin",
        "--pcap-return",
        "last",
    ]);
    assert!(
        err.contains(stem) && err.contains("asked for last returns") && err.contains("packet"),
        "{err}"
    );
    let err = fails(&["convert", s(&pcap), "--out", "x", "--pcap-return", "first"]);
    assert!(err.contains("strongest or last"), "{err}");
}
