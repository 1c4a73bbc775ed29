//! Detection power of `murk diagnose`: how often a hidden survival effect
//! along elevation (ground rings' vanishing distance × f in rain) is found as
//! the top significant finding, by effect size and campaign size.
//!
//! `cargo run --release -p murk-diagnose --example power [REPLICATES]`
//! prints one line per (factor, recordings): detections / replicates and the
//! mean held-out gain.

use murk_campaign::Campaign;
use murk_diagnose::DiagnoseParams;
use murk_fixtures::{
    EffectFunction, EffectSpec, Generator, GeneratorConfig, Observable, OutputOptions, PerClass,
    Preset,
};
use murk_types::{ExtensionObservable, WeatherClass};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let reps: u64 = std::env::args().nth(1).map_or(Ok(3), |s| s.parse())?;
    println!("factor  recordings  found/replicates  mean gain (survival log loss)");
    for recordings in [24usize, 56] {
        for factor in [1.0, 0.95, 0.9, 0.8] {
            let (mut found, mut gain) = (0, 0.0);
            for seed in 0..reps {
                let mut c = GeneratorConfig::preset(Preset::Small);
                c.campaign.recordings = recordings;
                c.weather.mix = PerClass {
                    clear: 0.25,
                    fog: 0.0,
                    rain: 0.75,
                    snow: 0.0,
                };
                c.review.reject = PerClass {
                    clear: 0.05,
                    fog: 0.05,
                    rain: 0.05,
                    snow: 0.05,
                };
                if factor < 1.0 {
                    c.effects = vec![EffectSpec {
                        name: "ground".into(),
                        observable: Observable::Survival,
                        survival_mode: None,
                        covariate: "elevation".into(),
                        weathers: vec![WeatherClass::Rain],
                        function: EffectFunction::Step {
                            threshold: -6.0,
                            below: factor,
                            above: 1.0,
                        },
                        returns: None,
                    }];
                }
                let dir = tempfile::tempdir()?;
                let out = dir.path().join("c");
                Generator::new(c)?.write_campaign(100 + seed, &OutputOptions::new(&out))?;
                let d = DiagnoseParams::new(WeatherClass::Rain)
                    .seed(seed)
                    .check()?
                    .run(&Campaign::open(&out)?)?;
                if let Some(t) = d.report.top() {
                    if t.observable == ExtensionObservable::Survival && t.covariate == "elevation" {
                        found += 1;
                        gain += d.report.gain.as_ref().map_or(0.0, |g| g.relative);
                    } else {
                        eprintln!(
                            "  factor {factor} recordings {recordings} seed {seed}: top is {} x {} \
                             (effect {:.3}, threshold {}, p_adj {:.4}, {} recordings)",
                            t.observable,
                            t.covariate,
                            t.effect,
                            t.relevance_threshold,
                            t.p_adjusted,
                            t.recordings
                        );
                        if factor >= 1.0 {
                            found += 1; // a false positive in the null row
                        }
                    }
                }
            }
            println!(
                "{factor:>6}  {recordings:>10}  {found:>5}/{reps:<10}  {:+.3}",
                if found > 0 { gain / found as f64 } else { 0.0 }
            );
        }
    }
    Ok(())
}
