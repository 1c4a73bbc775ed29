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
    /// Moments of the ghost returns themselves (Table 5), present whenever
    /// any was seen, also when `ghost` is null.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ghost_returns: Option<ReturnMoments>,
    /// Ring ("fake wall") returns (no clear counterpart, in the ring window);
    /// null when none were found.
    pub ring: Option<NoiseLaw>,
    /// Why `ring` is null.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ring_reason: Option<String>,
    /// Moments of the ring returns themselves (Table 5), present whenever
    /// any was seen, also when `ring` is null.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ring_returns: Option<ReturnMoments>,
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
    /// Which vanishing law the bands use (survival fit only; absent in
    /// tables before it, which use the line).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub law_choice: Option<LawChoice>,
    /// Whether the weather's near returns *replace* the returns it loses
    /// (a strongest-return sensor reports the fog's echo where it beats
    /// the hard target's) or *hide* returns independently of their fate (a
    /// first-return sensor: a ghost in front hides what is behind). Absent
    /// in tables before the test.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub occlusion: Option<OcclusionTest>,
}

/// The test of how a weather's near returns (ghost, ring) relate to the
/// returns it loses, on the clear returns beyond the noise windows (every
/// near return of their ray lies in front of them).
///
/// If near returns hide clear returns independently of their fate, a
/// recording's cells that the weather keeps and those it loses are hidden
/// alike; if they replace lost returns, only the lost ones are. Per
/// recording, cells whose returns the weather mostly keeps (paired share ≥
/// 0.8 over the weather) are compared with cells whose returns it mostly
/// loses (≤ 0.2): the Mantel–Haenszel odds ratio of being hidden, lost
/// against kept, with recordings as strata, and the Cochran–Mantel–Haenszel
/// test of ratio 1. When it is significant and at least
/// [`OcclusionTest::MIN_ODDS_RATIO`], the near returns replace: the
/// survival trials count a hidden return as lost (it is: the sensor
/// reported the weather's echo instead), and `murk apply` places near
/// returns on rays whose return vanished (or that had none), never in
/// front of a kept one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OcclusionTest {
    /// Recordings with cells of both kinds beyond the noise windows.
    pub recordings: u32,
    /// Share of the expected returns hidden, over the cells the weather
    /// keeps.
    #[serde(default)]
    pub hidden_where_kept: Option<f64>,
    /// Share of the expected returns hidden, over the cells the weather
    /// loses.
    #[serde(default)]
    pub hidden_where_lost: Option<f64>,
    /// Mantel–Haenszel odds ratio of being hidden, lost cells against kept
    /// ones (`None` when no kept return is hidden: unbounded).
    #[serde(default)]
    pub odds_ratio: Option<f64>,
    /// Two-sided Cochran–Mantel–Haenszel p-value of ratio 1.
    #[serde(default)]
    pub p_value: Option<f64>,
    /// Significance level of the decision.
    pub alpha: f64,
    /// The near returns replace lost returns (the decision).
    pub replaced: bool,
    /// Why the test could not tell, when it could not (no recording with
    /// cells of both kinds beyond the noise windows: the scene is too
    /// small for its MOR range); the fit then keeps the hiding reading.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

