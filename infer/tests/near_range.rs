//! Near-range returns (seed 004 §4.2 step 3) and seeded determinism.

// Point clouds are columns (SoA): one index addresses several of them.
#![allow(clippy::needless_range_loop)]

mod common;

use common::*;
use murk_infer::{ApplyParams, Severity};
use murk_types::{CountLaw, IntensityScale, LidarSpec, PointCloud, WeatherClass};

/// A cylinder wall at `radius` metres seen by every VLP-16 ring on a 0.2°
/// grid (one revolution, every ray filled).
fn wall(radius: f64) -> PointCloud {
    wall_fired_at(radius, |bin| bin as f64 * 0.2)
}

/// The same wall with firing `bin` at `azimuth_deg(bin)`.
fn wall_fired_at(radius: f64, azimuth_deg: impl Fn(usize) -> f64) -> PointCloud {
    wall_of(radius, 1800, azimuth_deg)
}

/// The wall from a unit firing `firings` times a turn.
fn wall_of(radius: f64, firings: usize, azimuth_deg: impl Fn(usize) -> f64) -> PointCloud {
    let spec = LidarSpec::vlp16();
    let mut c = PointCloud::with_capacity(16 * firings);
    for bin in 0..firings {
        let az = azimuth_deg(bin).to_radians();
        for (ring, el) in spec.elevation_deg.iter().enumerate() {
            let el = el.to_radians();
            let r = radius / el.cos();
            c.push(
                (r * el.cos() * az.cos()) as f32,
                (r * el.cos() * az.sin()) as f32,
                (r * el.sin()) as f32,
                60.0,
                ring as u16,
            );
        }
    }
    c
}

fn near(mor: f64, seed: u64) -> murk_infer::Applier {
    ApplyParams::new(WeatherClass::Fog, Severity::Mor(mor))
        .near_range(true)
        .seed(seed)
        .build(&seed_table())
        .unwrap()
}

#[test]
fn closer_soft_targets_replace_the_return_of_their_ray() {
    // Wall at 12 m, inside the vanishing distance at MOR 100 (34.6 m):
    // nothing vanishes, every ghost (3–10 m) and ring (0.5–3 m) return is
    // closer than the wall, so each replaces one wall return.
    let c = wall(12.0);
    let (out, s) = near(100.0, 1).apply(&c, "wall").unwrap();
    let g = s.ghost.clone().unwrap();
    let r = s.ring.clone().unwrap();
    assert_eq!(s.vanished, 0);
    assert!(g.drawn > 10 && r.drawn > 0, "{g:?} {r:?}");
    assert_eq!(g.added + g.unplaced + r.added + r.unplaced, 0);
    // Two soft targets on the same wall return: the later closer one wins
    // and the earlier is counted occluded, so replaced + occluded = drawn.
    assert_eq!(g.replaced + g.occluded, g.drawn);
    assert_eq!(r.replaced + r.occluded, r.drawn);
    assert_eq!(out.len(), c.len(), "replacement keeps the point count");
    assert_eq!(s.points_out, c.len() as u64);
    let mut changed = 0;
    for i in 0..c.len() {
        if out.x[i] != c.x[i] || out.y[i] != c.y[i] || out.z[i] != c.z[i] {
            changed += 1;
            // Same beam: direction kept, ring kept.
            let ri = c.range(i) as f64;
            let ro = out.range(i) as f64;
            assert!(ro < ri && ro > 0.5 - 1e-4 && ro < 10.0 + 1e-4, "{ro}");
            assert!((out.x[i] as f64 / ro - c.x[i] as f64 / ri).abs() < 1e-5);
            assert!((out.z[i] as f64 / ro - c.z[i] as f64 / ri).abs() < 1e-5);
            assert_eq!(out.ring[i], c.ring[i]);
            assert!(out.intensity[i] >= 0.0);
        }
    }
    assert_eq!(changed as u64, g.replaced + r.replaced);
}

/// A wall fired half a step off the grid, with jitter (±0.02 of a step):
/// on the grid's own wedges half the firings would cross into the next
/// wedge, leaving wedges empty beside wedges holding two, and a soft
/// target on an empty wedge would be added in front of a wall that is
/// there. The wedges follow the scan's firings (their phase measured per
/// ring), so every soft target finds its wall return.
#[test]
fn soft_targets_find_their_ray_when_the_firings_are_off_the_grid() {
    let c = wall_fired_at(12.0, |bin| {
        let jitter = if (bin * 7919) % 3 == 0 { 0.02 } else { -0.02 };
        (bin as f64 + 0.5 + jitter) * 0.2
    });
    let (out, s) = near(100.0, 4).apply(&c, "off-grid wall").unwrap();
    let (g, r) = (s.ghost.unwrap(), s.ring.unwrap());
    assert!(g.drawn > 10, "{g:?}");
    assert_eq!(g.added + r.added, 0, "{g:?} {r:?}");
    assert_eq!(g.replaced + g.occluded, g.drawn);
    assert_eq!(out.len(), c.len());
}

