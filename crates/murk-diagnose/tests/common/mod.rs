//! Campaigns that hide several effects, junk columns, a confounded proxy
//! column or outages, and the scoring of a diagnosis against them.
#![allow(dead_code)]

use murk_campaign::Campaign;
use murk_diagnose::{DiagnoseParams, Diagnosis};
use murk_fixtures::{
    ColumnSpec, EffectFunction, EffectSpec, Gauss, Generator, GeneratorConfig, Law, Observable,
    OutputOptions, PerClass, Preset, ReturnLaw,
};
use murk_types::WeatherClass;
use std::collections::BTreeMap;
use std::path::Path;

/// A column added to `weather.csv` after generation: `name` =
/// `scale · source + N(0, noise²)` (a proxy confounded with `source`).
#[derive(Debug, Clone)]
pub struct Proxy {
    pub name: String,
    pub source: String,
    pub scale: f64,
    pub noise: f64,
}

/// One generated case.
#[derive(Debug, Clone)]
pub struct Case {
    pub name: String,
    pub weather: WeatherClass,
    pub effects: Vec<EffectSpec>,
    /// Extra generated columns.
    pub columns: Vec<ColumnSpec>,
    /// Outage rate of the wind column (default 0.01).
    pub wind_outage: Option<f64>,
    pub proxy: Option<Proxy>,
    pub recordings: usize,
}

