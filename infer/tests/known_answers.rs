//! Known answers on hand-built clouds: every point's fate is computed by
//! hand from the seed's Table 4 slopes.

// Point clouds are columns (SoA): one index addresses several of them.
#![allow(clippy::needless_range_loop)]

mod common;

use common::*;
use murk_infer::{ApplyParams, DEFAULT_CLEAR_MOR_M, InferError, Severity, SlopeSource};
use murk_types::{IntensityScale, PointCloud, WeatherClass};

fn fog(mor: f64) -> murk_infer::Applier {
    ApplyParams::new(WeatherClass::Fog, Severity::Mor(mor))
        .build(&seed_table())
        .unwrap()
}

/// The published Python model filters with an expression whose operator
/// precedence makes the low-reflectivity slope never apply: every return
/// gets the high slope. A return of reflectivity < 10 whose range lies
/// between `slope_low·MOR` and `slope_high·MOR` must vanish; a return of
/// reflectivity ≥ 10 at the same range must stay.
#[test]
fn operator_precedence_bug_low_reflectivity_slope_is_applied() {
    for (w, low, high) in [
        (WeatherClass::Fog, FOG_LOW, FOG_HIGH),
        (WeatherClass::Rain, RAIN_LOW, RAIN_HIGH),
    ] {
        let mor = 80.0;
        let a = ApplyParams::new(w, Severity::Mor(mor))
            .build(&seed_table())
            .unwrap();
        let r = (low + high) / 2.0 * mor; // between the two vanishing distances
        let mut c = PointCloud::with_capacity(2);
        c.push(r as f32, 0.0, 0.0, 5.0, 0); // low reflectivity
        c.push(r as f32, 0.0, 0.0, 50.0, 0); // high reflectivity
        let (out, s) = a.apply(&c, "precedence").unwrap();
        assert_eq!(out.intensity, vec![50.0], "{w}: only the high return stays");
        assert_eq!(s.bands[0].vanished, 1, "{w}");
        assert_eq!(s.bands[1].vanished, 0, "{w}");
    }
}

#[test]
fn every_point_fate_matches_the_hand_computation() {
    let mor = 60.0;
    let a = fog(mor);
    let d_low = FOG_LOW * mor; // 18.1719 m
    let d_high = FOG_HIGH * mor; // 20.7806 m
    assert!((a.vanishing_distance_m(5.0) - d_low).abs() < 1e-12);
    assert!((a.vanishing_distance_m(10.0) - d_high).abs() < 1e-12);
    let mut c = PointCloud::with_capacity(0);
    let mut expected = Vec::new();
    let mut k = 0u16;
    for r in [1.0, 10.0, 18.0, 18.4, 20.5, 21.0, 50.0] {
        for refl in [0.0f32, 9.5, 10.0, 100.0, 255.0] {
            // Spread over directions: the fate depends on range only.
            let az = (k as f64 * 0.7).sin() * 3.0;
            let el = (k as f64 * 0.3).cos() * 0.2;
            let (x, y, z) = (
                r * el.cos() * az.cos(),
                r * el.cos() * az.sin(),
                r * el.sin(),
            );
            c.push(x as f32, y as f32, z as f32, refl, k);
            let d = if refl < 10.0 { d_low } else { d_high };
            if r <= d {
                expected.push(k);
            }
            k += 1;
        }
    }
    let (out, s) = a.apply(&c, "grid").unwrap();
    assert_eq!(out.ring, expected, "kept rings in input order");
    assert_eq!(s.points_in, 35);
    assert_eq!(s.points_out, expected.len() as u64);
    // Low band (0, 9.5): kept at 1, 10, 18 m → 6 of 14. High band: kept at
    // 1, 10, 18, 18.4, 20.5 m → 15 of 21.
    assert_eq!((s.bands[0].points_in, s.bands[0].vanished), (14, 8));
    assert_eq!((s.bands[1].points_in, s.bands[1].vanished), (21, 6));
}

#[test]
fn kept_points_are_bit_identical_and_keep_every_column() {
    let c = synthetic_scan(50_000, 3);
    let (out, s) = fog(60.0).apply(&c, "s").unwrap();
    assert!(s.vanished > 0 && s.points_out > 0);
    let time = out.time.as_ref().unwrap();
    let mut j = 0;
    for i in 0..c.len() {
        if j < out.len() && c.time.as_ref().unwrap()[i] == time[j] {
            assert_eq!(
                (c.x[i], c.y[i], c.z[i], c.intensity[i], c.ring[i]),
                (out.x[j], out.y[j], out.z[j], out.intensity[j], out.ring[j])
            );
            j += 1;
        }
    }
    assert_eq!(
        j,
        out.len(),
        "every output point is an input point, in order"
    );
}