/// The seed table with its fog's near returns read as replacing lost
/// returns (its occlusion test said so: a strongest-return sensor).
fn replacing_table() -> murk_types::CoefficientTable {
    let mut t = seed_table();
    t.weathers.get_mut(&WeatherClass::Fog).unwrap().occlusion = Some(
        serde_json::from_value(serde_json::json!({
            "recordings": 20, "odds_ratio": 40.0, "p_value": 1e-12, "alpha": 0.01, "replaced": true,
        }))
        .unwrap(),
    );
    t
}

/// The returns of `full` on the left half of the revolution (y ≥ 0).
fn left_half(full: &PointCloud) -> PointCloud {
    let mut c = PointCloud::with_capacity(full.len());
    for i in 0..full.len() {
        if full.y[i] >= 0.0 {
            c.push(
                full.x[i],
                full.y[i],
                full.z[i],
                full.intensity[i],
                full.ring[i],
            );
        }
    }
    c
}

/// A table whose fog near returns *replace* lost returns (its occlusion
/// test said so: a strongest-return sensor): a kept return's echo beats
/// the weather's, so a soft target on a ray that still has a return is
/// occluded whatever its range, and only rays whose return vanished (or
/// that had none) get one. The same scan and seed without the flag: every
/// soft target closer than the wall replaces a wall return.
#[test]
fn replacing_near_returns_only_fill_rays_without_a_kept_return() {
    let t = replacing_table();
    let build = |t: &murk_types::CoefficientTable| {
        ApplyParams::new(WeatherClass::Fog, Severity::Mor(100.0))
            .near_range(true)
            .lidar(LidarSpec::vlp16())
            .seed(3)
            .build(t)
            .unwrap()
    };
    // A wall at 12 m on the left half of the revolution, nothing on the
    // right half; at MOR 100 the wall is kept (vanishing distance 34.6 m).
    let c = left_half(&wall(12.0));
    let (out, s) = build(&t).apply(&c, "half wall").unwrap();
    let g = s.ghost.clone().unwrap();
    assert_eq!(s.vanished, 0);
    assert!(g.drawn > 10, "{g:?}");
    assert_eq!(g.replaced, 0, "{g:?}");
    assert!(g.added > 0 && g.occluded > 0, "{g:?}");
    assert_eq!(g.added + g.occluded, g.drawn);
    // The wall is untouched; what was added lies on the empty half.
    for i in 0..c.len() {
        assert_eq!((out.x[i], out.y[i], out.z[i]), (c.x[i], c.y[i], c.z[i]));
    }
    let added = c.len()..out.len();
    assert!(
        added.clone().all(|i| out.y[i] < 0.05),
        "added on the wall's side"
    );
    assert_eq!(added.len() as u64, g.added + s.ring.clone().unwrap().added);
    // Hiding (the default): soft targets replace wall returns.
    let (_, s) = build(&seed_table()).apply(&c, "half wall").unwrap();
    assert!(s.ghost.unwrap().replaced > 0);
    // At MOR 20 the wall (12 m, beyond 0.346·20 = 6.9 m) vanishes: no ray
    // keeps a return, every soft target is shown — in front of a lost wall
    // return, along its beam, or on the empty half.
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(20.0))
        .near_range(true)
        .lidar(LidarSpec::vlp16())
        .seed(3)
        .build(&t)
        .unwrap();
    let (out, s) = a.apply(&c, "half wall").unwrap();
    let (g, r) = (s.ghost.unwrap(), s.ring.unwrap());
    assert_eq!(s.vanished, c.len() as u64);
    assert_eq!((g.occluded + r.occluded, g.replaced), (0, 0), "{g:?}");
    assert_eq!(out.len() as u64, g.drawn + r.drawn);
    let on_wall_side = (0..out.len()).filter(|&i| out.y[i] >= 0.0).count();
    // Half the rays are the wall's: about half the returns go there.
    let share = on_wall_side as f64 / out.len() as f64;
    assert!((share - 0.5).abs() < 0.15, "{share}");
}

