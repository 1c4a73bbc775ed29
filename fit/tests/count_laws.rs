//! Count laws and near-range laws as published (issue #12): on the committed
//! default campaign every truncated law is either pinned down by its data
//! or says why not, with the returns' own moments beside it; a narrow MOR
//! range gives a finite law or "not identifiable", never a failed table;
//! the table is the same bytes on 1 and 2 threads.
// Tests read the tables they write (fit's I/O rule is for its statistics).
#![allow(clippy::disallowed_methods, clippy::disallowed_types)]

use std::path::Path;

use murk_campaign::Campaign;
use murk_fit::{FitParams, FittedTable};
use murk_fixtures::{Generator, GeneratorConfig, Law, OutputOptions, PerClass, Preset};
use murk_types::{Gaussian, WeatherClass};

fn fit(path: &Path) -> FittedTable {
    let campaign = Campaign::open(path).unwrap();
    FitParams::default()
        .bootstrap_replicates(50)
        .check()
        .unwrap()
        .fit(&campaign)
        .unwrap()
}

/// A published law (no `reason`) must put at least 0.1 % of its mass in
/// its window and have a mean standard error no smaller than half of
/// σ/√n; a flagged one says "not identifiable" and has no standard errors.
fn check_gaussian(g: &Gaussian, n: u64, what: &str) -> Result<(), String> {
    match &g.reason {
        Some(r) => {
            if !r.starts_with("not identifiable") || g.mean_std_error.is_some() {
                return Err(format!("{what}: flagged law badly reported: {g:?}"));
            }
        }
        None => {
            let phi = |x: f64| 0.5 * libm::erfc(-x / std::f64::consts::SQRT_2);
            let a = g.lower.map_or(0.0, |l| phi((l - g.mean) / g.std));
            let b = g.upper.map_or(1.0, |u| phi((u - g.mean) / g.std));
            let se = g.mean_std_error.unwrap_or(f64::NAN);
            if !(b - a >= 1e-3 && se >= 0.5 * g.std / (n as f64).sqrt()) {
                return Err(format!(
                    "{what}: published law not pinned down: {g:?} (window mass {:.1e})",
                    b - a
                ));
            }
        }
    }
    Ok(())
}

#[test]
fn default_campaign_laws_are_pinned_down_or_say_why() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/default-campaign");
    let t = fit(&root).table().clone();
    let mut errors = Vec::new();
    for (class, w) in &t.weathers {
        for (name, law, moments) in [
            ("ghost", &w.ghost, &w.ghost_returns),
            ("ring", &w.ring, &w.ring_returns),
        ] {
            let Some(law) = law else { continue };
            let m = moments
                .as_ref()
                .unwrap_or_else(|| panic!("{class} {name}: no Table 5 moments"));
            assert_eq!(m.points, law.points, "{class} {name}");
            eprintln!(
                "{class} {name}: distance {:.3}/{:.3} ({:?}), returns {:.3}/{:.3}; reflectivity {:.3}/{:.3} ({:?}), returns {:.3}/{:.3}; n {}; count law {:?} ({:?})",
                law.distance_m.mean,
                law.distance_m.std,
                law.distance_m.reason,
                m.distance_mean_m,
                m.distance_std_m,
                law.reflectivity.mean,
                law.reflectivity.std,
                law.reflectivity.reason,
                m.reflectivity_mean,
                m.reflectivity_std,
                m.points,
                law.count_law.as_ref().map(|c| c.family()),
                law.count_law_choice.as_ref().map(|c| &c.reason),
            );
            for (what, g) in [
                ("distance", &law.distance_m),
                ("reflectivity", &law.reflectivity),
            ] {
                if let Err(e) = check_gaussian(g, law.points, &format!("{class} {name} {what}")) {
                    errors.push(e);
                }
            }
            // The returns' moments lie inside the window they were taken in.
            let (lo, hi) = (law.distance_m.lower.unwrap(), law.distance_m.upper.unwrap());
            assert!(
                (lo..hi).contains(&m.distance_mean_m),
                "{class} {name}: {m:?}"
            );
        }
    }
    assert!(errors.is_empty(), "{errors:#?}");
}

