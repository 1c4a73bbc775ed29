//! The coefficient table: the one contract between `murk fit` (which writes
//! it) and the appliers (which read it).
//!
//! A table is plain serde data in the layout of `report-formats.md`
//! (`format = "weather-noise-coefficients/1"`). Every number is a finite JSON
//! number; where a value cannot be computed it is `null` and a sibling
//! `…reason` field says why. Readers go through [`CoefficientTable::from_json`]
//! or [`CoefficientTable::read`], which check the format tag and every value an
//! applier depends on (bands ordered and contiguous, slopes and standard
//! deviations positive, rates in `[0, 1]`) so that a damaged or hand-edited
//! table fails on load, naming the field, rather than in the middle of a run.
//!
//! Fields may be added in later versions of the same format; unknown fields
//! are ignored on load so that older appliers keep reading newer tables.
//!
//! **API boundary:** only this module knows the JSON layout. `fit` builds the
//! values, `infer` reads them; neither depends on the other.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::{TypesError, WeatherClass};

/// The format tag every table carries.
pub const TABLE_FORMAT: &str = "weather-noise-coefficients/1";

/// A fitted coefficient table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CoefficientTable {
    /// Always [`TABLE_FORMAT`].
    pub format: String,
    /// Campaign name (`campaign.toml` `name`).
    pub campaign: String,
    /// The LiDAR the table was fitted for.
    pub lidar: TableLidar,
    /// Coefficients per degraded weather. A weather with no recording is
    /// absent here and listed in [`CoefficientTable::absent`].
    pub weathers: BTreeMap<WeatherClass, WeatherCoefficients>,
    /// Weathers left out of [`CoefficientTable::weathers`], with the reason.
    #[serde(default)]
    pub absent: BTreeMap<WeatherClass, String>,
    /// Clear-weather reference statistics (the baseline of Table 7).
    #[serde(default)]
    pub clear: Option<ClearCoefficients>,
    /// Radar no-change rates, when the campaign has `radar/`.
    #[serde(default)]
    pub radar: Option<RadarCoefficients>,
    /// Selected recordings the fit could not use, and why.
    #[serde(default)]
    pub excluded_recordings: Vec<ExcludedRecording>,
    /// How the table was made: tool, parameters, input digests.
    pub provenance: Provenance,
}

/// The sensor part of a table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TableLidar {
    /// Free-text model name.
    pub model: String,
    /// Range-scale coefficient of the fitted sensor: vanishing distance =
    /// slope × MOR × range_scale.
    pub range_scale: f64,
    /// The firing geometry the fit paired on: measured from the clear
    /// recordings (or the declared one when it could not be measured).
    /// Absent in tables written before it was measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub geometry: Option<SensorGeometry>,
    /// What the recordings contradict in `campaign.toml` (azimuth step, ring
    /// elevations, ring count), each with both values.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// Unit of every near-range count in the table (`points_per_scan` and
    /// the count laws). A table without it counted per recording of one
    /// revolution, which is the same as per revolution.
    #[serde(default)]
    pub count_unit: CountUnit,
}

/// Unit of the near-range counts of a table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CountUnit {
    /// Returns per revolution (per scan) of the sensor.
    #[default]
    PerRevolution,
    /// Returns per recording, whatever its length.
    PerRecording,
}

/// The firing geometry of a LiDAR as the fit measured it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SensorGeometry {
    /// `measured` (from the clear recordings) or `declared` (campaign.toml,
    /// when the recordings could not tell).
    pub source: String,
    /// Clear recordings measured.
    pub recordings: u32,
    /// Scans (revolutions of a `.pcap`, whole files otherwise) measured.
    pub frames: u32,
    /// Median azimuth step of the measured rings, degrees.
    pub azimuth_step_deg: f64,
    /// `azimuth_resolution_deg` of campaign.toml.
    pub declared_azimuth_step_deg: f64,
    /// Per ring.
    pub rings: Vec<RingGeometry>,
}

/// The measured firing grid of one ring.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RingGeometry {
    /// Ring number.
    pub ring: u16,
    /// Azimuth step between consecutive firings, degrees (360 / bins).
    pub azimuth_step_deg: f64,
    /// Azimuth of the firing grid modulo the step, degrees in `[0, step)`:
    /// pairing cells are centred on `phase + k·step`.
    pub azimuth_phase_deg: f64,
    /// Resultant length of the firings' phases (1: every revolution fires at
    /// the same azimuths, phase-locked; near 0: free-running).
    pub phase_locking: f64,
    /// Median elevation of the ring's returns, degrees (null without returns).
    pub elevation_deg: Option<f64>,
    /// The elevation campaign.toml declares for the ring.
    pub declared_elevation_deg: Option<f64>,
    /// Returns the ring's step was measured from.
    pub returns: u64,
    /// False when the ring had too few returns and took the other rings'
    /// step (or the declared one).
    pub measured: bool,
}

