//! Intervals of the seed's quantile slope (`vanishing_slope_q99`, issue
//! #12: "intervals over recordings for every fitted number"): a
//! delete-a-group jackknife over the used MOR bins of recordings. Checked
//! by how often each seed's 95 % interval covers the estimator's mean over
//! the seeds — what the width answers for; the quantile estimator's own
//! bias against the true vanishing distance (the 0.99 quantile of the
//! survivors is not the edge) is in no interval — on two sources: murk's
//! generator with 7.5 % MOR noise, and the real VLP-16 scene with
//! synthetic fog (skipped, saying so, when `../shared/data/real` is
//! absent). An interval a hundred times too narrow, as the
//! independent-returns ones were, would cover almost never.
//!
//! The measurements over 40 seeds are `#[ignore]`d:
//! `cargo test -p murk-fit --test q99_intervals -- --ignored`.

#![allow(clippy::disallowed_methods, clippy::disallowed_types)]

mod common;

use std::path::Path;

use murk_campaign::Campaign;
use murk_fit::FitParams;
use murk_fixtures::semi_real::{self, SemiRealConfig};
use murk_fixtures::{Generator, OutputOptions};
use murk_types::WeatherClass;

/// Per band: the q99 slope and its interval, `None` where either is null.
type Row = Option<(f64, f64, f64)>;

fn fit_q99(path: &Path, mor_bin_m: f64) -> Vec<Row> {
    let campaign = Campaign::open(path).unwrap();
    let fitted = FitParams::default()
        .bootstrap_replicates(0)
        .mor_bin_width_m(mor_bin_m)
        .compare_laws(false)
        .check()
        .unwrap()
        .fit(&campaign)
        .unwrap();
    let fog = &fitted.table().weathers[&WeatherClass::Fog];
    fog.vanishing_slope_q99
        .iter()
        .map(|b| {
            let s = b.slope?;
            let ci = b.ci95.as_ref()?;
            assert!(ci.low < s && s < ci.high, "{s} {ci:?}");
            assert!(ci.method.contains("jackknife"), "{}", ci.method);
            Some((s, ci.low, ci.high))
        })
        .collect()
}

fn generated(seed: u64) -> Vec<Row> {
    let mut c = common::fog_campaign();
    c.weather.mor_noise_rel = 0.075;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("campaign");
    Generator::new(c)
        .unwrap()
        .write_campaign(seed, &OutputOptions::new(&path))
        .unwrap();
    fit_q99(&path, 10.0)
}

fn semi_real_fog(capture: &Path, seed: u64) -> Vec<Row> {
    let dir = tempfile::tempdir().unwrap();
    // The real scene is small (90 % of its returns within 7.3 m, none
    // beyond 24 m): its fog must be dense for the quantiles to see the
    // weather rather than the end of the scene, and its MOR bins narrow.
    let cfg = SemiRealConfig {
        degraded: 30,
        mor_m: [4.0, 30.0],
        mor_noise_rel: 0.075,
        ..SemiRealConfig::default()
    };
    semi_real::vlp16_campaign(capture, dir.path(), &cfg, seed).unwrap();
    fit_q99(dir.path(), 3.0)
}

/// Intervals covering their band's mean estimate over the seeds, intervals
/// in all (bands with a slope and an interval), and the widest ratio of a
/// band's mean half-width to 1.96 times its slopes' spread over the seeds
/// (about 1 for an interval of the right width).
fn coverage(what: &str, rows: &[Vec<Row>]) -> (usize, usize, f64) {
    let bands = rows.iter().map(Vec::len).max().unwrap_or(0);
    let (mut covered, mut n, mut ratio) = (0, 0, 0f64);
    for b in 0..bands {
        let got: Vec<(f64, f64, f64)> = rows
            .iter()
            .filter_map(|r| r.get(b).copied().flatten())
            .collect();
        if got.len() < 3 {
            eprintln!(
                "{what} band {b}: {} seeds with an interval, skipped",
                got.len()
            );
            continue;
        }
        let mean = got.iter().map(|g| g.0).sum::<f64>() / got.len() as f64;
        let sd =
            (got.iter().map(|g| (g.0 - mean).powi(2)).sum::<f64>() / (got.len() - 1) as f64).sqrt();
        let half = got.iter().map(|g| 0.5 * (g.2 - g.1)).sum::<f64>() / got.len() as f64;
        let c = got.iter().filter(|g| g.1 <= mean && mean <= g.2).count();
        eprintln!(
            "{what} band {b}: mean slope {mean:.4}, spread over seeds {sd:.4}, mean half-width {half:.4} (1.96·spread {:.4}); {c}/{} intervals cover the mean",
            1.96 * sd,
            got.len()
        );
        covered += c;
        n += got.len();
        ratio = ratio.max(half / (1.96 * sd));
    }
    eprintln!("SUMMARY {what}: {covered}/{n}, widest half-width / (1.96 spread) {ratio:.2}");
    (covered, n, ratio)
}

#[test]
fn q99_intervals_cover_the_estimators_mean() {
    let rows: Vec<Vec<Row>> = (300..308).map(generated).collect();
    let (c, n, wide) = coverage("generator", &rows);
    // At 95 % coverage P(≤ 70 % of 16) is below 0.1 %; intervals too
    // narrow by a factor of three would cover about 35 %. Nor may they be
    // uselessly wide (measured 1.3 and 1.5; the spread of 8 seeds is
    // itself uncertain by about a quarter).
    assert!(n >= 12, "{n} intervals");
    assert!(c as f64 >= 0.7 * n as f64, "generator: {c}/{n}");
    assert!(wide < 2.5, "generator: intervals {wide:.2} times too wide");
    let Some(capture) = semi_real::vlp16_capture(env!("CARGO_MANIFEST_DIR")) else {
        eprintln!("SKIP the real-scene half: ../shared/data/real is absent");
        return;
    };
    let rows: Vec<Vec<Row>> = (310..318).map(|s| semi_real_fog(&capture, s)).collect();
    let (c, n, wide) = coverage("real scene, synthetic fog", &rows);
    assert!(n >= 6, "{n} intervals");
    assert!(c as f64 >= 0.7 * n as f64, "real scene: {c}/{n}");
    assert!(wide < 2.5, "real scene: intervals {wide:.2} times too wide");
}

/// Measured (session 12): generator (seeds 400–439) 74/80 intervals hold
/// the mean estimate (92.5 %), half-width 1.07–1.14 times 1.96 × the
/// spread over seeds; the mean estimate sits 4 % below the true low-band
/// slope (0.2905 against 0.303: the 0.99 quantile of the survivors lies
/// short of the edge), which no interval holds. Real scene with synthetic
/// fog (seeds 440–479): 77/80 (96 %), half-width up to 1.5 times: the
/// jackknife over a few MOR bins is conservative there.
#[test]
#[ignore = "40 seeds per source: run with --ignored"]
fn q99_intervals_cover_the_estimators_mean_40_seeds() {
    let rows: Vec<Vec<Row>> = (400..440).map(generated).collect();
    let (c, n, _) = coverage("generator", &rows);
    assert!(c as f64 >= 0.85 * n as f64, "generator: {c}/{n}");
    if let Some(capture) = semi_real::vlp16_capture(env!("CARGO_MANIFEST_DIR")) {
        let rows: Vec<Vec<Row>> = (440..480).map(|s| semi_real_fog(&capture, s)).collect();
        let (c, n, _) = coverage("real scene, synthetic fog", &rows);
        assert!(c as f64 >= 0.85 * n as f64, "real scene: {c}/{n}");
    }
}
