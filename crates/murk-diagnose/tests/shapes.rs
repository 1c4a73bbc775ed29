//! Extension terms of the right shape (issue #13 item 4): where the hidden
//! mechanism has a known parametric form, diagnose must choose that form
//! and recover its parameter; where it is a step, the piecewise shapes must
//! stay (or the shape chosen must not lose on held-out recordings).
//!
//! Sources with known truth:
//! - the generator's two-way attenuation of intensity along range
//!   (`EffectFunction::TwoWayAttenuation { k: 1.5 }`: `exp(−2·1.5·r/MOR)`,
//!   so the term's `k` is 3.0), seeds 14 and 15;
//! - the physics fog on the real VLP-16 scene with the lidar equation's
//!   two-way transmission on every kept return's reflectivity
//!   (`PhysicsFog::attenuate_intensity`: `exp(−2αr)`, `α = ln 20/MOR`, so
//!   `k = 2·ln 20 ≈ 5.99`), seed 61 (62 with `--ignored`); skipped without
//!   the capture;
//! - the generator's wet road (survival × elevation, a step at −6° to 0.6),
//!   seed 11 (13 with `--ignored`).
//!
//! Tolerances: `k` within 5 % of the truth (generated) and 15 % (physics:
//! reflectivities are floored at 0.5 before the log ratio, which shortens
//! the deepest attenuation).

mod common;

use murk_campaign::Campaign;
use murk_diagnose::{DiagnoseParams, Diagnosis, Step};
use murk_fixtures::physics_fog::PhysicsFog;
use murk_fixtures::semi_real::{SemiRealConfig, vlp16_campaign, vlp16_capture};
use murk_fixtures::{
    EffectFunction, EffectSpec, Generator, GeneratorConfig, Observable, OutputOptions, PerClass,
    Preset,
};
use murk_types::{ExtensionFunction, WeatherClass};
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

fn generated(weather: WeatherClass, effect: EffectSpec, seed: u64) -> Diagnosis {
    let mut c = GeneratorConfig::preset(Preset::Small);
    c.campaign.recordings = 56;
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
    c.effects = vec![effect];
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("campaign");
    Generator::new(c)
        .unwrap()
        .write_campaign(seed, &OutputOptions::new(&out))
        .unwrap();
    diagnose(&out, weather, seed)
}

fn describe(s: &Step) -> String {
    let shapes: Vec<String> = s
        .shapes
        .iter()
        .map(|t| {
            format!(
                "{}{} ({} par) loss {:.6} p_worse {:?}",
                if t.chosen { "*" } else { "" },
                t.shape,
                t.parameters,
                t.held_out_loss,
                t.p_worse_than_best
            )
        })
        .collect();
    format!(
        "{} × {}: {} {:?}; gain {:+.3}; shapes {shapes:#?}",
        s.observable, s.covariate, s.shape, s.parameters, s.gain.relative
    )
}

/// The accepted intensity step along range must be the attenuation form
/// with `k` within `tol` (relative) of `truth`, not lose to the bins held
/// out, and the table must hold the same term.
fn expect_attenuation(d: &Diagnosis, truth: f64, tol: f64, source: &str) -> f64 {
    let r = &d.report;
    let steps: Vec<String> = r.steps.iter().map(describe).collect();
    eprintln!("{source}: {steps:#?}");
    let s = r
        .steps
        .iter()
        .find(|s| s.observable.name() == "intensity" && s.covariate == "range")
        .unwrap_or_else(|| panic!("{source}: no intensity × range step: {steps:#?}"));
    assert_eq!(s.shape, "attenuation", "{source}: {}", describe(s));
    let k = s.parameters.iter().find(|p| p.name == "k").expect("k");
    assert!(
        (k.value - truth).abs() <= tol * truth,
        "{source}: k = {} (95 % {:?}), truth {truth}",
        k.value,
        k.ci95
    );
    let iv = k.ci95.expect("a bootstrap interval for k");
    assert!(iv[0] <= k.value && k.value <= iv[1], "{iv:?}");
    let loss = |name: &str| {
        s.shapes
            .iter()
            .find(|t| t.shape == name)
            .map(|t| t.held_out_loss)
    };
    let (att, bins) = (loss("attenuation").unwrap(), loss("bins").unwrap());
    assert!(
        att <= bins * 1.001,
        "{source}: attenuation {att} vs bins {bins}"
    );
    // The extended table applies the same form.
    let t = d.extended_table.as_ref().unwrap();
    let w = &t.weathers[&r.weather.parse::<WeatherClass>().unwrap()];
    assert!(w.extensions.iter().any(|e| e.covariate == "range"
        && matches!(e.function, ExtensionFunction::Attenuation { k: kk } if kk == k.value)));
    eprintln!(
        "{source}: k = {:.3} (95 % {:.3}–{:.3}), truth {truth:.3}, error {:+.1} %; held-out loss attenuation {att:.6} vs bins {bins:.6}",
        k.value,
        iv[0],
        iv[1],
        100.0 * (k.value - truth) / truth
    );
    k.value
}