/// Everything fitted for one degraded weather.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WeatherCoefficients {
    /// Recordings of this weather that were used.
    pub recordings: u32,
    /// Smallest MOR among them, metres.
    #[serde(default)]
    pub mor_min_m: Option<f64>,
    /// Largest MOR among them, metres.
    #[serde(default)]
    pub mor_max_m: Option<f64>,
    /// The vanishing slope per reflectivity band, as appliers use it:
    /// the maximum-likelihood edge of the survival boundary.
    pub vanishing_slope: Vec<SlopeBand>,
    /// The seed's estimate in the same bands: zero-intercept least squares of
    /// the per-MOR-bin quantile of the clear range of *no change* returns.
    #[serde(default)]
    pub vanishing_slope_q99: Vec<SlopeBand>,
    /// The quantile used by [`WeatherCoefficients::vanishing_slope_q99`].
    pub quantile: f64,
    /// Per-MOR-bin quantiles over all reflectivities (the seed's Figure 26).
    #[serde(default)]
    pub mor_bins: Vec<MorBin>,
    /// The survival-boundary fit behind `vanishing_slope`.
    #[serde(default)]
    pub survival: Option<SurvivalFit>,
    /// Fraction of clear returns still present unchanged (Table 7).
    pub no_change_rate: Option<f64>,
    /// Bootstrap-over-recordings uncertainty of `no_change_rate`.
    #[serde(default)]
    pub no_change_rate_uncertainty: Option<Uncertainty>,
    /// Why `no_change_rate` is null.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub no_change_rate_reason: Option<String>,
    /// Ghost returns (no clear counterpart, in the ghost window); null when
    /// none were found.
    pub ghost: Option<NoiseLaw>,
    /// Why `ghost` is null.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ghost_reason: Option<String>,
    /// Ring ("fake wall") returns (no clear counterpart, in the ring window);
    /// null when none were found.
    pub ring: Option<NoiseLaw>,
    /// Why `ring` is null.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ring_reason: Option<String>,
    /// `MOR = slope · R + intercept` from recordings with both a rain rate and
    /// a MOR (rain only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mor_from_rain_rate: Option<RainConversion>,
    /// Why `mor_from_rain_rate` is missing (rain only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mor_from_rain_rate_reason: Option<String>,
    /// Both slope estimates over a finer sweep of reflectivity bands (the
    /// seed's Figure 27).
    #[serde(default)]
    pub reflectivity_sweep: Vec<SweepBand>,
    /// Terms added along further covariates by `murk diagnose` (empty for a
    /// plain fit); see [`crate::ModelExtension`].
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub extensions: Vec<crate::ModelExtension>,
}

/// One reflectivity band of a slope list.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SlopeBand {
    /// Lower edge (inclusive), calibrated reflectivity.
    pub reflectivity_min: f64,
    /// Upper edge (exclusive); null means unbounded.
    pub reflectivity_max: Option<f64>,
    /// Vanishing slope (dimensionless: vanishing distance / (MOR × range_scale)).
    pub slope: Option<f64>,
    /// Clear returns of this band that entered the estimate.
    pub points: u64,
    /// Why `slope` is null.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// Standard error of `slope`, when known. For the survival fit it is
    /// over recordings (cluster-robust: the returns of one recording share
    /// its MOR reading and sensor state); tables before this field's
    /// documentation changed held the independent-returns value here.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub std_error: Option<f64>,
    /// The standard error as if every return were independent (inverse
    /// observed information), beside `std_error` for comparison: far
    /// smaller when recordings disagree.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub std_error_independent: Option<f64>,
    /// 95 % interval of `slope` over recordings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ci95: Option<Interval>,
    /// The held-out test that the data show an edge at all (survival fit
    /// only); `slope` is null, with the reason, when they do not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edge_test: Option<EdgeTest>,
    /// Relative width of the soft edge (survival fit only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edge_width: Option<f64>,
    /// 95 % interval of `edge_width` over recordings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edge_width_ci95: Option<Interval>,
    /// Per-MOR-bin quantiles of this band (quantile estimate only).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub mor_bins: Vec<MorBin>,
}

/// A confidence interval and how it was made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Interval {
    /// Lower end.
    pub low: f64,
    /// Upper end.
    pub high: f64,
    /// Nominal coverage (0.95).
    pub level: f64,
    /// How: `cluster-robust over recordings` (sandwich covariance with one
    /// cluster per recording, in the fit's internal parameters — log slope,
    /// log width, logit dropout — with Student's t on recordings − 1 degrees
    /// of freedom) or `bootstrap over recordings`.
    pub method: String,
}

