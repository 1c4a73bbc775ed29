//! The applier's data types: the checked pieces of a model (band rules,
//! the soft survival edge, near-range laws at the applied MOR, how a rain
//! rate became the MOR, which slope estimate is used) and the serialisable
//! description of a model ([`ModelSummary`]).
//!
//! They live apart from [`crate::applier`] (which applies them),
//! [`crate::hyperparams`] (which builds them from a table) and the kernels
//! (`kernel`, `near`, `extension`, which read them), so that each of those
//! depends on this module and none on another's internals.

use murk_types::{EdgeShape, NoiseLaw, RayDensity, SurvivalFit, WeatherClass};
use rand::RngExt;
use rand::rngs::ChaCha8Rng;
use serde::Serialize;

use crate::sampling::TruncNormal;

/// Which of the table's slope estimates decides vanishing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SlopeSource {
    /// `vanishing_slope`: the maximum-likelihood edge of the survival
    /// boundary, "as appliers use it" (the table's own recommendation).
    #[default]
    Survival,
    /// `vanishing_slope_q99`: the seed's estimate (zero-intercept regression
    /// of the per-MOR 0.99 quantile), to reproduce the seed's model exactly.
    Quantile,
}

impl SlopeSource {
    /// The table field this source reads.
    pub fn field(self) -> &'static str {
        match self {
            SlopeSource::Survival => "vanishing_slope",
            SlopeSource::Quantile => "vanishing_slope_q99",
        }
    }
}

/// One reflectivity band of the applied model.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[non_exhaustive]
pub struct BandRule {
    /// Lower edge (inclusive), calibrated reflectivity.
    pub reflectivity_min: f64,
    /// Upper edge (exclusive); `None` when unbounded.
    pub reflectivity_max: Option<f64>,
    /// Vanishing slope of the band at the applied MOR (NaN only for an
    /// identity model built on a band without slope): the table's slope for
    /// the linear law, `a·MOR^(b−1)` for a law that bends
    /// ([`murk_types::VanishingLaw::effective_slope`]).
    pub slope: f64,
    /// `slope × MOR × range_scale`, metres (infinite for the identity): the
    /// distance at the band's reference reflectivity when the law has a
    /// reflectivity term.
    pub vanishing_distance_m: f64,
    /// Relative soft-edge width, when the table has it.
    pub edge_width: Option<f64>,
    /// The law's reflectivity term inside the band at the applied MOR, if
    /// it has one: a return of calibrated reflectivity `x` vanishes at
    /// `vanishing_distance_m · factor(x)` (murk-types owns the factor; a
    /// term whose exponent changes with MOR is resolved at the applied MOR
    /// with [`murk_types::ReflectivityDependence::at_mor`]).
    pub reflectivity: Option<murk_types::ReflectivityDependence>,
}

impl BandRule {
    /// The vanishing distance, metres, of a return of calibrated
    /// reflectivity `x` in this band.
    #[inline]
    pub fn distance_at(&self, x: f64) -> f64 {
        match &self.reflectivity {
            None => self.vanishing_distance_m,
            Some(r) => self.vanishing_distance_m * r.factor(x),
        }
    }
}

/// The fitted survival edge.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub(crate) struct SoftEdge {
    /// The edge law, murk-types' one definition (the one fit fitted).
    pub edge: EdgeShape,
    pub dropout: f64,
    pub residual: f64,
    /// `1 / (1 − dropout_clear)`: the input is a clear recording that
    /// already lost its clear-weather dropout, so survival is conditioned on
    /// being present in it.
    pub clear_factor: f64,
}

impl SoftEdge {
    pub(crate) fn new(s: &SurvivalFit) -> Result<SoftEdge, String> {
        let edge = s.edge;
        if s.dropout + s.residual > 1.0 {
            return Err(format!(
                "dropout {} + residual {} exceed 1",
                s.dropout, s.residual
            ));
        }
        let clear = s.dropout_clear.unwrap_or(0.0);
        if !(0.0..1.0).contains(&clear) {
            return Err(format!("dropout_clear {clear} is not in [0, 1)"));
        }
        Ok(SoftEdge {
            edge,
            dropout: s.dropout,
            residual: s.residual,
            clear_factor: 1.0 / (1.0 - clear),
        })
    }

    /// Unconditional `P(kept)` at standardised distance `z = (r − D)/(w·D)`
    /// from the vanishing distance: [`EdgeShape::keep_probability`].
    #[inline]
    pub(crate) fn keep_probability(&self, z: f64) -> f64 {
        self.edge.keep_probability(z, self.dropout, self.residual)
    }

    /// `P(kept)` at `z` given that the return is present in the clear input
    /// (which already lost the clear-weather dropout).
    #[inline]
    pub(crate) fn keep_probability_given_clear(&self, z: f64) -> f64 {
        (self.keep_probability(z) * self.clear_factor).min(1.0)
    }
}

/// Largest expected near-range count per scan accepted.
const MAX_EXPECTED_NEAR: f64 = 1e8;

/// A ghost or ring law evaluated at the applied MOR.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct NearLaw {
    pub expected: f64,
    pub count_source: &'static str,
    pub distance: TruncNormal,
    pub reflectivity: TruncNormal,
    /// The distance law reweighted by the table's count terms along range
    /// (`None` without such terms: the law as it is).
    pub range: Option<murk_types::RangeCells>,
    /// Those terms' factor on the expected count (their mean under the
    /// law; 1 without them, 0 when they are 0 over the whole law).
    pub range_factor: f64,
}

