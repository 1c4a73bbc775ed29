//! The diagnosis report (`weather-noise-diagnosis/1`) and its plain-language
//! causes.

use murk_types::{CoefficientTable, ExtensionObservable, ModelExtension, WeatherClass};
use serde::{Deserialize, Serialize};

use crate::DiagnoseError;
use crate::Relevance;
use crate::attribution::ProfileBin;
use crate::data::{Loaded, read_calibrated};
use crate::evaluate::{Metrics, applier, xyz};

/// The report's format tag.
pub const DIAGNOSIS_FORMAT: &str = "weather-noise-diagnosis/1";

/// A model's held-out metrics.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ModelMetrics {
    /// Where the model came from.
    pub source: String,
    /// The metrics.
    pub metrics: Metrics,
}

/// Where a covariate varies, and so how its test is run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Level {
    /// Point by point inside recordings (range, reflectivity, ring,
    /// elevation, azimuth): residuals are compared within each recording.
    Point,
    /// Once per recording (MOR, time, a `weather.csv` column): recordings
    /// are compared with each other.
    Scan,
}

impl Level {
    /// The name used in reports (`point`, `scan`).
    pub fn name(self) -> &'static str {
        match self {
            Level::Point => "point",
            Level::Scan => "scan",
        }
    }
}

impl std::fmt::Display for Level {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// One (observable, covariate) test.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Finding {
    /// `survival`, `count`, `range` or `intensity`.
    pub observable: ExtensionObservable,
    /// A point-level name, `mor`, `timestamp` or a `weather.csv` header.
    pub covariate: String,
    /// Effect size in multiples of the observable's relevance threshold.
    pub strength: f64,
    /// Significant after Holm's adjustment and at least as large as the
    /// relevance threshold (and not explained by a stronger finding).
    pub significant: bool,
    /// Plain-language cause.
    pub cause: String,
    /// `point` or `scan`.
    pub level: Level,
    /// Effect size in the residual's unit (RMS of the profile beyond chance).
    pub effect: f64,
    /// The observable's relevance threshold, same unit.
    pub relevance_threshold: f64,
    /// Permutation p-value.
    pub p_value: f64,
    /// Holm-adjusted p-value over all tests.
    pub p_adjusted: f64,
    /// Recordings with data.
    pub recordings: usize,
    /// The covariate that explains this dependence: a stronger one whose
    /// profile, once removed, leaves nothing; the covariate of an accepted
    /// extension step after which nothing is left; or `mor` for a column
    /// that reads the recording's MOR.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub explained_by: Option<String>,
    /// The extension step (1-based) that accepted this finding's term.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step: Option<usize>,
    /// Why this finding's term was turned down (no significant held-out
    /// gain), when it was tested as a candidate and rejected.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rejected: Option<String>,
    /// Mean residual per bin of the covariate.
    pub profile: Vec<ProfileBin>,
    /// The smallest effect (same unit as `effect`) this test finds with
    /// 80 % power on this campaign at the level the decision uses
    /// ([`crate::power`]): a test that finds nothing says "nothing larger
    /// than this". Null when the test cannot tell (`detectable_reason`
    /// says why), and in reports written before the field.
    #[serde(default)]
    pub detectable: Option<f64>,
    /// Why `detectable` is null (too few recordings for the null to reach
    /// the level, say).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub detectable_reason: Option<String>,
}

/// The extended model: every accepted term together.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Extended {
    /// The terms, in words, in the order they were accepted.
    pub term: String,
    /// The first accepted term fitted on every recording (as in the
    /// extended table).
    pub extension: ModelExtension,
    /// Every accepted term fitted on every recording, in order (as in the
    /// extended table).
    pub extensions: Vec<ModelExtension>,
    /// Held-out metrics with every term (each fitted per fold on the fit
    /// set).
    pub metrics: Metrics,
    /// The held-out gain of all terms together on each metric an accepted
    /// term targets.
    pub gains: Vec<Gain>,
    /// The scene-level gain (voxel global difference).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scene_gain: Option<Gain>,
}

/// Held-out improvement.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Gain {
    /// The metric.
    pub metric: String,
    /// Baseline value.
    pub before: f64,
    /// Extended value.
    pub after: f64,
    /// `(before − after) / before`.
    pub relative: f64,
}