/// Held-out evidence that the weather's survival follows an edge in
/// `r / MOR`.
///
/// Recordings are split into `folds` folds; each is predicted by three
/// models fitted without it: the edge; the clear scene's own survival of
/// each return (measured on the clear recordings, leave-one-out) times one
/// rate — "the weather does nothing", the null; and survival by range
/// alone (a rate per 5 % of range, also times the clear survival). Each
/// recording's gain is the difference of its held-out log-likelihoods. The
/// edge counts as seen (`edge_seen`) when it beats the null (mean gain
/// `gain_over_constant_nats_per_recording` > 0 with a one-sided sign-flip
/// p-value over recordings `p_value_over_constant` ≤ `alpha`, exact up to
/// 20 recordings) and range alone does not beat it significantly
/// (`p_value_range_better` > `alpha` or the mean gain over range alone,
/// `gain_nats_per_recording`, ≥ 0). Tables written before the null knew
/// the clear survival decided on `p_value` (edge better than range alone)
/// and hold no `p_value_range_better`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EdgeTest {
    /// Mean held-out log-likelihood gain of the edge over range alone per
    /// recording, nats.
    pub gain_nats_per_recording: f64,
    /// Recordings the edge predicted better than range alone.
    pub recordings_better: u32,
    /// Recordings with returns in the band.
    pub recordings: u32,
    /// One-sided sign-flip p-value of the mean gain over range alone.
    pub p_value: f64,
    /// The level the p-value must reach.
    pub alpha: f64,
    /// Mean held-out gain over the null — the clear scene's own survival
    /// of each return times one rate: "the weather does nothing" — nats
    /// per recording (older tables: over one constant rate).
    pub gain_over_constant_nats_per_recording: f64,
    /// Its one-sided sign-flip p-value.
    pub p_value_over_constant: f64,
    /// Standard deviation of `ln MOR` over the recordings.
    pub mor_spread: f64,
    /// One-sided sign-flip p-value that range alone predicts the held-out
    /// recordings better than the edge.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub p_value_range_better: Option<f64>,
    /// What decided, in words (older tables: `r/MOR against range alone`
    /// or `edge against constant survival`).
    pub basis: String,
    /// Folds over recordings.
    pub folds: u32,
    /// True when the test saw an edge.
    pub edge_seen: bool,
}

/// One MOR bin of the quantile estimate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MorBin {
    /// Mean MOR of the bin's recordings, metres (the regression abscissa).
    pub mor_m: f64,
    /// Lower edge of the bin, metres.
    #[serde(default)]
    pub mor_lo_m: Option<f64>,
    /// Upper edge of the bin, metres.
    #[serde(default)]
    pub mor_hi_m: Option<f64>,
    /// Recordings in the bin.
    #[serde(default)]
    pub recordings: u32,
    /// Quantile of the clear range of *no change* returns, metres.
    pub q99_range_m: Option<f64>,
    /// *No change* returns in the bin.
    pub points: u64,
    /// True when the far end of the clear scene, not the weather, bounds the
    /// quantile; such a bin is left out of the regression.
    #[serde(default)]
    pub censored: bool,
    /// True when the bin entered the regression.
    #[serde(default)]
    pub used: bool,
    /// Why the bin was left out or its quantile is null.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

/// The maximum-likelihood survival boundary of one weather.
///
/// `P(kept | r, MOR, band) = π + (1 − ε − π) · (1 − F((r − s_b·M)/(w_b·s_b·M)))`
/// with `M = MOR × range_scale` and `F` the unit-variance [`SurvivalFit::edge`]
/// CDF; [`crate::EdgeShape`] is the one definition of this law.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SurvivalFit {
    /// `probit` (normal CDF) or `logistic` (unit-variance logistic CDF); the
    /// names older tables wrote still parse.
    pub edge: crate::EdgeShape,
    /// Dropout ε: probability that a return well inside the vanishing
    /// distance is still lost.
    pub dropout: f64,
    /// The clear-weather dropout (leave-one-out against the reference).
    #[serde(default)]
    pub dropout_clear: Option<f64>,
    /// 95 % interval of `dropout` over recordings (when it was fitted).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dropout_ci95: Option<Interval>,
    /// Residual survival π beyond the edge (returns that outlive the
    /// weather: retro-reflectors, mismatches). It often sits at its bound,
    /// where the likelihood is flat: no interval is given.
    pub residual: f64,
    /// Negative log-likelihood at the optimum.
    pub neg_log_likelihood: f64,
    /// Clear returns (trials) in the likelihood.
    pub trials: u64,
}

