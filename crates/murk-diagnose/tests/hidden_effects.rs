//! Hidden-effect tests: each generated campaign hides one effect the
//! baseline model lacks (fixtures' effect hooks); `diagnose` must name the
//! right observable and covariate as its top significant finding and gain on
//! held-out recordings. Two campaigns hide nothing and must come back with no
//! significant finding.
//!
//! Campaign size: 56 recordings at 1° azimuth resolution, about three
//! quarters of them in the weather under test (review rejections 5 %).

use murk_campaign::Campaign;
use murk_diagnose::{DiagnoseParams, Diagnosis};
use murk_fixtures::{
    EffectFunction, EffectSpec, Gauss, Generator, GeneratorConfig, Observable, OutputOptions,
    PerClass, Preset, ReturnLaw,
};
use murk_types::WeatherClass;
use std::collections::BTreeMap;

fn diagnose(weather: WeatherClass, effects: Vec<EffectSpec>, seed: u64) -> Diagnosis {
    let mut c = GeneratorConfig::preset(Preset::Small);
    c.campaign.recordings = 56;
    let (f, r, s) = match weather {
        WeatherClass::Fog => (0.75, 0.0, 0.0),
        WeatherClass::Rain => (0.0, 0.75, 0.0),
        _ => (0.0, 0.0, 0.75),
    };
    c.weather.mix = PerClass {
        clear: 0.25,
        fog: f,
        rain: r,
        snow: s,
    };
    c.review.reject = PerClass {
        clear: 0.05,
        fog: 0.05,
        rain: 0.05,
        snow: 0.05,
    };
    c.effects = effects;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("campaign");
    Generator::new(c)
        .unwrap()
        .write_campaign(seed, &OutputOptions::new(&out))
        .unwrap();
    let campaign = Campaign::open(&out).unwrap();
    DiagnoseParams::new(weather)
        .seed(seed)
        .check()
        .unwrap()
        .run(&campaign)
        .unwrap()
}

fn effect(
    name: &str,
    observable: Observable,
    covariate: &str,
    weather: WeatherClass,
    function: EffectFunction,
) -> EffectSpec {
    EffectSpec {
        name: name.into(),
        observable,
        survival_mode: None,
        covariate: covariate.into(),
        weathers: vec![weather],
        function,
        returns: None,
    }
}

/// The top significant finding is (observable, covariate) and the extension
/// gains at least `min_gain` (relative) on its metric, held out.
fn expect_top(d: &Diagnosis, observable: &str, covariate: &str, min_gain: f64) {
    expect_top_steps(d, observable, covariate, min_gain, &[covariate]);
}

/// [`expect_top`] with the covariates the first accepted term may be along.
fn expect_top_steps(
    d: &Diagnosis,
    observable: &str,
    covariate: &str,
    min_gain: f64,
    first_step: &[&str],
) {
    let r = &d.report;
    let summary: Vec<String> = r
        .findings
        .iter()
        .take(5)
        .map(|f| {
            format!(
                "{} {:?} s={:.2} p={:.4} sig={}",
                f.observable, f.covariate, f.strength, f.p_adjusted, f.significant
            )
        })
        .collect();
    let top = r
        .top()
        .unwrap_or_else(|| panic!("no significant finding; top five: {summary:#?}"));
    assert_eq!(
        (top.observable.name(), top.covariate.as_str()),
        (observable, covariate),
        "top five: {summary:#?}"
    );
    let g = r.gain.as_ref().expect("a gain");
    eprintln!(
        "{} {observable} vs {covariate}: strength {:.2}, p_adj {:.4}; held-out {} {:.4} → {:.4} ({:+.1} %)",
        r.weather,
        top.strength,
        top.p_adjusted,
        g.metric,
        g.before,
        g.after,
        100.0 * g.relative
    );
    assert!(
        g.relative >= min_gain,
        "gain on {} is {:+.3} ({} → {}), expected ≥ {min_gain}",
        g.metric,
        g.relative,
        g.before,
        g.after
    );
    // The extended table carries the term and applies.
    let t = d.extended_table.as_ref().expect("an extended table");
    t.validate().unwrap();
    let w = &t.weathers[&r.weather.parse::<WeatherClass>().unwrap()];
    let steps: Vec<String> = r
        .steps
        .iter()
        .map(|s| {
            format!(
                "{} × {} {:+.4} p {:.4}",
                s.observable, s.covariate, s.gain.relative, s.p_value
            )
        })
        .collect();
    let rej: Vec<String> = r
        .rejected
        .iter()
        .map(|s| format!("{} × {}: {}", s.observable, s.covariate, s.reason))
        .collect();
    eprintln!("steps {steps:#?} rejected {rej:#?}");
    // The first accepted term is the hidden effect's (or, for an effect
    // that reads two covariates, one of them; `first_step`).
    assert!(!w.extensions.is_empty(), "no term; top five: {summary:#?}");
    assert_eq!(w.extensions.len(), r.steps.len());
    assert!(
        first_step.contains(&w.extensions[0].covariate.as_str()),
        "first term along {:?}; steps {steps:#?}",
        w.extensions[0].covariate
    );
}