/// One accepted extension step.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Step {
    /// The observable the term changes.
    pub observable: ExtensionObservable,
    /// Its covariate.
    pub covariate: String,
    /// The term, in words.
    pub term: String,
    /// Its own held-out gain: the model before the step against the model
    /// with it, both fitted per fold on the fit set.
    pub gain: Gain,
    /// One-sided p-value of the paired test over held-out recordings
    /// (sign flips of the per-recording loss differences).
    pub p_value: f64,
    /// Held-out recordings in the paired test.
    pub recordings: usize,
    /// The term's shape, chosen on held-out recordings (`bins`, `step`,
    /// `monotone`, `attenuation`, `linear`, `power`).
    pub shape: String,
    /// The parametric shape's parameters, fitted on every recording, with
    /// 95 % intervals where a bootstrap over recordings gives one (empty
    /// for the piecewise shapes).
    pub parameters: Vec<ShapeParameter>,
    /// Every shape tried for the term, with its held-out loss.
    pub shapes: Vec<ShapeTried>,
}

/// A parameter of a step's term.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ShapeParameter {
    /// Its name (`k`, `intercept`, `slope`, `scale`, `exponent`).
    pub name: String,
    /// Its value, fitted on every recording.
    pub value: f64,
    /// 95 % percentile interval of a bootstrap over recordings; absent
    /// when the fit has no closed form to resample cheaply.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ci95: Option<[f64; 2]>,
}

/// One shape tried for a step's term.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ShapeTried {
    /// The shape.
    pub shape: String,
    /// Its free parameters (most over the folds).
    pub parameters: usize,
    /// Mean per-recording loss on held-out recordings (the paired test's
    /// loss: survival log loss per return, mean square range or log
    /// intensity residual, |log count ratio|).
    pub held_out_loss: f64,
    /// One-sided p-value that the lowest-loss shape beats this one on
    /// held-out recordings (absent for the lowest itself).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub p_worse_than_best: Option<f64>,
    /// The shape kept: the fewest parameters among those not
    /// significantly worse than the lowest.
    pub chosen: bool,
}

/// A candidate term tested and turned down.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Rejected {
    /// The observable.
    pub observable: ExtensionObservable,
    /// The covariate.
    pub covariate: String,
    /// The step at which it was tested (1-based).
    pub step: usize,
    /// Its held-out gain when it could be measured.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gain: Option<Gain>,
    /// One-sided p-value of the paired test.
    pub p_value: f64,
    /// Why it was turned down.
    pub reason: String,
}

/// The report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// [`DIAGNOSIS_FORMAT`].
    pub format: String,
    /// The weather.
    pub weather: String,
    /// Recordings evaluated held-out (every recording, once).
    pub heldout_recordings: usize,
    /// Folds.
    pub folds: usize,
    /// Master seed.
    pub seed: u64,
    /// Recordings left out, with the reason.
    pub skipped: Vec<String>,
    /// How findings are tested, in words.
    pub method: String,
    /// The baseline's held-out metrics.
    pub baseline: ModelMetrics,
    /// Every test, significant first, strongest first.
    pub findings: Vec<Finding>,
    /// The extended model with every accepted term (null when no term was
    /// accepted).
    pub extended: Option<Extended>,
    /// The gain of all accepted terms together on the first accepted
    /// term's metric (null without extension).
    pub gain: Option<Gain>,
    /// Every accepted step, in order, with its own held-out gain.
    pub steps: Vec<Step>,
    /// Candidates tested and turned down, with the reason.
    pub rejected: Vec<Rejected>,
}

impl Report {
    /// The report as pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("the report serialises")
    }

    /// The strongest significant finding.
    pub fn top(&self) -> Option<&Finding> {
        self.findings.iter().find(|f| f.significant)
    }
}

/// Everything a diagnosis returns.
#[derive(Debug, Clone)]
pub struct Diagnosis {
    /// The report.
    pub report: Report,
    /// The table `murk apply` uses: the baseline fitted on every recording
    /// (or the table given) plus every accepted extension term, in step
    /// order; without one, the baseline itself (no term).
    /// Always present after a run; `None` only in a hand-built value.
    pub extended_table: Option<CoefficientTable>,
    /// Data of the figures.
    pub figures: FigureData,
}

/// Data of the bird's-eye figure of one held-out recording.
#[derive(Debug, Clone, PartialEq)]
pub struct FigureData {
    /// Recording id.
    pub recording: String,
    /// The recording's MOR, metres (what the simulation was run at).
    pub mor_m: f64,
    /// The clear recording simulated from.
    pub clear: Vec<[f32; 3]>,
    /// The baseline simulation.
    pub simulated: Vec<[f32; 3]>,
    /// The measurement.
    pub measured: Vec<[f32; 3]>,
}

