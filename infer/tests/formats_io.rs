//! The I/O side of `murk apply`: the intensity scale survives a format
//! conversion, captures are applied per revolution, replaced points do not
//! keep another return's cells, points below the first band are reported
//! as such, and every reader refuses what `convert` refuses.

// Point clouds are columns (SoA): one index addresses several of them.
#![allow(clippy::needless_range_loop)]

mod common;

use std::path::{Path, PathBuf};

use common::*;
use murk_infer::batch::{plan, run};
use murk_infer::{ApplyParams, BatchOptions, BatchReport, Severity};
use murk_io::{ReadOptions, read_cloud, write_cloud};
use murk_types::{
    CoefficientTable, IntensityScale, LidarSpec, PointCloud, PointFormat, WeatherClass,
};

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

fn fog(mor: f64) -> murk_infer::Applier {
    ApplyParams::new(WeatherClass::Fog, Severity::Mor(mor))
        .build(&seed_table())
        .unwrap()
}

fn apply(
    inputs: &[PathBuf],
    out: &Path,
    a: &murk_infer::Applier,
    opts: &BatchOptions,
) -> BatchReport {
    let p = plan(inputs, out, opts).unwrap();
    run(a, &p, opts, &|_| {}).unwrap()
}

/// Calibrated reflectivity of a cloud read back from `path`.
fn calibrated(path: &Path) -> PointCloud {
    let mut c = read_cloud(path, &ReadOptions::default()).unwrap();
    c.to_calibrated();
    c
}

/// Applying to a KITTI `.bin` and to its conversion to PCD (what `murk
/// convert --format pcd` writes: values as read, the scale in the header)
/// keeps the same points and reports the same bands.
fn bin_then_pcd_equals_bin(bin: &Path, dir: &Path) {
    let pcd = dir.join("conv.pcd");
    let cloud = read_cloud(bin, &ReadOptions::default()).unwrap();
    assert_eq!(cloud.intensity_scale, IntensityScale::KITTI);
    let mut conv = cloud.clone();
    conv.to_scale(murk_io::portable_scale(
        PointFormat::Pcd,
        cloud.intensity_scale,
    ));
    write_cloud(&pcd, &conv, PointFormat::Pcd).unwrap();

    let a = fog(40.0);
    let opts = BatchOptions {
        format: Some(PointFormat::Pcd),
        ..BatchOptions::default()
    };
    let r_bin = apply(&[bin.to_path_buf()], &dir.join("o1"), &a, &opts);
    let r_pcd = apply(std::slice::from_ref(&pcd), &dir.join("o2"), &a, &opts);
    let (t1, t2) = (&r_bin.totals, &r_pcd.totals);
    println!(
        "{}: {} in, kept {:.2} % (bin) / {:.2} % (pcd); band 0: {} / {}",
        bin.display(),
        t1.points_in,
        100.0 * t1.kept_fraction(),
        100.0 * t2.kept_fraction(),
        t1.bands[0].points_in,
        t2.bands[0].points_in
    );
    assert_eq!(t1.points_out, t2.points_out);
    assert_eq!(t1.bands, t2.bands);
    assert_eq!(t1.below_bands, t2.below_bands);
    assert_eq!(r_pcd.files[0].intensity_scale, "kitti");
    assert_eq!(
        r_pcd.files[0].intensity_scale_source,
        "recorded in the file"
    );
    assert_eq!(
        r_bin.files[0].intensity_scale_source,
        "assumed (format default)"
    );
    let stem = bin.file_stem().unwrap().to_string_lossy().to_string();
    let o1 = calibrated(&dir.join("o1").join(format!("{stem}.pcd")));
    let o2 = calibrated(&dir.join("o2/conv.pcd"));
    assert_eq!(o1.x, o2.x);
    assert_eq!(o1.intensity, o2.intensity);
}

#[test]
fn bin_to_pcd_to_apply_keeps_the_points_of_bin_to_apply_on_a_known_cloud() {
    let dir = tempfile::tempdir().unwrap();
    // Reflectivities 0–255 in KITTI's 0–1, ranges 0.5–120 m: at MOR 40 the
    // two bands vanish beyond 12.1 and 13.9 m, so both bands keep and lose
    // points, and a lost scale would move every point to band [0, 10).
    let mut c = synthetic_scan(4_001, 3);
    c.time = None;
    c.to_scale(IntensityScale::KITTI);
    let bin = dir.path().join("k.bin");
    write_cloud(&bin, &c, PointFormat::KittiBin).unwrap();
    bin_then_pcd_equals_bin(&bin, dir.path());
}

#[test]
fn bin_to_pcd_to_apply_keeps_the_points_of_bin_to_apply_on_the_real_kitti_scan() {
    let Some(bin) = real("kitti-000008.bin") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    bin_then_pcd_equals_bin(&bin, dir.path());
}

