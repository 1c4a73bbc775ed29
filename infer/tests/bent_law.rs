//! A table whose bands carry a law that bends (`a·MOR^b`, murk-types'
//! `VanishingLaw`) is applied by that law: known answers on synthetic
//! clouds, hard and soft edge; a table without the field applies its slope
//! as before.

mod common;

use common::*;
use murk_infer::{ApplyParams, Severity};
use murk_types::{
    CoefficientTable, EdgeShape, PointCloud, ReflectivityDependence, VanishingLaw, WeatherClass,
};

const A: f64 = 1.6;
const B: f64 = 0.72;

fn bent_table() -> CoefficientTable {
    let mut t = seed_table();
    let fog = t.weathers.get_mut(&WeatherClass::Fog).unwrap();
    for b in &mut fog.vanishing_slope {
        b.law = Some(VanishingLaw::Power {
            a: A,
            b: B,
            reflectivity: None,
        });
    }
    if let Some(s) = fog.survival.as_mut() {
        s.dropout = 0.0;
        s.residual = 0.0;
    }
    // Through JSON, as a published table reaches an applier.
    CoefficientTable::from_json(&t.to_json().unwrap()).unwrap()
}

/// Hard edge: a return is kept exactly when its range is within
/// `A·MOR^B`, at several MORs, in both bands (the slope fields say
/// otherwise and must be ignored).
#[test]
fn hard_edge_keeps_exactly_the_returns_inside_the_bent_distance() {
    let t = bent_table();
    for mor in [20.0, 60.0, 200.0] {
        let d = A * f64::powf(mor, B);
        let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(mor))
            .build(&t)
            .unwrap();
        assert!((a.vanishing_distance_m(5.0) - d).abs() < 1e-9 * d);
        assert!((a.vanishing_distance_m(50.0) - d).abs() < 1e-9 * d);
        let mut c = PointCloud::with_capacity(0);
        let mut want = Vec::new();
        let mut k = 0u16;
        for f in [0.2, 0.9, 0.99, 1.01, 1.2, 3.0] {
            for refl in [5.0f32, 50.0] {
                c.push((f * d) as f32, 0.0, 0.0, refl, k);
                if f < 1.0 {
                    want.push(k);
                }
                k += 1;
            }
        }
        let (out, _) = a.apply(&c, "bent").unwrap();
        assert_eq!(out.ring, want, "MOR {mor}");
    }
}

/// Soft edge (probit, width 0.1, no dropout nor residual): the kept share
/// at `D·(1 + w·z)` is `1 − Φ(z)` within four binomial standard errors.
#[test]
fn soft_edge_gives_the_bent_laws_survival() {
    let t = bent_table();
    let mor = 80.0;
    let d = A * f64::powf(mor, B);
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(mor))
        .soft_edge(true)
        .seed(3)
        .build(&t)
        .unwrap();
    let w = t.weathers[&WeatherClass::Fog].vanishing_slope[0]
        .edge_width
        .unwrap();
    for z in [-1.0, 0.0, 1.0] {
        let n = 20_000;
        let r = d * (1.0 + w * z);
        let mut c = PointCloud::with_capacity(n);
        for i in 0..n {
            let az = i as f64 * 1e-4;
            c.push((r * az.cos()) as f32, (r * az.sin()) as f32, 0.0, 5.0, 0);
        }
        let (out, _) = a.apply(&c, &format!("soft-{z}")).unwrap();
        let got = out.len() as f64 / n as f64;
        let want = EdgeShape::Probit.sf(z);
        let se = (want * (1.0 - want) / n as f64).sqrt();
        assert!(
            (got - want).abs() < 4.0 * se + 1e-3,
            "z {z}: {got} vs {want}"
        );
    }
}

/// A table without `law` applies `slope·MOR`, and writes no `law` field.
#[test]
fn a_table_without_the_law_applies_its_slope() {
    let t = seed_table();
    let j = t.to_json().unwrap();
    assert!(!j.contains("\"law\""));
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(60.0))
        .build(&CoefficientTable::from_json(&j).unwrap())
        .unwrap();
    assert!((a.vanishing_distance_m(5.0) - FOG_LOW * 60.0).abs() < 1e-12);
}

/// A law with a non-positive coefficient is refused on load, naming it.
#[test]
fn a_bad_law_is_refused_naming_the_field() {
    let mut t = seed_table();
    t.weathers
        .get_mut(&WeatherClass::Fog)
        .unwrap()
        .vanishing_slope[1]
        .law = Some(VanishingLaw::Power {
        a: 0.0,
        b: 0.7,
        reflectivity: None,
    });
    let e = t.to_json().unwrap_err().to_string();
    assert!(e.contains("weathers.fog.vanishing_slope[1].law"), "{e}");
}

