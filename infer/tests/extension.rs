//! Extension terms (from `murk diagnose`) applied by murk-infer: known
//! answers per observable, the baseline when turned off, and the same bytes
//! whatever the thread count.

mod common;

use std::collections::BTreeMap;

use murk_infer::{ApplyParams, CoefficientTable, PointCloud, Severity};
use murk_types::{
    CovariateValue, ExtensionFunction, ExtensionObservable, ModelExtension, WeatherClass,
};

fn table(ext: Vec<ModelExtension>) -> CoefficientTable {
    let mut t = CoefficientTable::from_json(
        r#"{
      "format": "weather-noise-coefficients/1", "campaign": "ext",
      "lidar": { "model": "VLP16", "range_scale": 1.0 },
      "weathers": { "fog": {
        "recordings": 28, "quantile": 0.99, "no_change_rate": 0.38,
        "vanishing_slope": [
          { "reflectivity_min": 0,  "reflectivity_max": 10,   "slope": 0.3, "points": 1 },
          { "reflectivity_min": 10, "reflectivity_max": null, "slope": 0.4, "points": 1 } ],
        "ghost": null, "ring": null } },
      "provenance": { "tool": "test", "inputs_sha256": "", "parameters": {} }
    }"#,
    )
    .unwrap();
    t.weathers.get_mut(&WeatherClass::Fog).unwrap().extensions = ext;
    t.validate().unwrap();
    t
}

fn term(obs: ExtensionObservable, cov: &str, edges: Vec<f64>, values: Vec<f64>) -> ModelExtension {
    ModelExtension {
        observable: obs,
        covariate: cov.into(),
        function: ExtensionFunction::Bins { edges, values },
        default: obs.neutral(),
        description: String::new(),
    }
}

#[test]
fn each_term_does_what_its_table_says() {
    // MOR 100: vanishing distances 30 m (dark) and 40 m (bright).
    let t = table(vec![
        // Ground returns (elevation < −4°) vanish at half the distance.
        term(
            ExtensionObservable::Survival,
            "elevation",
            vec![-4.0],
            vec![0.5, 1.0],
        ),
        // Returns beyond 20 m come back at 80 % reflectivity.
        term(
            ExtensionObservable::Intensity,
            "range",
            vec![20.0],
            vec![1.0, 0.8],
        ),
    ]);
    let mut scan = PointCloud::with_capacity(4);
    scan.push(35.0, 0.0, 0.0, 50.0, 0); // bright, level, 35 m < 40: kept, 80 %
    scan.push(25.0, 0.0, -3.0, 50.0, 1); // bright, −6.8°: 25.2 m > 20: vanishes
    scan.push(15.0, 0.0, -3.0, 50.0, 2); // bright, −11.3°: 15.3 m < 20: kept, 100 %
    scan.push(35.0, 0.0, 0.0, 5.0, 3); // dark, 35 m > 30: vanishes
    let ap = ApplyParams::new(WeatherClass::Fog, Severity::Mor(100.0))
        .build(&t)
        .unwrap();
    let (out, summary) = ap.apply(&scan, "s").unwrap();
    assert_eq!(out.ring, vec![0, 2]);
    assert_eq!(out.intensity, vec![40.0, 50.0]);
    assert_eq!(out.x, vec![35.0, 15.0]);
    assert_eq!(
        (summary.points_in, summary.points_out, summary.vanished),
        (4, 2, 2)
    );
    assert_eq!(ap.describe().extensions.len(), 2);
    // Turned off: the baseline keeps the ground return at 25 m.
    let base = ApplyParams::new(WeatherClass::Fog, Severity::Mor(100.0))
        .extensions(false)
        .build(&t)
        .unwrap();
    assert_eq!(base.apply(&scan, "s").unwrap().0.ring, vec![0, 1, 2]);
    // The keep probability the diagnosis uses agrees.
    assert_eq!(ap.survival_probability(25.2, 50.0, 0.5, false), 0.0);
    assert_eq!(ap.survival_probability(25.2, 50.0, 1.0, false), 1.0);
}