impl OcclusionTest {
    /// Smallest odds ratio read as replacement: an effect, not only a
    /// significant one (a fit's own selection moves the ratio of a weather
    /// whose returns hide independently by tens of per cent, not by a
    /// factor of two).
    pub const MIN_ODDS_RATIO: f64 = 2.0;
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
    /// `edge_width` is the edge as the fit sees it, in range over the MOR
    /// *readings*; noisy readings widen it (a recording's edge moves with
    /// its reading error). This is the width with that noise taken out,
    /// `√(edge_width² − v)` with `v` the square of
    /// [`SurvivalFit::mor_reading_noise`]: the edge at a known MOR. Absent
    /// when the reading noise is unknown (see
    /// [`SurvivalFit::mor_reading_noise_reason`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edge_width_corrected: Option<f64>,
    /// `edge_width_ci95` with the same correction applied to its ends.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edge_width_corrected_ci95: Option<Interval>,
    /// Per-MOR-bin quantiles of this band (quantile estimate only).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub mor_bins: Vec<MorBin>,
    /// The vanishing law appliers use when it is not the linear law of
    /// `slope` (survival fit only): a law that bends, `a·MOR^b`, chosen over
    /// the line on held-out recordings, possibly with a reflectivity term
    /// inside the band (`·(x/x_ref)^k`, chosen the same way; see
    /// [`WeatherCoefficients::law_choice`]). Absent: the line `slope·MOR`.
    /// `slope` stays the linear fit either way, so published tables can be
    /// re-derived. Use [`SlopeBand::vanishing_law`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub law: Option<crate::VanishingLaw>,
    /// Per MOR bin, the nonparametric 50 %-survival range of the band with
    /// its interval over recordings, beside the fitted laws' (survival fit
    /// only).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub survival_bins: Vec<SurvivalBin>,
    /// The test of the fitted line against `survival_bins` (survival fit
    /// only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lack_of_fit: Option<LackOfFit>,
}

/// The nonparametric 50 %-survival range of one band in one MOR bin.
///
/// The bin's clear returns of the band, from every recording in the bin,
/// are pooled by range; the kept share is made non-increasing in range
/// (pool-adjacent-violators, weighted by trials), and the range where it
/// falls through 50 % is read off by linear interpolation. The interval
/// resamples the bin's recordings (bootstrap over recordings, percentile).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SurvivalBin {
    /// Mean MOR of the bin's recordings, metres.
    pub mor_m: f64,
    /// Lower edge of the bin, metres.
    pub mor_lo_m: f64,
    /// Upper edge of the bin, metres.
    pub mor_hi_m: f64,
    /// Recordings in the bin with returns in the band.
    pub recordings: u32,
    /// Clear returns (trials) of the band in the bin.
    pub trials: u64,
    /// The range where half the band's clear returns survive, metres; null
    /// with `reason` when survival does not cross 50 % inside the scene.
    pub half_survival_range_m: Option<f64>,
    /// 95 % interval of `half_survival_range_m` over recordings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ci95: Option<Interval>,
    /// The fitted line's 50 %-survival range at `mor_m` (its edge, dropout
    /// and residual survival included), metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub line_m: Option<f64>,
    /// The applied law's (`law`, or the line) 50 %-survival range at
    /// `mor_m`, metres. With a reflectivity term each return has its own
    /// distance, so this is the 50 % crossing of the law's survival over
    /// the bin's own clear returns, pooled by range as
    /// `half_survival_range_m` is (the law's prediction of that number).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub law_m: Option<f64>,
    /// Why `half_survival_range_m` or its interval is null.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

/// Does the fitted line describe the per-bin 50 %-survival ranges?
///
/// `statistic = Σ ((ln r̂_k − ln ℓ_k) / se_k)²` over the bins with a range
/// and an interval, `r̂_k` the nonparametric range, `ℓ_k` the line's, `se_k`
/// the bootstrap standard error of `ln r̂_k` (from its 95 % interval); under
/// the line it is χ² with `dof = bins − 1`. `lack_of_fit` is true when
/// `p_value ≤ alpha`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LackOfFit {
    /// The χ² statistic.
    pub statistic: f64,
    /// Degrees of freedom.
    pub dof: u32,
    /// Bins that entered.
    pub bins: u32,
    /// Upper-tail χ² p-value.
    pub p_value: f64,
    /// Level of the test.
    pub alpha: f64,
    /// True when the line does not fit the bins.
    pub lack_of_fit: bool,
    /// The bin whose range departs most from the line, as `range / line`.
    pub worst_ratio: f64,
}