impl FigureData {
    /// Simulates recording `j` of `loaded` with `table`.
    pub fn new(
        loaded: &Loaded,
        table: &CoefficientTable,
        j: usize,
        seed: u64,
    ) -> Result<FigureData, DiagnoseError> {
        let rec = &loaded.recs[j];
        let clear = &loaded.clear[rec.clear].read(&loaded.spec)?;
        let ap = applier(table, loaded, rec, true, seed)?;
        let (out, _) = ap
            .apply(clear, &format!("{}#figure", rec.id))
            .map_err(|e| DiagnoseError::Infer {
                what: format!("recording {}", rec.id),
                source: Box::new(e),
            })?;
        Ok(FigureData {
            recording: rec.id.clone(),
            mor_m: rec.mor,
            clear: xyz(clear),
            simulated: xyz(&out),
            measured: xyz(&read_calibrated(&rec.lidar, &loaded.spec)?),
        })
    }
}

/// The method, in words, for the report.
pub fn method_text(permutations: usize, alpha: f64, r: &Relevance) -> String {
    format!(
        "Residual = measured − simulated on held-out recordings. Point-level covariates: residuals centred per recording, binned; null by flipping the sign of whole recordings ({permutations} draws). Scan-level covariates: one residual per recording, binned; null by shuffling the covariate across recordings ({permutations} draws). Strength = RMS of the binned profile beyond its null mean, over the relevance threshold (survival {} keep probability, count {} log ratio, range {} m, intensity {} log ratio). Significant = Holm-adjusted p < {alpha} over all tests and effect ≥ threshold; a weaker covariate of the same observable is re-tested after removing the strongest one's profile; a weather.csv column that reads the recording's MOR (|r| ≥ {mor_r} on log values) is one quantity with mor. Stagewise: the candidates of the strongest observable each get a term fitted per fold on the fit set; the one with the largest held-out gain is accepted when a paired sign-flip test over held-out recordings (per-recording loss before − after, one-sided) gives p < {alpha}; the model is re-evaluated, every test re-run, and the next term added, until nothing significant is left or {steps} steps. A significant finding is kept only when its term is accepted; one that disappears after a step is explained by that step's covariate. Detectable = the smallest step along the covariate (worst edge with ≥ 1/4 of the weight on each side) the test finds with 80 % power at α/m and ≥ the threshold, from the test's own null draws; null with the reason when the test cannot tell.",
        r.survival,
        r.count,
        r.range,
        r.intensity,
        mor_r = crate::aliases::MOR_ALIAS_R,
        steps = crate::MAX_STEPS,
    )
}

