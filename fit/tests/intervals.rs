//! Coverage of the slope intervals over recordings (issue #12) on generated
//! campaigns whose visibility sensors read MOR with 7.5 % noise: how often
//! the 95 % interval of each ML slope covers the true slope, and the mean
//! estimate over seeds (measured figures at the 40-seed tests).
//!
//! The full check (40 seeds) is `#[ignore]`d for the normal test run; run it
//! with `cargo test -p murk-fit --test intervals -- --ignored`. The fast
//! version checks fewer seeds at a looser bound, and that the intervals are
//! not the independent-returns ones (which cover almost never).

mod common;

use murk_campaign::Campaign;
use murk_fit::FitParams;
use murk_fixtures::{Generator, GeneratorConfig, OutputOptions};
use murk_types::WeatherClass;

/// The campaign: 40 recordings, 70 % fog, MOR read with `mor_noise`; with
/// `one_slope` both bands vanish at the low band's slope (no band mixing).
fn config(mor_noise: f64, one_slope: bool) -> GeneratorConfig {
    let mut c = common::fog_campaign();
    c.weather.mor_noise_rel = mor_noise;
    if one_slope {
        let s = c.degradation.fog.bands[0].slope;
        for b in &mut c.degradation.fog.bands {
            b.slope = s;
        }
    }
    c
}

/// One band of one seed: (truth, slope, low, high, independent SE).
type Row = (f64, f64, f64, f64, f64);

/// Per seed and band: (truth, slope, low, high, independent SE).
fn intervals(seed: u64, mor_noise: f64, one_slope: bool) -> Vec<Row> {
    let cfg = config(mor_noise, one_slope);
    let generator = Generator::new(cfg.clone()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("campaign");
    generator
        .write_campaign(seed, &OutputOptions::new(&path))
        .unwrap();
    let campaign = Campaign::open(&path).unwrap();
    let fitted = FitParams::default()
        .bootstrap_replicates(0)
        .check()
        .unwrap()
        .fit(&campaign)
        .unwrap();
    let fog = &fitted.table().weathers[&WeatherClass::Fog];
    let model = &cfg.degradation.fog;
    fog.vanishing_slope
        .iter()
        .map(|b| {
            let truth = model.slope_at(b.reflectivity_min + 0.5);
            let s = b
                .slope
                .unwrap_or_else(|| panic!("seed {seed}: null slope: {:?}", b.reason));
            let ci = b.ci95.as_ref().expect("interval");
            (
                truth,
                s,
                ci.low,
                ci.high,
                b.std_error_independent.unwrap_or(f64::NAN),
            )
        })
        .collect()
}

/// Coverage over seeds: intervals covering the truth, intervals in all,
/// independent-returns intervals covering the truth, and intervals covering
/// the mean estimate of their band over the seeds (what the width alone
/// answers for: the estimator's own bias is not in any interval).
#[derive(Debug, Clone, Copy)]
struct Coverage {
    truth: usize,
    n: usize,
    independent: usize,
    mean: usize,
}

fn coverage(seeds: std::ops::Range<u64>, mor_noise: f64, one_slope: bool) -> Coverage {
    let mut all: Vec<Vec<Row>> = Vec::new();
    for seed in seeds.clone() {
        let v = intervals(seed, mor_noise, one_slope);
        for (t, s, lo, hi, _) in &v {
            eprintln!(
                "seed {seed}: truth {t:.4} slope {s:.4} [{lo:.4}, {hi:.4}] ({:+.2} %)",
                100.0 * (s / t - 1.0)
            );
        }
        all.push(v);
    }
    let bands = all.first().map_or(0, Vec::len);
    let mut c = Coverage {
        truth: 0,
        n: 0,
        independent: 0,
        mean: 0,
    };
    for b in 0..bands {
        let mean = all.iter().map(|v| v[b].1).sum::<f64>() / all.len() as f64;
        let bias = mean / all[0][b].0 - 1.0;
        eprintln!(
            "band {b}: mean estimate {mean:.4}, bias {:+.2} %",
            100.0 * bias
        );
        for v in &all {
            let (t, s, lo, hi, se) = v[b];
            c.n += 1;
            c.truth += usize::from(lo <= t && t <= hi);
            c.independent += usize::from((s - t).abs() <= 1.96 * se);
            c.mean += usize::from(lo <= mean && mean <= hi);
        }
    }
    eprintln!(
        "SUMMARY noise {mor_noise}, one slope {one_slope}: covered truth {}/{}, mean estimate {}/{}; independent-returns intervals {}/{}",
        c.truth, c.n, c.mean, c.n, c.independent, c.n
    );
    c
}

#[test]
fn intervals_over_recordings_cover_the_truth_fast() {
    let c = coverage(100..106, 0.075, false);
    // 12 intervals: at the measured 84 % coverage of the truth (see the
    // 40-seed test) P(≤ 7 covered) ≈ 2 %; at the independent-returns
    // intervals' ~25 % it is certain.
    assert!(c.truth >= 8, "{c:?}");
    assert!(c.independent < c.truth, "{c:?}");
}

/// Measured (seeds 200–239, 80 intervals): the truth is covered 67 times
/// (84 %), the independent-returns intervals 20 times (25 %). Most of the
/// shortfall from 95 % is the estimator's own bias, which no interval
/// contains: the low band comes out +1.6 % high on average (+0.9 % with
/// exact MOR readings, where the intervals are narrower and cover the truth
/// 60 % of the time). The width alone is checked by the coverage of the
/// mean estimate: 72/80 (90 %); a sandwich over ~28 recordings runs a
/// little narrow (a grouped jackknife over recordings gave 75/80 at three
/// times the fitting time, and 71/80 in the one-slope campaign).
#[test]
#[ignore = "40 seeds: run with --ignored"]
fn intervals_over_recordings_cover_the_truth_40_seeds() {
    let c = coverage(200..240, 0.075, false);
    let rate = |k: usize| k as f64 / c.n as f64;
    assert!(rate(c.truth) >= 0.80, "{c:?}");
    assert!((0.85..=0.99).contains(&rate(c.mean)), "{c:?}");
}

/// The same with one slope in both bands (no reflectivity-band mixing):
/// measured 70/80 covering the truth, 71/80 the mean estimate (bias +1.3 %
/// and +0.3 %): band mixing is not what biases the low band.
#[test]
#[ignore = "40 seeds, one slope in both bands: run with --ignored"]
fn intervals_cover_the_truth_without_band_mixing_40_seeds() {
    let c = coverage(200..240, 0.075, true);
    let rate = |k: usize| k as f64 / c.n as f64;
    assert!(rate(c.truth) >= 0.80, "{c:?}");
    assert!((0.85..=0.99).contains(&rate(c.mean)), "{c:?}");
}