/// Which vanishing law a weather's bands use, chosen on held-out
/// recordings.
///
/// Recordings are split into `folds` folds; each fold is predicted by the
/// line and by the law that bends (`a·MOR^b` per band, each band with its
/// own exponent, edge width, dropout and residual survival, fitted by
/// maximum likelihood; the line is fitted per band with the same freedom,
/// so the comparison weighs the exponent alone), both fitted without it. Each recording's gain is the difference of its held-out
/// log-likelihoods (bent − line); the law that bends is chosen when their
/// mean is positive and the one-sided sign-flip p-value is `≤ alpha`, so
/// the line stays when it is enough.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LawChoice {
    /// `linear` or `power`.
    pub chosen: String,
    /// Per band of `vanishing_slope`, the exponent `b` of its power law
    /// fitted on all recordings (null for a band without a slope).
    pub exponents: Vec<Option<f64>>,
    /// Per band, the 95 % interval of its exponent: a grouped jackknife
    /// over the held-out comparison's folds of recordings (each fold's fit
    /// without it), Student's t on folds − 1 degrees of freedom; null for a
    /// band without an exponent, or when a fold's exponent is missing or
    /// sits at the searched range's end. Absent in tables before it.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub exponent_ci95: Vec<Option<Interval>>,
    /// Mean held-out gain of the bent law over the line, nats per
    /// recording.
    pub gain_nats_per_recording: f64,
    /// Recordings the bent law predicted better.
    pub recordings_better: u32,
    /// Recordings compared.
    pub recordings: u32,
    /// One-sided sign-flip p-value of the mean gain.
    pub p_value: f64,
    /// Level.
    pub alpha: f64,
    /// Folds over recordings.
    pub folds: u32,
    /// Why the comparison could not be made, if it could not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// The held-out comparison of a reflectivity term inside each band
    /// with the law chosen above (absent when it was not asked for: murk
    /// fit's `reflectivity_law`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reflectivity: Option<ReflectivityChoice>,
}

/// Does a band's vanishing distance grow with reflectivity inside the band?
///
/// Each band's law is refitted with `(max(x, floor)/x_ref)^k` beside it
/// (`x` the return's clear reflectivity, `x_ref` the geometric mean of the
/// band's trials; `k` and, when the law bends, its exponent profiled by
/// maximum likelihood) and compared with the law without it on held-out
/// recordings, as [`LawChoice`] compares the bend with the line. Chosen
/// (and written into each band's `law` when murk fit's `apply_bend` is on)
/// when the mean gain is positive with a one-sided sign-flip p-value
/// `≤ alpha`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReflectivityChoice {
    /// True when the term is applied: it predicts held-out recordings
    /// significantly better and the fit was asked to apply it (murk fit's
    /// `apply_bend`); a term that won but is not applied says so in
    /// `reason`.
    pub chosen: bool,
    /// Per band, its exponent `k` fitted on all recordings (null for a
    /// band without a slope, or one whose reflectivities do not spread).
    pub exponents: Vec<Option<f64>>,
    /// Per band, the 95 % grouped-jackknife interval of `k` over the
    /// comparison's folds.
    pub exponent_ci95: Vec<Option<Interval>>,
    /// Per band, the reference reflectivity `x_ref`.
    pub references: Vec<Option<f64>>,
    /// Reflectivities below count as this one.
    pub floor: f64,
    /// Mean held-out gain over the law without the term, nats per
    /// recording.
    pub gain_nats_per_recording: f64,
    /// Recordings the term predicted better.
    pub recordings_better: u32,
    /// Recordings compared.
    pub recordings: u32,
    /// One-sided sign-flip p-value of the mean gain.
    pub p_value: f64,
    /// Why the comparison could not be made, or why a chosen term is not
    /// applied.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// Whether `k` changes with MOR, compared once the term is chosen
    /// (absent when it was not).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mor: Option<ReflectivityMorChoice>,
}