/// Direction of a numeric profile: slope sign of the residual against the
/// covariate (`None` for categories or a flat profile).
fn trend(f: &Finding) -> Option<f64> {
    let pts: Vec<(f64, f64, f64)> = f
        .profile
        .iter()
        .filter_map(|b| b.center.map(|c| (c, b.mean_residual, b.weight)))
        .collect();
    if pts.len() < 2 {
        return None;
    }
    let w: f64 = pts.iter().map(|p| p.2).sum();
    let mx = pts.iter().map(|p| p.0 * p.2).sum::<f64>() / w;
    let my = pts.iter().map(|p| p.1 * p.2).sum::<f64>() / w;
    let sxy: f64 = pts.iter().map(|p| p.2 * (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| p.2 * (p.0 - mx).powi(2)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

/// The plain-language cause of a finding.
pub fn cause(f: &Finding, weather: WeatherClass) -> String {
    let obs = f.observable;
    if let Some(by) = &f.explained_by {
        return format!(
            "{} follows {:?} only as far as {:?} does: nothing is left after removing the {by:?} profile",
            f.observable, f.covariate, by
        );
    }
    if let Some(why) = &f.rejected {
        return format!(
            "{} along {:?} was tested as an extension and turned down: {why}",
            f.observable, f.covariate
        );
    }
    if !f.significant {
        return format!(
            "no dependence of {} on {:?} beyond chance and the {} threshold",
            f.observable, f.covariate, f.relevance_threshold
        );
    }
    let slope = trend(f);
    let rises = slope.map(|s| s > 0.0);
    let low_high = {
        let mut bins: Vec<&ProfileBin> = f.profile.iter().collect();
        bins.sort_by(|a, b| a.mean_residual.total_cmp(&b.mean_residual));
        match (bins.first(), bins.last()) {
            (Some(lo), Some(hi)) => format!(
                "lowest in {} ({:+.3}), highest in {} ({:+.3})",
                lo.label, lo.mean_residual, hi.label, hi.mean_residual
            ),
            _ => String::new(),
        }
    };
    let what = match obs {
        ExtensionObservable::Survival => "returns survive",
        ExtensionObservable::Count => "returns with no clear counterpart appear",
        ExtensionObservable::Range => "kept returns' range shifts",
        ExtensionObservable::Intensity => "kept returns' reflectivity changes",
    };
    let known = match (obs, f.covariate.as_str(), rises) {
        (ExtensionObservable::Survival, "reflectivity", Some(true)) => Some(
            "low-reflectivity returns drop first: the model's reflectivity bands are too coarse or their slopes too close".to_string(),
        ),
        (ExtensionObservable::Survival, "elevation" | "ring", _)
            if matches!(weather, WeatherClass::Rain | WeatherClass::Snow) =>
        {
            Some("wet-road specular loss on ground rings: returns from the road surface vanish sooner than the model's slopes say".to_string())
        }
        (ExtensionObservable::Count, "elevation" | "ring" | "azimuth", _) => Some(format!(
            "ghost and ring returns fall more often on some rays than the model's uniform placement says (counted per laser and {}° azimuth sector, against simulations from the same clear scene)",
            360 / crate::data::AZIMUTH_SECTORS
        )),
        (ExtensionObservable::Count, "mor", Some(false)) => Some(
            "droplet backscatter near the sensor grows faster as visibility falls than the fitted count law".to_string(),
        ),
        (ExtensionObservable::Intensity, "range", Some(false)) => Some(
            "two-way attenuation of intensity: reflectivity of kept returns falls with range through the weather".to_string(),
        ),
        _ => None,
    };
    let dep = format!(
        "{what} differently from the model along {:?} ({}); {low_high}",
        f.covariate,
        match rises {
            Some(true) => "the residual rises with it".to_string(),
            Some(false) => "the residual falls with it".to_string(),
            None => "by category".to_string(),
        }
    );
    match known {
        Some(k) => format!("{k} ({dep})"),
        None => dep,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The typed `observable` and `level` write the strings the report has
    /// always carried, and a finding reads back from its JSON unchanged.
    #[test]
    fn a_finding_round_trips_with_the_report_strings() {
        let mut expected = Vec::new();
        for (observable, level, obs_name, level_name) in [
            (
                ExtensionObservable::Survival,
                Level::Point,
                "survival",
                "point",
            ),
            (ExtensionObservable::Count, Level::Scan, "count", "scan"),
            (ExtensionObservable::Range, Level::Point, "range", "point"),
            (
                ExtensionObservable::Intensity,
                Level::Scan,
                "intensity",
                "scan",
            ),
        ] {
            let f = Finding {
                observable,
                covariate: "Road state".into(),
                strength: 2.5,
                significant: true,
                cause: "wet road".into(),
                level,
                effect: 0.05,
                relevance_threshold: 0.02,
                p_value: 0.001,
                p_adjusted: 0.01,
                recordings: 12,
                explained_by: None,
                step: None,
                rejected: None,
                profile: vec![ProfileBin {
                    label: "wet".into(),
                    center: None,
                    mean_residual: 0.04,
                    weight: 300.0,
                    recordings: 6,
                }],
                detectable: Some(0.03),
                detectable_reason: None,
            };
            let json = serde_json::to_value(&f).unwrap();
            let want = serde_json::json!({
                "observable": obs_name, "covariate": "Road state", "strength": 2.5,
                "significant": true, "cause": "wet road", "level": level_name,
                "effect": 0.05, "relevance_threshold": 0.02, "p_value": 0.001,
                "p_adjusted": 0.01, "recordings": 12,
                "profile": [{"label": "wet", "mean_residual": 0.04, "weight": 300.0,
                             "recordings": 6}],
                "detectable": 0.03,
            });
            assert_eq!(json, want);
            assert_eq!(serde_json::from_value::<Finding>(json.clone()).unwrap(), f);
            // A report written before `detectable` reads back with none.
            let mut old = json;
            old.as_object_mut().unwrap().remove("detectable");
            let back = serde_json::from_value::<Finding>(old).unwrap();
            assert_eq!((back.detectable, back.detectable_reason), (None, None));
            assert_eq!(observable.to_string(), obs_name);
            assert_eq!(level.to_string(), level_name);
            expected.push(f);
        }
        let text = serde_json::to_string(&expected).unwrap();
        assert_eq!(
            serde_json::from_str::<Vec<Finding>>(&text).unwrap(),
            expected
        );
    }
}