#[test]
fn generated_two_way_attenuation_is_chosen_with_its_k() {
    for seed in [14, 15] {
        let d = generated(
            WeatherClass::Fog,
            common::effect(
                "two-way attenuation",
                Observable::Intensity,
                "range",
                WeatherClass::Fog,
                EffectFunction::TwoWayAttenuation { k: 1.5 },
            ),
            seed,
        );
        expect_attenuation(&d, 3.0, 0.05, &format!("generated fog seed {seed}"));
    }
}

#[test]
fn physics_fog_intensity_is_two_way_attenuation_with_k_2_ln_20() {
    physics_fog_attenuation(&[61]);
}

/// The second seed of the measurement (each takes several minutes on the
/// 2-core machine): `cargo test --workspace --test shapes -- --ignored`.
#[test]
#[ignore = "a second physics-fog seed: several minutes; run with --ignored"]
fn physics_fog_intensity_second_seed() {
    physics_fog_attenuation(&[62]);
}

fn physics_fog_attenuation(seeds: &[u64]) {
    let Some(capture) = vlp16_capture(env!("CARGO_MANIFEST_DIR")) else {
        eprintln!("skipped: the real VLP-16 capture is not present");
        return;
    };
    for &seed in seeds {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("physics");
        let cfg = SemiRealConfig {
            clear: 10,
            degraded: 36,
            mor_m: [8.0, 40.0],
            declared_azimuth_deg: 0.4,
            physics: Some(PhysicsFog {
                fog_returns: false,
                attenuate_intensity: true,
                ..PhysicsFog::default()
            }),
            ..SemiRealConfig::default()
        };
        vlp16_campaign(&capture, &out, &cfg, seed).unwrap();
        let d = diagnose(&out, WeatherClass::Fog, seed);
        // The fixture's own relation: exp(−2αr) = exp(−k·r/MOR).
        let truth = -(PhysicsFog::intensity_factor(100.0, 100.0)).ln();
        assert!((truth - 2.0 * 20f64.ln()).abs() < 1e-12);
        expect_attenuation(&d, truth, 0.15, &format!("physics fog seed {seed}"));
    }
}

#[test]
fn a_wet_road_step_keeps_a_piecewise_shape_or_loses_nothing() {
    wet_road(&[11]);
}

/// The second seed of the measurement: `--ignored`.
#[test]
#[ignore = "a second wet-road seed: several minutes; run with --ignored"]
fn a_wet_road_step_second_seed() {
    wet_road(&[13]);
}

fn wet_road(seeds: &[u64]) {
    for &seed in seeds {
        let d = generated(
            WeatherClass::Rain,
            common::effect(
                "wet road",
                Observable::Survival,
                "elevation",
                WeatherClass::Rain,
                EffectFunction::Step {
                    threshold: -6.0,
                    below: 0.6,
                    above: 1.0,
                },
            ),
            seed,
        );
        let steps: Vec<String> = d.report.steps.iter().map(describe).collect();
        eprintln!("wet road seed {seed}: {steps:#?}");
        let s = d
            .report
            .steps
            .iter()
            .find(|s| s.covariate == "elevation")
            .unwrap_or_else(|| panic!("seed {seed}: no elevation step: {steps:#?}"));
        let loss = |name: &str| s.shapes.iter().find(|t| t.shape == name);
        let chosen = s.shapes.iter().find(|t| t.chosen).unwrap();
        assert_eq!(chosen.shape, s.shape);
        let bins = loss("bins").unwrap();
        assert!(
            ["bins", "step", "monotone"].contains(&s.shape.as_str())
                || chosen.held_out_loss <= bins.held_out_loss,
            "seed {seed}: {}",
            describe(s)
        );
    }
}