#[test]
fn band_edge_is_inclusive_in_every_intensity_scale() {
    // Reflectivity exactly 10 is in the ≥ 10 band; just below is not. The
    // same in calibrated, KITTI (0–1) and a negative-gain scale.
    let mor = 60.0;
    let r = ((FOG_LOW + FOG_HIGH) / 2.0 * mor) as f32;
    for scale in [
        IntensityScale::Calibrated,
        IntensityScale::KITTI,
        IntensityScale::linear(-2.0, 300.0).unwrap(),
    ] {
        let mut c = PointCloud::with_capacity(3);
        for cal in [10.0f32, 9.99, 200.0] {
            c.push(r, 0.0, 0.0, scale.from_calibrated(cal), 0);
        }
        c.intensity_scale = scale;
        let (out, _) = fog(mor).apply(&c, "edge").unwrap();
        assert_eq!(
            out.intensity,
            vec![scale.from_calibrated(10.0), scale.from_calibrated(200.0)],
            "{scale}"
        );
        assert_eq!(
            out.intensity_scale, scale,
            "written back in the input's scale"
        );
    }
}

#[test]
fn kitti_and_vlp16_scans_get_the_same_band_semantics() {
    let mor = 100.0;
    let mut vlp = synthetic_scan(20_000, 9);
    vlp.time = None;
    let mut kitti = vlp.clone();
    kitti.to_scale(IntensityScale::KITTI);
    let (a, sa) = fog(mor).apply(&vlp, "v").unwrap();
    let (b, sb) = fog(mor).apply(&kitti, "k").unwrap();
    assert_eq!(a.x, b.x);
    assert_eq!(sa.bands, sb.bands);
}

#[test]
fn range_scale_multiplies_the_vanishing_distance() {
    let mor = 50.0;
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(mor))
        .range_scale(0.9)
        .build(&seed_table())
        .unwrap();
    let d = FOG_HIGH * mor * 0.9; // 15.585 m
    let mut c = PointCloud::with_capacity(2);
    c.push((d - 0.01) as f32, 0.0, 0.0, 50.0, 0);
    c.push((d + 0.01) as f32, 0.0, 0.0, 50.0, 0);
    let (out, _) = a.apply(&c, "k").unwrap();
    assert_eq!(out.len(), 1);
    assert!((out.x[0] as f64 - (d - 0.01)).abs() < 1e-5);
}

#[test]
fn quantile_slopes_are_used_when_asked() {
    let mor = 100.0;
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(mor))
        .slope_source(SlopeSource::Quantile)
        .build(&seed_table())
        .unwrap();
    assert!((a.vanishing_distance_m(50.0) - FOG_HIGH * 0.9 * mor).abs() < 1e-9);
}

#[test]
fn snow_has_one_slope_for_every_reflectivity() {
    let a = ApplyParams::new(WeatherClass::Snow, Severity::Mor(100.0))
        .build(&seed_table())
        .unwrap();
    assert_eq!(a.bands().len(), 1);
    assert!((a.vanishing_distance_m(0.0) - SNOW * 100.0).abs() < 1e-9);
    assert!((a.vanishing_distance_m(250.0) - SNOW * 100.0).abs() < 1e-9);
}

#[test]
fn clear_mor_is_the_identity_even_with_every_option_on() {
    let c = synthetic_scan(40_000, 5);
    for mor in [2000.0, 5000.0] {
        let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(mor))
            .near_range(true)
            .range_noise_m(0.1)
            .attenuate_intensity(true)
            .soft_edge(true)
            .build(&seed_table())
            .unwrap();
        assert!(a.is_identity());
        let (out, s) = a.apply(&c, "clear").unwrap();
        assert_eq!(out, c);
        assert!(s.identity);
        assert_eq!((s.points_in, s.points_out, s.vanished), (40_000, 40_000, 0));
        assert_eq!(s.bands.iter().map(|b| b.points_in).sum::<u64>(), 40_000);
    }
    // Just below the threshold it is not.
    let a = fog(1999.0);
    assert!(!a.is_identity());
    // The threshold is a parameter.
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(500.0))
        .clear_mor_threshold_m(400.0)
        .build(&seed_table())
        .unwrap();
    assert!(a.is_identity());
    assert_eq!(a.describe().clear_mor_threshold_m, 400.0);
}