pub fn effect(
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

fn step(threshold: f64, below: f64, above: f64) -> EffectFunction {
    EffectFunction::Step {
        threshold,
        below,
        above,
    }
}

pub const WIND: &str = "Wind speed (m/s)";

/// Twelve junk columns: eight numeric, four categorical, none of which
/// the degradation reads.
pub fn junk_columns() -> Vec<ColumnSpec> {
    let mut out = Vec::new();
    let numeric = [
        (
            "Dew point (°C)",
            Law::Normal {
                mean: 1.0,
                std: 4.0,
                min: None,
                max: None,
            },
        ),
        (
            "Pressure (hPa)",
            Law::Normal {
                mean: 870.0,
                std: 8.0,
                min: None,
                max: None,
            },
        ),
        (
            "Solar (W/m2)",
            Law::Gamma {
                shape: 1.2,
                scale: 80.0,
            },
        ),
        (
            "Cabin temp (°C)",
            Law::Uniform {
                min: 15.0,
                max: 30.0,
            },
        ),
        (
            "Battery (V)",
            Law::Normal {
                mean: 12.6,
                std: 0.3,
                min: None,
                max: None,
            },
        ),
        (
            "Gust dir (deg)",
            Law::Uniform {
                min: 0.0,
                max: 360.0,
            },
        ),
        (
            "Snow depth (cm)",
            Law::LogNormal {
                median: 20.0,
                sigma: 0.8,
                min: None,
                max: None,
            },
        ),
        (
            "Traffic (veh/h)",
            Law::Gamma {
                shape: 2.0,
                scale: 40.0,
            },
        ),
    ];
    for (name, law) in numeric {
        out.push(ColumnSpec {
            name: name.into(),
            law,
            by_class: BTreeMap::new(),
            decimals: 2,
            outage_rate: 0.03,
        });
    }
    let cats: [(&str, &[(&str, f64)]); 4] = [
        ("Operator", &[("ana", 1.0), ("bo", 1.0), ("cy", 1.0)]),
        ("Camera state", &[("ok", 3.0), ("fogged", 1.0)]),
        ("Mast light", &[("on", 1.0), ("off", 1.0)]),
        (
            "Day part",
            &[("night", 1.0), ("dawn", 0.5), ("day", 1.0), ("dusk", 0.5)],
        ),
    ];
    for (name, w) in cats {
        out.push(ColumnSpec {
            name: name.into(),
            law: Law::Categorical {
                weights: w.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
            },
            by_class: BTreeMap::new(),
            decimals: 0,
            outage_rate: 0.0,
        });
    }
    out
}

impl Case {
    fn new(name: &str, weather: WeatherClass, effects: Vec<EffectSpec>) -> Case {
        Case {
            name: name.into(),
            weather,
            effects,
            columns: Vec::new(),
            wind_outage: None,
            proxy: None,
            recordings: 56,
        }
    }
}

/// The cases of issue #13 (wave 2), for `weather`.
pub fn cases() -> Vec<Case> {
    use WeatherClass::*;
    let mut v = Vec::new();
    // Two effects on one observable: ground rings and wind (issue #13's
    // measured case), in rain.
    v.push(Case::new(
        "two effects: survival × ring, survival × wind (rain)",
        Rain,
        vec![
            // The first four lasers of a worn unit (elevations −15°, 1°,
            // −13°, 3°: not one elevation range).
            effect(
                "worn lasers",
                Observable::Survival,
                "ring",
                Rain,
                EffectFunction::Categories {
                    values: ["0", "1", "2", "3"]
                        .iter()
                        .map(|k| (k.to_string(), 0.6))
                        .collect(),
                    default: Some(1.0),
                },
            ),
            effect(
                "windy",
                Observable::Survival,
                WIND,
                Rain,
                step(7.0, 1.0, 0.7),
            ),
        ],
    ));
    // Three effects across observables, in fog.
    v.push(Case::new(
        "three effects: survival × elevation, intensity × range, range × wind (fog)",
        Fog,
        vec![
            effect(
                "wet road",
                Observable::Survival,
                "elevation",
                Fog,
                step(-6.0, 0.6, 1.0),
            ),
            effect(
                "two-way attenuation",
                Observable::Intensity,
                "range",
                Fog,
                EffectFunction::TwoWayAttenuation { k: 1.5 },
            ),
            effect(
                "mast sway",
                Observable::Range,
                WIND,
                Fog,
                EffectFunction::Linear {
                    intercept: 0.0,
                    slope: 0.02,
                },
            ),
        ],
    ));
    // A confounded proxy of the cause.
    let mut c = Case::new(
        "survival × wind with a gust column that follows wind (fog)",
        Fog,
        vec![effect(
            "windy",
            Observable::Survival,
            WIND,
            Fog,
            step(7.0, 1.0, 0.65),
        )],
    );
    c.proxy = Some(Proxy {
        name: "Gust speed (m/s)".into(),
        source: WIND.into(),
        scale: 1.4,
        noise: 2.5,
    });
    v.push(c);
    // The cause with 25 % empty cells, and a count effect beside it.
    let mut c = Case::new(
        "range × wind (25 % empty cells) and count × road state (snow)",
        Snow,
        vec![
            effect(
                "mast sway",
                Observable::Range,
                WIND,
                Snow,
                EffectFunction::Linear {
                    intercept: 0.0,
                    slope: 0.02,
                },
            ),
            {
                let mut e = effect(
                    "spray from slush",
                    Observable::Count,
                    "Road state",
                    Snow,
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
                e
            },
        ],
    );
    c.wind_outage = Some(0.25);
    v.push(c);
    // Nulls with a dozen junk columns.
    for w in [Fog, Rain] {
        let mut c = Case::new(&format!("null with 12 junk columns ({w})"), w, vec![]);
        c.columns = junk_columns();
        v.push(c);
    }
    v
}

/// Adds the proxy column to `weather.csv`.
fn add_proxy(dir: &Path, p: &Proxy, seed: u64) {
    let path = dir.join("weather.csv");
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let cols: Vec<&str> = header.split(',').collect();
    let k = cols.iter().position(|c| *c == p.source).unwrap();
    let mut out = format!("{header},{}\n", p.name);
    let mut g = seed.wrapping_mul(0x9E3779B97F4A7C15) | 1;
    let mut normal = || {
        // Sum of 12 uniforms − 6: N(0, 1) closely enough.
        (0..12)
            .map(|_| {
                g ^= g << 13;
                g ^= g >> 7;
                g ^= g << 17;
                (g >> 11) as f64 / (1u64 << 53) as f64
            })
            .sum::<f64>()
            - 6.0
    };
    for line in lines {
        let cells: Vec<&str> = line.split(',').collect();
        let v = cells[k]
            .trim()
            .parse::<f64>()
            .ok()
            .map(|x| format!("{:.1}", (p.scale * x + p.noise * normal()).max(0.0)))
            .unwrap_or_default();
        out.push_str(&format!("{line},{v}\n"));
    }
    std::fs::write(&path, out).unwrap();
}

/// Generates `case` with `seed` and diagnoses it.
pub fn run(case: &Case, seed: u64) -> Diagnosis {
    let mut c = GeneratorConfig::preset(Preset::Small);
    c.campaign.recordings = case.recordings;
    let (f, r, s) = match case.weather {
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
    if let Some(o) = case.wind_outage {
        for col in c.columns.iter_mut().filter(|col| col.name == WIND) {
            col.outage_rate = o;
        }
    }
    c.columns.extend(case.columns.iter().cloned());
    c.effects = case.effects.clone();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("campaign");
    Generator::new(c)
        .unwrap()
        .write_campaign(seed, &OutputOptions::new(&out))
        .unwrap();
    if let Some(p) = &case.proxy {
        add_proxy(&out, p, seed);
    }
    let campaign = Campaign::open(&out).unwrap();
    DiagnoseParams::new(case.weather)
        .seed(seed)
        .check()
        .unwrap()
        .run(&campaign)
        .unwrap()
}

/// How a diagnosis did against the truth.
#[derive(Debug, Clone)]
pub struct Score {
    /// Hidden effects among the significant findings.
    pub found: usize,
    /// Hidden effects.
    pub hidden: usize,
    /// Significant findings that are no hidden effect.
    pub false_findings: Vec<String>,
    /// Hidden effects not found.
    pub missed: Vec<String>,
    /// Held-out gain of each accepted step (relative), with its p-value.
    pub steps: Vec<(String, f64, f64)>,
    /// Combined gains.
    pub combined: Vec<(String, f64)>,
}

fn observable_name(o: Observable) -> &'static str {
    match o {
        Observable::Survival => "survival",
        Observable::Intensity => "intensity",
        Observable::Range => "range",
        Observable::Count => "count",
    }
}

pub fn score(case: &Case, d: &Diagnosis) -> Score {
    let r = &d.report;
    let sig: Vec<(String, String)> = r
        .findings
        .iter()
        .filter(|f| f.significant)
        .map(|f| (f.observable.name().to_string(), f.covariate.clone()))
        .collect();
    let hidden: Vec<(String, String)> = case
        .effects
        .iter()
        .map(|e| {
            (
                observable_name(e.observable).to_string(),
                e.covariate.clone(),
            )
        })
        .collect();
    // What the effects read: their covariate, and the MOR for two-way
    // attenuation exp(−2k·r/MOR) (a piecewise-constant term along range
    // cannot hold its dependence on MOR; one along mor is that effect too).
    let mut reads = hidden.clone();
    for e in &case.effects {
        if matches!(e.function, EffectFunction::TwoWayAttenuation { .. }) {
            reads.push((observable_name(e.observable).to_string(), "mor".into()));
        }
    }
    let found = hidden.iter().filter(|h| sig.contains(h)).count();
    Score {
        found,
        hidden: hidden.len(),
        false_findings: sig
            .iter()
            .filter(|s| !reads.contains(s))
            .map(|(o, c)| format!("{o} × {c}"))
            .collect(),
        missed: hidden
            .iter()
            .filter(|h| !sig.contains(h))
            .map(|(o, c)| format!("{o} × {c}"))
            .collect(),
        steps: r
            .steps
            .iter()
            .map(|s| {
                (
                    format!("{} × {}", s.observable, s.covariate),
                    s.gain.relative,
                    s.p_value,
                )
            })
            .collect(),
        combined: r
            .extended
            .as_ref()
            .map(|e| {
                e.gains
                    .iter()
                    .map(|g| (g.metric.clone(), g.relative))
                    .collect()
            })
            .unwrap_or_default(),
    }
}

/// A one-line summary of the significant and rejected findings.
pub fn summary(d: &Diagnosis) -> String {
    let r = &d.report;
    let mut s = String::new();
    for f in r.findings.iter().take(8) {
        s.push_str(&format!(
            "\n  {} × {:?} s={:.2} p_adj={:.4} sig={} step={:?} by={:?} rej={}",
            f.observable,
            f.covariate,
            f.strength,
            f.p_adjusted,
            f.significant,
            f.step,
            f.explained_by,
            f.rejected.is_some()
        ));
    }
    for x in &r.rejected {
        s.push_str(&format!(
            "\n  rejected {} × {:?} at step {}: {}",
            x.observable, x.covariate, x.step, x.reason
        ));
    }
    s
}

/// The wave-2 acceptance: every hidden effect significant, nothing else
/// significant, every step gaining on held-out recordings.
pub fn check(case: &Case, d: &Diagnosis) -> Score {
    let s = score(case, d);
    let why = format!("{}: {s:?}{}", case.name, summary(d));
    assert!(s.missed.is_empty(), "missed {:?}; {why}", s.missed);
    assert!(
        s.false_findings.is_empty(),
        "false {:?}; {why}",
        s.false_findings
    );
    for (name, gain, p) in &s.steps {
        assert!(
            *gain > 0.0 && *p < 0.05,
            "step {name}: gain {gain}, p {p}; {why}"
        );
    }
    // The extended table holds every accepted term, in order.
    let t = d.extended_table.as_ref().expect("a table");
    t.validate().unwrap();
    let w = &t.weathers[&case.weather];
    assert_eq!(w.extensions.len(), d.report.steps.len(), "{why}");
    for (e, st) in w.extensions.iter().zip(&d.report.steps) {
        assert_eq!(
            (e.observable, e.covariate.as_str()),
            (st.observable, st.covariate.as_str())
        );
    }
    s
}

/// A fog diagnosis of a semi-real campaign from the real VLP-16 capture
/// (the caller checks it is present), declared at its 0.4° firing step,
/// with `edit` applied to the default configuration.
pub fn semi_real_fog(
    seed: u64,
    edit: impl FnOnce(&mut murk_fixtures::semi_real::SemiRealConfig),
) -> Diagnosis {
    use murk_fixtures::semi_real::{SemiRealConfig, vlp16_campaign, vlp16_capture};
    let capture = vlp16_capture(env!("CARGO_MANIFEST_DIR")).expect("checked by the caller");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("semi-real");
    let mut cfg = SemiRealConfig {
        declared_azimuth_deg: 0.4,
        ..SemiRealConfig::default()
    };
    edit(&mut cfg);
    vlp16_campaign(&capture, &out, &cfg, seed).unwrap();
    let campaign = Campaign::open(&out).unwrap();
    DiagnoseParams::new(WeatherClass::Fog)
        .seed(seed)
        .check()
        .unwrap()
        .run(&campaign)
        .unwrap()
}
