//! Round trip of the soft survival edge through fit and apply (issue #15):
//! a campaign generated with a known edge shape and a wide edge is fitted
//! with that shape, the table is applied with the soft edge to clear scans at
//! each fog recording's MOR, and per range bin
//!
//! - the applier's edge (its survival law with the level the dropouts set
//!   divided out) matches the kept fraction measured in the generated fog
//!   recordings within 0.04, and
//! - what apply's sampling kernel keeps matches the applier's law given
//!   clear presence within binomial scatter.
//!
//! The level is divided out because the fitted dropouts are not what this
//! test is about: on this 1° campaign the clear-weather dropout comes out
//! far above the generator's (a pairing matter of issue #12), which lifts
//! the applied level everywhere.
//!
//! Fit and apply must agree on the edge law for this to hold: before the law
//! had one owner, fit fitted the logistic at unit variance and infer applied
//! the standard logistic, 1.8× wider in `r`; with the 25 % edge width used
//! here that moves the kept fraction near the edge by far more than the
//! tolerance.

use std::collections::BTreeMap;

use murk_campaign::Campaign;
use murk_fit::{EdgeShape, FitParams};
use murk_fixtures::{EdgeShape as GenEdge, Generator, Origin};
use murk_fixtures::{GeneratorConfig, OutputOptions, PerClass, Preset};
use murk_infer::{ApplyParams, Severity};
use murk_types::{PointCloud, WeatherClass};

/// Range bins, metres.
const BIN_M: f64 = 4.0;

fn config(edge: GenEdge) -> GeneratorConfig {
    let mut c = GeneratorConfig::preset(Preset::Small);
    c.campaign.recordings = 60;
    c.weather.mix = PerClass {
        clear: 0.3,
        fog: 0.7,
        rain: 0.0,
        snow: 0.0,
    };
    // Exact MOR readings: this test is about the edge law, not about
    // errors in MOR.
    c.weather.mor_noise_rel = 0.0;
    let fog = &mut c.degradation.fog;
    fog.edge = edge;
    fog.edge_width = 0.25;
    // No weather returns: a ghost or ring return replaces the clear return
    // of its ray, which would count as lost in the measured fraction.
    fog.ghost.count.n_ref = 0.0;
    fog.ring.count.n_ref = 0.0;
    c
}

fn ranges(cloud: &PointCloud, keep: impl Fn(usize) -> bool) -> Vec<f64> {
    (0..cloud.len())
        .filter(|&i| keep(i))
        .map(|i| {
            let (x, y, z) = (cloud.x[i] as f64, cloud.y[i] as f64, cloud.z[i] as f64);
            (x * x + y * y + z * z).sqrt()
        })
        .collect()
}

fn histogram(rs: &[f64], into: &mut BTreeMap<i64, f64>, weight: f64) {
    for r in rs {
        *into.entry((r / BIN_M).floor() as i64).or_default() += weight;
    }
}