/// A small fog campaign whose MOR readings all fall in 304–378 m, with
/// few ghost returns and no ring return at all.
fn narrow(seed: u64) -> tempfile::TempDir {
    let mut c = GeneratorConfig::preset(Preset::Small);
    c.campaign.recordings = 40;
    c.weather.mix = PerClass {
        clear: 0.25,
        fog: 0.75,
        rain: 0.0,
        snow: 0.0,
    };
    c.weather.mor_m.fog = Law::Uniform {
        min: 310.0,
        max: 370.0,
    };
    c.degradation.fog.ghost.count.n_ref = 1.5;
    c.degradation.fog.ring.count.n_ref = 0.0;
    let dir = tempfile::tempdir().unwrap();
    Generator::new(c)
        .unwrap()
        .write_campaign(seed, &OutputOptions::new(dir.path().join("c")))
        .unwrap();
    dir
}

#[test]
fn a_narrow_mor_range_and_no_ring_give_a_table_that_says_why() {
    for seed in [3, 4] {
        let dir = narrow(seed);
        let t = fit(&dir.path().join("c")).table().clone();
        t.validate().unwrap();
        let fog = &t.weathers[&WeatherClass::Fog];
        // The ring: no return at all; the law is null with its reason.
        assert!(fog.ring.is_none(), "{:?}", fog.ring);
        assert!(fog.ring_reason.is_some());
        // The ghost: a finite law, or a null count law that says why.
        if let Some(g) = &fog.ghost {
            match &g.count_law {
                Some(c) => {
                    for mor in [310.0, 340.0, 370.0] {
                        assert!(c.expected(mor).is_finite(), "{c:?}");
                    }
                }
                None => {
                    let r = g.count_law_reason.as_deref().unwrap();
                    assert!(r.starts_with("not identifiable") || r == "no count", "{r}");
                }
            }
            eprintln!(
                "seed {seed}: ghost count law {:?}, reason {:?}",
                g.count_law, g.count_law_reason
            );
        }
    }
}

#[test]
fn tables_are_the_same_bytes_on_one_and_two_threads() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/default-campaign");
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = Vec::new();
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let path = dir.path().join(format!("t{threads}.json"));
        pool.install(|| fit(&root).write(&path).unwrap());
        bytes.push(std::fs::read(&path).unwrap());
    }
    assert!(
        bytes[0] == bytes[1],
        "tables differ between 1 and 2 threads"
    );
}

#[test]
fn real_frames_at_a_narrow_mor_range_give_a_table() {
    // The case: the real capture's revolutions labelled fog at MOR
    // 304–378 m, weathered by the ground-truth fog model (few near returns
    // at that visibility). Before, the fit stopped with "count_law: n_ref
    // inf must be finite"; now every count law is finite or null with its
    // reason, and every near-range law pinned down or flagged.
    let Some(capture) = murk_fixtures::semi_real::vlp16_capture(env!("CARGO_MANIFEST_DIR")) else {
        return;
    };
    for (seed, null_weather) in [(7, false), (8, true)] {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("semi-real");
        let cfg = murk_fixtures::semi_real::SemiRealConfig {
            mor_m: [304.0, 378.0],
            declared_azimuth_deg: 0.4,
            null_weather,
            ..Default::default()
        };
        murk_fixtures::semi_real::vlp16_campaign(&capture, &out, &cfg, seed).unwrap();
        let t = fit(&out).table().clone();
        t.validate().unwrap();
        let fog = &t.weathers[&WeatherClass::Fog];
        for (name, law, reason) in [
            ("ghost", &fog.ghost, &fog.ghost_reason),
            ("ring", &fog.ring, &fog.ring_reason),
        ] {
            match law {
                Some(l) => {
                    eprintln!(
                        "seed {seed} (null {null_weather}) {name}: count law {:?}, reason {:?}, distance reason {:?}, reflectivity reason {:?}",
                        l.count_law, l.count_law_reason, l.distance_m.reason, l.reflectivity.reason
                    );
                    if let Some(c) = &l.count_law {
                        assert!(c.expected(340.0).is_finite(), "{c:?}");
                    } else {
                        assert!(l.count_law_reason.is_some());
                    }
                    for (what, g) in [
                        ("distance", &l.distance_m),
                        ("reflectivity", &l.reflectivity),
                    ] {
                        check_gaussian(g, l.points, &format!("seed {seed} {name} {what}")).unwrap();
                    }
                }
                None => {
                    eprintln!("seed {seed} (null {null_weather}) {name}: null, {reason:?}");
                    assert!(reason.is_some());
                }
            }
        }
    }
}