/// The table records no clear threshold, so without the parameter it is
/// [`DEFAULT_CLEAR_MOR_M`] whatever the table holds: even a table fitted on
/// fog recordings up to 3000 m applies its slopes at 2500 m only when told.
#[test]
fn clear_threshold_is_the_default_unless_given() {
    let mut t = seed_table();
    let fog = t.weathers.get_mut(&WeatherClass::Fog).unwrap();
    fog.mor_max_m = Some(3000.0);
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(2500.0))
        .build(&t)
        .unwrap();
    assert_eq!(a.describe().clear_mor_threshold_m, DEFAULT_CLEAR_MOR_M);
    assert!(a.is_identity(), "2500 m ≥ the 2000 m default");
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(2500.0))
        .clear_mor_threshold_m(4000.0)
        .build(&t)
        .unwrap();
    assert!(!a.is_identity());
    assert!((a.vanishing_distance_m(50.0) - FOG_HIGH * 2500.0).abs() < 1e-9);
}

#[test]
fn rain_rate_uses_the_table_conversion() {
    let a = ApplyParams::new(WeatherClass::Rain, Severity::RainRate(50.0))
        .build(&seed_table())
        .unwrap();
    let mor = -0.8308 * 50.0 + 159.16; // 117.62 m
    assert!((a.mor_m() - mor).abs() < 1e-9);
    assert!((a.vanishing_distance_m(5.0) - RAIN_LOW * mor).abs() < 1e-9);
    assert!((a.vanishing_distance_m(50.0) - RAIN_HIGH * mor).abs() < 1e-9);
}

#[test]
fn rain_rate_above_the_validity_is_an_error_naming_the_range() {
    let e = ApplyParams::new(WeatherClass::Rain, Severity::RainRate(250.0))
        .build(&seed_table())
        .unwrap_err();
    assert!(matches!(e, InferError::RainRateOutOfRange { .. }), "{e}");
    let m = e.to_string();
    assert!(m.contains("250") && m.contains("[1, 100]"), "{m}");
}

#[test]
fn rain_rate_below_the_validity_is_an_error() {
    let e = ApplyParams::new(WeatherClass::Rain, Severity::RainRate(0.5))
        .build(&seed_table())
        .unwrap_err()
        .to_string();
    assert!(e.contains("0.5") && e.contains("[1, 100]"), "{e}");
}

#[test]
fn rain_rate_clamp_is_explicit_and_warned() {
    let a = ApplyParams::new(WeatherClass::Rain, Severity::RainRate(250.0))
        .clamp_rain_rate(true)
        .build(&seed_table())
        .unwrap();
    assert!((a.mor_m() - (-0.8308 * 100.0 + 159.16)).abs() < 1e-9);
    assert!(
        a.warnings().iter().any(|w| w.contains("clamped to 100")),
        "{:?}",
        a.warnings()
    );
    let d = a.describe();
    assert_eq!(d.rain_rate_requested_mm_h, Some(250.0));
    assert_eq!(d.rain_rate_used_mm_h, Some(100.0));
}

#[test]
fn rain_rate_where_mor_reaches_zero_cannot_be_clamped() {
    let mut t = seed_table();
    let conv = t
        .weathers
        .get_mut(&WeatherClass::Rain)
        .unwrap()
        .mor_from_rain_rate
        .as_mut()
        .unwrap();
    conv.rain_rate_min = None;
    conv.rain_rate_max = None;
    // 159.16 / 0.8308 = 191.57 mm/h gives MOR 0: everything would vanish.
    let e = ApplyParams::new(WeatherClass::Rain, Severity::RainRate(195.0))
        .clamp_rain_rate(true)
        .build(&t)
        .unwrap_err()
        .to_string();
    assert!(e.contains("191.5") && e.contains("MOR is 0"), "{e}");
    // Inside it is fine.
    assert!(
        ApplyParams::new(WeatherClass::Rain, Severity::RainRate(150.0))
            .build(&t)
            .is_ok()
    );
}

#[test]
fn rain_rate_zero_is_no_rain() {
    let a = ApplyParams::new(WeatherClass::Rain, Severity::RainRate(0.0))
        .build(&seed_table())
        .unwrap();
    assert!(a.is_identity());
}