/// Bootstrap uncertainty of a rate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Uncertainty {
    /// Standard deviation of the bootstrap replicates.
    pub std: f64,
    /// 2.5 % percentile of the replicates.
    pub ci95_low: f64,
    /// 97.5 % percentile of the replicates.
    pub ci95_high: f64,
    /// Number of replicates.
    pub replicates: u32,
}

/// A Gaussian law, possibly truncated to `[lower, upper)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Gaussian {
    /// Mean of the untruncated normal.
    pub mean: f64,
    /// Standard deviation of the untruncated normal (> 0).
    pub std: f64,
    /// Lower truncation bound, when the law is truncated below.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lower: Option<f64>,
    /// Upper truncation bound, when the law is truncated above.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub upper: Option<f64>,
    /// Standard error of `mean`, when fitted (inverse curvature of the
    /// likelihood). A law cut far into its body, such as a reflectivity whose
    /// mean sits near the floor, is loose in its mean: this says how loose.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean_std_error: Option<f64>,
    /// Standard error of `std`, when fitted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub std_std_error: Option<f64>,
}

/// Ghost or ring returns of one weather: their laws and how many there are.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseLaw {
    /// Law of the range, metres.
    pub distance_m: Gaussian,
    /// Law of the calibrated reflectivity.
    pub reflectivity: Gaussian,
    /// Mean number per scan, in the table's `lidar.count_unit` (per
    /// revolution since that field exists).
    pub points_per_scan: f64,
    /// Mean number per recording (a recording may hold many revolutions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub points_per_recording: Option<f64>,
    /// Returns the laws were fitted on.
    #[serde(default)]
    pub points: u64,
    /// Share of the returns placed on random rays that stay visible (a
    /// weather return behind a closer return of its ray is hidden), as
    /// estimated from the campaign; `points_per_scan` ≈ `visible_fraction` ×
    /// the count law.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub visible_fraction: Option<f64>,
    /// Returns to place per scan as a function of MOR, before hiding: an
    /// applier draws this many on random rays and keeps those in front of
    /// the ray's return.
    #[serde(default)]
    pub count_law: Option<CountLaw>,
    /// Why `count_law` is null.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub count_law_reason: Option<String>,
}

/// Expected number of returns per scan as a function of MOR.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "law", rename_all = "lowercase")]
#[non_exhaustive]
pub enum CountLaw {
    /// `N(MOR) = n_ref · (mor_ref_m / MOR)^exponent`.
    Power {
        /// Expected count at `mor_ref_m`.
        n_ref: f64,
        /// Reference MOR, metres.
        mor_ref_m: f64,
        /// Power-law exponent.
        exponent: f64,
        /// Standard error of `n_ref` (Poisson likelihood curvature), when
        /// fitted.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        n_ref_std_error: Option<f64>,
        /// Standard error of `exponent`, when fitted: a narrow MOR range
        /// leaves the exponent loose, and this says how loose.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        exponent_std_error: Option<f64>,
    },
}

impl CountLaw {
    /// Expected count per scan at `mor_m`.
    pub fn expected(&self, mor_m: f64) -> f64 {
        match *self {
            CountLaw::Power {
                n_ref,
                mor_ref_m,
                exponent,
                ..
            } => n_ref * (mor_ref_m / mor_m).powf(exponent),
        }
    }
}

/// Linear conversion of a rain rate to an equivalent MOR.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RainConversion {
    /// `a` of `MOR = a·R + b`, metres per (mm/h).
    pub slope: f64,
    /// `b`, metres.
    pub intercept: f64,
    /// Recordings in the fit.
    pub points: u64,
    /// Standard error of `slope` (ordinary least squares; null with two
    /// points).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub slope_std_error: Option<f64>,
    /// Standard error of `intercept`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub intercept_std_error: Option<f64>,
    /// Smallest rain rate in the fit, mm/h.
    #[serde(default)]
    pub rain_rate_min: Option<f64>,
    /// Largest rain rate in the fit, mm/h.
    #[serde(default)]
    pub rain_rate_max: Option<f64>,
    /// Rain rate at which the line reaches MOR = 0 (null when it never does):
    /// the conversion is meaningless beyond it.
    #[serde(default)]
    pub zero_mor_rain_rate: Option<f64>,
    /// Ordinary least-squares slope of MOR on the measured rain rate, before
    /// the correction for gauge noise (null when no correction was made).
    /// Noise in the measured rate flattens an OLS line (regression
    /// dilution); `slope` is corrected for it where gauges disagree.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub slope_ols: Option<f64>,
    /// Ordinary least-squares intercept beside `slope_ols`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub intercept_ols: Option<f64>,
    /// Reliability of the measured rain rate: the share of its variance
    /// across recordings that is not gauge noise (1 = noise-free), as
    /// estimated from the disagreement of the rain gauges.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rain_rate_reliability: Option<f64>,
}