/// The expected ghost and ring counts of the fitted table against the
/// ground-truth model at `mors` (within 15 %), and the distance laws'
/// means (within three of their standard errors, which are over
/// recordings).
fn near_range_against_truth(
    t: &murk_types::CoefficientTable,
    truth: &murk_fixtures::WeatherModel,
    mors: &[f64],
    what: &str,
) -> Vec<String> {
    let fog = &t.weathers[&WeatherClass::Fog];
    let mut errors = Vec::new();
    for (name, law, truth) in [
        ("ghost", &fog.ghost, &truth.ghost),
        ("ring", &fog.ring, &truth.ring),
    ] {
        let law = law
            .as_ref()
            .unwrap_or_else(|| panic!("{what}: no {name} law"));
        let count = law.count_law.as_ref().expect("a count law");
        let ratios: Vec<f64> = mors
            .iter()
            .map(|&m| count.expected(m) / truth.count.expected(m))
            .collect();
        let d = &law.distance_m;
        let se = d.mean_std_error.expect("a standard error");
        let z = (d.mean - truth.distance_m.mean) / se;
        eprintln!(
            "{what} {name}: expected count / truth at MOR {mors:?}: {ratios:.3?}; distance mean {:.3} ± {se:.3} (truth {:.3}, z {z:+.2}), std {:.3} (truth {:.3}); visible {:.3}",
            d.mean,
            truth.distance_m.mean,
            d.std,
            truth.distance_m.std,
            law.visible_fraction.unwrap_or(f64::NAN)
        );
        for (m, r) in mors.iter().zip(&ratios) {
            if (r - 1.0).abs() > 0.15 {
                errors.push(format!(
                    "{what} {name}: count at MOR {m} m {r:.3} × the truth"
                ));
            }
        }
        if z.abs() > 3.0 {
            errors.push(format!(
                "{what} {name}: distance mean {z:+.2} standard errors off"
            ));
        }
    }
    errors
}

/// Near-range laws on a real scene (issue #12's semi-real source): the
/// real VLP-16 revolutions (its mount and walls within 1–3 m of the sensor
/// on most rays), weathered by the ground-truth fog model, whose ghost and
/// ring returns fall on any firing and are hidden behind nearer returns.
/// Where the scene is near, a weather return at the distance of a clear
/// return of its cell or a neighbour is paired or called scene, not
/// counted; the fit sees the laws through that mask as through the
/// occluders. Expected counts within 15 % of the truth at three MORs and
/// distance means within three standard errors, on three seeds (measured:
/// counts 0.91–1.09 of the truth, distance means within 1.8 standard
/// errors). Without the mask the counts came out 0.62–0.67 (ring) and
/// 0.76–0.84 (ghost) of the truth on these seeds, outside their
/// intervals. (murk's generator is the other source:
/// `default_campaign_laws_are_pinned_down_or_say_why` and the coverage
/// tests.) Skips without `../shared/data/real`.
#[test]
fn near_range_laws_on_a_real_scene_recover_the_truth() {
    use murk_fixtures::semi_real::{self, SemiRealConfig};
    let Some(capture) = semi_real::vlp16_capture(env!("CARGO_MANIFEST_DIR")) else {
        return;
    };
    let mors = [30.0, 60.0, 120.0];
    let mut errors = Vec::new();
    for seed in [21, 22, 23] {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("semi-real");
        let cfg = SemiRealConfig {
            declared_azimuth_deg: 0.4,
            interleave_revolutions: true,
            ..SemiRealConfig::default()
        };
        semi_real::vlp16_campaign(&capture, &out, &cfg, seed).unwrap();
        let t = fit(&out).table().clone();
        errors.extend(near_range_against_truth(
            &t,
            &cfg.model,
            &mors,
            &format!("VLP-16 seed {seed}"),
        ));
    }
    assert!(errors.is_empty(), "{errors:#?}");
}