/// The held-out comparison of a reflectivity term whose exponent changes
/// with MOR, `k + g·ln(MOR / M_ref)`, with the term of one `k` (both with
/// the law the comparison prefers), as [`ReflectivityChoice`] compares the
/// term with the law without it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReflectivityMorChoice {
    /// True when applied: it predicts held-out recordings significantly
    /// better than one `k`, and the term itself is applied.
    pub chosen: bool,
    /// `M_ref`, metres: the geometric mean MOR of the weather's recordings.
    pub mor_reference_m: f64,
    /// Per band, `k` at `M_ref`, fitted with `g` on all recordings.
    pub exponents: Vec<Option<f64>>,
    /// Per band, `g`: the change of `k` per unit of `ln MOR`.
    pub per_ln_mor: Vec<Option<f64>>,
    /// Per band, the 95 % grouped-jackknife interval of `g` over the
    /// comparison's folds.
    pub per_ln_mor_ci95: Vec<Option<Interval>>,
    /// Mean held-out gain over the term of one `k`, nats per recording.
    pub gain_nats_per_recording: f64,
    /// Recordings the varying exponent predicted better.
    pub recordings_better: u32,
    /// Recordings compared.
    pub recordings: u32,
    /// One-sided sign-flip p-value of the mean gain.
    pub p_value: f64,
    /// Why the comparison could not be made, or why a chosen `g` is not
    /// applied.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
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
    /// How: `cluster-robust over recordings (leave-one-recording-out, CR3)`
    /// (the survival fit: the spread of one-step estimates with one
    /// recording left out, in the fit's internal parameters — log slope,
    /// log width, logit dropout — with Student's t on recordings − 1 degrees
    /// of freedom; the count laws' intervals say the same, with t on
    /// recordings − parameters), `cluster-robust over recordings` (tables
    /// written before the leave-one-out form) or `bootstrap over
    /// recordings`.
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
    /// Standard deviation of a recording's MOR reading error in `ln MOR`
    /// (root mean square over the weather's recordings), from the
    /// visibility sensors' disagreement: each sensor's scatter, pooled,
    /// over the number of sensors a recording's MOR averages. Error the
    /// sensors share does not show and is not in it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mor_reading_noise: Option<f64>,
    /// Why `mor_reading_noise` is unknown (one visibility sensor, or MOR
    /// from the rain conversion).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mor_reading_noise_reason: Option<String>,
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
    /// Set when the data cannot pin the truncated law down (`not
    /// identifiable: …`, with the numbers the fit gave): `mean` and `std`
    /// are then the returns' own moments, not a fitted law — applied inside
    /// the truncation they give back roughly the returns seen — and the
    /// standard errors are null.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
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
    /// How the count law's family was chosen (null in older tables and
    /// where no law could be fitted).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub count_law_choice: Option<CountLawChoice>,
}

/// Expected number of returns per scan as a function of MOR.
///
/// Two families: the seed's [`CountLaw::Power`] and [`CountLaw::Onset`], a
/// power law times a smooth onset in ln MOR (returns that appear only below
/// some MOR, or saturate in dense weather). The power law is the onset law's
/// limit as `onset_mor_m` grows without bound; `murk fit` chooses between
/// them per weather and law by held-out likelihood over recordings
/// ([`CountLawChoice`]). [`CountLaw::expected`] is the one evaluation every
/// applier and the diagnosis use.
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
        /// Standard error of `n_ref`, when fitted: cluster-robust over
        /// recordings in tables that carry `n_ref_ci95`, the Poisson
        /// likelihood's curvature in older ones.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        n_ref_std_error: Option<f64>,
        /// Standard error of `exponent`, when fitted: a narrow MOR range
        /// leaves the exponent loose, and this says how loose.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        exponent_std_error: Option<f64>,
        /// 95 % interval of `n_ref` over recordings.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        n_ref_ci95: Option<Interval>,
        /// 95 % interval of `exponent` over recordings.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        exponent_ci95: Option<Interval>,
    },
    /// `N(MOR) = n_ref · (mor_ref_m / MOR)^exponent / (1 + (MOR / onset_mor_m)^onset_steepness)`:
    /// the power law switched on below `onset_mor_m` (where the factor is
    /// ½), over a width of about `1 / onset_steepness` in ln MOR. With
    /// `exponent` 0 the count saturates at `n_ref` in dense weather; with a
    /// negative exponent it peaks at intermediate MOR.
    Onset {
        /// Scale: the power-law part's count at `mor_ref_m`.
        n_ref: f64,
        /// Reference MOR, metres.
        mor_ref_m: f64,
        /// Exponent of the power-law part.
        exponent: f64,
        /// MOR at which the onset factor is ½, metres.
        onset_mor_m: f64,
        /// Steepness of the onset in ln MOR (> 0).
        onset_steepness: f64,
        /// 95 % interval of `n_ref` over recordings.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        n_ref_ci95: Option<Interval>,
        /// 95 % interval of `exponent` over recordings.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        exponent_ci95: Option<Interval>,
        /// 95 % interval of `onset_mor_m` over recordings.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        onset_mor_ci95: Option<Interval>,
        /// 95 % interval of `onset_steepness` over recordings.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        onset_steepness_ci95: Option<Interval>,
    },
}