impl RainConversion {
    /// Equivalent MOR of a rain rate, metres.
    pub fn mor(&self, rain_rate: f64) -> f64 {
        self.slope * rain_rate + self.intercept
    }
}

/// One band of the reflectivity sweep (Figure 27).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SweepBand {
    /// Lower edge (inclusive).
    pub reflectivity_min: f64,
    /// Upper edge (exclusive); null means unbounded.
    pub reflectivity_max: Option<f64>,
    /// Maximum-likelihood slope.
    pub slope: Option<f64>,
    /// Quantile slope.
    pub slope_q99: Option<f64>,
    /// Clear returns of the band.
    pub points: u64,
}

/// Clear-weather statistics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClearCoefficients {
    /// Clear recordings (the reference).
    pub recordings: u32,
    /// Reference cells (directions with a stable clear return).
    pub reference_cells: u64,
    /// No-change rate of each clear recording against a reference built
    /// without it.
    pub no_change_rate: Option<f64>,
    /// Its bootstrap uncertainty.
    #[serde(default)]
    pub no_change_rate_uncertainty: Option<Uncertainty>,
    /// Why `no_change_rate` is null (a single clear recording).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub no_change_rate_reason: Option<String>,
}

/// Radar no-change rates (Table 7).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RadarCoefficients {
    /// No-change rate per weather (clear included).
    pub no_change_rate: BTreeMap<WeatherClass, f64>,
    /// Bootstrap uncertainty per weather.
    #[serde(default)]
    pub uncertainty: BTreeMap<WeatherClass, Uncertainty>,
    /// Recordings per weather.
    #[serde(default)]
    pub recordings: BTreeMap<WeatherClass, u32>,
    /// Weathers without a rate, and why.
    #[serde(default)]
    pub absent: BTreeMap<WeatherClass, String>,
    /// Pairing tolerance, metres.
    #[serde(default)]
    pub tolerance_m: Option<f64>,
}

/// A selected recording left out of the fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExcludedRecording {
    /// Recording id.
    pub recording: String,
    /// Its weather class.
    pub weather: WeatherClass,
    /// Why it was left out.
    pub reason: String,
}

/// How a table was made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// `name version` of the tool.
    pub tool: String,
    /// SHA-256 over the sorted `(path, digest)` list of every input file.
    pub inputs_sha256: String,
    /// Every input file, sorted by relative path.
    #[serde(default)]
    pub inputs: Vec<InputDigest>,
    /// Every parameter of the fit.
    pub parameters: serde_json::Value,
}

/// The digest of one input file.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct InputDigest {
    /// Path relative to the campaign folder, `/`-separated.
    pub path: String,
    /// Lower-case hex SHA-256 of the file's bytes.
    pub sha256: String,
}

impl WeatherCoefficients {
    /// The band of `vanishing_slope` that holds `reflectivity`.
    pub fn band_for(&self, reflectivity: f64) -> Option<&SlopeBand> {
        self.vanishing_slope
            .iter()
            .find(|b| b.contains(reflectivity))
    }
}

impl SlopeBand {
    /// True when `reflectivity` lies in `[reflectivity_min, reflectivity_max)`.
    pub fn contains(&self, reflectivity: f64) -> bool {
        reflectivity >= self.reflectivity_min
            && self.reflectivity_max.is_none_or(|m| reflectivity < m)
    }
}

impl CoefficientTable {
    /// Parses and validates a table from JSON text.
    pub fn from_json(text: &str) -> Result<Self, TypesError> {
        Self::parse(text, "<memory>")
    }