/// A replacing weather's returns show on the rays without a kept return,
/// the sky among them, so the sky must be counted on the scan's own
/// firings: a half wall from a unit firing every 0.25° (1,440 firings a
/// turn), described as the VLP-16's 0.2°. On the measured step half the
/// rays are open and about half the drawn returns show; on the declared
/// grid (given explicitly) 28,800 wedges hold 11,520 returns and three
/// in five would.
#[test]
fn the_sky_of_a_replacing_weather_is_counted_on_the_scan_s_firings() {
    let t = replacing_table();
    let spec = LidarSpec::vlp16();
    let c = left_half(&wall_of(12.0, 1440, |bin| 0.25 * bin as f64));
    let shown = |explicit: Option<f64>| {
        let mut p = ApplyParams::new(WeatherClass::Fog, Severity::Mor(100.0))
            .near_range(true)
            .near_range_count_scale(20.0)
            .lidar(spec.clone())
            .seed(5);
        if let Some(res) = explicit {
            p = p.azimuth_resolution_deg(res);
        }
        let (_, s) = p.build(&t).unwrap().apply(&c, "half wall").unwrap();
        assert_eq!(s.vanished, 0);
        let (g, r) = (s.ghost.unwrap(), s.ring.unwrap());
        assert!(g.drawn + r.drawn > 300, "{g:?} {r:?}");
        (g.added + r.added) as f64 / (g.drawn + r.drawn) as f64
    };
    let (measured, declared) = (shown(None), shown(Some(0.2)));
    eprintln!("shown: {measured:.3} on the measured step, {declared:.3} on the declared grid");
    assert!((measured - 0.5).abs() < 0.05, "{measured}");
    assert!((declared - 0.6).abs() < 0.05, "{declared}");
}

#[test]
fn farther_soft_targets_are_occluded() {
    // Wall at 0.3 m: closer than any ghost or ring return (≥ 0.5 m).
    let c = wall(0.3);
    let (out, s) = near(100.0, 2).apply(&c, "near wall").unwrap();
    let g = s.ghost.unwrap();
    assert!(g.drawn > 0);
    assert_eq!(g.occluded, g.drawn);
    let r = s.ring.unwrap();
    assert_eq!(r.occluded, r.drawn);
    assert_eq!(out, c);
}

/// The VLP-16 description with points nearer than `min_range_m` declared
/// not returns.
fn with_min_range(min_range_m: Option<f64>) -> LidarSpec {
    LidarSpec {
        min_range_m,
        ..LidarSpec::vlp16()
    }
}

#[test]
fn points_nearer_than_the_minimum_range_are_not_returns() {
    // The 0.3 m wall of the test above, declared not returns (a format that
    // writes its no-return firings as points at the origin): nothing hides
    // the near returns, every one is added on its open ray, and the wall is
    // written as it was, first, in its order.
    let c = wall(0.3);
    let applier = |min_range_m| {
        ApplyParams::new(WeatherClass::Fog, Severity::Mor(100.0))
            .near_range(true)
            .lidar(with_min_range(min_range_m))
            .seed(2)
            .build(&seed_table())
            .unwrap()
    };
    let (hidden, s) = applier(None).apply(&c, "near wall").unwrap();
    assert_eq!(hidden, c);
    assert_eq!(s.not_returns, 0);
    let (out, s) = applier(Some(0.5)).apply(&c, "near wall").unwrap();
    assert_eq!(s.not_returns, c.len() as u64);
    assert_eq!((s.points_in, s.vanished), (c.len() as u64, 0));
    let (g, r) = (s.ghost.unwrap(), s.ring.unwrap());
    assert!(g.drawn > 0 && r.drawn > 0);
    assert_eq!(
        (g.occluded, r.occluded, g.replaced, r.replaced),
        (0, 0, 0, 0)
    );
    assert_eq!(g.added + g.unplaced, g.drawn);
    assert_eq!(r.added + r.unplaced, r.drawn);
    assert_eq!(out.len() as u64, s.points_out);
    assert_eq!(out.len(), c.len() + (g.added + r.added) as usize);
    assert_eq!(out.x[..c.len()], c.x[..]);
    assert_eq!(out.z[..c.len()], c.z[..]);
}