#[test]
fn scan_level_terms_use_the_value_given_or_their_default() {
    let mut bias = term(ExtensionObservable::Range, "Road state", vec![], vec![0.0]);
    bias.function = ExtensionFunction::Categories {
        values: BTreeMap::from([("wet".to_string(), 0.5)]),
    };
    bias.default = 0.25;
    let t = table(vec![bias]);
    let mut scan = PointCloud::with_capacity(1);
    scan.push(10.0, 0.0, 0.0, 50.0, 0);
    let wet = ApplyParams::new(WeatherClass::Fog, Severity::Mor(100.0))
        .covariate("Road state", CovariateValue::parse("wet"))
        .build(&t)
        .unwrap();
    assert!(wet.warnings().is_empty());
    assert_eq!(wet.apply(&scan, "s").unwrap().0.x, vec![10.5]);
    let unknown = ApplyParams::new(WeatherClass::Fog, Severity::Mor(100.0))
        .build(&t)
        .unwrap();
    assert!(
        unknown.warnings()[0].contains("Road state"),
        "{:?}",
        unknown.warnings()
    );
    assert_eq!(unknown.apply(&scan, "s").unwrap().0.x, vec![10.25]);
    // Clear weather stays the identity.
    let clear = ApplyParams::new(WeatherClass::Fog, Severity::Mor(5000.0))
        .build(&t)
        .unwrap();
    assert_eq!(clear.apply(&scan, "s").unwrap().0, scan);
}

#[test]
fn soft_edge_with_terms_is_the_same_for_any_thread_count() {
    let mut t = table(vec![term(
        ExtensionObservable::Survival,
        "azimuth",
        vec![180.0],
        vec![0.7, 1.2],
    )]);
    let w = t.weathers.get_mut(&WeatherClass::Fog).unwrap();
    w.survival = Some(
        serde_json::from_value(serde_json::json!({"edge": "probit", "dropout": 0.05,
            "residual": 0.01, "neg_log_likelihood": 1.0, "trials": 100}))
        .unwrap(),
    );
    for b in &mut w.vanishing_slope {
        b.edge_width = Some(0.1);
    }
    let mut scan = PointCloud::with_capacity(20_000);
    for i in 0..20_000 {
        let a = i as f32 * 0.018_f32.to_radians() * 20.0;
        let r = 5.0 + (i % 50) as f32;
        scan.push(
            r * a.cos(),
            r * a.sin(),
            0.0,
            (i % 30) as f32,
            (i % 16) as u16,
        );
    }
    let ap = ApplyParams::new(WeatherClass::Fog, Severity::Mor(100.0))
        .soft_edge(true)
        .seed(3)
        .build(&t)
        .unwrap();
    let run = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
            .install(|| ap.apply(&scan, "k").unwrap().0)
    };
    let one = run(1);
    assert_eq!(one, run(3));
    assert!(one.len() > 1000 && one.len() < scan.len());
}

/// Several terms on one observable (what `murk diagnose`'s stagewise
/// extension writes): survival factors multiply, range biases add, a
/// scan-level term combines with a point-level one on the same points.
#[test]
fn several_terms_on_one_observable_combine() {
    let mut wind = term(
        ExtensionObservable::Survival,
        "Wind speed (m/s)",
        vec![5.0],
        vec![1.0, 0.5],
    );
    wind.default = 1.0;
    let t = table(vec![
        // Ground rings (elevation < −4°): distance × 0.8.
        term(
            ExtensionObservable::Survival,
            "elevation",
            vec![-4.0],
            vec![0.8, 1.0],
        ),
        // Windy scans: distance × 0.5.
        wind,
        // Range: +0.25 m beyond 20 m, +0.5 m everywhere from a second term.
        term(
            ExtensionObservable::Range,
            "range",
            vec![20.0],
            vec![0.0, 0.25],
        ),
        term(ExtensionObservable::Range, "ring", vec![], vec![0.5]),
    ]);
    // MOR 100: bright returns vanish beyond 40 m.
    let mut scan = PointCloud::with_capacity(3);
    scan.push(35.0, 0.0, 0.0, 50.0, 0); // level, 35 m
    scan.push(15.0, 0.0, -3.0, 50.0, 1); // −11.3°, 15.3 m
    scan.push(25.0, 0.0, 0.0, 50.0, 2); // level, 25 m
    let calm = ApplyParams::new(WeatherClass::Fog, Severity::Mor(100.0))
        .covariate("Wind speed (m/s)", CovariateValue::Number(2.0))
        .build(&t)
        .unwrap();
    // Calm: ground 15.3 m < 32 m kept; all kept; biases 0.25 + 0.5 beyond
    // 20 m, 0.5 below.
    let (out, _) = calm.apply(&scan, "s").unwrap();
    assert_eq!(out.ring, vec![0, 1, 2]);
    assert!((out.x[0] - 35.75).abs() < 1e-4, "{}", out.x[0]);
    let r1 = (out.x[1].powi(2) + out.z[1].powi(2)).sqrt();
    let r1_in = (15.0f32.powi(2) + 9.0).sqrt();
    assert!((r1 - (r1_in + 0.5)).abs() < 1e-4, "{r1}");
    assert!((out.x[2] - 25.75).abs() < 1e-4, "{}", out.x[2]);
    // Windy: distance 40 × 0.5 = 20 m (level), 40 × 0.5 × 0.8 = 16 m
    // (ground): the 35 m and 25 m returns vanish, the 15.3 m ground return
    // stays.
    let windy = ApplyParams::new(WeatherClass::Fog, Severity::Mor(100.0))
        .covariate("Wind speed (m/s)", CovariateValue::Number(8.0))
        .build(&t)
        .unwrap();
    assert_eq!(windy.apply(&scan, "s").unwrap().0.ring, vec![1]);
    // A third survival term (× 0.9 everywhere) makes the ground product
    // 0.8 · 0.5 · 0.9 = 0.36: 14.4 m < 15.3 m, and it vanishes as well.
    let mut t3 = t.clone();
    t3.weathers
        .get_mut(&WeatherClass::Fog)
        .unwrap()
        .extensions
        .push(term(
            ExtensionObservable::Survival,
            "ring",
            vec![],
            vec![0.9],
        ));
    let windy3 = ApplyParams::new(WeatherClass::Fog, Severity::Mor(100.0))
        .covariate("Wind speed (m/s)", CovariateValue::Number(8.0))
        .build(&t3)
        .unwrap();
    assert!(windy3.apply(&scan, "s").unwrap().0.is_empty());
}