    /// Reads and validates a table file.
    pub fn read(path: &Path) -> Result<Self, TypesError> {
        let shown = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| TypesError::Table {
            path: shown.clone(),
            location: "file".into(),
            reason: e.to_string(),
        })?;
        Self::parse(&text, &shown)
    }

    fn parse(text: &str, path: &str) -> Result<Self, TypesError> {
        let table: CoefficientTable =
            serde_json::from_str(text).map_err(|e| TypesError::Table {
                path: path.to_string(),
                location: format!("line {} column {}", e.line(), e.column()),
                // serde_json ends its text with the same position: once is enough.
                reason: {
                    let text = e.to_string();
                    let at = format!(" at line {} column {}", e.line(), e.column());
                    text.strip_suffix(&at).unwrap_or(&text).to_string()
                },
            })?;
        table.validate().map_err(|e| match e {
            TypesError::Table {
                location, reason, ..
            } => TypesError::Table {
                path: path.to_string(),
                location,
                reason,
            },
            other => other,
        })?;
        Ok(table)
    }

    /// The table as pretty JSON (deterministic: struct fields in declaration
    /// order, maps sorted), after validation.
    pub fn to_json(&self) -> Result<String, TypesError> {
        self.validate()?;
        let mut s = serde_json::to_string_pretty(self).map_err(|e| TypesError::Table {
            path: "<memory>".into(),
            location: "serialisation".into(),
            reason: e.to_string(),
        })?;
        s.push('\n');
        Ok(s)
    }

    /// Checks every value an applier depends on.
    pub fn validate(&self) -> Result<(), TypesError> {
        let mut v = Validator::default();
        v.check(self.format == TABLE_FORMAT, "format", || {
            format!("expected {TABLE_FORMAT:?}, found {:?}", self.format)
        });
        v.positive(Some(self.lidar.range_scale), "lidar.range_scale");
        for (w, c) in &self.weathers {
            let at = format!("weathers.{w}");
            v.check(*w != WeatherClass::Clear, &at, || {
                "clear is the reference, not a degraded weather".into()
            });
            v.bands(&c.vanishing_slope, &format!("{at}.vanishing_slope"));
            v.bands(&c.vanishing_slope_q99, &format!("{at}.vanishing_slope_q99"));
            v.check(
                c.quantile > 0.0 && c.quantile < 1.0,
                &format!("{at}.quantile"),
                || format!("{} is not in (0, 1)", c.quantile),
            );
            v.rate(c.no_change_rate, &format!("{at}.no_change_rate"));
            for (name, law) in [("ghost", &c.ghost), ("ring", &c.ring)] {
                if let Some(l) = law {
                    v.gaussian(&l.distance_m, &format!("{at}.{name}.distance_m"));
                    v.gaussian(&l.reflectivity, &format!("{at}.{name}.reflectivity"));
                    v.check(
                        l.points_per_scan.is_finite() && l.points_per_scan >= 0.0,
                        &format!("{at}.{name}.points_per_scan"),
                        || format!("{} must be a finite count ≥ 0", l.points_per_scan),
                    );
                    if let Some(CountLaw::Power {
                        n_ref,
                        mor_ref_m,
                        exponent,
                        ..
                    }) = &l.count_law
                    {
                        let f = format!("{at}.{name}.count_law");
                        v.check(n_ref.is_finite() && *n_ref >= 0.0, &f, || {
                            format!("n_ref {n_ref} must be finite and ≥ 0")
                        });
                        v.positive(Some(*mor_ref_m), &format!("{f}.mor_ref_m"));
                        v.check(exponent.is_finite(), &f, || {
                            format!("exponent {exponent} is not finite")
                        });
                    }
                }
            }
            if let Some(r) = &c.mor_from_rain_rate {
                let f = format!("{at}.mor_from_rain_rate");
                v.check(r.slope.is_finite() && r.intercept.is_finite(), &f, || {
                    format!(
                        "slope {} and intercept {} must be finite",
                        r.slope, r.intercept
                    )
                });
            }
            if let Some(s) = &c.survival {
                let f = format!("{at}.survival");
                v.rate(Some(s.dropout), &format!("{f}.dropout"));
                v.rate(Some(s.residual), &format!("{f}.residual"));
            }
            for (i, e) in c.extensions.iter().enumerate() {
                let res = e.check();
                v.check(res.is_ok(), &format!("{at}.extensions[{i}]"), || {
                    res.unwrap_err()
                });
            }
        }
        if let Some(c) = &self.clear {
            v.rate(c.no_change_rate, "clear.no_change_rate");
        }
        if let Some(r) = &self.radar {
            for (w, x) in &r.no_change_rate {
                v.rate(Some(*x), &format!("radar.no_change_rate.{w}"));
            }
        }
        v.finish()
    }
}

/// Collects the first validation failure.
#[derive(Default)]
struct Validator {
    err: Option<(String, String)>,
}

impl Validator {
    fn check(&mut self, ok: bool, field: &str, reason: impl FnOnce() -> String) {
        if !ok && self.err.is_none() {
            self.err = Some((field.to_string(), reason()));
        }
    }

    fn positive(&mut self, x: Option<f64>, field: &str) {
        if let Some(x) = x {
            self.check(x.is_finite() && x > 0.0, field, || {
                format!("{x} must be finite and > 0")
            });
        }
    }

    fn rate(&mut self, x: Option<f64>, field: &str) {
        if let Some(x) = x {
            self.check((0.0..=1.0).contains(&x), field, || {
                format!("{x} is not a rate in [0, 1]")
            });
        }
    }

