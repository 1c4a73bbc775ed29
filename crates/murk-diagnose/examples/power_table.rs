//! The measured power table of `murk diagnose`: detection rate by effect
//! size (in units of the reported minimum detectable effect, and absolute)
//! × campaign size, for a point-level survival effect and a scan-level
//! range effect; and the time of a diagnosis with and without the power
//! computation.
//!
//! `cargo run --profile test -p murk-diagnose --example power_table [REPLICATES] [SIZES]`
//!
//! Per campaign size (`SIZES`, comma-separated recordings; `33` is the
//! seed-sized 5 clear + 28 fog, others are a quarter clear): one campaign
//! with nothing hidden (seed 500) gives the MDE of survival × elevation and
//! range × "Road state" (`Finding::detectable`); then `REPLICATES`
//! campaigns (seeds 501…) per level hide both effects at once:
//!
//! - survival × elevation: the keep logit of returns below −6° lowered by
//!   0.25, 0.5 or 1 (a wet-road loss; its strength is not closed-form, so
//!   the table gives the mean measured `effect` and its ratio to the MDE);
//! - range × "Road state": every kept return of a wet recording longer by
//!   δ = m · MDE / √(p(1 − p)) metres (p the share of wet recordings), m =
//!   0.5, 1, 2: its strength is m · MDE by construction.
//!
//! Found = the report's decision for that test (Holm-adjusted p < α and
//! effect ≥ the relevance threshold). Range's relevance threshold is set to
//! 0 so that its rows measure the test's own power, not the 2 cm
//! threshold's (with it, range's MDE is the threshold on every size here);
//! survival keeps its default (0.02).

use std::collections::BTreeMap;
use std::time::Instant;

use murk_campaign::Campaign;
use murk_diagnose::{DiagnoseParams, Diagnosis, Finding, Relevance};
use murk_fixtures::{
    EffectFunction, EffectSpec, Generator, GeneratorConfig, Observable, OutputOptions, PerClass,
    Preset, SurvivalMode,
};
use murk_types::{ExtensionObservable, WeatherClass};

const ROAD: &str = "Road state";

fn campaign(recordings: usize, effects: Vec<EffectSpec>, seed: u64, dir: &std::path::Path) {
    let mut c = GeneratorConfig::preset(Preset::Small);
    c.campaign.recordings = recordings;
    let clear = if recordings == 33 { 5.0 / 33.0 } else { 0.25 };
    c.weather.mix = PerClass {
        clear,
        fog: 1.0 - clear,
        rain: 0.0,
        snow: 0.0,
    };
    c.review.reject = PerClass {
        clear: 0.0,
        fog: 0.0,
        rain: 0.0,
        snow: 0.0,
    };
    c.effects = effects;
    Generator::new(c)
        .expect("config")
        .write_campaign(seed, &OutputOptions::new(dir))
        .expect("campaign");
}

fn diagnose(dir: &std::path::Path, seed: u64, power: bool) -> (Diagnosis, f64) {
    let t = Instant::now();
    let d = DiagnoseParams::new(WeatherClass::Fog)
        .seed(seed)
        .relevance(Relevance {
            range: 0.0,
            ..Relevance::default()
        })
        .detectable(power)
        .check()
        .expect("params")
        .run(&Campaign::open(dir).expect("open"))
        .expect("diagnosis");
    (d, t.elapsed().as_secs_f64())
}

fn finding<'a>(d: &'a Diagnosis, obs: ExtensionObservable, cov: &str) -> &'a Finding {
    d.report
        .findings
        .iter()
        .find(|f| f.observable == obs && f.covariate == cov)
        .expect("the test")
}

fn found(f: &Finding) -> bool {
    f.p_adjusted < 0.05 && f.effect >= f.relevance_threshold
}

