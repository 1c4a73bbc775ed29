//! Issue #12, "no edge here" and "honest intervals", on a source of truth
//! other than murk-fixtures: the 50 full revolutions of the real VLP-16
//! capture (`shared/data/real/vlp16-test-90deg-1-50-frames.pcap`), some
//! labelled clear (the reference), the others labelled fog at a MOR drawn
//! here, with weather applied — or not — by a hand-written known-answer
//! model that shares no code with the generator or with murk-infer:
//!
//! - *no weather*: the fog frames are clear frames. A slope reported there
//!   is a false positive (the issue measured 1.13 and 0.25 on main).
//! - *hard edge*: every return of a fog frame is kept iff its range is below
//!   `s_b · MOR` (the seed's law, `s_b` by reflectivity band), the MOR
//!   readings of the two visibility sensors carrying 5 % noise each. The
//!   fit must see the edge (power), give `s_b` back, and its 95 % interval
//!   over recordings must cover it.
//!
//! And the generator's no-weather campaign: fog whose vanishing distance
//! lies far beyond the scene.
//!
//! The scene is small (99 % of its returns within 12.7 m, none beyond
//! 25 m), so the MORs of the edge case are 8–120 m: the edge then lies
//! between 2.4 and 42 m and is seen in about half the recordings.

// These tests build campaigns on disk: fit/clippy.toml keeps I/O out of
// the library's statistics, not out of its tests.
#![allow(clippy::disallowed_methods, clippy::disallowed_types)]

mod common;

use std::fmt::Write as _;
use std::path::Path;

use murk_campaign::Campaign;
use murk_fit::FitParams;
use murk_io::{ReadOptions, read_frames, write_cloud};
use murk_types::{PointCloud, PointFormat, SlopeBand, WeatherClass, real_data};
use rand::{RngExt, SeedableRng, rngs::ChaCha8Rng};
use rand_distr::{Distribution, Normal};

const CAPTURE: &str = "vlp16-test-90deg-1-50-frames.pcap";

/// The full revolutions of the capture, or `None` (skipping) without the
/// real data.
fn revolutions() -> Option<Vec<PointCloud>> {
    let path = real_data::real_data_file(env!("CARGO_MANIFEST_DIR"), CAPTURE)?;
    let frames = read_frames(&path, &ReadOptions::default()).unwrap();
    // The first and last revolutions are partial.
    Some(frames[1..frames.len() - 1].to_vec())
}

const CAMPAIGN_TOML: &str = "name = \"vlp16-known-answer\"\n\
rules = \"pdd-2022-2023\"\n\
[lidar]\n\
model = \"VLP16\"\n\
range_scale = 1.0\n\
elevation_deg = [-15.0, 1.0, -13.0, 3.0, -11.0, 5.0, -9.0, 7.0, -7.0, 9.0, -5.0, 11.0, -3.0, 13.0, -1.0, 15.0]\n\
azimuth_resolution_deg = 0.2\n\
max_range_m = 100.0\n";

/// A hand-written weather: which returns of a fog frame at true `mor` stay.
#[derive(Debug, Clone, Copy)]
enum Weather {
    /// Every return stays.
    Nothing,
    /// Hard edge: kept iff range < slope(band) · MOR; bands [0, 10), [10, ∞).
    Hard { low: f64, high: f64 },
}

impl Weather {
    fn slope(&self, reflectivity: f32) -> Option<f64> {
        match *self {
            Weather::Nothing => None,
            Weather::Hard { low, high } => Some(if reflectivity < 10.0 { low } else { high }),
        }
    }
}