    fn gaussian(&mut self, g: &Gaussian, field: &str) {
        self.check(g.mean.is_finite(), field, || {
            format!("mean {} is not finite", g.mean)
        });
        self.positive(Some(g.std), &format!("{field}.std"));
    }

    fn bands(&mut self, bands: &[SlopeBand], field: &str) {
        for (i, b) in bands.iter().enumerate() {
            let f = format!("{field}[{i}]");
            self.check(b.reflectivity_min.is_finite(), &f, || {
                format!("reflectivity_min {} is not finite", b.reflectivity_min)
            });
            if let Some(m) = b.reflectivity_max {
                self.check(m > b.reflectivity_min, &f, || {
                    format!(
                        "reflectivity_max {m} must exceed reflectivity_min {}",
                        b.reflectivity_min
                    )
                });
            }
            self.positive(b.slope, &format!("{f}.slope"));
            self.check(b.slope.is_some() || b.reason.is_some(), &f, || {
                "slope is null without a reason".into()
            });
            if i + 1 < bands.len() {
                let next = bands[i + 1].reflectivity_min;
                self.check(b.reflectivity_max == Some(next), &f, || {
                    format!(
                        "bands must be sorted and contiguous: reflectivity_max {:?} but the next band starts at {next}",
                        b.reflectivity_max
                    )
                });
            }
        }
    }