impl CountLaw {
    /// Expected count per scan at `mor_m` (computed in log space, so a
    /// steep onset does not overflow).
    pub fn expected(&self, mor_m: f64) -> f64 {
        match *self {
            CountLaw::Power {
                n_ref,
                mor_ref_m,
                exponent,
                ..
            } => n_ref * (mor_ref_m / mor_m).powf(exponent),
            CountLaw::Onset {
                n_ref,
                mor_ref_m,
                exponent,
                onset_mor_m,
                onset_steepness,
                ..
            } => {
                if n_ref <= 0.0 {
                    return 0.0;
                }
                let u = onset_steepness * (mor_m / onset_mor_m).ln();
                // ln(1 + e^u), stable for large |u|.
                let softplus = if u > 0.0 {
                    u + (-u).exp().ln_1p()
                } else {
                    u.exp().ln_1p()
                };
                (n_ref.ln() + exponent * (mor_ref_m / mor_m).ln() - softplus).exp()
            }
        }
    }

    /// The family's name as written in the table (`power`, `onset`).
    pub fn family(&self) -> &'static str {
        match self {
            CountLaw::Power { .. } => "power",
            CountLaw::Onset { .. } => "onset",
        }
    }
}

/// How `murk fit` chose a count law's family: the held-out Poisson
/// log-likelihood over recordings of each candidate (recordings split into
/// folds by MOR rank; each fold predicted by the law fitted on the others).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CountLawChoice {
    /// Family chosen (`power`, `onset`).
    pub chosen: String,
    /// Folds of the held-out comparison.
    pub folds: u32,
    /// Held-out log-likelihood of the power law, nats summed over
    /// recordings (up to the counts' constant).
    pub power_heldout_log_likelihood: f64,
    /// Same for the onset law (null when it was not tried or could not be
    /// fitted on some fold).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub onset_heldout_log_likelihood: Option<f64>,
    /// One-sided sign-flip p-value over recordings of the onset law's
    /// per-recording held-out gain.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub onset_gain_p: Option<f64>,
    /// Why the family was chosen.
    pub reason: String,
}