/// A fog applier at MOR 60 m with near-range returns on `spec`'s rays.
fn near_applier(t: &CoefficientTable, spec: &murk_types::LidarSpec) -> murk_infer::Applier {
    ApplyParams::new(WeatherClass::Fog, Severity::Mor(60.0))
        .near_range(true)
        .lidar(spec.clone())
        .build(t)
        .unwrap()
}

/// One return 300 m out on every laser of `spec` (at azimuth 0), so that
/// every ring is present; at MOR 60 m they all vanish.
fn far_return_per_laser(spec: &murk_types::LidarSpec) -> PointCloud {
    let mut scan = PointCloud::with_capacity(spec.rings());
    for ring in 0..spec.rings() as u16 {
        let el = spec.elevation_deg[ring as usize].to_radians();
        scan.push(
            (300.0 * el.cos()) as f32,
            0.0,
            (300.0 * el.sin()) as f32,
            50.0,
            ring,
        );
    }
    scan
}

#[test]
fn count_terms_along_the_beams_place_ghosts_by_their_density() {
    // Hand-built known answer: ghost and ring returns three times as dense
    // on the downward lasers (8 of the VLP-16's 16), twice as dense in the
    // half-turn 0–180°. Expected per scan: (41 + 12) × mean density
    // (3·8 + 8)/16 × (2 + 1)/2 = 53 × 2 × 1.5 = 159; on an empty scene each
    // return is added on its ray, so the output shows the densities.
    let mut t = common::seed_table();
    t.weathers.get_mut(&WeatherClass::Fog).unwrap().extensions = vec![
        term(
            ExtensionObservable::Count,
            "elevation",
            vec![0.0],
            vec![3.0, 1.0],
        ),
        term(
            ExtensionObservable::Count,
            "azimuth",
            vec![180.0],
            vec![2.0, 1.0],
        ),
    ];
    t.validate().unwrap();
    let spec = murk_types::LidarSpec::vlp16();
    let scan = far_return_per_laser(&spec);
    let ap = near_applier(&t, &spec);
    let (mut down, mut up, mut first_half, mut second_half) = (0usize, 0usize, 0usize, 0usize);
    let mut expected = 0.0;
    let scans = 300;
    for k in 0..scans {
        let (out, summary) = ap.apply(&scan, &format!("s{k}")).unwrap();
        expected +=
            summary.ghost.as_ref().unwrap().expected + summary.ring.as_ref().unwrap().expected;
        for i in 0..out.len() {
            let (x, y, z) = (out.x[i] as f64, out.y[i] as f64, out.z[i] as f64);
            if (x * x + y * y + z * z).sqrt() > 20.0 {
                continue;
            }
            if spec.elevation_deg[out.ring[i] as usize] < 0.0 {
                down += 1;
            } else {
                up += 1;
            }
            let az = y.atan2(x).to_degrees().rem_euclid(360.0);
            if az < 180.0 {
                first_half += 1;
            } else {
                second_half += 1;
            }
        }
    }
    assert!((expected / scans as f64 - 159.0).abs() < 1e-9, "{expected}");
    let n = (down + up) as f64 / scans as f64;
    assert!((n / 159.0 - 1.0).abs() < 0.03, "{n} per scan");
    // Truth 3 and 2; ~48 000 returns put the bounds at about 4 standard
    // errors.
    let beams = down as f64 / up as f64;
    let halves = first_half as f64 / second_half as f64;
    assert!((beams - 3.0).abs() < 0.12, "down/up {beams}");
    assert!((halves - 2.0).abs() < 0.08, "0–180°/180–360° {halves}");
    // Without the terms the placement is uniform over the rays.
    let base = ApplyParams::new(WeatherClass::Fog, Severity::Mor(60.0))
        .near_range(true)
        .lidar(spec)
        .extensions(false)
        .build(&t)
        .unwrap();
    let (out, summary) = base.apply(&scan, "s0").unwrap();
    assert_eq!(
        summary.ghost.unwrap().expected + summary.ring.unwrap().expected,
        53.0
    );
    assert!(out.len() > 16);
}

