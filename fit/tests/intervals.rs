//! Coverage of the slope intervals over recordings (issue #12) on generated
//! campaigns whose visibility sensors read MOR with 7.5 % noise: how often
//! the 95 % interval of each ML slope covers the true slope, and the mean
//! estimate over seeds (measured figures at the 40-seed tests; the
//! intervals are the leave-one-recording-out "CR3" form of
//! `murk_fit::survival::robust_covariance`).
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
    fit_rows(seed, config(mor_noise, one_slope))
}

/// The rows of the campaign of `cfg` at `seed`.
fn fit_rows(seed: u64, cfg: GeneratorConfig) -> Vec<Row> {
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
        // The spread of the estimates over seeds against the standard
        // errors the intervals stand for (half-width / t of G − 1 ≈ 27).
        let sd = (all.iter().map(|v| (v[b].1 - mean).powi(2)).sum::<f64>()
            / (all.len() as f64 - 1.0))
            .sqrt();
        let se = (all
            .iter()
            .map(|v| ((v[b].3 - v[b].2) / (2.0 * 2.05)).powi(2))
            .sum::<f64>()
            / all.len() as f64)
            .sqrt();
        eprintln!(
            "band {b}: mean estimate {mean:.4}, bias {:+.2} %; sd over seeds {sd:.5}, rms interval se {se:.5} (ratio {:.3})",
            100.0 * bias,
            sd / se
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
    // 12 intervals: at the measured 90 % coverage of the truth (see the
    // 40-seed test) P(≤ 7 covered) ≈ 0.4 %; at the independent-returns
    // intervals' ~20 % it is certain.
    assert!(c.truth >= 8, "{c:?}");
    assert!(c.independent < c.truth, "{c:?}");
}

/// Seeds 200–239: the intervals cover the truth in 90–99 % of them (the
/// issue's acceptance) and the seeds' mean estimate in 85–99 %.
fn coverage_over_40_seeds(mor_noise: f64, one_slope: bool) {
    let c = coverage(200..240, mor_noise, one_slope);
    let rate = |k: usize| k as f64 / c.n as f64;
    assert!((0.90..=0.99).contains(&rate(c.truth)), "{c:?}");
    assert!((0.85..=0.99).contains(&rate(c.mean)), "{c:?}");
}

/// Measured (seeds 200–239, 80 intervals): the truth is covered 72 times
/// (90 %), the mean estimate over seeds 73 times; the independent-returns
/// intervals cover the truth 16 times (20 %). The spread of the slopes over
/// seeds is 0.98–1.01 times the standard error the intervals stand for
/// (1.09–1.12 with the plain sandwich they replaced, which covered the
/// truth as often and the mean estimate 71 times). The shortfall from 95 %
/// is the estimator's bias under MOR noise, which no interval contains:
/// +0.57 % (low band) and +0.24 %, where exact MOR readings give +0.03 %
/// and −0.26 % (`intervals_with_exact_mor_40_seeds`). Fitting `r / MOR'`
/// with a reading `MOR' = MOR·(1 + ε)` puts the edge at `s / (1 + ε)`,
/// whose mean over recordings is `s·(1 + σ²)` — +0.3 % for the mean of two
/// sensors with 7.5 % noise each: an errors-in-variables bias of order σ²,
/// small against the statistical error at campaign sizes, and not
/// corrected (murk-fit's crate doc, "Errors in variables", says why).
#[test]
#[ignore = "40 seeds: run with --ignored"]
fn intervals_over_recordings_cover_the_truth_40_seeds() {
    coverage_over_40_seeds(0.075, false);
}

/// The same with one slope in both bands (no reflectivity-band mixing):
/// measured 73/80 covering the truth, 75/80 the mean estimate (bias +0.55 %
/// and +0.53 %, spread / standard error 0.98): band mixing is not what
/// biases the slopes.
#[test]
#[ignore = "40 seeds, one slope in both bands: run with --ignored"]
fn intervals_cover_the_truth_without_band_mixing_40_seeds() {
    coverage_over_40_seeds(0.075, true);
}

/// The same with exact MOR readings: measured 74/80 covering the truth
/// and the mean estimate (bias +0.03 % and −0.26 %; spread / standard
/// error 0.75 and 1.12, standard errors a fifth of the noisy campaign's).
#[test]
#[ignore = "40 seeds, exact MOR: run with --ignored"]
fn intervals_with_exact_mor_40_seeds() {
    coverage_over_40_seeds(0.0, false);
}

/// Errors in both variables at once (issue #12): each visibility sensor
/// reads MOR with 10 % noise and reflectivities carry 5 % relative noise
/// (the generator's default is 3 %), so returns near the band edge at 10
/// are assigned to the wrong band now and then. At this MOR noise a single
/// campaign's slope is only good to about 3 % (its standard error), so
/// what is checked is what the estimator promises: its intervals over
/// recordings cover the truth, and its mean over the seeds stays within
/// 2 % of the truth in each band (the errors-in-variables bias is of order
/// σ², see the 40-seed test).
#[test]
fn slopes_hold_with_noisy_mor_and_reflectivity() {
    let (mut covered, mut n) = (0, 0);
    let mut err_sum = [0.0f64; 2];
    let seeds = 300..306;
    for seed in seeds.clone() {
        let mut cfg = config(0.10, false);
        cfg.sensor.reflectivity_noise_rel = 0.05;
        let rows = fit_rows(seed, cfg);
        assert_eq!(rows.len(), 2);
        for (b, (t, s, lo, hi, _)) in rows.into_iter().enumerate() {
            let err = s / t - 1.0;
            eprintln!(
                "noisy MOR and reflectivity, seed {seed}: truth {t:.4} slope {s:.4} [{lo:.4}, {hi:.4}] ({:+.2} %)",
                100.0 * err
            );
            err_sum[b] += err;
            n += 1;
            covered += usize::from(lo <= t && t <= hi);
        }
    }
    let k = seeds.count() as f64;
    let mean: Vec<f64> = err_sum.iter().map(|e| e / k).collect();
    eprintln!("covered {covered}/{n}; mean error per band {mean:?}");
    for m in &mean {
        assert!(m.abs() <= 0.02, "mean error {mean:?}");
    }
    // 12 intervals at 95 %: P(≤ 8 covered) < 0.2 %.
    assert!(covered >= 9, "{covered}/{n}");
}
