//! Real scans from `../shared/data/real/` beside the checkout (KITTI `.bin`,
//! nuScenes `.pcd.bin`), when present; each test prints a line and passes
//! when the file is absent (fails with `MURK_REQUIRE_REAL_DATA=1`).

// Point clouds are columns (SoA): one index addresses several of them.
#![allow(clippy::needless_range_loop)]

mod common;

use common::*;
use murk_infer::{ApplyParams, Severity};
use murk_io::{ReadOptions, read_cloud};
use murk_types::{PointCloud, WeatherClass};

fn load(name: &str) -> Option<PointCloud> {
    let p = murk_types::real_data::real_data_file(env!("CARGO_MANIFEST_DIR"), name)?;
    Some(read_cloud(&p, &ReadOptions::default()).unwrap())
}

/// Kept fraction at each MOR equals the count of points inside their
/// band's vanishing distance (computed here in f64 from calibrated
/// reflectivity), and decreases with MOR.
fn check(c: &PointCloud, name: &str) {
    assert!(c.len() > 10_000, "{name}: {} points", c.len());
    let mut cal = c.clone();
    cal.to_calibrated();
    let mut last = f64::INFINITY;
    for mor in [1500.0, 400.0, 200.0, 100.0, 60.0, 30.0, 10.0] {
        for w in [WeatherClass::Fog, WeatherClass::Rain] {
            let a = ApplyParams::new(w, Severity::Mor(mor))
                .build(&seed_table())
                .unwrap();
            let (out, s) = a.apply(c, name).unwrap();
            let (low, high) = match w {
                WeatherClass::Fog => (FOG_LOW, FOG_HIGH),
                _ => (RAIN_LOW, RAIN_HIGH),
            };
            let mut inside = 0u64;
            let mut ambiguous = 0u64;
            for i in 0..c.len() {
                let r = (c.x[i] as f64).hypot(c.y[i] as f64).hypot(c.z[i] as f64);
                let d = if cal.intensity[i] < 10.0 { low } else { high } * mor;
                if (r - d).abs() < 1e-5 * d || (cal.intensity[i] - 10.0).abs() < 1e-4 {
                    ambiguous += 1;
                }
                inside += (r <= d) as u64;
            }
            assert!(
                (out.len() as u64).abs_diff(inside) <= ambiguous,
                "{name} {w} MOR {mor}: kept {} vs {inside} inside ({ambiguous} on an edge)",
                out.len()
            );
            if w == WeatherClass::Fog {
                let f = s.kept_fraction();
                assert!(f <= last, "{name}: kept fraction rises at MOR {mor}");
                last = f;
                println!("{name}: fog MOR {mor:>6} m keeps {:.4}", f);
            }
        }
    }
    assert!(last < 0.5, "{name}: MOR 10 m still keeps {last}");
}

#[test]
fn kitti_scan_kept_fraction_matches_the_thresholds() {
    if let Some(c) = load("kitti-000008.bin") {
        check(&c, "kitti-000008.bin");
    }
}

#[test]
fn nuscenes_scan_kept_fraction_matches_the_thresholds() {
    if let Some(c) = load("nuscenes-lidar-top.pcd.bin") {
        check(&c, "nuscenes-lidar-top.pcd.bin");
    }
}

#[test]
fn nuscenes_scan_with_every_option_stays_consistent() {
    let Some(c) = load("nuscenes-lidar-top.pcd.bin") else {
        return;
    };
    // nuScenes has 32 rings: without a sensor description the ring
    // elevations are measured on the scan.
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(40.0))
        .near_range(true)
        .range_noise_m(0.02)
        .attenuate_intensity(true)
        .seed(1)
        .build(&seed_table())
        .unwrap();
    let (out, s) = a.apply(&c, "nuscenes").unwrap();
    let g = s.ghost.unwrap();
    let r = s.ring.unwrap();
    assert_eq!(
        s.points_out,
        s.points_in - s.vanished + g.added + r.added,
        "{g:?} {r:?}"
    );
    assert_eq!(out.len() as u64, s.points_out);
    assert!(out.first_non_finite().is_none());
}