fn reflectivity_table(edge_width: Option<f64>) -> CoefficientTable {
    reflectivity_table_varying(edge_width, None)
}

/// [`reflectivity_table`] with `k` changing with MOR: `(g, M_ref)`.
fn reflectivity_table_varying(edge_width: Option<f64>, g: Option<(f64, f64)>) -> CoefficientTable {
    let mut t = seed_table();
    let fog = t.weathers.get_mut(&WeatherClass::Fog).unwrap();
    for b in &mut fog.vanishing_slope {
        b.law = Some(VanishingLaw::Power {
            a: A,
            b: B,
            reflectivity: Some(ReflectivityDependence {
                exponent: K,
                reference: X_REF,
                floor: 1.0,
                edge_width,
                exponent_per_ln_mor: g.map(|g| g.0),
                mor_reference_m: g.map(|g| g.1),
            }),
        });
    }
    if let Some(s) = fog.survival.as_mut() {
        s.dropout = 0.0;
        s.residual = 0.0;
    }
    CoefficientTable::from_json(&t.to_json().unwrap()).unwrap()
}

const K: f64 = 0.2;
const X_REF: f64 = 20.0;

/// With a reflectivity term each return has its own distance
/// `A·MOR^B·(max(x, 1)/20)^0.2`: hard edge, returns of several
/// reflectivities in both bands (and one below the floor) kept exactly
/// inside their own distance; the applier reports the same distance.
#[test]
fn hard_edge_places_each_return_by_its_reflectivity() {
    hard_edge_by_reflectivity(None);
}

/// As [`hard_edge_places_each_return_by_its_reflectivity`] with `k`
/// changing with MOR (`0.2 + 0.06·ln(MOR/50)`): each MOR applies its own
/// exponent.
#[test]
fn an_exponent_that_changes_with_mor_is_applied_at_the_mor() {
    hard_edge_by_reflectivity(Some((0.06, 50.0)));
}

fn hard_edge_by_reflectivity(g: Option<(f64, f64)>) {
    let t = reflectivity_table_varying(None, g);
    for mor in [20.0, 60.0, 200.0] {
        let k_mor = K + g.map_or(0.0, |(g, m)| g * f64::ln(mor / m));
        let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(mor))
            .build(&t)
            .unwrap();
        let mut c = PointCloud::with_capacity(0);
        let mut want = Vec::new();
        let mut k = 0u16;
        for refl in [0.0f32, 2.0, 7.0, 12.0, 60.0, 200.0] {
            let d = A * f64::powf(mor, B) * ((refl as f64).max(1.0) / X_REF).powf(k_mor);
            assert!(
                (a.vanishing_distance_m(refl as f64) - d).abs() < 1e-9 * d,
                "MOR {mor} x {refl}"
            );
            for f in [0.5, 0.98, 1.02, 2.0] {
                c.push((f * d) as f32, 0.0, 0.0, refl, k);
                if f < 1.0 {
                    want.push(k);
                }
                k += 1;
            }
        }
        let (out, summary) = a.apply(&c, "refl").unwrap();
        assert_eq!(out.ring, want, "MOR {mor}");
        assert_eq!(summary.points_out as usize, want.len());
    }
}

/// Soft edge with the width the term carries (0.05, not the band's 0.1):
/// at reflectivity 80 the kept share at `D(80)·(1 + 0.05·z)` is `1 − Φ(z)`.
#[test]
fn soft_edge_uses_the_terms_own_distance_and_width() {
    let t = reflectivity_table(Some(0.05));
    let mor = 80.0;
    let x = 80.0f32;
    let d = A * f64::powf(mor, B) * (x as f64 / X_REF).powf(K);
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(mor))
        .soft_edge(true)
        .seed(3)
        .build(&t)
        .unwrap();
    for z in [-1.0, 0.0, 1.0] {
        let n = 20_000;
        let r = d * (1.0 + 0.05 * z);
        let mut c = PointCloud::with_capacity(n);
        for i in 0..n {
            let az = i as f64 * 1e-4;
            c.push((r * az.cos()) as f32, (r * az.sin()) as f32, 0.0, x, 0);
        }
        let (out, _) = a.apply(&c, &format!("soft-refl-{z}")).unwrap();
        let got = out.len() as f64 / n as f64;
        let want = EdgeShape::Probit.sf(z);
        let se = (want * (1.0 - want) / n as f64).sqrt();
        assert!(
            (got - want).abs() < 4.0 * se + 1e-3,
            "z {z}: {got} vs {want}"
        );
    }
}
