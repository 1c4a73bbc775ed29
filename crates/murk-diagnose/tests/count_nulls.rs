//! Campaigns with nothing hidden must not show a count × MOR finding (issue
//! #12, #13), nor a count along the rays (per laser, elevation or azimuth
//! sector, #13 item 3): the count law's family (power or onset, chosen by held-out
//! likelihood) and its intervals over recordings leave no MOR profile in the
//! held-out count residuals.
//!
//! "Flagged" is the permutation test's own verdict before the stagewise
//! step can turn a term down: Holm-adjusted p < 0.05 and an effect at
//! least the relevance threshold (strength ≥ 1). Sources: generated
//! campaigns (56 recordings at 1°, three quarters in the weather; fog seeds
//! 41–43 and rain seed 44), and the semi-real source (the real VLP-16
//! revolutions weathered by the ground-truth fog model, spread over the
//! capture), when the capture is present. Tolerance: no seed may flag
//! count × MOR nor a count along the rays.

use murk_campaign::Campaign;
use murk_diagnose::{DiagnoseParams, Diagnosis};
use murk_fixtures::semi_real::{SemiRealConfig, vlp16_campaign, vlp16_capture};
use murk_fixtures::{Generator, GeneratorConfig, OutputOptions, PerClass, Preset};
use murk_types::{ExtensionObservable, WeatherClass};
use std::path::Path;

fn diagnose(dir: &Path, weather: WeatherClass, seed: u64) -> Diagnosis {
    let campaign = Campaign::open(dir).unwrap();
    DiagnoseParams::new(weather)
        .seed(seed)
        .check()
        .unwrap()
        .run(&campaign)
        .unwrap()
}

fn generated(weather: WeatherClass, seed: u64) -> Diagnosis {
    generated_n(weather, seed, 56)
}