#[test]
fn other_formats_get_calibrated_intensity_and_say_which_scale_was_read() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = synthetic_scan(2_001, 5);
    c.time = None;
    c.to_scale(IntensityScale::KITTI);
    let bin = dir.path().join("k.bin");
    write_cloud(&bin, &c, PointFormat::KittiBin).unwrap();
    let opts = BatchOptions {
        format: Some(PointFormat::Csv),
        ..BatchOptions::default()
    };
    let r = apply(&[bin], &dir.path().join("o"), &fog(5000.0), &opts);
    assert!(r.model.identity);
    let back = read_cloud(&dir.path().join("o/k.csv"), &ReadOptions::default()).unwrap();
    let mut cal = c.clone();
    cal.to_calibrated();
    for (a, b) in back.intensity.iter().zip(&cal.intensity) {
        assert!((a - b).abs() < 1e-3, "{a} vs {b}");
    }
    // A declared scale is reported as declared.
    let mut cal_csv = cal.clone();
    cal_csv.intensity_scale = IntensityScale::Calibrated;
    let csv = dir.path().join("s.csv");
    write_cloud(&csv, &cal_csv, PointFormat::Csv).unwrap();
    let opts = BatchOptions {
        read: ReadOptions {
            intensity_scale: Some(IntensityScale::SIX_BIT),
            ..ReadOptions::default()
        },
        ..BatchOptions::default()
    };
    let r = apply(&[csv], &dir.path().join("o2"), &fog(60.0), &opts);
    assert_eq!(r.files[0].intensity_scale, "six-bit");
    assert_eq!(r.files[0].intensity_scale_source, "declared");
}

/// A table whose only bands are [10, 50) and [50, ∞).
fn table_from_10() -> CoefficientTable {
    let mut t = seed_table();
    let w = t.weathers.get_mut(&WeatherClass::Fog).unwrap();
    w.vanishing_slope = vec![
        band(10.0, Some(50.0), Some(0.3)),
        band(50.0, None, Some(0.4)),
    ];
    w.vanishing_slope_q99 = w.vanishing_slope.clone();
    t
}

#[test]
fn points_below_the_first_band_are_reported_below_it() {
    // 30 points at reflectivity 5 (below 10), 20 at 20, 10 at 60; half of
    // each group at 5 m (kept), half at 50 m (beyond 0.3 × 100 = 30 m and
    // 0.4 × 100 = 40 m: vanished).
    let mut c = PointCloud::with_capacity(60);
    for (refl, n) in [(5.0, 30), (20.0, 20), (60.0, 10)] {
        for i in 0..n {
            let r = if i % 2 == 0 { 5.0 } else { 50.0 };
            c.push(r, 0.0, 0.0, refl, 0);
        }
    }
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(100.0))
        .build(&table_from_10())
        .unwrap();
    let (_, s) = a.apply(&c, "below").unwrap();
    assert_eq!(s.below_bands, 30);
    assert_eq!(s.below_bands_vanished, 15);
    assert_eq!(s.bands[0].points_in, 20, "band [10, 50) holds only its own");
    assert_eq!(s.bands[0].vanished, 10);
    assert_eq!(s.bands[1].points_in, 10);
    assert_eq!(s.vanished, 15 + 10 + 5);
    let total: u64 = s.bands.iter().map(|b| b.points_in).sum::<u64>() + s.below_bands;
    assert_eq!(total, s.points_in);
}

/// A cylinder wall at `radius` seen by every VLP-16 ring on a 0.2° grid,
/// as CSV rows with a `label` column (`car`).
fn labelled_wall(radius: f64) -> String {
    let spec = LidarSpec::vlp16();
    let mut s = String::from("x,y,z,intensity,ring,label\n");
    for bin in (0..1800).step_by(3) {
        let az = (bin as f64 * 0.2).to_radians();
        for (ring, el) in spec.elevation_deg.iter().enumerate() {
            let el = el.to_radians();
            let r = radius / el.cos();
            s.push_str(&format!(
                "{},{},{},60,{ring},car\n",
                (r * el.cos() * az.cos()) as f32,
                (r * el.cos() * az.sin()) as f32,
                (r * el.sin()) as f32,
            ));
        }
    }
    s
}