fn effects(logit: f64, range_m: f64) -> Vec<EffectSpec> {
    vec![
        EffectSpec {
            name: "wet-road loss".into(),
            observable: Observable::Survival,
            survival_mode: Some(SurvivalMode::Logit),
            covariate: "elevation".into(),
            weathers: vec![WeatherClass::Fog],
            function: EffectFunction::Step {
                threshold: -6.0,
                below: -logit,
                above: 0.0,
            },
            returns: None,
        },
        EffectSpec {
            name: "wet range offset".into(),
            observable: Observable::Range,
            survival_mode: None,
            covariate: ROAD.into(),
            weathers: vec![WeatherClass::Fog],
            function: EffectFunction::Categories {
                values: BTreeMap::from([("wet".to_string(), range_m)]),
                default: Some(0.0),
            },
            returns: None,
        },
    ]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let reps: u64 = args.next().map_or(Ok(2), |s| s.parse())?;
    let sizes: Vec<usize> = args
        .next()
        .unwrap_or_else(|| "33,24,56".into())
        .split(',')
        .map(str::parse)
        .collect::<Result<_, _>>()?;
    println!(
        "| recordings (fog) | test | MDE | level | effect (mean measured) | effect / MDE | found |"
    );
    println!("|---|---|---|---|---|---|---|");
    for &n in &sizes {
        let dir = tempfile::tempdir()?;
        let out = dir.path().join("null");
        campaign(n, vec![], 500, &out);
        let (null, t_on) = diagnose(&out, 500, true);
        let (_, t_off) = diagnose(&out, 500, false);
        let sv = finding(&null, ExtensionObservable::Survival, "elevation");
        let rg = finding(&null, ExtensionObservable::Range, ROAD);
        let nrec = null.report.heldout_recordings;
        eprintln!(
            "{n} recordings ({nrec} fog): diagnosis {t_on:.1} s with the power computation, {t_off:.1} s without"
        );
        let (Some(mde_s), Some(mde_r)) = (sv.detectable, rg.detectable) else {
            println!(
                "| {n} ({nrec}) | – | cannot tell: {:?} / {:?} | | | | |",
                sv.detectable_reason, rg.detectable_reason
            );
            continue;
        };
        let total: f64 = rg.profile.iter().map(|b| b.weight).sum();
        let wet: f64 = rg
            .profile
            .iter()
            .filter(|b| b.label == "wet")
            .map(|b| b.weight)
            .sum();
        let p = wet / total;
        let per_m = (p * (1.0 - p)).sqrt();
        for (logit, m) in [(0.25, 0.5), (0.5, 1.0), (1.0, 2.0)] {
            let delta = m * mde_r / per_m;
            let (mut hs, mut hr, mut es, mut er) = (0, 0, 0.0, 0.0);
            for r in 0..reps {
                let seed = 501 + r;
                let out = dir.path().join(format!("c{seed}-{m}"));
                campaign(n, effects(logit, delta), seed, &out);
                let (d, t) = diagnose(&out, seed, true);
                let s = finding(&d, ExtensionObservable::Survival, "elevation");
                let g = finding(&d, ExtensionObservable::Range, ROAD);
                eprintln!(
                    "  n {n} seed {seed}: survival logit −{logit}: effect {:.4} p_adj {:.4}; range {m}× ({delta:.4} m): effect {:.4} p_adj {:.4} ({t:.0} s)",
                    s.effect, s.p_adjusted, g.effect, g.p_adjusted
                );
                hs += found(s) as usize;
                hr += found(g) as usize;
                es += s.effect / reps as f64;
                er += g.effect / reps as f64;
            }
            println!(
                "| {n} ({nrec}) | survival × elevation | {mde_s:.4} | logit −{logit} | {es:.4} | {:.2} | {hs}/{reps} |",
                es / mde_s
            );
            println!(
                "| {n} ({nrec}) | range × Road state | {mde_r:.4} m | {m} × MDE ({:.4} m) | {er:.4} m | {:.2} | {hr}/{reps} |",
                m * mde_r,
                er / mde_r
            );
        }
    }
    Ok(())
}
