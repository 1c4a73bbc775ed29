//! The reported minimum detectable effect (`Finding::detectable`) against
//! effects hidden in generated campaigns at a known size.
//!
//! Each case diagnoses a campaign with nothing hidden (the null run) and
//! reads the MDE of one test; then hides an additive range offset whose
//! strength, as the test measures it, is a multiple of that MDE, in
//! campaigns of other seeds, and counts how often the test finds it (Holm-
//! adjusted p < α and effect ≥ the relevance threshold, the report's own
//! decision). Range offsets are additive (metres), so the hidden strength is
//! known in closed form: a step δ on a share `w` of the recordings has a
//! centred profile of RMS δ·√(w(1 − w)); `w` is read from the null run's
//! profile.
//!
//! Campaign sizes: 5 clear + n of the weather, drawn at that ratio: the
//! seed-sized 5 + 28 fog and 5 + 11 rain, and 5 + 40 rain.

use murk_campaign::Campaign;
use murk_diagnose::{DiagnoseParams, Diagnosis, Finding, Relevance};
use murk_fixtures::{
    EffectFunction, EffectSpec, Generator, GeneratorConfig, Observable, OutputOptions, PerClass,
    Preset,
};
use murk_types::{ExtensionObservable, WeatherClass};
use std::collections::BTreeMap;

/// A campaign of 5 clear and `n_weather` recordings of `weather` (drawn at
/// that ratio) with `effects`, diagnosed.
fn diagnose(
    weather: WeatherClass,
    n_weather: usize,
    effects: Vec<EffectSpec>,
    seed: u64,
    relevance: Relevance,
) -> Diagnosis {
    let mut c = GeneratorConfig::preset(Preset::Small);
    c.campaign.recordings = 5 + n_weather;
    let w = n_weather as f64 / (5 + n_weather) as f64;
    c.weather.mix = PerClass {
        clear: 1.0 - w,
        fog: if weather == WeatherClass::Fog { w } else { 0.0 },
        rain: if weather == WeatherClass::Rain {
            w
        } else {
            0.0
        },
        snow: 0.0,
    };
    c.review.reject = PerClass {
        clear: 0.0,
        fog: 0.0,
        rain: 0.0,
        snow: 0.0,
    };
    c.effects = effects;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("campaign");
    Generator::new(c)
        .unwrap()
        .write_campaign(seed, &OutputOptions::new(&out))
        .unwrap();
    DiagnoseParams::new(weather)
        .seed(seed)
        .relevance(relevance)
        .check()
        .unwrap()
        .run(&Campaign::open(&out).unwrap())
        .unwrap()
}

fn finding<'a>(d: &'a Diagnosis, obs: ExtensionObservable, cov: &str) -> &'a Finding {
    d.report
        .findings
        .iter()
        .find(|f| f.observable == obs && f.covariate == cov)
        .unwrap_or_else(|| panic!("no {obs} × {cov} test"))
}

/// The report's own decision for one test, before the stagewise loop
/// (an accepted or rejected extension does not change whether it was
/// found).
fn found(f: &Finding) -> bool {
    f.p_adjusted < 0.05 && f.effect >= f.relevance_threshold
}

/// The hidden range offset: `delta` metres on every kept return of a
/// recording in one category of `Road state` (scan level).
#[derive(Debug, Clone, Copy)]
struct Hidden(&'static str);

impl Hidden {
    fn covariate(self) -> &'static str {
        "Road state"
    }

    fn spec(self, weather: WeatherClass, delta: f64) -> EffectSpec {
        EffectSpec {
            name: "range offset".into(),
            observable: Observable::Range,
            survival_mode: None,
            covariate: self.covariate().into(),
            weathers: vec![weather],
            function: EffectFunction::Categories {
                values: BTreeMap::from([(self.0.to_string(), delta)]),
                default: Some(0.0),
            },
            returns: None,
        }
    }

    /// RMS of the centred profile per metre of offset, from the null run's
    /// profile weights (recordings per category).
    fn rms_per_metre(self, f: &Finding) -> f64 {
        let total: f64 = f.profile.iter().map(|b| b.weight).sum();
        let on: f64 = f
            .profile
            .iter()
            .filter(|b| b.label == self.0)
            .map(|b| b.weight)
            .sum();
        let w = on / total;
        (w * (1.0 - w)).sqrt()
    }
}

