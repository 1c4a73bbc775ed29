//! Edge cases on hand-made toy campaigns whose answers are known exactly: a
//! single ring of 360 one-degree directions looking at surfaces from 4 to
//! 100 m, alternately dark (reflectivity 5) and bright (50); in fog every
//! return closer than `0.3 × MOR` stays and every other one disappears.

// These tests build campaigns on disk: fit/clippy.toml keeps I/O out of
// the library's statistics, not out of its tests.
#![allow(clippy::disallowed_methods, clippy::disallowed_types)]

use std::path::Path;

use murk_campaign::Campaign;
use murk_fit::{FitError, FitParams, FittedTable};
use murk_types::WeatherClass;

const HEADER: &str = "recording,timestamp,PWD12_Weather Type,PWD12_Rain intensity (mm/h),PWD12_MOR (m),VS2K_MOR (m),WXT530_Rain intensity (mm/h)";

fn range_of(k: usize) -> f64 {
    4.0 + 96.0 * k as f64 / 359.0
}

/// `rows`: (id, class, MOR). Clear rows get MOR 3000.
fn write_campaign(dir: &Path, rows: &[(&str, &str, f64)]) {
    std::fs::write(
        dir.join("campaign.toml"),
        "name = \"toy\"\nrules = \"pdd-2022-2023\"\n[lidar]\nmodel = \"toy\"\n\
         elevation_deg = [0.0]\nazimuth_resolution_deg = 1.0\n",
    )
    .unwrap();
    let mut csv = format!("{HEADER}\n");
    std::fs::create_dir_all(dir.join("lidar")).unwrap();
    for (i, (id, class, mor)) in rows.iter().enumerate() {
        let (kind, mor) = if *class == "clear" {
            ("Clear", 3000.0)
        } else {
            ("Fog", *mor)
        };
        csv += &format!(
            "{id},2023-01-01T{:02}:00:00Z,{kind},0,{mor},{mor},0\n",
            i % 24
        );
        let edge = if *class == "clear" {
            f64::INFINITY
        } else {
            0.3 * mor
        };
        let mut pts = String::from("x,y,z,intensity,ring\n");
        for k in 0..360 {
            let r = range_of(k);
            if r < edge {
                let az = (k as f64 + 0.5).to_radians();
                let refl = if k % 2 == 0 { 5 } else { 50 };
                pts += &format!("{:.4},{:.4},0,{refl},0\n", r * az.cos(), r * az.sin());
            }
        }
        std::fs::write(dir.join("lidar").join(format!("{id}.csv")), pts).unwrap();
    }
    std::fs::write(dir.join("weather.csv"), csv).unwrap();
}

fn params() -> FitParams {
    FitParams::default()
        .min_points_per_bin(10)
        .bootstrap_replicates(50)
}

fn fit(dir: &Path, p: FitParams) -> Result<FittedTable, FitError> {
    let c = Campaign::open(dir).unwrap();
    p.check().unwrap().fit(&c)
}

fn clear3() -> Vec<(&'static str, &'static str, f64)> {
    vec![
        ("c1", "clear", 0.0),
        ("c2", "clear", 0.0),
        ("c3", "clear", 0.0),
    ]
}

#[test]
fn weather_without_recordings_is_absent_with_its_reason() {
    let d = tempfile::tempdir().unwrap();
    let mut rows = clear3();
    rows.extend([("f1", "fog", 60.0), ("f2", "fog", 150.0)]);
    write_campaign(d.path(), &rows);
    let t = fit(d.path(), params()).unwrap();
    let table = t.table();
    assert!(table.weathers.contains_key(&WeatherClass::Fog));
    for class in [WeatherClass::Rain, WeatherClass::Snow] {
        assert!(!table.weathers.contains_key(&class));
        let reason = &table.absent[&class];
        assert!(reason.contains("no recording"), "{reason}");
    }
    assert!(t.summary().contains("rain: absent"), "{}", t.summary());
    // Exact no-change rate: f1 keeps r < 18 m, f2 r < 45 m.
    let kept = (0..360).filter(|&k| range_of(k) < 18.0).count()
        + (0..360).filter(|&k| range_of(k) < 45.0).count();
    let fog = &table.weathers[&WeatherClass::Fog];
    assert_eq!(fog.no_change_rate, Some(kept as f64 / 720.0));
    assert_eq!(table.clear.as_ref().unwrap().no_change_rate, Some(1.0));
}