#[test]
fn points_that_are_not_returns_keep_their_places_and_values() {
    // Every third firing of a 12 m wall written as a point 5 cm from the
    // sensor (nuScenes keeps its no-return firings so). With every option
    // on, those points come out untouched and in their order among the
    // rest, and the returns come out exactly as from the scan without them.
    let wall = wall(12.0);
    let mut c = PointCloud::with_capacity(wall.len());
    let mut returns = PointCloud::with_capacity(wall.len());
    let mut markers = Vec::new();
    for i in 0..wall.len() {
        let (x, y, z) = (wall.x[i], wall.y[i], wall.z[i]);
        if i % 3 == 0 {
            let f = 0.05 / wall.range(i);
            c.push(x * f, y * f, z * f, 3.0, wall.ring[i]);
            markers.push([x * f, y * f, z * f, 3.0]);
        } else {
            c.push(x, y, z, wall.intensity[i], wall.ring[i]);
            returns.push(x, y, z, wall.intensity[i], wall.ring[i]);
        }
    }
    let applier = |min_range_m| {
        ApplyParams::new(WeatherClass::Fog, Severity::Mor(40.0))
            .near_range(true)
            .range_noise_m(0.03)
            .attenuate_intensity(true)
            .soft_edge(true)
            .lidar(with_min_range(min_range_m))
            .seed(5)
            .build(&seed_table())
            .unwrap()
    };
    let (out, s) = applier(Some(1.0)).apply(&c, "scan").unwrap();
    let (alone, s_alone) = applier(None).apply(&returns, "scan").unwrap();
    assert_eq!(s.not_returns, markers.len() as u64);
    assert_eq!(s.points_out, s_alone.points_out + markers.len() as u64);
    assert_eq!(s.vanished, s_alone.vanished);
    assert!(s.vanished > 0 && s.ghost.as_ref().unwrap().drawn > 0);
    let point = |p: &PointCloud, i: usize| [p.x[i], p.y[i], p.z[i], p.intensity[i]];
    // Near returns start at 0.5 m: the points within 0.1 m are the markers.
    let (near, rest): (Vec<usize>, Vec<usize>) = (0..out.len()).partition(|&i| out.range(i) < 0.1);
    let near: Vec<[f32; 4]> = near.iter().map(|&i| point(&out, i)).collect();
    assert_eq!(near, markers);
    let rest: Vec<[f32; 4]> = rest.iter().map(|&i| point(&out, i)).collect();
    let alone: Vec<[f32; 4]> = (0..alone.len()).map(|i| point(&alone, i)).collect();
    assert_eq!(rest, alone);
    // The mask form agrees: every marker kept.
    let mut mask = Vec::new();
    let mut replaced = Vec::new();
    let (_, s_marked) = applier(Some(1.0))
        .apply_marked(&c, "scan", &mut mask, true, &mut replaced)
        .unwrap();
    assert_eq!(s_marked, s);
    assert!((0..c.len()).step_by(3).all(|i| mask[i] == 1));
    assert_eq!(
        mask.iter().map(|&m| u64::from(m)).sum::<u64>(),
        s.points_in - s.vanished
    );
}

#[test]
fn soft_targets_on_empty_rays_are_added_on_the_grid() {
    // No return at all: every soft target is added on its grid ray, at the
    // ring elevation of the sensor description, inside its distance window.
    let spec = LidarSpec::vlp16();
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(100.0))
        .near_range(true)
        .lidar(spec.clone())
        .seed(5)
        .build(&seed_table())
        .unwrap();
    let empty = PointCloud::with_capacity(0);
    let (out, s) = a.apply(&empty, "sky").unwrap();
    let g = s.ghost.unwrap();
    let r = s.ring.unwrap();
    assert_eq!(g.added, g.drawn);
    assert_eq!(r.added, r.drawn);
    assert_eq!(out.len() as u64, g.drawn + r.drawn);
    for i in 0..out.len() {
        let el = out.elevation_deg(i) as f64;
        assert!(
            (el - spec.elevation_deg[out.ring[i] as usize]).abs() < 1e-3,
            "ring {} elevation {el}",
            out.ring[i]
        );
        let az = out.azimuth_deg(i) as f64;
        let k = az / 0.2;
        assert!(
            (k - k.round()).abs() < 1e-2,
            "azimuth {az} off the 0.2° grid"
        );
        let range = out.range(i);
        let ghost = i < g.drawn as usize;
        let (lo, hi) = if ghost { (3.0, 10.0) } else { (0.5, 3.0) };
        assert!(range >= lo - 1e-4 && range <= hi + 1e-4, "{range}");
    }
}

