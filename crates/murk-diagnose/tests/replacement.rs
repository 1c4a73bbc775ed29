//! `murk diagnose` on a campaign whose near returns replace the returns
//! the weather loses (a strongest-return sensor; issue #12): the physics
//! fog on the real VLP-16 scene with the fog's echo on every ray that no
//! hard target beats — the rays whose target was lost and the open ones.
//! The table fitted on every recording finds replacement, the diagnosis
//! counts each recording's hidden returns as lost as the fit did, and so
//! its survival residuals must show no profile along range or MOR: the
//! one a hiding reading would leave (hidden returns out of the trials, so
//! nothing lost beyond the edge) is not there.
//!
//! What the physics does differ in on survival, the diagnosis may say: the
//! lidar equation's reflectivity dependence inside a band (survival ×
//! reflectivity); every other significant survival finding must be
//! explained by another. Count findings are printed, not held to: the fog
//! echo's range is a function of MOR rather than murk's truncated
//! Gaussian, and the capture's own near returns and open rays differ from
//! revolution to revolution (murk-diagnose's lib docs; the revolutions are
//! interleaved so that they do not follow time). Skipped, saying so,
//! without the capture.

mod common;

use murk_fixtures::physics_fog::PhysicsFog;
use murk_fixtures::semi_real::vlp16_capture;
use murk_types::{ExtensionObservable, WeatherClass};

#[test]
fn a_replacing_fog_leaves_no_survival_profile_along_range_or_mor() {
    if vlp16_capture(env!("CARGO_MANIFEST_DIR")).is_none() {
        eprintln!("skipped: the real VLP-16 capture is not present");
        return;
    }
    let d = common::semi_real_fog(61, |c| {
        c.degraded = 36;
        c.mor_m = [8.0, 40.0];
        c.interleave_revolutions = true;
        c.physics = Some(PhysicsFog {
            fog_returns: true,
            sky_returns: true,
            ..PhysicsFog::default()
        });
    });
    let r = &d.report;
    let table = d.extended_table.as_ref().expect("the table");
    let occlusion = table.weathers[&WeatherClass::Fog]
        .occlusion
        .as_ref()
        .unwrap();
    assert!(occlusion.replaced, "{occlusion:?}");
    for f in &r.findings {
        eprintln!(
            "{} × {}: p {:.4}, Holm {:.4}, strength {:.2}, significant {}, explained by {:?}",
            f.observable.name(),
            f.covariate,
            f.p_value,
            f.p_adjusted,
            f.strength,
            f.significant,
            f.explained_by
        );
    }
    eprintln!("baseline {:?}", r.baseline.metrics);
    for f in r
        .findings
        .iter()
        .filter(|f| f.significant && f.observable == ExtensionObservable::Survival)
    {
        assert!(
            f.covariate == "reflectivity" || f.explained_by.is_some(),
            "{} × {}: strength {:.2}, p {:.4}",
            f.observable.name(),
            f.covariate,
            f.strength,
            f.p_adjusted
        );
    }
    for cov in ["range", "mor"] {
        let f = r
            .findings
            .iter()
            .find(|f| f.observable == ExtensionObservable::Survival && f.covariate == cov)
            .unwrap_or_else(|| panic!("survival × {cov} was not tested"));
        assert!(
            !f.significant,
            "survival × {cov}: strength {:.2}",
            f.strength
        );
    }
    // The survival the baseline predicts on held-out recordings is close
    // to what they show (log loss of a fair coin: 0.69), and so is the
    // share of cells unchanged: measured, a hidden return counts as lost,
    // as the table was fitted. Measured (seed 61): log loss 0.084,
    // no-change error 0.0075; with the hidden returns left out of the
    // measured trials instead (the hiding reading) 0.047 and 0.0144 — the
    // survival tests above pass either way (strengths 0.49 / 0.42 against
    // 0.67 / 0.32), the no-change rate does not.
    let m = &r.baseline.metrics;
    assert!(m.survival_log_loss < 0.2, "{m:?}");
    assert!(m.no_change_rate_error < 0.01, "{m:?}");
}
