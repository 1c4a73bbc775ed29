//! Invariants of vanishing, checked on random clouds (proptest).

// Point clouds are columns (SoA): one index addresses several of them.
#![allow(clippy::needless_range_loop)]

mod common;

use common::*;
use murk_infer::{ApplyParams, Severity};
use murk_types::{IntensityScale, PointCloud, WeatherClass};
use proptest::prelude::*;

fn cloud_strategy() -> impl Strategy<Value = PointCloud> {
    prop::collection::vec(
        (
            -150f32..150.0,
            -150f32..150.0,
            -20f32..20.0,
            0f32..255.0,
            0u16..16,
        ),
        0..400,
    )
    .prop_map(|pts| {
        let mut c = PointCloud::with_capacity(pts.len());
        for (x, y, z, i, r) in pts {
            c.push(x, y, z, i, r);
        }
        c
    })
}

fn weather_strategy() -> impl Strategy<Value = WeatherClass> {
    prop_oneof![
        Just(WeatherClass::Fog),
        Just(WeatherClass::Rain),
        Just(WeatherClass::Snow)
    ]
}

fn applier(w: WeatherClass, mor: f64) -> murk_infer::Applier {
    ApplyParams::new(w, Severity::Mor(mor))
        .build(&seed_table())
        .unwrap()
}

/// Points of `out` as (bits of x, y, z, intensity, ring) tuples.
fn keys(c: &PointCloud) -> Vec<(u32, u32, u32, u32, u16)> {
    (0..c.len())
        .map(|i| {
            (
                c.x[i].to_bits(),
                c.y[i].to_bits(),
                c.z[i].to_bits(),
                c.intensity[i].to_bits(),
                c.ring[i],
            )
        })
        .collect()
}

/// True when `a` is a subsequence of `b`.
fn subsequence<T: PartialEq>(a: &[T], b: &[T]) -> bool {
    let mut it = b.iter();
    a.iter().all(|x| it.any(|y| y == x))
}

proptest! {
    #[test]
    fn lower_mor_never_keeps_a_point_a_higher_mor_drops(
        c in cloud_strategy(),
        w in weather_strategy(),
        m1 in 1.0f64..1999.0,
        m2 in 1.0f64..1999.0,
    ) {
        let (lo, hi) = if m1 < m2 { (m1, m2) } else { (m2, m1) };
        let mut k_lo = Vec::new();
        let mut k_hi = Vec::new();
        applier(w, lo).mask(&c, "p", &mut k_lo).unwrap();
        applier(w, hi).mask(&c, "p", &mut k_hi).unwrap();
        for i in 0..c.len() {
            prop_assert!(k_lo[i] <= k_hi[i], "point {} kept at MOR {} but not at {}", i, lo, hi);
        }
    }

    #[test]
    fn low_reflectivity_never_outlives_high_at_equal_range(
        r in 0.1f32..300.0,
        low in 0f32..10.0,
        high in 10f32..255.0,
        w in weather_strategy(),
        mor in 1.0f64..1999.0,
    ) {
        let mut c = PointCloud::with_capacity(2);
        c.push(r, 0.0, 0.0, low, 0);
        c.push(r, 0.0, 0.0, high, 0);
        let mut m = Vec::new();
        applier(w, mor).mask(&c, "p", &mut m).unwrap();
        prop_assert!(m[0] <= m[1]);
    }

    #[test]
    fn clear_weather_is_the_identity(
        c in cloud_strategy(),
        w in weather_strategy(),
        mor in 2000.0f64..1e6,
    ) {
        let a = ApplyParams::new(w, Severity::Mor(mor))
            .near_range(true)
            .range_noise_m(0.5)
            .attenuate_intensity(true)
            .build(&seed_table())
            .unwrap();
        let (out, s) = a.apply(&c, "p").unwrap();
        prop_assert_eq!(&out, &c);
        prop_assert!(s.identity);
    }

    #[test]
    fn vanishing_only_output_is_an_ordered_subset_of_the_input(
        mut c in cloud_strategy(),
        w in weather_strategy(),
        mor in 1.0f64..3000.0,
        kitti in any::<bool>(),
    ) {
        if kitti {
            c.to_scale(IntensityScale::KITTI);
        }
        let (out, s) = applier(w, mor).apply(&c, "p").unwrap();
        prop_assert!(subsequence(&keys(&out), &keys(&c)));
        prop_assert_eq!(s.points_out + s.vanished, s.points_in);
        prop_assert_eq!(s.bands.iter().map(|b| b.points_in).sum::<u64>(), s.points_in);
        prop_assert_eq!(s.bands.iter().map(|b| b.vanished).sum::<u64>(), s.vanished);
        prop_assert_eq!(out.intensity_scale, c.intensity_scale);
    }

    #[test]
    fn hard_decision_agrees_with_the_f64_definition(
        c in cloud_strategy(),
        w in weather_strategy(),
        mor in 1.0f64..1999.0,
    ) {
        let a = applier(w, mor);
        let mut m = Vec::new();
        a.mask(&c, "p", &mut m).unwrap();
        for i in 0..c.len() {
            let r = (c.x[i] as f64).hypot(c.y[i] as f64).hypot(c.z[i] as f64);
            let d = a.vanishing_distance_m(c.intensity[i] as f64);
            // The kernel compares in f32: only points within 1e-5 relative
            // of their threshold may differ.
            if (r - d).abs() > 1e-5 * d {
                prop_assert_eq!(m[i] == 1, r <= d, "point {} r {} d {}", i, r, d);
            }
        }
    }
}