/// Per case and seed: the MDE of the campaign with nothing hidden, then the
/// same campaign (same seed) with the effect hidden at each of `multiples`
/// of that MDE; how many seeds find it, per multiple. Range's relevance
/// threshold is `range_thr`.
fn sweep(
    weather: WeatherClass,
    n_weather: usize,
    hidden: Hidden,
    range_thr: f64,
    seeds: &[u64],
    multiples: &[f64],
) -> (Vec<usize>, usize) {
    let relevance = Relevance {
        range: range_thr,
        ..Relevance::default()
    };
    let mut hits = vec![0; multiples.len()];
    let mut told = 0;
    for &s in seeds {
        let null = diagnose(weather, n_weather, vec![], s, relevance);
        let f = finding(&null, ExtensionObservable::Range, hidden.covariate());
        let Some(mde) = f.detectable else {
            // Honest, and not a miss: counted as neither.
            eprintln!(
                "{weather} seed {s}: cannot tell ({:?}); seed left out",
                f.detectable_reason
            );
            continue;
        };
        told += 1;
        let per_m = hidden.rms_per_metre(f);
        eprintln!(
            "{weather} range × {} seed {s}: MDE {mde:.5} m (threshold {}), {} recordings, null effect {:.5}, p_adj {:.4}",
            hidden.covariate(),
            f.relevance_threshold,
            f.recordings,
            f.effect,
            f.p_adjusted
        );
        for (i, &m) in multiples.iter().enumerate() {
            let delta = m * mde / per_m;
            let d = diagnose(
                weather,
                n_weather,
                vec![hidden.spec(weather, delta)],
                s,
                relevance,
            );
            let g = finding(&d, ExtensionObservable::Range, hidden.covariate());
            eprintln!(
                "  {m}× (δ {delta:.5} m): effect {:.5}, p_adj {:.4}, found {}",
                g.effect,
                g.p_adjusted,
                found(g)
            );
            hits[i] += found(g) as usize;
        }
    }
    eprintln!(
        "{weather} range × {}: {multiples:?} × MDE found {hits:?} of {told} seeds that can tell",
        hidden.covariate()
    );
    (hits, told)
}

/// Seed-sized rain campaign (5 + 11): every test reports a finite MDE at
/// or above its relevance threshold, or says why it cannot tell; never NaN,
/// infinite or a silent 0. A point-level test says "cannot tell" exactly
/// when its recordings' 2ⁿ sign patterns cannot reach α/m (the mirror
/// pattern ties with the observed one, so p ≥ 2^(1 − n)).
#[test]
fn seed_sized_rain_campaign_reports_a_number_or_a_reason() {
    let d = diagnose(WeatherClass::Rain, 11, vec![], 3, Relevance::default());
    let level = 0.05 / d.report.findings.len() as f64;
    let mut numbers = 0;
    for f in &d.report.findings {
        let name = format!("{} × {}", f.observable, f.covariate);
        match (f.detectable, &f.detectable_reason) {
            (Some(x), None) => {
                assert!(x.is_finite() && x > 0.0, "{name}: {x}");
                // Nothing below what the decision itself requires.
                assert!(x >= f.relevance_threshold * 0.999, "{name}: {x}");
                numbers += 1;
            }
            (None, Some(why)) => assert!(!why.is_empty()),
            other => panic!("{name}: {other:?}"),
        }
        if f.level == murk_diagnose::Level::Point {
            let resolvable = 2f64.powf(1.0 - f.recordings as f64) < level;
            assert_eq!(
                f.detectable.is_some(),
                resolvable,
                "{name}: {} recordings, {:?}",
                f.recordings,
                f.detectable_reason
            );
        }
    }
    let lines = d.report.power_summary();
    for l in &lines {
        eprintln!("{l}");
    }
    assert!(numbers > 0, "no test can tell anything");
    assert!(
        lines.iter().any(|l| l.contains("effect larger than")),
        "{lines:?}"
    );
}

/// The seed sweep: per seed (11–13), the MDE of the campaign with nothing
/// hidden, then the same campaign with the effect at 2× and 0.5× of it:
/// range × "Road state" (a wet road's offset, scan level) in fog (5 + 28)
/// and rain (5 + 40: with 11 or 20 rain recordings split 80 : 20 between
/// "wet" and "standing water", the shuffles cannot reach α/m and the
/// report says so), range's relevance threshold at 0 so that the test's
/// own power is measured, not the 2 cm threshold's.
///
/// Measured 2026-12-03 (test profile), found at 2× / 0.5× of the campaign's
/// own MDE: fog seeds 11, 12, 13: MDE 0.00065, 0.00053, 0.00033 m; 2× 3/3,
/// 0.5× 1/3 (seed 12, p_adj 0.027). Rain 5 + 40, seed 11: MDE 0.00041 m
/// (32 rain recordings), 2× found (p_adj 0.012), 0.5× not (p_adj 0.18);
/// seed 12: cannot tell (41 recordings, one of them alone in its
/// category: 41 assignments), left out; seed 13 not measured (deadline).
/// A seed whose test cannot tell is left out, not counted.
/// (Range × elevation is not a clean case at threshold 0: the baseline's
/// own sub-millimetre range misfit along elevation is significant there, so
/// a 0.5× effect on top of it is found too; at the default 2 cm threshold
/// its MDE is the threshold's, 0.0201 m on fog 5 + 28 seed 10, and effects
/// at 2× were found 3/3 and at 0.5× 0/3 in seeds 11–13.)
#[test]
#[ignore = "18 diagnoses: about 15 minutes on 2 cores"]
fn hidden_at_twice_the_mde_is_found_and_at_half_rarely() {
    let seeds = [11, 12, 13];
    let mut results = Vec::new();
    for (weather, n) in [(WeatherClass::Rain, 40), (WeatherClass::Fog, 28)] {
        let r = sweep(weather, n, Hidden("wet"), 0.0, &seeds, &[2.0, 0.5]);
        results.push((weather, r));
    }
    for (weather, r) in &results {
        // Of the seeds whose test can tell: found in at least two thirds
        // at 2×, in at most a third at 0.5×.
        let (hits, told) = r;
        assert!(*told >= 1, "{weather}: no seed can tell");
        assert!(3 * hits[0] >= 2 * told, "{weather} 2×: {hits:?} of {told}");
        assert!(3 * hits[1] <= *told, "{weather} 0.5×: {hits:?} of {told}");
    }
}