impl NearLaw {
    pub(crate) fn new(l: &NoiseLaw, mor: f64, count_scale: f64) -> Result<NearLaw, String> {
        let (base, count_source) = match &l.count_law {
            Some(c) => (c.expected(mor), "count_law"),
            None => (l.points_per_scan, "points_per_scan"),
        };
        let expected = base * count_scale;
        if !(expected.is_finite() && (0.0..=MAX_EXPECTED_NEAR).contains(&expected)) {
            return Err(format!(
                "expected count {expected} per scan at MOR {mor} m (from {count_source}) is not in [0, {MAX_EXPECTED_NEAR}]"
            ));
        }
        let dlo = l.distance_m.lower.unwrap_or(0.0).max(0.0);
        let dhi = l.distance_m.upper.unwrap_or(f64::INFINITY);
        // Calibrated reflectivity lives in [0, 255].
        let rlo = l.reflectivity.lower.unwrap_or(0.0).max(0.0);
        let rhi = l.reflectivity.upper.unwrap_or(255.0).min(255.0);
        if dlo >= dhi {
            return Err(format!(
                "distance_m truncation [{dlo}, {dhi}] m is empty (ranges are > 0)"
            ));
        }
        if rlo >= rhi {
            return Err(format!(
                "reflectivity truncation [{rlo}, {rhi}] is empty (calibrated reflectivity lies in [0, 255])"
            ));
        }
        Ok(NearLaw {
            expected,
            count_source,
            distance: TruncNormal::new(l.distance_m.mean, l.distance_m.std, dlo, dhi),
            reflectivity: TruncNormal::new(l.reflectivity.mean, l.reflectivity.std, rlo, rhi),
            range: None,
            range_factor: 1.0,
        })
    }

    /// The law with the count terms along range of `density` (the
    /// applier's, fixed for its MOR): the reweighted distance law tabulated
    /// once, not per scan.
    pub(crate) fn with_range_terms(mut self, density: &RayDensity) -> NearLaw {
        if density.has_range_terms() {
            let cells = density.range_cells(|t| self.distance.at(t));
            self.range_factor = cells.as_ref().map_or(0.0, |c| c.mean);
            self.range = cells;
        }
        self
    }

    /// One draw of the distance (one uniform, reweighted or not).
    pub(crate) fn sample_distance(&self, rng: &mut ChaCha8Rng) -> f64 {
        match &self.range {
            None => self.distance.sample(rng),
            Some(c) => self.distance.at(c.fraction(rng.random())),
        }
    }
}

/// How a rain rate became the applied MOR.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct RainUse {
    pub requested_mm_h: f64,
    pub used_mm_h: f64,
    pub warning: Option<String>,
}

/// A serialisable description of an [`Applier`](crate::Applier): what was applied.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[non_exhaustive]
pub struct ModelSummary {
    /// The weather.
    pub weather: WeatherClass,
    /// The applied MOR, metres (null for a rain rate of 0).
    pub mor_m: Option<f64>,
    /// The rain rate asked for, mm/h (rain given as a rate only).
    pub rain_rate_requested_mm_h: Option<f64>,
    /// The rain rate converted (differs from the request after a clamp).
    pub rain_rate_used_mm_h: Option<f64>,
    /// True when applying is the identity.
    pub identity: bool,
    /// The clear-weather MOR threshold, metres.
    pub clear_mor_threshold_m: f64,
    /// Range-scale coefficient of the target sensor.
    pub range_scale: f64,
    /// `vanishing_slope` or `vanishing_slope_q99`.
    pub slope_field: &'static str,
    /// `hard`, `soft-probit` or `soft-logistic`.
    pub vanishing: &'static str,
    /// Near-range returns on.
    pub near_range: bool,
    /// σ of the range noise, metres (null when off).
    pub range_noise_m: Option<f64>,
    /// α of the intensity attenuation, 1/m (null when off).
    pub attenuation_alpha_per_m: Option<f64>,
    /// Master seed.
    pub seed: u64,
    /// The bands applied.
    pub bands: Vec<BandSummaryRule>,
    /// Warnings raised while checking the parameters.
    pub warnings: Vec<String>,
    /// Extension terms applied (from `murk diagnose`), empty for a plain table.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub extensions: Vec<murk_types::ModelExtension>,
    /// Scan-level covariate values supplied for the extension terms.
    #[serde(skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub covariates: std::collections::BTreeMap<String, murk_types::CovariateValue>,
}

/// One band of a [`ModelSummary`] (finite numbers or null, for JSON).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[non_exhaustive]
pub struct BandSummaryRule {
    /// Lower edge (inclusive).
    pub reflectivity_min: f64,
    /// Upper edge (exclusive); null when unbounded.
    pub reflectivity_max: Option<f64>,
    /// Slope (null when the table has none and the model is the identity).
    pub slope: Option<f64>,
    /// Vanishing distance, metres (null for the identity); with a
    /// reflectivity term, at its reference reflectivity.
    pub vanishing_distance_m: Option<f64>,
    /// The law's reflectivity term, when it has one: each return's distance
    /// is `vanishing_distance_m · (max(x, floor)/reference)^exponent`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reflectivity: Option<murk_types::ReflectivityDependence>,
}