/// `∫ₐᵇ exp(−((x − μ)/σ)²/2) dx` by Simpson's rule (2,000 intervals): the
/// test's own integral, independent of the sampler's Φ and quantile.
fn gauss_mass(mean: f64, std: f64, a: f64, b: f64) -> f64 {
    let n = 2000;
    let h = (b - a) / n as f64;
    let f = |x: f64| (-0.5 * ((x - mean) / std).powi(2)).exp();
    let mut s = f(a) + f(b);
    for i in 1..n {
        s += f(a + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
    }
    s * h / 3.0
}

#[test]
fn count_terms_along_range_reshape_the_distance_law_and_scale_the_count() {
    // Hand-built known answer (the seed-004 per-echo range law): near-range
    // returns three times as dense below 5 m as the table's law says and
    // half as dense beyond. The ghost law N(5.011, 1.753²) on [3, 10] m has
    // mass P below 5 m, so its count scales by 3P + 0.5(1 − P) and a share
    // 3P / (3P + 0.5(1 − P)) of the ghosts falls below 5 m; the ring law
    // (0.5–3 m) lies below 5 m: its count triples and its shape stays.
    let mut t = common::seed_table();
    t.weathers.get_mut(&WeatherClass::Fog).unwrap().extensions = vec![term(
        ExtensionObservable::Count,
        "range",
        vec![5.0],
        vec![3.0, 0.5],
    )];
    t.validate().unwrap();
    let p = gauss_mass(5.011, 1.753, 3.0, 5.0) / gauss_mass(5.011, 1.753, 3.0, 10.0);
    let ghost_factor = 3.0 * p + 0.5 * (1.0 - p);
    let share_below = 3.0 * p / ghost_factor;
    let spec = murk_types::LidarSpec::vlp16();
    let scan = far_return_per_laser(&spec);
    let ap = near_applier(&t, &spec);
    let (mut ghosts, mut below, mut rings, mut ring_sum) = (0usize, 0usize, 0usize, 0.0f64);
    let scans = 300;
    for k in 0..scans {
        let (out, summary) = ap.apply(&scan, &format!("s{k}")).unwrap();
        let g = summary.ghost.as_ref().unwrap().expected;
        let r = summary.ring.as_ref().unwrap().expected;
        // One of the 1,024 cells straddles 5 m: at most 2.5/1,024 off.
        assert!((g - 41.0 * ghost_factor).abs() < 41.0 * 2.5e-3, "ghost {g}");
        assert!((r - 36.0).abs() < 1e-9, "ring {r}");
        for i in 0..out.len() {
            let (x, y, z) = (out.x[i] as f64, out.y[i] as f64, out.z[i] as f64);
            let d = (x * x + y * y + z * z).sqrt();
            if d < 3.0 {
                rings += 1;
                ring_sum += d;
            } else if d <= 10.0 {
                ghosts += 1;
                below += usize::from(d < 5.0);
            }
        }
    }
    // ~19 000 ghosts: the share's standard error is about 0.003.
    let per_scan = ghosts as f64 / scans as f64;
    assert!(
        (per_scan / (41.0 * ghost_factor) - 1.0).abs() < 0.03,
        "{per_scan} ghosts per scan, expected {}",
        41.0 * ghost_factor
    );
    let share = below as f64 / ghosts as f64;
    eprintln!(
        "ghosts per scan {per_scan:.2} (expected {:.2}), share below 5 m {share:.4} (truth {share_below:.4}), ring mean {:.4} m",
        41.0 * ghost_factor,
        ring_sum / rings as f64
    );
    assert!(
        (share - share_below).abs() < 0.012,
        "share below 5 m {share}, truth {share_below}"
    );
    // The ring law is unchanged in shape: its mean stays that of
    // N(1.308, 0.172²) (the truncation at 0.5 and 3 m is 4.7 and 9.8
    // standard deviations away).
    assert!((rings as f64 / scans as f64 / 36.0 - 1.0).abs() < 0.03);
    assert!((ring_sum / rings as f64 - 1.308).abs() < 0.005);
    // A term that is 0 over the whole law places none of its kind.
    let mut none = t.clone();
    none.weathers
        .get_mut(&WeatherClass::Fog)
        .unwrap()
        .extensions = vec![term(
        ExtensionObservable::Count,
        "range",
        vec![3.0],
        vec![1.0, 0.0],
    )];
    let (out, summary) = near_applier(&none, &spec).apply(&scan, "s0").unwrap();
    assert_eq!(summary.ghost.as_ref().unwrap().expected, 0.0);
    assert_eq!(summary.ring.as_ref().unwrap().expected, 36.0 / 3.0);
    // (The 300 m returns vanish at MOR 60 m: only ring returns remain.)
    let ring = summary.ring.as_ref().unwrap();
    assert_eq!(out.len() as u64, ring.added, "{summary:?}");
    assert!(ring.drawn > 0);
    for i in 0..out.len() {
        let (x, y, z) = (out.x[i], out.y[i], out.z[i]);
        assert!((x * x + y * y + z * z).sqrt() < 3.0);
    }
}

#[test]
fn the_monotone_and_parametric_shapes_apply_at_the_applied_mor() {
    let shaped =
        |obs: ExtensionObservable, cov: &str, function: ExtensionFunction| ModelExtension {
            observable: obs,
            covariate: cov.into(),
            function,
            default: obs.neutral(),
            description: String::new(),
        };
    let t = table(vec![
        // Two-way attenuation of reflectivity: exp(−k·r/MOR).
        shaped(
            ExtensionObservable::Intensity,
            "range",
            ExtensionFunction::Attenuation {
                k: 2.0 * 20f64.ln(),
            },
        ),
        // A range bias growing as MOR falls: 2 m / MOR.
        shaped(
            ExtensionObservable::Range,
            "mor",
            ExtensionFunction::Power {
                scale: 2.0,
                exponent: -1.0,
            },
        ),
        // Vanishing distance × 1 up to 10 m, falling linearly to 0.5 at
        // 30 m and beyond.
        shaped(
            ExtensionObservable::Survival,
            "range",
            ExtensionFunction::Monotone {
                knots: vec![10.0, 30.0],
                values: vec![1.0, 0.5],
            },
        ),
    ]);
    let mut scan = PointCloud::with_capacity(3);
    scan.push(10.0, 0.0, 0.0, 50.0, 0); // factor 1: 10 < 40 kept
    scan.push(20.0, 0.0, 0.0, 50.0, 1); // factor 0.75: 20 < 30 kept
    scan.push(35.0, 0.0, 0.0, 50.0, 2); // factor 0.5: 35 > 20 vanishes
    for mor in [100.0, 50.0] {
        let ap = ApplyParams::new(WeatherClass::Fog, Severity::Mor(mor))
            .build(&t)
            .unwrap();
        let (out, _) = ap.apply(&scan, "s").unwrap();
        let factor = |r: f64| 50.0 * (-2.0 * 20f64.ln() * r / mor).exp();
        if mor == 100.0 {
            assert_eq!(out.ring, vec![0, 1]);
        }
        let bias = 2.0 / mor;
        for (i, r) in [10.0f64, 20.0].into_iter().take(out.len()).enumerate() {
            assert!(
                (out.intensity[i] as f64 - factor(r)).abs() < 1e-3,
                "MOR {mor}: {} vs {}",
                out.intensity[i],
                factor(r)
            );
            assert!((out.x[i] as f64 - (r + bias)).abs() < 1e-4, "{}", out.x[i]);
        }
    }
}