#[test]
fn without_a_description_ring_elevations_are_measured_on_the_scan() {
    // Only ring 3 (3°) present, and only in one azimuth quadrant: soft
    // targets on other azimuths are added at 3° elevation.
    let mut c = PointCloud::with_capacity(0);
    for i in 0..90 {
        let az = (i as f64).to_radians();
        let el = 3f64.to_radians();
        c.push(
            (20.0 * el.cos() * az.cos()) as f32,
            (20.0 * el.cos() * az.sin()) as f32,
            (20.0 * el.sin()) as f32,
            40.0,
            3,
        );
    }
    let (out, s) = near(60.0, 9).apply(&c, "quadrant").unwrap();
    let g = s.ghost.unwrap();
    assert!(g.added > 0);
    for i in c.len()..out.len() {
        assert_eq!(out.ring[i], 3);
        assert!((out.elevation_deg(i) - 3.0).abs() < 1e-3);
    }
}

#[test]
fn ring_outside_the_description_is_an_error_with_the_point() {
    let mut c = wall(12.0);
    c.ring[77] = 40;
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(100.0))
        .near_range(true)
        .lidar(LidarSpec::vlp16())
        .build(&seed_table())
        .unwrap();
    let e = a.apply(&c, "hdl.pcd").unwrap_err().to_string();
    assert!(
        e.contains("hdl.pcd") && e.contains("point 77") && e.contains("ring 40"),
        "{e}"
    );
}

#[test]
fn count_is_poisson_with_the_count_law_mean() {
    // N(MOR) = 20·(100/MOR)^1.5 ghost returns: 160 at MOR 25. Over 50 seeds
    // the mean count is within 4 standard errors (√(160/50) ≈ 1.8).
    let mut t = seed_table();
    let fog = t.weathers.get_mut(&WeatherClass::Fog).unwrap();
    fog.ghost.as_mut().unwrap().count_law = Some(CountLaw::Power {
        n_ref: 20.0,
        mor_ref_m: 100.0,
        exponent: 1.5,
        n_ref_std_error: None,
        exponent_std_error: None,
        n_ref_ci95: None,
        exponent_ci95: None,
    });
    let c = wall(2.0);
    let mut total = 0;
    for seed in 0..50 {
        let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(25.0))
            .near_range(true)
            .seed(seed)
            .build(&t)
            .unwrap();
        let (_, s) = a.apply(&c, "w").unwrap();
        let g = s.ghost.unwrap();
        assert_eq!(g.count_source, "count_law");
        assert!((g.expected - 160.0).abs() < 1e-9);
        total += g.drawn;
    }
    let mean = total as f64 / 50.0;
    assert!(
        (mean - 160.0).abs() < 4.0 * (160.0f64 / 50.0).sqrt(),
        "{mean}"
    );
}

#[test]
fn ghost_reflectivity_is_written_in_the_input_scale() {
    let mut c = wall(12.0);
    c.to_scale(IntensityScale::KITTI);
    let (out, _) = near(100.0, 4).apply(&c, "k").unwrap();
    assert_eq!(out.intensity_scale, IntensityScale::KITTI);
    assert!(out.intensity.iter().all(|&v| (0.0..=1.0).contains(&v)));
}

fn all_options(seed: u64) -> murk_infer::Applier {
    ApplyParams::new(WeatherClass::Fog, Severity::Mor(40.0))
        .near_range(true)
        .near_range_count_scale(5.0)
        .range_noise_m(0.03)
        .attenuate_intensity(true)
        .soft_edge(true)
        .seed(seed)
        .build(&seed_table())
        .unwrap()
}

#[test]
fn output_is_identical_for_one_and_two_threads() {
    let c = synthetic_scan(300_000, 8); // 19 chunks
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| all_options(21).apply(&c, "scan/000001.pcd").unwrap())
    };
    let (a, sa) = run(1);
    let (b, sb) = run(2);
    assert_eq!(sa, sb);
    assert!(sa.ghost.as_ref().unwrap().drawn > 0 && sa.vanished > 0);
    // Bit-level equality, NaN-safe.
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&a.x), bits(&b.x));
    assert_eq!(bits(&a.intensity), bits(&b.intensity));
    assert_eq!(a, b);
}

#[test]
fn seed_and_key_change_the_draws_and_only_them() {
    let c = synthetic_scan(50_000, 8);
    let (a, _) = all_options(1).apply(&c, "a").unwrap();
    let (a2, _) = all_options(1).apply(&c, "a").unwrap();
    let (b, _) = all_options(2).apply(&c, "a").unwrap();
    let (k, _) = all_options(1).apply(&c, "b").unwrap();
    assert_eq!(a, a2);
    assert_ne!(a, b);
    assert_ne!(a, k);
}