/// Largest |predicted − measured| kept fraction over range bins with
/// enough clear returns, and the number of such bins.
fn round_trip(gen_edge: GenEdge, fit_edge: EdgeShape, seed: u64) -> (f64, usize) {
    let cfg = config(gen_edge);
    let generator = Generator::new(cfg).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("campaign");
    generator
        .write_campaign(seed, &OutputOptions::new(&path))
        .unwrap();
    let campaign = Campaign::open(&path).unwrap();
    let fitted = FitParams::default()
        .edge(fit_edge)
        .bootstrap_replicates(20)
        .check()
        .unwrap()
        .fit(&campaign)
        .unwrap();
    let table = fitted.table();
    let fog = &table.weathers[&WeatherClass::Fog];
    assert_eq!(fog.survival.as_ref().unwrap().edge, fit_edge);

    let log = generator.weather_log(seed);
    let clear: Vec<_> = log
        .iter()
        .filter(|r| r.class == WeatherClass::Clear && r.fault.is_none())
        .map(|r| generator.simulate(seed, r))
        .collect();
    assert!(clear.len() >= 5, "{} clear recordings", clear.len());
    let surv = fog.survival.as_ref().unwrap();
    let plateau = 1.0 - surv.dropout - surv.residual;
    let mut base: BTreeMap<i64, f64> = BTreeMap::new();
    let mut meas = BTreeMap::new();
    let mut n_pred: BTreeMap<i64, f64> = BTreeMap::new();
    let mut edge_pred: BTreeMap<i64, f64> = BTreeMap::new();
    let mut law_pred: BTreeMap<i64, f64> = BTreeMap::new();
    let mut applied = BTreeMap::new();
    let per_clear = 1.0 / clear.len() as f64;
    let mut fogs = 0;
    for rec in log
        .iter()
        .filter(|r| r.class == WeatherClass::Fog && r.fault.is_none())
    {
        fogs += 1;
        // Measured: surviving clear returns of the fog recording, against
        // the mean clear recording.
        let sim = generator.simulate(seed, rec);
        let kept = ranges(&sim.cloud, |i| sim.labels[i].origin == Origin::Clear);
        histogram(&kept, &mut meas, 1.0);
        for c in &clear {
            histogram(&ranges(&c.cloud, |_| true), &mut base, per_clear);
        }
        // Predicted on one clear scan at this MOR: the applier's edge (its
        // survival law without the level set by the dropouts), the law
        // given clear presence, and what apply's sampling kernel kept.
        let cloud = &clear[fogs % clear.len()].cloud;
        let applier = ApplyParams::new(WeatherClass::Fog, Severity::Mor(rec.mor_m))
            .soft_edge(true)
            .seed(seed ^ fogs as u64)
            .build(table)
            .unwrap();
        let rs = ranges(cloud, |_| true);
        for (i, r) in rs.iter().enumerate() {
            let k = (r / BIN_M).floor() as i64;
            let refl = cloud.intensity_scale.to_calibrated(cloud.intensity[i]) as f64;
            let p = applier.survival_probability(*r, refl, 1.0, false);
            *n_pred.entry(k).or_default() += 1.0;
            *edge_pred.entry(k).or_default() += (p - surv.residual) / plateau;
            *law_pred.entry(k).or_default() += applier.survival_probability(*r, refl, 1.0, true);
        }
        let (out, _) = applier.apply(cloud, &rec.id).unwrap();
        histogram(&ranges(&out, |_| true), &mut applied, 1.0);
    }
    assert!(fogs >= 20, "{fogs} fog recordings");
    let (mut worst, mut bins) = (0.0f64, 0);
    for (k, n) in &n_pred {
        // Near range holds weather returns; skip it and thin bins.
        if (*k as f64) * BIN_M < 10.0 || *n < 2000.0 {
            continue;
        }
        let get = |h: &BTreeMap<i64, f64>| h.get(k).copied().unwrap_or(0.0);
        let edge = get(&edge_pred) / n;
        let m = get(&meas) / base[k];
        let law = get(&law_pred) / n;
        let kept = get(&applied) / n;
        eprintln!(
            "{gen_edge:?} {:5.1} m: edge {edge:.3} measured {m:.3}; law {law:.3} applied {kept:.3} (n {n})",
            *k as f64 * BIN_M
        );
        worst = worst.max((edge - m).abs());
        // apply's kernel draws from the same law: binomial scatter only.
        let sd = (law * (1.0 - law) / n).sqrt();
        assert!(
            (kept - law).abs() < 5.0 * sd + 1e-3,
            "{gen_edge:?} bin {k}: applied {kept:.4} vs law {law:.4}"
        );
        bins += 1;
    }
    (worst, bins)
}

#[test]
fn probit_edge_fitted_is_the_edge_applied() {
    let (worst, bins) = round_trip(GenEdge::Probit, EdgeShape::Probit, 21);
    assert!(bins >= 8, "{bins} bins");
    assert!(worst < 0.04, "largest kept-fraction error {worst:.4}");
}

#[test]
fn logistic_edge_fitted_is_the_edge_applied() {
    let (worst, bins) = round_trip(GenEdge::Logistic, EdgeShape::Logistic, 22);
    assert!(bins >= 8, "{bins} bins");
    assert!(worst < 0.04, "largest kept-fraction error {worst:.4}");
}