#[test]
fn survival_along_elevation_wet_road_in_rain() {
    let d = diagnose(
        WeatherClass::Rain,
        vec![effect(
            "wet road loss on ground rings",
            Observable::Survival,
            "elevation",
            WeatherClass::Rain,
            EffectFunction::Step {
                threshold: -6.0,
                below: 0.6,
                above: 1.0,
            },
        )],
        11,
    );
    expect_top(&d, "survival", "elevation", 0.01);
    assert!(d.report.top().unwrap().cause.contains("wet-road"));
}

#[test]
fn survival_along_reflectivity_within_a_band_in_fog() {
    let d = diagnose(
        WeatherClass::Fog,
        vec![effect(
            "dark returns drop first",
            Observable::Survival,
            "reflectivity",
            WeatherClass::Fog,
            EffectFunction::Step {
                threshold: 25.0,
                below: 0.75,
                above: 1.0,
            },
        )],
        12,
    );
    expect_top(&d, "survival", "reflectivity", 0.005);
}

#[test]
fn survival_along_temperature_in_snow() {
    let d = diagnose(
        WeatherClass::Snow,
        vec![effect(
            "wet snow below −3 °C? no: dry snow",
            Observable::Survival,
            "PWD12_Temperature (°C)",
            WeatherClass::Snow,
            EffectFunction::Step {
                threshold: -3.0,
                below: 0.65,
                above: 1.0,
            },
        )],
        13,
    );
    expect_top(&d, "survival", "PWD12_Temperature (°C)", 0.01);
}

#[test]
fn intensity_along_range_two_way_attenuation_in_fog() {
    let d = diagnose(
        WeatherClass::Fog,
        vec![effect(
            "two-way attenuation",
            Observable::Intensity,
            "range",
            WeatherClass::Fog,
            EffectFunction::TwoWayAttenuation { k: 1.5 },
        )],
        14,
    );
    // exp(−2k·r/MOR) reads range and MOR: its own form (the attenuation
    // shape, issue #13 item 4) takes both in one term along range, where
    // piecewise-constant terms needed one along each.
    expect_top_steps(&d, "intensity", "range", 0.05, &["range"]);
    assert_eq!(d.report.steps.len(), 1, "{:#?}", d.report.steps);
    assert_eq!(d.report.steps[0].shape, "attenuation");
    assert!(d.report.top().unwrap().cause.contains("two-way"));
}

#[test]
fn range_along_wind_speed_column_in_fog() {
    let d = diagnose(
        WeatherClass::Fog,
        vec![effect(
            "mast sway in wind",
            Observable::Range,
            "Wind speed (m/s)",
            WeatherClass::Fog,
            EffectFunction::Linear {
                intercept: 0.0,
                slope: 0.02,
            },
        )],
        15,
    );
    expect_top(&d, "range", "Wind speed (m/s)", 0.05);
}

#[test]
fn count_along_road_state_column_in_snow() {
    let mut e = effect(
        "spray from a slushy road",
        Observable::Count,
        "Road state",
        WeatherClass::Snow,
        EffectFunction::Categories {
            values: BTreeMap::from([("slush".to_string(), 60.0)]),
            default: Some(0.0),
        },
    );
    e.returns = Some(ReturnLaw {
        distance_m: Gauss {
            mean: 5.0,
            std: 1.5,
        },
        reflectivity: Gauss {
            mean: 6.0,
            std: 3.0,
        },
        range_m: [3.0, 10.0],
    });
    let d = diagnose(WeatherClass::Snow, vec![e], 16);
    expect_top(&d, "count", "Road state", 0.05);
}

#[test]
fn nothing_hidden_in_fog_finds_nothing() {
    let d = diagnose(WeatherClass::Fog, vec![], 21);
    assert!(d.report.top().is_none(), "{:?}", d.report.top());
    assert!(d.report.extended.is_none());
    // The table to use is then the baseline, with no extension term.
    let t = d
        .extended_table
        .as_ref()
        .expect("the baseline as the table to use");
    assert!(t.weathers.values().all(|w| w.extensions.is_empty()));
    assert!(
        d.report.findings.len() > 40,
        "every observable × covariate is tested"
    );
}

#[test]
fn nothing_hidden_in_rain_finds_nothing() {
    let d = diagnose(WeatherClass::Rain, vec![], 22);
    assert!(d.report.top().is_none(), "{:?}", d.report.top());
}