#[test]
fn rain_rate_for_fog_is_a_conflict() {
    let e = ApplyParams::new(WeatherClass::Fog, Severity::RainRate(10.0))
        .build(&seed_table())
        .unwrap_err();
    assert!(matches!(e, InferError::Conflict(_)), "{e}");
}

#[test]
fn rain_rate_without_conversion_is_an_error() {
    let mut t = seed_table();
    let rain = t.weathers.get_mut(&WeatherClass::Rain).unwrap();
    rain.mor_from_rain_rate = None;
    rain.mor_from_rain_rate_reason = Some("no recording with both sensors".into());
    let e = ApplyParams::new(WeatherClass::Rain, Severity::RainRate(10.0))
        .build(&t)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("weathers.rain.mor_from_rain_rate") && e.contains("no recording with both"),
        "{e}"
    );
}

#[test]
fn zero_mor_is_refused() {
    let e = ApplyParams::new(WeatherClass::Fog, Severity::Mor(0.0))
        .build(&seed_table())
        .unwrap_err()
        .to_string();
    assert!(e.contains("mor_m") && e.contains("> 0"), "{e}");
}

#[test]
fn nan_mor_is_refused() {
    assert!(
        ApplyParams::new(WeatherClass::Fog, Severity::Mor(f64::NAN))
            .build(&seed_table())
            .is_err()
    );
}

#[test]
fn negative_range_noise_is_refused() {
    let e = ApplyParams::new(WeatherClass::Fog, Severity::Mor(50.0))
        .range_noise_m(-0.1)
        .build(&seed_table())
        .unwrap_err()
        .to_string();
    assert!(e.contains("range_noise_m"), "{e}");
}

#[test]
fn zero_range_scale_is_refused() {
    let e = ApplyParams::new(WeatherClass::Fog, Severity::Mor(50.0))
        .range_scale(0.0)
        .build(&seed_table())
        .unwrap_err()
        .to_string();
    assert!(e.contains("range_scale"), "{e}");
}

#[test]
fn absent_weather_names_the_reason_and_what_exists() {
    let mut t = seed_table();
    t.weathers.remove(&WeatherClass::Snow);
    t.absent.insert(
        WeatherClass::Snow,
        "no snow recording survived review".into(),
    );
    let e = ApplyParams::new(WeatherClass::Snow, Severity::Mor(50.0))
        .build(&t)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("weathers.snow") && e.contains("survived review") && e.contains("fog, rain"),
        "{e}"
    );
}

#[test]
fn clear_weather_is_not_a_model() {
    let e = ApplyParams::new(WeatherClass::Clear, Severity::Mor(50.0))
        .build(&seed_table())
        .unwrap_err();
    assert!(matches!(e, InferError::Conflict(_)), "{e}");
}

#[test]
fn null_slope_band_is_named() {
    let mut t = seed_table();
    t.weathers
        .get_mut(&WeatherClass::Fog)
        .unwrap()
        .vanishing_slope[0] = band(0.0, Some(10.0), None);
    let e = ApplyParams::new(WeatherClass::Fog, Severity::Mor(50.0))
        .build(&t)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("weathers.fog.vanishing_slope[0].slope") && e.contains("too few points"),
        "{e}"
    );
}

#[test]
fn soft_edge_without_survival_fit_is_named() {
    let mut t = seed_table();
    t.weathers.get_mut(&WeatherClass::Fog).unwrap().survival = None;
    let e = ApplyParams::new(WeatherClass::Fog, Severity::Mor(50.0))
        .soft_edge(true)
        .build(&t)
        .unwrap_err()
        .to_string();
    assert!(e.contains("weathers.fog.survival"), "{e}");
}

#[test]
fn soft_edge_with_quantile_slopes_is_a_conflict() {
    let e = ApplyParams::new(WeatherClass::Fog, Severity::Mor(50.0))
        .soft_edge(true)
        .slope_source(SlopeSource::Quantile)
        .build(&seed_table())
        .unwrap_err();
    assert!(matches!(e, InferError::Conflict(_)), "{e}");
}

#[test]
fn near_range_without_laws_is_named() {
    let mut t = seed_table();
    let fog = t.weathers.get_mut(&WeatherClass::Fog).unwrap();
    fog.ghost = None;
    fog.ghost_reason = Some("no ghost returns".into());
    fog.ring = None;
    fog.ring_reason = Some("no ring returns".into());
    let e = ApplyParams::new(WeatherClass::Fog, Severity::Mor(50.0))
        .near_range(true)
        .build(&t)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no ghost returns") && e.contains("no ring returns"),
        "{e}"
    );
}

