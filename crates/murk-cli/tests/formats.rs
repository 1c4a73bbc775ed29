//! File formats end to end through the binary: the intensity scale survives
//! `convert` then `apply`, layouts murk must be told about have flags, a
//! `.bin` murk cannot tell apart is refused once, with the flag to use.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

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

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `../shared/data/real/NAME` next to the checkout, or `None` (printed).
fn real(name: &str) -> Option<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .find(|d| d.join("Cargo.lock").exists())
        .unwrap_or(Path::new(env!("CARGO_MANIFEST_DIR")));
    let p = root.join("../shared/data/real").join(name);
    if p.exists() {
        Some(p)
    } else {
        println!("skipping: {} is not present", p.display());
        None
    }
}

/// The seed's fog (Table 4).
const TABLE: &str = r#"{
  "format": "weather-noise-coefficients/1", "campaign": "seed",
  "lidar": { "model": "VLP16", "range_scale": 1.0 },
  "weathers": {
    "fog": { "recordings": 28, "quantile": 0.99, "no_change_rate": 0.38,
      "vanishing_slope": [
        { "reflectivity_min": 0,  "reflectivity_max": 10,   "slope": 0.30286536, "points": 1 },
        { "reflectivity_min": 10, "reflectivity_max": null, "slope": 0.34634364, "points": 1 } ],
      "ghost": null, "ring": null } },
  "provenance": { "tool": "test", "inputs_sha256": "", "parameters": {} }
}"#;

/// The `points in …` and `reflectivity […)` lines of an apply summary.
fn counts(stdout: &str) -> Vec<String> {
    stdout
        .lines()
        .filter(|l| l.contains("points in") || l.contains("reflectivity"))
        .map(str::to_string)
        .collect()
}

/// `convert BIN --format pcd`, then `apply` on the PCD and on the `.bin`:
/// the same counts, and the summary names the scale of each.
fn convert_then_apply(bin: &Path, dir: &Path) {
    let table = dir.join("t.json");
    std::fs::write(&table, TABLE).unwrap();
    let conv = dir.join("conv");
    let out = ok(&["convert", s(bin), "--out", s(&conv), "--format", "pcd"]);
    assert!(out.contains("intensity kitti"), "{out}");
    let stem = bin.file_stem().unwrap().to_string_lossy().to_string();
    let pcd = conv.join(format!("{stem}.pcd"));
    let apply = |input: &Path, out: &Path| {
        ok(&[
            "apply",
            "--coefficients",
            s(&table),
            "--weather",
            "fog",
            "--mor",
            "40",
            s(input),
            "--out",
            s(out),
        ])
    };
    let from_bin = apply(bin, &dir.join("o1"));
    let from_pcd = apply(&pcd, &dir.join("o2"));
    println!("{from_bin}\n{from_pcd}");
    assert_eq!(counts(&from_bin), counts(&from_pcd));
    assert!(
        from_bin.contains("intensity read as kitti (assumed (format default))"),
        "{from_bin}"
    );
    assert!(
        from_pcd.contains("intensity read as kitti (recorded in the file)"),
        "{from_pcd}"
    );
}

#[test]
fn convert_to_pcd_then_apply_counts_like_apply_on_the_bin() {
    let dir = tempfile::tempdir().unwrap();
    let el = LidarSpec::vlp16().elevation_deg;
    let mut c = PointCloud::with_capacity(3001);
    for i in 0..3001 {
        let ring = i % 16;
        let e = el[ring].to_radians();
        let a = i as f64 * 0.37;
        let r = 1.0 + (i % 40) as f64 * 0.9;
        c.push(
            (r * e.cos() * a.cos()) as f32,
            (r * e.cos() * a.sin()) as f32,
            (r * e.sin()) as f32,
            (i % 256) as f32,
            ring as u16,
        );
    }
    c.to_scale(IntensityScale::KITTI);
    let bin = dir.path().join("k.bin");
    murk_io::write_cloud(&bin, &c, PointFormat::KittiBin).unwrap();
    convert_then_apply(&bin, dir.path());
}

#[test]
fn convert_to_pcd_then_apply_counts_like_apply_on_the_real_kitti_scan() {
    let Some(bin) = real("kitti-000008.bin") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    convert_then_apply(&bin, dir.path());
}

#[test]
fn header_less_csv_and_five_float_bin_have_flags() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("r.csv");
    std::fs::write(&csv, "1.5,0,0.1,7,3\n-2,4,0.5,9,12\n").unwrap();
    let o = murk(&[
        "convert",
        s(&csv),
        "--out",
        s(&dir.path().join("o")),
        "--format",
        "pcd",
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("r.csv") && err.contains("--columns"), "{err}");
    let out = ok(&[
        "convert",
        s(&csv),
        "--out",
        s(&dir.path().join("o")),
        "--format",
        "csv",
        "--columns",
        "x,y,z,intensity,ring",
    ]);
    assert!(out.contains("2 points"), "{out}");
    let back = std::fs::read_to_string(dir.path().join("o/r.csv")).unwrap();
    assert_eq!(back, "x,y,z,intensity,ring\n1.5,0,0.1,7,3\n-2,4,0.5,9,12\n");

    // 8 Seeing-Through-Fog records: 160 bytes fit 16- and 20-byte records.
    let mut v = Vec::new();
    for i in 0..8 {
        for f in [10.5 + i as f32, 0.25, -1.0, 40.0, (i % 4) as f32] {
            v.extend_from_slice(&f.to_le_bytes());
        }
    }
    let bin = dir.path().join("stf.bin");
    std::fs::write(&bin, &v).unwrap();
    let o = murk(&[
        "convert",
        s(&bin),
        "--out",
        s(&dir.path().join("p")),
        "--format",
        "csv",
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("stf.bin") && err.contains("160 bytes") && err.contains("--bin-layout"),
        "{err}"
    );
    let out = ok(&[
        "convert",
        s(&bin),
        "--out",
        s(&dir.path().join("p")),
        "--format",
        "csv",
        "--bin-layout",
        "xyzir",
    ]);
    assert!(out.contains("8 points"), "{out}");
    let back = std::fs::read_to_string(dir.path().join("p/stf.csv")).unwrap();
    assert!(back.lines().nth(2).unwrap().ends_with(",40,1"), "{back}");
}

#[test]
fn a_pcap_error_is_printed_once() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.pcap");
    std::fs::write(&p, b"\xd4\xc3\xb2\xa1\x02\x00\x04\x00").unwrap();
    let o = murk(&[
        "convert",
        s(&p),
        "--out",
        s(&dir.path().join("o")),
        "--format",
        "pcd",
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.matches("bad.pcap").count(), 1, "{err}");
}