#[test]
fn new_near_range_points_get_empty_extra_cells() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("wall.csv");
    let text = labelled_wall(12.0);
    std::fs::write(&input, &text).unwrap();
    // Far half of the sky is empty (every third azimuth bin only), so some
    // soft targets are added on empty rays and others replace wall returns.
    // The sensor fires every 0.2° (what the scan alone would read as a
    // 0.6° step).
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(100.0))
        .near_range(true)
        .azimuth_resolution_deg(0.2)
        .near_range_count_scale(3.0)
        .seed(11)
        .build(&seed_table())
        .unwrap();
    let r = apply(
        &[input],
        &dir.path().join("o"),
        &a,
        &BatchOptions::default(),
    );
    let t = &r.totals;
    let (g, ring) = (t.ghost.clone().unwrap(), t.ring.clone().unwrap());
    let new = g.replaced + g.added + ring.replaced + ring.added;
    assert!(g.replaced > 5 && g.added > 5, "{g:?}");
    let originals: std::collections::HashSet<&str> = text.lines().skip(1).collect();
    let out = std::fs::read_to_string(dir.path().join("o/wall.csv")).unwrap();
    let (mut kept, mut fresh) = (0u64, 0u64);
    for row in out.lines().skip(1) {
        if originals.contains(row) {
            kept += 1;
        } else {
            fresh += 1;
            let label = row.rsplit(',').next().unwrap();
            assert_eq!(label, "", "a new point carries another row's label: {row}");
            // Its ring cell is the ring of its ray.
            let cells: Vec<&str> = row.split(',').collect();
            assert_eq!(cells.len(), 6, "{row}");
            assert!(cells[4].parse::<u16>().unwrap() < 16, "{row}");
        }
    }
    assert_eq!(fresh, new, "every new point, and only those, is unlabelled");
    assert_eq!(kept + fresh, t.points_out);
}

#[test]
fn a_ring_murk_cannot_hold_is_refused_by_apply_as_by_convert() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("r.csv");
    std::fs::write(&input, "x,y,z,intensity,ring\n1,0,0,5,3\n2,0,0,5,70000\n").unwrap();
    let opts = BatchOptions::default();
    let p = plan(std::slice::from_ref(&input), &dir.path().join("o"), &opts).unwrap();
    let e = run(&fog(60.0), &p, &opts, &|_| {}).unwrap_err().to_string();
    assert!(
        e.contains("r.csv") && e.contains("point 1") && e.contains("70000"),
        "{e}"
    );
}

/// A capture of `packets` VLP-16 data packets from 90°: a partial first
/// revolution, full ones, a partial last one.
fn capture(dir: &Path, packets: usize) -> PathBuf {
    let sweep = murk_velodyne::synth::Sweep {
        packets,
        start_azimuth_deg: 90.0,
        ..Default::default()
    };
    let p = dir.join("cap.pcap");
    std::fs::write(&p, sweep.to_pcap()).unwrap();
    p
}

#[test]
fn a_capture_is_applied_per_revolution_without_its_partial_ends() {
    let dir = tempfile::tempdir().unwrap();
    // 600 rpm: ~75 packets per revolution; 250 packets from 90° give a
    // partial first, two full and a partial last revolution.
    let cap = capture(dir.path(), 250);
    let frames = murk_io::read_frames_noted(&cap, &ReadOptions::default()).unwrap();
    assert_eq!(frames.partial, vec![true, false, false, true]);
    let a = fog(40.0);
    let opts = BatchOptions {
        format: Some(PointFormat::Pcd),
        ..BatchOptions::default()
    };
    let r = apply(std::slice::from_ref(&cap), &dir.path().join("o"), &a, &opts);
    let outs: Vec<String> = r
        .files
        .iter()
        .map(|f| f.output.file_name().unwrap().to_string_lossy().to_string())
        .collect();
    assert_eq!(outs, ["frame-000002.pcd", "frame-000003.pcd"]);
    for (f, k) in r.files.iter().zip([1, 2]) {
        assert_eq!(f.summary.points_in as usize, frames.clouds[k].len());
        assert!(f.output.parent().unwrap().ends_with("cap"));
        // Each revolution on its own: the same as applying to that frame.
        let (want, _) = a
            .apply(&frames.clouds[k], &format!("cap/frame-{:06}.pcd", k + 1))
            .unwrap();
        let got = read_cloud(&f.output, &ReadOptions::default()).unwrap();
        assert_eq!(got.x, want.x);
    }
    let w = r.totals.warnings.join("\n");
    assert!(
        w.contains("left out 2 partial revolutions") && w.contains("frame-000001.pcd"),
        "{w}"
    );

    let keep = BatchOptions {
        keep_partial: true,
        ..opts
    };
    let r = apply(&[cap], &dir.path().join("o2"), &a, &keep);
    assert_eq!(r.files.len(), 4);
    let partial: Vec<bool> = r.files.iter().map(|f| f.partial).collect();
    assert_eq!(partial, vec![true, false, false, true]);
}

#[test]
fn the_real_capture_is_applied_to_its_50_full_revolutions() {
    let Some(cap) = real("vlp16-test-90deg-1-50-frames.pcap") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let opts = BatchOptions {
        format: Some(PointFormat::Pcd),
        ..BatchOptions::default()
    };
    let r = apply(&[cap], &dir.path().join("o"), &fog(60.0), &opts);
    println!(
        "real capture: {} revolutions written, {} points in, {:.2} % kept",
        r.files.len(),
        r.totals.points_in,
        100.0 * r.totals.kept_fraction()
    );
    assert_eq!(r.files.len(), 50);
    assert!(r.files.iter().all(|f| !f.partial));
}