/// Writes a campaign of the revolutions: `clear` of them clear, the rest
/// fog at true MOR log-uniform on `mor_range`, read by two sensors with
/// relative noise `noise`. Returns the true MOR per fog recording id.
fn write_campaign(
    dir: &Path,
    revs: &[PointCloud],
    seed: u64,
    clear: usize,
    mor_range: [f64; 2],
    noise: f64,
    weather: Weather,
) {
    std::fs::create_dir_all(dir.join("lidar")).unwrap();
    std::fs::write(dir.join("campaign.toml"), CAMPAIGN_TOML).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n01 = Normal::new(0.0, 1.0).unwrap();
    // Which revolutions are clear: a seeded shuffle, so that labellings
    // differ between seeds.
    let mut order: Vec<usize> = (0..revs.len()).collect();
    for i in (1..order.len()).rev() {
        let j = rng.random_range(0..=i);
        order.swap(i, j);
    }
    let mut csv = String::from(
        "recording,timestamp,PWD12_Weather Type,PWD12_Rain intensity (mm/h),PWD12_MOR (m),PWD12_Temperature (°C),VS2K_MOR (m),WXT530_Rain intensity (mm/h)\n",
    );
    for (k, &i) in order.iter().enumerate() {
        let id = format!("r{i:04}");
        let mut cloud = revs[i].clone();
        let (kind, pwd, vs) = if k < clear {
            ("Clear", 20_000.0, 20_000.0)
        } else {
            let (a, b) = (mor_range[0].ln(), mor_range[1].ln());
            let mor = (a + (b - a) * rng.random_range(0.0..1.0)).exp();
            let read = |x: f64| (mor * (1.0 + noise * x)).clamp(1.0, 399.0);
            let (pwd, vs) = (read(n01.sample(&mut rng)), read(n01.sample(&mut rng)));
            let keep: Vec<bool> = (0..cloud.len())
                .map(|j| {
                    weather
                        .slope(cloud.intensity[j])
                        .is_none_or(|s| f64::from(cloud.range(j)) < s * mor)
                })
                .collect();
            cloud.retain_mask(&keep);
            ("Fog", pwd, vs)
        };
        writeln!(
            csv,
            "{id},2023-01-14T{:02}:{:02}:00Z,{kind},0,{pwd:.1},2.0,{vs:.1},0",
            k / 60,
            k % 60
        )
        .unwrap();
        write_cloud(
            &dir.join("lidar").join(format!("{id}.pcd")),
            &cloud,
            PointFormat::Pcd,
        )
        .unwrap();
    }
    std::fs::write(dir.join("weather.csv"), csv).unwrap();
}

/// The fog bands of the fitted table of a campaign written as
/// [`write_campaign`] says.
fn fog_bands(
    revs: &[PointCloud],
    seed: u64,
    mor_range: [f64; 2],
    noise: f64,
    weather: Weather,
) -> Vec<SlopeBand> {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("campaign");
    write_campaign(&dir, revs, seed, 16, mor_range, noise, weather);
    let campaign = Campaign::open(&dir).unwrap();
    let fitted = FitParams::default()
        .bootstrap_replicates(0)
        .require_edge(true)
        .check()
        .unwrap()
        .fit(&campaign)
        .unwrap();
    fitted.table().weathers[&WeatherClass::Fog]
        .vanishing_slope
        .clone()
}

fn describe(b: &SlopeBand) -> String {
    match (b.slope, &b.ci95) {
        (Some(s), Some(ci)) => format!("{s:.4} [{:.4}, {:.4}]", ci.low, ci.high),
        (Some(s), None) => format!("{s:.4} (no interval)"),
        (None, _) => format!("null: {}", b.reason.as_deref().unwrap_or("?")),
    }
}

/// (non-null slopes, bands) over `seeds` on relabelled clear frames at
/// MORs log-uniform on `mor_range`.
fn false_positives(
    revs: &[PointCloud],
    seeds: std::ops::Range<u64>,
    mor_range: [f64; 2],
) -> (usize, usize) {
    let (mut hits, mut n) = (0, 0);
    for seed in seeds {
        for b in fog_bands(revs, seed, mor_range, 0.03, Weather::Nothing) {
            n += 1;
            hits += usize::from(b.slope.is_some());
            eprintln!(
                "no weather, labelling {seed}, band {}: {}; edge test {:?}",
                b.reflectivity_min,
                describe(&b),
                b.edge_test
            );
        }
    }
    eprintln!("no weather: {hits}/{n} bands got a slope");
    (hits, n)
}

/// Over `seeds` with the hard edge: (slopes seen, intervals covering the
/// truth, bands, worst relative error of a slope).
fn known_edge(revs: &[PointCloud], seeds: std::ops::Range<u64>) -> (usize, usize, usize, f64) {
    let (low, high) = (0.30, 0.35);
    let (mut seen, mut covered, mut n, mut worst) = (0, 0, 0, 0.0f64);
    for seed in seeds {
        let bands = fog_bands(revs, seed, [8.0, 120.0], 0.05, Weather::Hard { low, high });
        for b in bands {
            let truth = if b.reflectivity_min < 10.0 { low } else { high };
            n += 1;
            if let Some(s) = b.slope {
                seen += 1;
                worst = worst.max((s / truth - 1.0).abs());
                covered += usize::from(
                    b.ci95
                        .as_ref()
                        .is_some_and(|c| c.low <= truth && truth <= c.high),
                );
            }
            eprintln!(
                "hard edge, seed {seed}, band {}: truth {truth}, {}; edge test {:?}",
                b.reflectivity_min,
                describe(&b),
                b.edge_test
            );
        }
    }
    eprintln!(
        "hard edge: seen {seen}/{n}, covered {covered}/{seen}, worst error {:.2} %",
        100.0 * worst
    );
    (seen, covered, n, worst)
}