/// Moments of the near-range returns themselves (what the seed's Table 5
/// reports), beside the truncated laws fitted to them: they describe only
/// the part of a law inside its window, so a truncated mean below zero or
/// beyond the window reads against these.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReturnMoments {
    /// Returns.
    pub points: u64,
    /// Mean range of the returns, metres.
    pub distance_mean_m: f64,
    /// Standard deviation of their range, metres.
    pub distance_std_m: f64,
    /// Mean calibrated reflectivity of the returns.
    pub reflectivity_mean: f64,
    /// Standard deviation of their reflectivity.
    pub reflectivity_std: f64,
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
    /// The vanishing law of the band: `law` when the table gives one, else
    /// the line of `slope`; `None` without either.
    pub fn vanishing_law(&self) -> Option<crate::VanishingLaw> {
        self.law.or(self
            .slope
            .map(|slope| crate::VanishingLaw::Linear { slope }))
    }

    /// True when `reflectivity` lies in `[reflectivity_min, reflectivity_max)`.
    pub fn contains(&self, reflectivity: f64) -> bool {
        reflectivity >= self.reflectivity_min
            && self.reflectivity_max.is_none_or(|m| reflectivity < m)
    }

    /// Scales `edge_width` by `factor` (an edge re-fitted beside a model
    /// extension): `edge_width_corrected` follows it, with the survival
    /// fit's `mor_reading_noise` taken out again, and the intervals, which
    /// were the fitted width's, go. A law's reflectivity term carries the
    /// width appliers use in its place; it is scaled alike.
    pub fn scale_edge_width(&mut self, factor: f64, mor_reading_noise: Option<f64>) {
        if let Some(crate::VanishingLaw::Power {
            reflectivity: Some(r),
            ..
        }) = self.law.as_mut()
            && let Some(w) = r.edge_width.as_mut()
        {
            *w *= factor;
        }
        if let Some(e) = self.edge_width.as_mut() {
            *e *= factor;
            self.edge_width_corrected =
                mor_reading_noise.map(|n| crate::deconvolve_edge_width(*e, n * n));
            self.edge_width_ci95 = None;
            self.edge_width_corrected_ci95 = None;
        }
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
            for (i, b) in c.vanishing_slope.iter().enumerate() {
                if let Some(l) = &b.law {
                    let res = l.check();
                    v.check(
                        res.is_ok(),
                        &format!("{at}.vanishing_slope[{i}].law"),
                        || res.unwrap_err(),
                    );
                }
            }
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
                    if let Some(law) = &l.count_law {
                        v.count_law(law, &format!("{at}.{name}.count_law"));
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

    fn count_law(&mut self, law: &CountLaw, f: &str) {
        let (n_ref, mor_ref_m, exponent) = match law {
            CountLaw::Power {
                n_ref,
                mor_ref_m,
                exponent,
                ..
            } => (*n_ref, *mor_ref_m, *exponent),
            CountLaw::Onset {
                n_ref,
                mor_ref_m,
                exponent,
                onset_mor_m,
                onset_steepness,
                ..
            } => {
                self.positive(Some(*onset_mor_m), &format!("{f}.onset_mor_m"));
                self.positive(Some(*onset_steepness), &format!("{f}.onset_steepness"));
                (*n_ref, *mor_ref_m, *exponent)
            }
        };
        self.check(n_ref.is_finite() && n_ref >= 0.0, f, || {
            format!("n_ref {n_ref} must be finite and ≥ 0")
        });
        self.positive(Some(mor_ref_m), &format!("{f}.mor_ref_m"));
        self.check(exponent.is_finite(), f, || {
            format!("exponent {exponent} is not finite")
        });
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
            edge_width_corrected: None,
            edge_width_corrected_ci95: None,
            mor_bins: vec![],
            law: None,
            survival_bins: vec![],
            lack_of_fit: None,
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
                reason: None,
            },
            reflectivity: Gaussian {
                mean: 4.0,
                std: 11.0,
                lower: Some(0.0),
                upper: None,
                mean_std_error: None,
                std_std_error: None,
                reason: None,
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
                n_ref_ci95: None,
                exponent_ci95: None,
            }),
            count_law_reason: None,
            count_law_choice: None,
        }
    }

    #[test]
    fn a_rescaled_edge_width_carries_its_correction_and_drops_its_intervals() {
        let ci = Interval {
            low: 0.08,
            high: 0.11,
            level: 0.95,
            method: "x".into(),
        };
        let mut b = band(0.0, None, 0.3);
        b.edge_width = Some(0.095);
        b.edge_width_ci95 = Some(ci.clone());
        b.edge_width_corrected = Some(0.079);
        b.edge_width_corrected_ci95 = Some(ci);
        b.scale_edge_width(1.2, Some(0.053));
        let w = 0.095 * 1.2;
        assert!((b.edge_width.unwrap() - w).abs() < 1e-15);
        let want = (w * w - 0.053 * 0.053).sqrt();
        assert!((b.edge_width_corrected.unwrap() - want).abs() < 1e-15);
        assert!(b.edge_width_ci95.is_none() && b.edge_width_corrected_ci95.is_none());
        // Without a known reading noise there is no corrected width.
        b.scale_edge_width(1.0, None);
        assert!(b.edge_width_corrected.is_none());
        // Without a width nothing changes.
        let mut none = band(0.0, None, 0.3);
        none.scale_edge_width(2.0, Some(0.05));
        assert_eq!(none, band(0.0, None, 0.3));
        // A law's reflectivity term carries its own width: scaled too.
        let mut r = band(0.0, None, 0.3);
        r.edge_width = Some(0.1);
        r.law = Some(crate::VanishingLaw::Power {
            a: 1.0,
            b: 0.8,
            reflectivity: Some(crate::ReflectivityDependence {
                exponent: 0.2,
                reference: 20.0,
                floor: 1.0,
                edge_width: Some(0.04),
                exponent_per_ln_mor: None,
                mor_reference_m: None,
            }),
        });
        r.scale_edge_width(1.5, None);
        let w = r.law.unwrap().reflectivity().unwrap().edge_width.unwrap();
        assert!((w - 0.06).abs() < 1e-15, "{w}");
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
            ghost_returns: None,
            ring: None,
            ring_reason: Some("no ring returns".into()),
            ring_returns: None,
            mor_from_rain_rate: None,
            mor_from_rain_rate_reason: None,
            reflectivity_sweep: vec![],
            extensions: vec![],
            law_choice: None,
            occlusion: None,
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
    fn an_old_power_law_loads_and_evaluates_as_before() {
        // A law as tables without intervals or a choice wrote it.
        let c: CountLaw = serde_json::from_str(
            r#"{ "law": "power", "n_ref": 41.0, "mor_ref_m": 100.0, "exponent": 1.5,
                 "n_ref_std_error": 1.0, "exponent_std_error": 0.1 }"#,
        )
        .unwrap();
        assert_eq!(c.family(), "power");
        assert!((c.expected(25.0) - 41.0 * 4f64.powf(1.5)).abs() < 1e-9);
    }

    #[test]
    fn the_onset_law_evaluates_its_formula_and_is_validated() {
        let law = |steep: f64| CountLaw::Onset {
            n_ref: 40.0,
            mor_ref_m: 100.0,
            exponent: 0.5,
            onset_mor_m: 120.0,
            onset_steepness: steep,
            n_ref_ci95: None,
            exponent_ci95: None,
            onset_mor_ci95: None,
            onset_steepness_ci95: None,
        };
        for mor in [10.0f64, 120.0, 1e4] {
            let want = 40.0 * (100.0 / mor).powf(0.5) / (1.0 + (mor / 120.0f64).powf(4.0));
            assert!((law(4.0).expected(mor) / want - 1.0).abs() < 1e-12, "{mor}");
        }
        // A steep onset far above its MOR does not overflow.
        let far = law(50.0).expected(1e6);
        assert!(far.is_finite() && far < 1e-100, "{far}");
        let mut t = table();
        let fog = t.weathers.get_mut(&WeatherClass::Fog).unwrap();
        fog.ghost.as_mut().unwrap().count_law = Some(law(0.0));
        let e = t.validate().unwrap_err().to_string();
        assert!(e.contains("ghost.count_law.onset_steepness"), "{e}");
        let fog = t.weathers.get_mut(&WeatherClass::Fog).unwrap();
        fog.ghost.as_mut().unwrap().count_law = Some(law(4.0));
        t.validate().unwrap();
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