#[test]
fn mor_bin_with_too_few_points_is_left_out_and_said_so() {
    let d = tempfile::tempdir().unwrap();
    let mut rows = clear3();
    // MOR 30: 9 m edge keeps 19 returns (9-10 per band); MOR 200: 60 m.
    rows.extend([
        ("f1", "fog", 30.0),
        ("f2", "fog", 200.0),
        ("f3", "fog", 300.0),
    ]);
    write_campaign(d.path(), &rows);
    let t = fit(d.path(), params().min_points_per_bin(40)).unwrap();
    let fog = &t.table().weathers[&WeatherClass::Fog];
    let bins = &fog.vanishing_slope_q99[0].mor_bins;
    let b30 = bins.iter().find(|b| b.mor_m == 30.0).unwrap();
    assert!(!b30.used && !b30.censored, "{b30:?}");
    assert!(b30.reason.as_ref().unwrap().contains("too few"), "{b30:?}");
    let b200 = bins.iter().find(|b| b.mor_m == 200.0).unwrap();
    assert!(b200.used, "{b200:?}");
    assert!(b200.points >= 40);
    // The slope comes from the used bins only: with a hard edge at 0.3·MOR
    // the quantile of the survivors sits just below it.
    let s = fog.vanishing_slope_q99[0].slope.unwrap();
    assert!(s > 0.27 && s < 0.3, "{s}");
}

#[test]
fn all_censored_bins_give_null_slopes_with_reasons() {
    let d = tempfile::tempdir().unwrap();
    let mut rows = clear3();
    // 0.3 × 380 = 114 m: the edge lies beyond the 100 m scene, nothing
    // vanishes, every quantile is the scene's own.
    rows.extend([("f1", "fog", 380.0), ("f2", "fog", 390.0)]);
    write_campaign(d.path(), &rows);
    let t = fit(d.path(), params()).unwrap();
    let fog = &t.table().weathers[&WeatherClass::Fog];
    for band in &fog.vanishing_slope_q99 {
        assert!(band.slope.is_none());
        assert!(
            band.reason.as_ref().unwrap().contains("every MOR bin"),
            "{band:?}"
        );
        assert!(band.mor_bins.iter().all(|b| b.censored));
    }
    for band in &fog.vanishing_slope {
        assert!(band.slope.is_none());
        let r = band.reason.as_ref().unwrap();
        assert!(r.contains("censored"), "{r}");
    }
    assert_eq!(fog.no_change_rate, Some(1.0));
}

#[test]
fn campaign_without_clear_recordings_is_a_clear_error() {
    let d = tempfile::tempdir().unwrap();
    write_campaign(d.path(), &[("f1", "fog", 60.0), ("f2", "fog", 90.0)]);
    let e = fit(d.path(), params()).unwrap_err();
    assert!(matches!(e, FitError::NoClearReference { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(msg.contains("no clear reference"), "{msg}");
}

#[test]
fn ring_outside_the_lidar_names_the_file_and_the_point() {
    let d = tempfile::tempdir().unwrap();
    let mut rows = clear3();
    rows.push(("f1", "fog", 60.0));
    write_campaign(d.path(), &rows);
    let f = d.path().join("lidar/f1.csv");
    let mut text = std::fs::read_to_string(&f).unwrap();
    text += "1.0,1.0,0,5,3\n";
    std::fs::write(&f, text).unwrap();
    let n = (0..360).filter(|&k| range_of(k) < 18.0).count();
    let e = fit(d.path(), params()).unwrap_err().to_string();
    assert!(e.contains("f1.csv"), "{e}");
    assert!(e.contains(&format!("point {n}")), "{e}");
    assert!(e.contains("ring 3"), "{e}");
}

#[test]
fn bad_radar_value_names_the_file_and_line() {
    let d = tempfile::tempdir().unwrap();
    let mut rows = clear3();
    rows.push(("f1", "fog", 60.0));
    write_campaign(d.path(), &rows);
    std::fs::create_dir(d.path().join("radar")).unwrap();
    for id in ["c1", "c2", "c3", "f1"] {
        std::fs::write(
            d.path().join("radar").join(format!("{id}.csv")),
            "x,y,z,rcs,velocity\n10,0,0,5,0\n20,5,0,3,0\n",
        )
        .unwrap();
    }
    std::fs::write(
        d.path().join("radar/c2.csv"),
        "x,y,z,rcs,velocity\n10,0,0,5,0\n20,five,0,3,0\n",
    )
    .unwrap();
    let e = fit(d.path(), params()).unwrap_err().to_string();
    assert!(
        e.contains("c2.csv") && e.contains("line 3") && e.contains("five"),
        "{e}"
    );
}

#[test]
fn radar_of_identical_recordings_never_changes() {
    let d = tempfile::tempdir().unwrap();
    let mut rows = clear3();
    rows.push(("f1", "fog", 60.0));
    write_campaign(d.path(), &rows);
    std::fs::create_dir(d.path().join("radar")).unwrap();
    for id in ["c1", "c2", "c3", "f1"] {
        std::fs::write(
            d.path().join("radar").join(format!("{id}.csv")),
            "x,y,z,rcs,velocity\n10,0,0,5,0\n20,5,0,3,0\n30,-5,1,3,0\n",
        )
        .unwrap();
    }
    let t = fit(d.path(), params()).unwrap();
    let r = t.table().radar.as_ref().unwrap();
    assert_eq!(r.no_change_rate[&WeatherClass::Clear], 1.0);
    assert_eq!(r.no_change_rate[&WeatherClass::Fog], 1.0);
    assert!(r.absent[&WeatherClass::Rain].contains("no recording"));
}