    fn finish(self) -> Result<(), TypesError> {
        match self.err {
            None => Ok(()),
            Some((location, reason)) => Err(TypesError::Table {
                path: "<memory>".into(),
                location,
                reason,
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn band(min: f64, max: Option<f64>, slope: f64) -> SlopeBand {
        SlopeBand {
            reflectivity_min: min,
            reflectivity_max: max,
            slope: Some(slope),
            points: 10,
            reason: None,
            std_error: None,
            std_error_independent: None,
            ci95: None,
            edge_test: None,
            edge_width: None,
            edge_width_ci95: None,
            mor_bins: vec![],
        }
    }

    fn law(mean: f64, std: f64) -> NoiseLaw {
        NoiseLaw {
            distance_m: Gaussian {
                mean,
                std,
                lower: Some(3.0),
                upper: Some(10.0),
                mean_std_error: None,
                std_std_error: None,
            },
            reflectivity: Gaussian {
                mean: 4.0,
                std: 11.0,
                lower: Some(0.0),
                upper: None,
                mean_std_error: None,
                std_std_error: None,
            },
            points_per_scan: 41.0,
            points_per_recording: Some(41.0),
            points: 410,
            visible_fraction: Some(0.9),
            count_law: Some(CountLaw::Power {
                n_ref: 41.0,
                mor_ref_m: 100.0,
                exponent: 1.5,
                n_ref_std_error: None,
                exponent_std_error: None,
            }),
            count_law_reason: None,
        }
    }

    fn table() -> CoefficientTable {
        let fog = WeatherCoefficients {
            recordings: 28,
            mor_min_m: Some(50.0),
            mor_max_m: Some(200.0),
            vanishing_slope: vec![band(0.0, Some(10.0), 0.3029), band(10.0, None, 0.3463)],
            vanishing_slope_q99: vec![band(0.0, Some(10.0), 0.25), band(10.0, None, 0.3)],
            quantile: 0.99,
            mor_bins: vec![MorBin {
                mor_m: 52.5,
                mor_lo_m: Some(50.0),
                mor_hi_m: Some(55.0),
                recordings: 2,
                q99_range_m: Some(17.9),
                points: 4567,
                censored: false,
                used: true,
                reason: None,
            }],
            survival: None,
            no_change_rate: Some(0.38),
            no_change_rate_uncertainty: None,
            no_change_rate_reason: None,
            ghost: Some(law(5.011, 1.753)),
            ghost_reason: None,
            ring: None,
            ring_reason: Some("no ring returns".into()),
            mor_from_rain_rate: None,
            mor_from_rain_rate_reason: None,
            reflectivity_sweep: vec![],
            extensions: vec![],
        };
        CoefficientTable {
            format: TABLE_FORMAT.into(),
            campaign: "pdd".into(),
            lidar: TableLidar {
                model: "VLP16".into(),
                range_scale: 1.0,
                geometry: None,
                warnings: vec![],
                count_unit: CountUnit::PerRevolution,
            },
            weathers: BTreeMap::from([(WeatherClass::Fog, fog)]),
            absent: BTreeMap::from([(WeatherClass::Snow, "no recording".into())]),
            clear: None,
            radar: None,
            excluded_recordings: vec![],
            provenance: Provenance {
                tool: "murk-fit 0.1.0".into(),
                inputs_sha256: "00".into(),
                inputs: vec![],
                parameters: serde_json::json!({"quantile": 0.99}),
            },
        }
    }

    #[test]
    fn json_round_trip_is_identity() {
        let t = table();
        let s = t.to_json().unwrap();
        let back = CoefficientTable::from_json(&s).unwrap();
        assert_eq!(back, t);
        assert_eq!(back.to_json().unwrap(), s);
        assert!(s.contains(r#""reflectivity_max": null"#), "{s}");
        assert!(s.contains(r#""ring": null"#), "{s}");
    }

    #[test]
    fn band_lookup_follows_half_open_edges() {
        let t = table();
        let fog = &t.weathers[&WeatherClass::Fog];
        assert_eq!(fog.band_for(9.99).unwrap().slope, Some(0.3029));
        assert_eq!(fog.band_for(10.0).unwrap().slope, Some(0.3463));
        assert_eq!(fog.band_for(250.0).unwrap().slope, Some(0.3463));
        assert!(fog.band_for(-1.0).is_none());
    }

    #[test]
    fn count_law_and_rain_conversion_evaluate() {
        let l = law(5.0, 1.0).count_law.unwrap();
        assert!((l.expected(50.0) - 41.0 * 2f64.powf(1.5)).abs() < 1e-9);
        let r = RainConversion {
            slope: -0.8308,
            intercept: 159.16,
            points: 42,
            slope_std_error: None,
            intercept_std_error: None,
            rain_rate_min: None,
            rain_rate_max: None,
            zero_mor_rain_rate: None,
            slope_ols: None,
            intercept_ols: None,
            rain_rate_reliability: None,
        };
        assert!((r.mor(10.0) - 150.852).abs() < 1e-9);
    }

    #[test]
    fn wrong_format_tag_is_rejected() {
        let mut t = table();
        t.format = "weather-noise-coefficients/0".into();
        let s = serde_json::to_string(&t).unwrap();
        let e = CoefficientTable::from_json(&s).unwrap_err().to_string();
        assert!(e.contains("format") && e.contains("/0"), "{e}");
    }

    #[test]
    fn non_positive_slope_is_rejected() {
        let mut t = table();
        t.weathers
            .get_mut(&WeatherClass::Fog)
            .unwrap()
            .vanishing_slope[1]
            .slope = Some(-0.1);
        let e = t.validate().unwrap_err().to_string();
        assert!(e.contains("weathers.fog.vanishing_slope[1].slope"), "{e}");
    }

    #[test]
    fn null_slope_needs_a_reason() {
        let mut t = table();
        t.weathers
            .get_mut(&WeatherClass::Fog)
            .unwrap()
            .vanishing_slope[0]
            .slope = None;
        let e = t.validate().unwrap_err().to_string();
        assert!(e.contains("without a reason"), "{e}");
    }

    #[test]
    fn gap_between_bands_is_rejected() {
        let mut t = table();
        t.weathers
            .get_mut(&WeatherClass::Fog)
            .unwrap()
            .vanishing_slope[1]
            .reflectivity_min = 12.0;
        let e = t.validate().unwrap_err().to_string();
        assert!(e.contains("contiguous"), "{e}");
    }

    #[test]
    fn zero_std_is_rejected() {
        let mut t = table();
        let fog = t.weathers.get_mut(&WeatherClass::Fog).unwrap();
        fog.ghost.as_mut().unwrap().distance_m.std = 0.0;
        let e = t.validate().unwrap_err().to_string();
        assert!(e.contains("ghost.distance_m.std"), "{e}");
    }

    #[test]
    fn rate_above_one_is_rejected() {
        let mut t = table();
        t.weathers
            .get_mut(&WeatherClass::Fog)
            .unwrap()
            .no_change_rate = Some(1.5);
        let e = t.validate().unwrap_err().to_string();
        assert!(e.contains("no_change_rate"), "{e}");
    }

    #[test]
    fn clear_as_degraded_weather_is_rejected() {
        let mut t = table();
        let fog = t.weathers[&WeatherClass::Fog].clone();
        t.weathers.insert(WeatherClass::Clear, fog);
        let e = t.validate().unwrap_err().to_string();
        assert!(e.contains("weathers.clear"), "{e}");
    }

    #[test]
    fn syntax_error_names_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.json");
        std::fs::write(&p, "{\n \"format\": \n").unwrap();
        let e = CoefficientTable::read(&p).unwrap_err().to_string();
        assert!(e.contains("t.json") && e.contains("line 3"), "{e}");
    }

    #[test]
    fn unknown_fields_are_ignored() {
        let t = table();
        let mut v: serde_json::Value = serde_json::from_str(&t.to_json().unwrap()).unwrap();
        v["future_field"] = serde_json::json!(1);
        let back = CoefficientTable::from_json(&v.to_string()).unwrap();
        assert_eq!(back, t);
    }
}