#[test]
fn extrapolated_mor_is_warned() {
    let a = fog(20.0);
    assert!(
        a.warnings().iter().any(|w| w.contains("extrapolates")),
        "{:?}",
        a.warnings()
    );
    assert!(fog(100.0).warnings().is_empty());
}

#[test]
fn ragged_cloud_is_refused_with_the_scan_name() {
    let mut c = synthetic_scan(10, 1);
    c.ring.pop();
    let e = fog(50.0).apply(&c, "bad.pcd").unwrap_err().to_string();
    assert!(e.contains("bad.pcd") && e.contains("ring"), "{e}");
}

#[test]
fn attenuation_is_two_way_koschmieder() {
    let mor = 50.0;
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(mor))
        .attenuate_intensity(true)
        .build(&seed_table())
        .unwrap();
    let mut c = PointCloud::with_capacity(2);
    c.push(0.0, 10.0, 0.0, 80.0, 0);
    c.push(5.0, 0.0, 0.0, 0.5, 0);
    c.intensity_scale = IntensityScale::KITTI;
    c.intensity[0] = 80.0 / 255.0;
    let (out, s) = a.apply(&c, "att").unwrap();
    let alpha = 20f64.ln() / mor;
    let e0 = 80.0 * (-2.0 * alpha * 10.0).exp() / 255.0; // ≈ 0.1335
    let e1 = 0.5 * (-2.0 * alpha * 5.0).exp();
    assert!(
        (out.intensity[0] as f64 - e0).abs() < 1e-6,
        "{}",
        out.intensity[0]
    );
    assert!((out.intensity[1] as f64 - e1).abs() < 1e-6);
    assert_eq!(out.x, c.x, "attenuation does not move points");
    assert_eq!(s.attenuated_points, 2);
}

#[test]
fn range_noise_keeps_directions_and_has_the_asked_sigma() {
    let sigma = 0.05;
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(1000.0))
        .range_noise_m(sigma)
        .seed(11)
        .build(&seed_table())
        .unwrap();
    let mut c = PointCloud::with_capacity(0);
    let n = 100_000;
    for i in 0..n {
        let az = i as f64 * 0.001;
        c.push(
            (10.0 * az.cos()) as f32,
            (10.0 * az.sin()) as f32,
            1.0,
            50.0,
            0,
        );
    }
    let (out, s) = a.apply(&c, "noise").unwrap();
    assert_eq!(s.range_noise_points, n as u64);
    let r0 = (101f64).sqrt();
    let (mut sum, mut sum2) = (0.0, 0.0);
    for i in 0..n {
        let (x, y, z) = (out.x[i] as f64, out.y[i] as f64, out.z[i] as f64);
        let r = (x * x + y * y + z * z).sqrt();
        // Same direction: z/r unchanged.
        assert!((z / r - 1.0 / r0).abs() < 1e-5);
        let e = r - r0;
        sum += e;
        sum2 += e * e;
    }
    let mean = sum / n as f64;
    let sd = (sum2 / n as f64 - mean * mean).sqrt();
    // Standard error of the mean 1.6e-4, of the sd 1.1e-4.
    assert!(mean.abs() < 1e-3, "{mean}");
    assert!((sd - sigma).abs() < 1e-3, "{sd}");
}

#[test]
fn soft_edge_keeps_with_the_fitted_probability() {
    // Probit edge, dropout 0.1, residual 0.05: at the band's vanishing
    // distance P = 0.05 + 0.85 · 0.5 = 0.475; far inside P = 0.9; far beyond 0.05.
    let mor = 100.0;
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(mor))
        .soft_edge(true)
        .seed(3)
        .build(&seed_table())
        .unwrap();
    let d = FOG_HIGH * mor;
    let n = 60_000;
    for (r, p) in [(d, 0.475), (1.0, 0.9), (5.0 * d, 0.05)] {
        let mut c = PointCloud::with_capacity(n);
        for _ in 0..n {
            c.push(r as f32, 0.0, 0.0, 50.0, 0);
        }
        let (_, s) = a.apply(&c, "soft").unwrap();
        let kept = s.kept_fraction();
        // Binomial standard error ≤ 0.0021; allow 4 of them.
        assert!((kept - p).abs() < 0.009, "r {r}: kept {kept}, expected {p}");
    }
}