fn generated_n(weather: WeatherClass, seed: u64, recordings: usize) -> Diagnosis {
    let mut c = GeneratorConfig::preset(Preset::Small);
    c.campaign.recordings = recordings;
    let (f, r) = match weather {
        WeatherClass::Fog => (0.75, 0.0),
        _ => (0.0, 0.75),
    };
    c.weather.mix = PerClass {
        clear: 0.25,
        fog: f,
        rain: r,
        snow: 0.0,
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("campaign");
    Generator::new(c)
        .unwrap()
        .write_campaign(seed, &OutputOptions::new(&out))
        .unwrap();
    diagnose(&out, weather, seed)
}

/// The count × MOR test's line, and whether it is flagged.
fn count_mor(d: &Diagnosis, source: &str) -> (String, bool) {
    let f = d
        .report
        .findings
        .iter()
        .find(|f| f.observable == ExtensionObservable::Count && f.covariate == "mor");
    match f {
        Some(f) => {
            let flagged = f.p_adjusted < 0.05 && f.strength >= 1.0;
            (
                format!(
                    "{source}: count × mor p {:.4}, Holm {:.4}, strength {:.2}, significant {}, flagged {flagged}",
                    f.p_value, f.p_adjusted, f.strength, f.significant
                ),
                flagged,
            )
        }
        None => (format!("{source}: count × mor not tested"), false),
    }
}

/// The point-level count tests (per laser, elevation, azimuth sector,
/// range bin): their lines, and whether any is flagged or significant.
fn count_rays(d: &Diagnosis, source: &str) -> (String, bool) {
    let mut line = format!("{source}:");
    let mut any = false;
    for f in d.report.findings.iter().filter(|f| {
        f.observable == ExtensionObservable::Count
            && murk_types::POINT_COVARIATES.contains(&f.covariate.as_str())
    }) {
        let flagged = (f.p_adjusted < 0.05 && f.strength >= 1.0) || f.significant;
        any |= flagged;
        line.push_str(&format!(
            " count × {} p {:.4}, Holm {:.4}, strength {:.2}, flagged {flagged};",
            f.covariate, f.p_value, f.p_adjusted, f.strength
        ));
    }
    (line, any)
}

#[test]
fn null_campaigns_show_no_count_along_mor() {
    let mut lines = Vec::new();
    let mut flagged = 0;
    for (weather, seed) in [
        (WeatherClass::Fog, 41),
        (WeatherClass::Fog, 42),
        (WeatherClass::Fog, 43),
        (WeatherClass::Rain, 44),
    ] {
        let d = generated(weather, seed);
        let (line, f) = count_mor(&d, &format!("generated {weather} seed {seed}"));
        eprintln!("{line}");
        lines.push(line);
        flagged += usize::from(f);
        // Nothing hidden along the rays either (issue #13 item 3).
        let (line, f) = count_rays(&d, &format!("generated {weather} seed {seed}"));
        eprintln!("{line}");
        lines.push(line);
        flagged += usize::from(f);
    }
    if let Some(capture) = vlp16_capture(env!("CARGO_MANIFEST_DIR")) {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("semi-real");
        let cfg = SemiRealConfig {
            declared_azimuth_deg: 0.4,
            interleave_revolutions: true,
            ..SemiRealConfig::default()
        };
        vlp16_campaign(&capture, &out, &cfg, 45).unwrap();
        let d = diagnose(&out, WeatherClass::Fog, 45);
        let (line, f) = count_mor(&d, "semi-real fog seed 45");
        eprintln!("{line}");
        lines.push(line);
        flagged += usize::from(f);
        // Nothing along the rays either. (Flagged before — count × range
        // 1.60, × azimuth 1.20 — while the fixture drew the weather's
        // returns only on firings with a scene return, fit's count laws
        // did not see the near scene's mask, and the point tests read a
        // log ratio biased low in sparse bins; see murk-diagnose's lib
        // docs.)
        let (line, f) = count_rays(&d, "semi-real fog seed 45");
        eprintln!("{line}");
        lines.push(line);
        flagged += usize::from(f);
    }
    assert_eq!(flagged, 0, "{lines:#?}");
}

/// A fog campaign whose MOR readings all fall in 60–74 m (as narrow in
/// ln MOR as the real capture's 304–378 m, but dense enough for every
/// band's edge to lie in the scene, so the slopes exist), with few ghost
/// returns and no ring return at all: fit gives a finite count law or a
/// null one with its reason (never a failed table), `murk apply`'s applier
/// builds from it and adds near-range returns, and the diagnosis runs.
#[test]
fn a_narrow_mor_range_and_a_weather_without_ring_returns_run_end_to_end() {
    use murk_fixtures::Law;
    use murk_infer::{ApplyParams, Severity};
    let mut c = GeneratorConfig::preset(Preset::Small);
    c.campaign.recordings = 40;
    c.weather.mix = PerClass {
        clear: 0.25,
        fog: 0.75,
        rain: 0.0,
        snow: 0.0,
    };
    c.weather.mor_m.fog = Law::Uniform {
        min: 60.0,
        max: 74.0,
    };
    c.degradation.fog.ghost.count.n_ref = 1.0;
    c.degradation.fog.ring.count.n_ref = 0.0;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("campaign");
    Generator::new(c)
        .unwrap()
        .write_campaign(5, &OutputOptions::new(&out))
        .unwrap();
    let campaign = Campaign::open(&out).unwrap();
    let fitted = murk_fit::FitParams::default()
        .bootstrap_replicates(20)
        .check()
        .unwrap()
        .fit(&campaign)
        .unwrap();
    let table = fitted.table().clone();
    let fog = &table.weathers[&WeatherClass::Fog];
    assert!(fog.ring.is_none() && fog.ring_reason.is_some(), "{fog:?}");
    let ghost = fog.ghost.as_ref().expect("a few ghost returns");
    if ghost.count_law.is_none() {
        let r = ghost.count_law_reason.as_deref().unwrap();
        assert!(r.starts_with("not identifiable"), "{r}");
    }
    eprintln!(
        "narrow: ghost count law {:?}, reason {:?}",
        ghost.count_law, ghost.count_law_reason
    );
    // Apply at a MOR inside and one far outside the range.
    let mut cloud = murk_types::PointCloud::with_capacity(16 * 360);
    let spec = murk_types::LidarSpec::vlp16();
    for bin in 0..360 {
        let az = (bin as f64).to_radians();
        for (ring, el) in spec.elevation_deg.iter().enumerate() {
            let el = el.to_radians();
            let r = 20.0 / el.cos();
            cloud.push(
                (r * el.cos() * az.cos()) as f32,
                (r * el.cos() * az.sin()) as f32,
                (r * el.sin()) as f32,
                40.0,
                ring as u16,
            );
        }
    }
    for mor in [67.0, 500.0, 10.0] {
        let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(mor))
            .near_range(true)
            .seed(1)
            .build(&table)
            .unwrap();
        let (_, s) = a.apply(&cloud, "scan").unwrap();
        let g = s.ghost.expect("ghost returns are applied");
        assert!(g.expected.is_finite(), "{g:?}");
    }
    let d = diagnose(&out, WeatherClass::Fog, 5);
    let (line, _) = count_mor(&d, "narrow fog seed 5");
    eprintln!("{line}");
}

/// The same check on larger null campaigns (160 recordings: more power to
/// see a count law's misfit), fog seeds 51–52. Run with `--ignored`.
#[test]
#[ignore = "larger campaigns: run with --ignored"]
fn larger_null_campaigns_show_no_count_along_mor() {
    let mut lines = Vec::new();
    let mut flagged = 0;
    for seed in [51, 52] {
        let d = generated_n(WeatherClass::Fog, seed, 160);
        let (line, f) = count_mor(&d, &format!("generated fog seed {seed}, 160 recordings"));
        eprintln!("{line}");
        lines.push(line);
        flagged += usize::from(f);
    }
    assert_eq!(flagged, 0, "{lines:#?}");
}