#[test]
fn real_clear_frames_labelled_fog_get_no_slope() {
    let Some(revs) = revolutions() else { return };
    let (hits, n) = false_positives(&revs, 0..3, [9.0, 390.0]);
    // The test is one-sided at 1 %: a slope in more than one of 6 bands
    // means it does not hold its level.
    assert!(
        hits <= 1,
        "{hits}/{n} bands of a weather that does nothing got a slope"
    );
}

/// The same at nearly one MOR (20–22 m, where an edge of slope 0.3–1
/// would lie amid the scene): r/MOR cannot be told from range, so the edge
/// is tested against constant survival — which the far returns' own
/// flicker must not pass for.
#[test]
fn real_clear_frames_labelled_fog_at_one_mor_get_no_slope() {
    let Some(revs) = revolutions() else { return };
    let (hits, n) = false_positives(&revs, 10..13, [20.0, 22.0]);
    assert!(
        hits <= 1,
        "{hits}/{n} bands of a weather that does nothing got a slope"
    );
}

#[test]
fn real_frames_with_a_hand_written_edge_give_it_back() {
    let Some(revs) = revolutions() else { return };
    let (seen, covered, n, worst) = known_edge(&revs, 0..3);
    assert_eq!(seen, n, "the edge was not seen in every band");
    assert!(worst < 0.05, "worst slope error {:.2} %", 100.0 * worst);
    // 6 intervals at 95 %: P(≤ 3 covered) < 0.3 %.
    assert!(covered >= 4, "covered {covered}/{seen}");
}

#[test]
#[ignore = "the measurement behind the report: 20 labellings and 20 seeds"]
fn real_frames_false_positive_rate_and_power() {
    let Some(revs) = revolutions() else { return };
    let (hits, n) = false_positives(&revs, 100..120, [9.0, 390.0]);
    let (hits_narrow, n_narrow) = false_positives(&revs, 200..210, [20.0, 22.0]);
    eprintln!("SUMMARY narrow MOR: false positives {hits_narrow}/{n_narrow}");
    let (seen, covered, m, worst) = known_edge(&revs, 100..120);
    eprintln!(
        "SUMMARY false positives {hits}/{n}; power {seen}/{m}; coverage {covered}/{seen}; worst error {:.2} %",
        100.0 * worst
    );
    assert!(hits * 20 <= n, "false-positive rate {hits}/{n}");
    assert!(seen * 10 >= m * 9, "power {seen}/{m}");
}

/// The generator's fog with its vanishing distance far beyond the scene
/// (slope 100: 900 m at the smallest MOR): nothing but clear dropout
/// removes returns, so no band may get a slope.
#[test]
fn generated_fog_that_does_nothing_gets_no_slope() {
    use murk_fixtures::{Generator, OutputOptions};
    let (mut hits, mut n) = (0, 0);
    for seed in [31, 32, 33] {
        let mut c = common::fog_campaign();
        for b in &mut c.degradation.fog.bands {
            b.slope = 100.0;
        }
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("campaign");
        Generator::new(c)
            .unwrap()
            .write_campaign(seed, &OutputOptions::new(&dir))
            .unwrap();
        let fitted = FitParams::default()
            .bootstrap_replicates(0)
            .require_edge(true)
            .check()
            .unwrap()
            .fit(&Campaign::open(&dir).unwrap())
            .unwrap();
        for b in &fitted.table().weathers[&WeatherClass::Fog].vanishing_slope {
            n += 1;
            hits += usize::from(b.slope.is_some());
            eprintln!(
                "generated no weather, seed {seed}, band {}: {}; edge test {:?}",
                b.reflectivity_min,
                describe(b),
                b.edge_test
            );
        }
    }
    assert_eq!(
        hits, 0,
        "{hits}/{n} bands of a weather that does nothing got a slope"
    );
}
