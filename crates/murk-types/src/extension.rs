//! Model extensions: terms that `murk diagnose` adds to a fitted weather
//! model along one covariate, and that `murk apply` uses.
//!
//! The baseline model of a weather (vanishing slopes, soft edge, near-range
//! laws) knows range, reflectivity and MOR. An extension makes one part of it
//! depend on one more variable, as a function fitted on measured recordings
//! ([`ExtensionFunction`]: piecewise constant, monotone, or a named
//! parametric form such as two-way attenuation `exp(−k·r/MOR)`):
//!
//! | observable | the function's value `f` is | neutral |
//! |---|---|---|
//! | `survival` | a factor on the vanishing distance: `D ← D·f` | 1 |
//! | `count` | a factor on the expected ghost and ring counts per scan (along a point covariate: on their density over the rays and along range) | 1 |
//! | `range` | a bias added to the range of kept returns, metres | 0 |
//! | `intensity` | a factor on the reflectivity of kept returns | 1 |
//!
//! The covariate is a point-level name ([`POINT_COVARIATES`]: the clear
//! return's `range` in m, calibrated `reflectivity`, `ring`, `elevation` and
//! `azimuth` in degrees), `mor` (the applied MOR, m), or a `weather.csv`
//! column by its exact header, whose value the user supplies per batch
//! (`murk apply --covariate "NAME=VALUE"`). When a scan-level value is not
//! supplied the term uses its `default`, the campaign-wide value fitted
//! beside the bins.
//!
//! ```
//! use std::collections::BTreeMap;
//! use murk_types::{CovariateValue, ExtensionFunction, ExtensionObservable, ModelExtension, PointCovariates};
//!
//! // Ground rings (elevation below −4°) lose their returns 20 % sooner.
//! let ext = ModelExtension {
//!     observable: ExtensionObservable::Survival,
//!     covariate: "elevation".into(),
//!     function: ExtensionFunction::Bins { edges: vec![-4.0], values: vec![0.8, 1.0] },
//!     default: 1.0,
//!     description: "wet road".into(),
//! };
//! let ground = PointCovariates { range: 8.0, reflectivity: 20.0, ring: 0, elevation: -15.0, azimuth: 3.0 };
//! let scan = BTreeMap::<String, CovariateValue>::new();
//! assert_eq!(ext.value(Some(&ground), &scan, 100.0), 0.8);
//! assert!(ext.is_point_level());
//! assert!(ext.check().is_ok());
//! ```

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// The point-level covariate names.
pub const POINT_COVARIATES: [&str; 5] = ["range", "reflectivity", "ring", "elevation", "azimuth"];

/// What an extension changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ExtensionObservable {
    /// Whether a clear return is kept (factor on the vanishing distance).
    Survival,
    /// Returns with no clear counterpart (factor on the expected count).
    Count,
    /// Range of kept returns (additive bias, metres).
    Range,
    /// Reflectivity of kept returns (factor).
    Intensity,
}

impl std::fmt::Display for ExtensionObservable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl ExtensionObservable {
    /// The name used in reports (`survival`, `count`, `range`, `intensity`).
    pub fn name(self) -> &'static str {
        match self {
            ExtensionObservable::Survival => "survival",
            ExtensionObservable::Count => "count",
            ExtensionObservable::Range => "range",
            ExtensionObservable::Intensity => "intensity",
        }
    }

    /// The value that changes nothing.
    pub fn neutral(self) -> f64 {
        match self {
            ExtensionObservable::Range => 0.0,
            _ => 1.0,
        }
    }

    /// True when values combine by multiplication (factors), false when they
    /// add (the range bias).
    pub fn multiplicative(self) -> bool {
        self != ExtensionObservable::Range
    }
}

/// A function of the covariate (and, for [`ExtensionFunction::Attenuation`],
/// the MOR): piecewise constant (`bins`, `categories`, the shapes of the
/// first terms), monotone and piecewise linear, or one of the named
/// parametric forms. Tables written before the other shapes existed hold
/// only `bins` and `categories` and load unchanged.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ExtensionFunction {
    /// Numeric covariate: `values[k]` where `k` is the number of `edges` at
    /// or below the value (`edges` ascending, one fewer than `values`).
    Bins {
        /// Bin edges, ascending.
        edges: Vec<f64>,
        /// Value per bin.
        values: Vec<f64>,
    },
    /// Categorical covariate: the value of the category (the extension's
    /// `default` for any other).
    Categories {
        /// Value per category.
        values: BTreeMap<String, f64>,
    },
    /// Numeric covariate, monotone (isotonic regression): linear
    /// interpolation between `(knots[i], values[i])`, constant beyond the
    /// first and last knot.
    Monotone {
        /// Knots, strictly ascending.
        knots: Vec<f64>,
        /// Value at each knot (monotone; one per knot).
        values: Vec<f64>,
    },
    /// Two-way attenuation `exp(−k·x / MOR)` of a factor (survival,
    /// count, intensity; not the range bias): for `intensity` along
    /// `range` this is Beer–Lambert extinction `exp(−2αr)` with
    /// `α = (k/2)/MOR` (Koschmieder's 5 % contrast gives `α = ln 20/MOR`,
    /// `k = 2·ln 20 ≈ 5.99`). Without a positive MOR it is the default.
    Attenuation {
        /// The rate `k` (dimensionless).
        k: f64,
    },
    /// `intercept + slope·x` (a factor is floored at 0): a slope modulated
    /// by the covariate, or a bias that grows with it.
    Linear {
        /// Value at x = 0.
        intercept: f64,
        /// Change per unit of x.
        slope: f64,
    },
    /// `scale·x^exponent` for x > 0 (the default otherwise): along `mor`, a
    /// range bias growing as MOR falls (`exponent` < 0), or a vanishing
    /// distance that bends with MOR.
    Power {
        /// Value at x = 1.
        scale: f64,
        /// Exponent.
        exponent: f64,
    },
}

impl ExtensionFunction {
    /// The shape's name as written in the table and reports (`bins`,
    /// `categories`, `monotone`, `attenuation`, `linear`, `power`).
    pub fn kind(&self) -> &'static str {
        match self {
            ExtensionFunction::Bins { .. } => "bins",
            ExtensionFunction::Categories { .. } => "categories",
            ExtensionFunction::Monotone { .. } => "monotone",
            ExtensionFunction::Attenuation { .. } => "attenuation",
            ExtensionFunction::Linear { .. } => "linear",
            ExtensionFunction::Power { .. } => "power",
        }
    }

    /// Free parameters: one per value and per edge or knot of the
    /// piecewise shapes, one per category, the parametric forms' own.
    pub fn parameter_count(&self) -> usize {
        match self {
            ExtensionFunction::Bins { edges, values } => edges.len() + values.len(),
            ExtensionFunction::Categories { values } => values.len(),
            ExtensionFunction::Monotone { knots, values } => knots.len() + values.len(),
            ExtensionFunction::Attenuation { .. } => 1,
            ExtensionFunction::Linear { .. } | ExtensionFunction::Power { .. } => 2,
        }
    }

    /// The named parameters of a parametric form (empty for the
    /// piecewise shapes).
    pub fn parameters(&self) -> Vec<(&'static str, f64)> {
        match *self {
            ExtensionFunction::Attenuation { k } => vec![("k", k)],
            ExtensionFunction::Linear { intercept, slope } => {
                vec![("intercept", intercept), ("slope", slope)]
            }
            ExtensionFunction::Power { scale, exponent } => {
                vec![("scale", scale), ("exponent", exponent)]
            }
            _ => Vec::new(),
        }
    }

    /// True when the function takes a number (every shape but
    /// `categories`).
    pub fn is_numeric(&self) -> bool {
        !matches!(self, ExtensionFunction::Categories { .. })
    }

    /// The value at the number `x` and MOR `mor_m` (`None`: the
    /// function cannot say, and the term's default applies).
    fn at(&self, x: f64, mor_m: f64) -> Option<f64> {
        if !x.is_finite() {
            return None;
        }
        let v = match self {
            ExtensionFunction::Bins { edges, values } => values[edges.partition_point(|e| *e <= x)],
            ExtensionFunction::Categories { .. } => return None,
            ExtensionFunction::Monotone { knots, values } => {
                let i = knots.partition_point(|k| *k <= x);
                if i == 0 {
                    values[0]
                } else if i == knots.len() {
                    values[i - 1]
                } else {
                    let t = (x - knots[i - 1]) / (knots[i] - knots[i - 1]);
                    values[i - 1] + t * (values[i] - values[i - 1])
                }
            }
            ExtensionFunction::Attenuation { k } => {
                if !(mor_m.is_finite() && mor_m > 0.0) {
                    return None;
                }
                (-k * x / mor_m).exp()
            }
            ExtensionFunction::Linear { intercept, slope } => intercept + slope * x,
            ExtensionFunction::Power { scale, exponent } => {
                if x <= 0.0 {
                    return None;
                }
                scale * x.powf(*exponent)
            }
        };
        v.is_finite().then_some(v)
    }
}

/// A value of a scan-level covariate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum CovariateValue {
    /// A number.
    Number(f64),
    /// A category.
    Text(String),
}

impl CovariateValue {
    /// Parses a command-line value: a number when it parses as one, else text.
    pub fn parse(s: &str) -> CovariateValue {
        match s.trim().parse::<f64>() {
            Ok(v) if v.is_finite() => CovariateValue::Number(v),
            _ => CovariateValue::Text(s.trim().to_string()),
        }
    }
}

/// The point-level covariates of one clear return.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointCovariates {
    /// Range, metres.
    pub range: f64,
    /// Calibrated reflectivity.
    pub reflectivity: f64,
    /// Laser id.
    pub ring: u16,
    /// Elevation, degrees.
    pub elevation: f64,
    /// Azimuth, degrees in [0, 360).
    pub azimuth: f64,
}

impl PointCovariates {
    /// The covariates of a point at `(x, y, z)`.
    pub fn of_point(x: f64, y: f64, z: f64, reflectivity: f64, ring: u16) -> PointCovariates {
        let rxy = x.hypot(y);
        let mut azimuth = y.atan2(x).to_degrees();
        if azimuth < 0.0 {
            azimuth += 360.0;
        }
        PointCovariates {
            range: rxy.hypot(z),
            reflectivity,
            ring,
            elevation: z.atan2(rxy).to_degrees(),
            azimuth,
        }
    }

    /// The value of a point-level covariate by name.
    pub fn get(&self, name: &str) -> Option<f64> {
        Some(match name {
            "range" => self.range,
            "reflectivity" => self.reflectivity,
            "ring" => self.ring as f64,
            "elevation" => self.elevation,
            "azimuth" => self.azimuth,
            _ => return None,
        })
    }
}

/// One fitted extension term (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelExtension {
    /// What it changes.
    pub observable: ExtensionObservable,
    /// Its covariate: a point-level name, `mor`, or a `weather.csv` header.
    pub covariate: String,
    /// The function of the covariate.
    pub function: ExtensionFunction,
    /// The value used when the covariate is unknown (a scan-level value not
    /// supplied, an unlisted category).
    pub default: f64,
    /// Plain-language description (what was found, on what data).
    #[serde(default)]
    pub description: String,
}

impl ModelExtension {
    /// True when the covariate is per point.
    pub fn is_point_level(&self) -> bool {
        POINT_COVARIATES.contains(&self.covariate.as_str())
    }

    /// Checks the term: finite values, ascending edges, factors ≥ 0, a count
    /// term on a scan-level covariate.
    pub fn check(&self) -> Result<(), String> {
        if self.covariate.trim().is_empty() {
            return Err("covariate is empty".into());
        }
        let finite = |what: &str, v: &[f64]| -> Result<(), String> {
            match v.iter().find(|e| !e.is_finite()) {
                Some(e) => Err(format!("{what} {e} is not finite")),
                None => Ok(()),
            }
        };
        let values: Vec<f64> = match &self.function {
            ExtensionFunction::Bins { edges, values } => {
                if values.len() != edges.len() + 1 {
                    return Err(format!(
                        "{} values for {} edges (need one more value than edges)",
                        values.len(),
                        edges.len()
                    ));
                }
                finite("edge", edges)?;
                if edges.windows(2).any(|w| !(w[0] < w[1])) {
                    return Err("edges are not strictly ascending".into());
                }
                values.clone()
            }
            ExtensionFunction::Categories { values } => values.values().copied().collect(),
            ExtensionFunction::Monotone { knots, values } => {
                if knots.is_empty() || values.len() != knots.len() {
                    return Err(format!(
                        "{} values for {} knots (need one value per knot, at least one)",
                        values.len(),
                        knots.len()
                    ));
                }
                finite("knot", knots)?;
                if knots.windows(2).any(|w| !(w[0] < w[1])) {
                    return Err("knots are not strictly ascending".into());
                }
                let up = values.windows(2).all(|w| w[0] <= w[1]);
                let down = values.windows(2).all(|w| w[0] >= w[1]);
                if !(up || down) {
                    return Err("values at the knots are not monotone".into());
                }
                values.clone()
            }
            ExtensionFunction::Attenuation { k } => {
                finite("k", &[*k])?;
                if !self.observable.multiplicative() {
                    return Err(format!(
                        "attenuation is a factor; {} takes a bias",
                        self.observable.name()
                    ));
                }
                Vec::new()
            }
            ExtensionFunction::Linear { intercept, slope } => {
                finite("parameter", &[*intercept, *slope])?;
                Vec::new()
            }
            ExtensionFunction::Power { scale, exponent } => {
                finite("parameter", &[*scale, *exponent])?;
                vec![*scale]
            }
        };
        for v in values.iter().chain(std::iter::once(&self.default)) {
            if !v.is_finite() {
                return Err(format!("value {v} is not finite"));
            }
            if self.observable.multiplicative() && *v < 0.0 {
                return Err(format!("factor {v} is negative"));
            }
        }
        if self.observable == ExtensionObservable::Count
            && self.is_point_level()
            && !COUNT_POINT_COVARIATES.contains(&self.covariate.as_str())
        {
            return Err(format!(
                "a count term needs a covariate of the near-range return ({}) or a scan-level one (mor or a weather.csv column), not {:?}",
                COUNT_POINT_COVARIATES.join(", "),
                self.covariate
            ));
        }
        Ok(())
    }

    /// The function's value for a point (`None` for scan-level evaluation),
    /// the scan's covariate values and its MOR.
    pub fn value(
        &self,
        point: Option<&PointCovariates>,
        scan: &BTreeMap<String, CovariateValue>,
        mor_m: f64,
    ) -> f64 {
        let x = if let Some(v) = point.and_then(|p| p.get(&self.covariate)) {
            Some(CovariateValue::Number(v))
        } else if self.covariate == "mor" {
            Some(CovariateValue::Number(mor_m))
        } else {
            scan.get(&self.covariate).cloned()
        };
        self.value_at(x.as_ref(), mor_m)
    }

    /// The function's value at a covariate value (`None`: unknown) with the
    /// MOR unknown (a function of the MOR gives the default).
    pub fn value_of(&self, x: Option<&CovariateValue>) -> f64 {
        self.value_at(x, f64::NAN)
    }

    /// The function's value at a covariate value (`None`: unknown) and the
    /// MOR `mor_m`, metres. A factor is never negative.
    pub fn value_at(&self, x: Option<&CovariateValue>, mor_m: f64) -> f64 {
        let v = match (&self.function, x) {
            (ExtensionFunction::Categories { values }, Some(CovariateValue::Text(t))) => {
                values.get(t).copied().unwrap_or(self.default)
            }
            (ExtensionFunction::Categories { values }, Some(CovariateValue::Number(x))) => values
                .iter()
                .find(|(k, _)| k.trim().parse::<f64>().ok() == Some(*x))
                .map(|(_, v)| *v)
                .unwrap_or(self.default),
            (f, Some(CovariateValue::Number(x))) => f.at(*x, mor_m).unwrap_or(self.default),
            _ => self.default,
        };
        if self.observable.multiplicative() {
            v.max(0.0)
        } else {
            v
        }
    }
}

/// The point-level covariates a count term may follow on the ray a
/// near-range return is placed on (its laser `ring`, that laser's
/// `elevation`, and the ray's `azimuth`): the seed-004 azimuthal factor
/// F_l(φ) and its per-laser analogue.
pub const COUNT_RAY_COVARIATES: [&str; 3] = ["ring", "elevation", "azimuth"];

/// Every point-level covariate a count term may follow: the ray's
/// ([`COUNT_RAY_COVARIATES`]) and `range`, which for a count term is the
/// near-range return's **own** range (its distance along the ray, the
/// seed-004 per-echo range law F_j(x)), not that of a clear return. The
/// other point-level name (`reflectivity`) describes a clear return, which
/// a ghost on an empty ray does not have.
pub const COUNT_POINT_COVARIATES: [&str; 4] = ["ring", "elevation", "azimuth", "range"];

/// Number of equal-probability cells over which [`RayDensity::range_cells`]
/// tabulates a distance law reweighted by range terms.
pub const RANGE_CELLS: usize = 1024;

/// Where near-range (ghost and ring) returns fall: the one evaluation of the
/// point-level count terms, used by `murk apply` when it places the returns
/// (`murk diagnose` measures such terms through `murk apply`'s simulations).
///
/// This is the seed-004 law family `P(X > x) = F_j(x)·F_l(φ)`, written as a
/// density over the rays and along range. The expected number of returns a
/// scan places on the ray `(ring, azimuth)` at a range in `[r, r + dr]` is
///
/// `N/(R·B) · g(ring)·h(azimuth) · p(r)·k(r) dr`,
///
/// where `N` is the count law's expectation (times the scan-level count
/// terms), `R·B` the rays (rings present × azimuth bins), `p` the table's
/// (truncated Gaussian) distance law of the kind, `g` the product of the
/// count terms along `ring` and `elevation`, `h` the product of those along
/// `azimuth`, and `k` the product of those along `range`. So the terms
/// redistribute the returns over the rays and along range, and scale their
/// total by the mean of `g` over the rings, the mean of `h` over the bins
/// ([`RayDensity::total_factor`]) and the mean of `k` under `p`
/// ([`RayDensity::range_cells`]; it differs between the ghost and the ring
/// law). Without point-level count terms all three are 1 and the placement
/// is the table's: uniform over the rays, Gaussian along range.
///
/// ```
/// use murk_types::{ExtensionFunction, ExtensionObservable, ModelExtension, RayDensity};
///
/// // Three times as many returns on the downward beams.
/// let t = ModelExtension {
///     observable: ExtensionObservable::Count,
///     covariate: "elevation".into(),
///     function: ExtensionFunction::Bins { edges: vec![0.0], values: vec![3.0, 1.0] },
///     default: 1.0,
///     description: String::new(),
/// };
/// let d = RayDensity::new(std::slice::from_ref(&t));
/// let rings = [(0u16, -15.0), (1, 1.0), (2, -13.0), (3, 3.0)];
/// let g = d.ring_weights(&rings);
/// assert_eq!(g, vec![3.0, 1.0, 3.0, 1.0]);
/// assert_eq!(d.total_factor(&g, &[1.0]), 2.0);
///
/// // Twice as many returns nearer than 5 m as the distance law says.
/// let near = ModelExtension {
///     covariate: "range".into(),
///     function: ExtensionFunction::Bins { edges: vec![5.0], values: vec![2.0, 1.0] },
///     ..t
/// };
/// let d = RayDensity::new(std::slice::from_ref(&near));
/// assert!(d.has_range_terms());
/// // A law uniform on [3, 7] m: half its mass below 5 m, so the mean factor
/// // is 1.5 and two thirds of the returns fall below 5 m.
/// let cells = d.range_cells(|t| 3.0 + 4.0 * t).unwrap();
/// assert!((cells.mean - 1.5).abs() < 1e-12);
/// let below = cells.cumulative[cells.cumulative.len() / 2 - 1];
/// assert!((below - 2.0 / 3.0).abs() < 1e-12);
/// ```
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RayDensity {
    beam: Vec<ModelExtension>,
    azimuth: Vec<ModelExtension>,
    range: Vec<ModelExtension>,
}

/// A distance law reweighted by the range terms, tabulated over
/// [`RANGE_CELLS`] cells of equal probability under the law
/// ([`RayDensity::range_cells`]).
#[derive(Debug, Clone, PartialEq)]
pub struct RangeCells {
    /// Normalised cumulative weight of the cells (the last is 1): cell `i`
    /// is drawn with probability `cumulative[i] − cumulative[i − 1]`.
    pub cumulative: Vec<f64>,
    /// The mean of `k` under the law: the factor on the expected count.
    pub mean: f64,
}

impl RangeCells {
    /// Maps a uniform `u` in `[0, 1)` to a probability fraction `t` of the
    /// unweighted law (its quantile gives the range): the cell by the
    /// cumulative weights, then the position inside the cell from the rest
    /// of `u`, so one uniform makes one draw. Exact for `k` constant inside
    /// each cell; `k` is read at the cells' centres.
    pub fn fraction(&self, u: f64) -> f64 {
        let n = self.cumulative.len();
        let i = self.cumulative.partition_point(|&c| c <= u).min(n - 1);
        let lo = if i == 0 { 0.0 } else { self.cumulative[i - 1] };
        let hi = self.cumulative[i];
        let inside = if hi > lo {
            ((u - lo) / (hi - lo)).clamp(0.0, 1.0)
        } else {
            0.5
        };
        (i as f64 + inside) / n as f64
    }
}

impl RayDensity {
    /// The point-level count terms among `terms` (others are ignored).
    pub fn new(terms: &[ModelExtension]) -> RayDensity {
        let of = |names: &[&str]| -> Vec<ModelExtension> {
            terms
                .iter()
                .filter(|t| {
                    t.observable == ExtensionObservable::Count
                        && names.contains(&t.covariate.as_str())
                })
                .cloned()
                .collect()
        };
        RayDensity {
            beam: of(&["ring", "elevation"]),
            azimuth: of(&["azimuth"]),
            range: of(&["range"]),
        }
    }

    /// True when no term changes the placement (uniform over the rays,
    /// the table's law along range).
    pub fn is_uniform(&self) -> bool {
        self.beam.is_empty() && self.azimuth.is_empty() && self.range.is_empty()
    }

    /// True when a term follows `ring` or `elevation`.
    pub fn has_beam_terms(&self) -> bool {
        !self.beam.is_empty()
    }

    /// True when a term follows `azimuth`.
    pub fn has_azimuth_terms(&self) -> bool {
        !self.azimuth.is_empty()
    }

    /// True when a term follows the returns' own `range`.
    pub fn has_range_terms(&self) -> bool {
        !self.range.is_empty()
    }

    fn product(terms: &[ModelExtension], p: &PointCovariates) -> f64 {
        let scan = BTreeMap::new();
        terms
            .iter()
            .map(|t| t.value(Some(p), &scan, f64::NAN).max(0.0))
            .product()
    }

    /// `g` of each `(ring, elevation in degrees)`.
    pub fn ring_weights(&self, rings: &[(u16, f64)]) -> Vec<f64> {
        rings
            .iter()
            .map(|&(ring, elevation)| {
                Self::product(
                    &self.beam,
                    &PointCovariates {
                        range: f64::NAN,
                        reflectivity: f64::NAN,
                        ring,
                        elevation,
                        azimuth: f64::NAN,
                    },
                )
            })
            .collect()
    }

    /// `h` of each azimuth (degrees).
    pub fn azimuth_weights(&self, azimuths_deg: &[f64]) -> Vec<f64> {
        azimuths_deg
            .iter()
            .map(|&azimuth| {
                Self::product(
                    &self.azimuth,
                    &PointCovariates {
                        range: f64::NAN,
                        reflectivity: f64::NAN,
                        ring: u16::MAX,
                        elevation: f64::NAN,
                        azimuth,
                    },
                )
            })
            .collect()
    }

    /// `k` at a near-range return's own range (metres).
    pub fn range_weight(&self, range_m: f64) -> f64 {
        Self::product(
            &self.range,
            &PointCovariates {
                range: range_m,
                reflectivity: f64::NAN,
                ring: u16::MAX,
                elevation: f64::NAN,
                azimuth: f64::NAN,
            },
        )
    }

    /// A distance law reweighted by `k`: `quantile(t)` is the law's range at
    /// probability fraction `t` in `[0, 1]` of its (truncated) mass. `k` is
    /// read at the centres of [`RANGE_CELLS`] cells of equal probability;
    /// the cells' shares are `k/ΣK` and the mean of `k` is the factor on
    /// the expected count. `None` without range terms, or when `k` is 0
    /// (or not finite) everywhere: then no return of the kind is placed
    /// (the caller's expected count times a mean of 0).
    pub fn range_cells(&self, quantile: impl Fn(f64) -> f64) -> Option<RangeCells> {
        if self.range.is_empty() {
            return None;
        }
        let n = RANGE_CELLS;
        let w: Vec<f64> = (0..n)
            .map(|i| {
                let k = self.range_weight(quantile((i as f64 + 0.5) / n as f64));
                if k.is_finite() { k.max(0.0) } else { 0.0 }
            })
            .collect();
        let total: f64 = w.iter().sum();
        if !(total > 0.0 && total.is_finite()) {
            return None;
        }
        let mut acc = 0.0;
        let cumulative = w
            .iter()
            .map(|x| {
                acc += x;
                acc / total
            })
            .collect();
        Some(RangeCells {
            cumulative,
            mean: total / n as f64,
        })
    }

    /// The factor on the scan's expected count: mean of the ring weights
    /// times mean of the azimuth weights (1 for empty lists). The range
    /// terms' factor depends on the kind's distance law and comes from
    /// [`RayDensity::range_cells`].
    pub fn total_factor(&self, ring_weights: &[f64], azimuth_weights: &[f64]) -> f64 {
        let mean = |v: &[f64]| {
            if v.is_empty() {
                1.0
            } else {
                v.iter().sum::<f64>() / v.len() as f64
            }
        };
        mean(ring_weights) * mean(azimuth_weights)
    }
}

/// Combines the values of several terms on one observable (factors
/// multiply, biases add).
pub fn combine(observable: ExtensionObservable, values: impl IntoIterator<Item = f64>) -> f64 {
    if observable.multiplicative() {
        values.into_iter().product()
    } else {
        values.into_iter().sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bins(edges: Vec<f64>, values: Vec<f64>) -> ModelExtension {
        ModelExtension {
            observable: ExtensionObservable::Intensity,
            covariate: "Wind speed (m/s)".into(),
            function: ExtensionFunction::Bins { edges, values },
            default: 0.9,
            description: String::new(),
        }
    }

    #[test]
    fn bins_pick_by_edges_and_fall_back_to_default() {
        let e = bins(vec![2.0, 5.0], vec![1.0, 0.8, 0.5]);
        let v = |x: f64| e.value_of(Some(&CovariateValue::Number(x)));
        assert_eq!(
            (v(1.9), v(2.0), v(4.99), v(5.0), v(50.0)),
            (1.0, 0.8, 0.8, 0.5, 0.5)
        );
        assert_eq!(e.value_of(None), 0.9);
        assert_eq!(e.value_of(Some(&CovariateValue::Text("calm".into()))), 0.9);
        let scan = BTreeMap::from([("Wind speed (m/s)".to_string(), CovariateValue::Number(3.0))]);
        assert_eq!(e.value(None, &scan, 100.0), 0.8);
        assert_eq!(e.value(None, &BTreeMap::new(), 100.0), 0.9);
    }

    #[test]
    fn categories_and_point_covariates() {
        let mut e = ModelExtension {
            observable: ExtensionObservable::Count,
            covariate: "Road state".into(),
            function: ExtensionFunction::Categories {
                values: BTreeMap::from([("wet".to_string(), 2.0)]),
            },
            default: 1.0,
            description: String::new(),
        };
        let scan = BTreeMap::from([("Road state".to_string(), CovariateValue::parse("wet"))]);
        assert_eq!(e.value(None, &scan, 50.0), 2.0);
        assert!(e.check().is_ok());
        e.covariate = "ring".into();
        assert!(e.check().is_ok());
        e.covariate = "reflectivity".into();
        assert!(e.check().unwrap_err().contains("scan-level"));
        // A point straight ahead, 1 m up at 10 m: elevation atan(0.1).
        let p = PointCovariates::of_point(10.0, 0.0, 1.0, 7.0, 3);
        assert!((p.elevation - 0.1f64.atan().to_degrees()).abs() < 1e-12);
        assert_eq!(p.azimuth, 0.0);
        let p = PointCovariates::of_point(0.0, -2.0, 0.0, 7.0, 3);
        assert!((p.azimuth - 270.0).abs() < 1e-12);
    }

    #[test]
    fn check_rejects_bad_terms() {
        assert!(bins(vec![2.0, 1.0], vec![1.0, 1.0, 1.0]).check().is_err());
        assert!(bins(vec![2.0], vec![1.0]).check().is_err());
        assert!(bins(vec![2.0], vec![1.0, -0.1]).check().is_err());
        let mut r = bins(vec![2.0], vec![-0.05, 0.05]);
        r.observable = ExtensionObservable::Range;
        assert!(r.check().is_ok());
        assert!(bins(vec![f64::NAN], vec![1.0, 1.0]).check().is_err());
    }

    #[test]
    fn combine_multiplies_factors_and_adds_biases() {
        assert_eq!(combine(ExtensionObservable::Survival, [0.5, 0.5]), 0.25);
        assert_eq!(combine(ExtensionObservable::Range, [0.5, 0.5]), 1.0);
        assert_eq!(combine(ExtensionObservable::Count, []), 1.0);
    }
    fn term(observable: ExtensionObservable, function: ExtensionFunction) -> ModelExtension {
        ModelExtension {
            observable,
            covariate: "range".into(),
            function,
            default: observable.neutral(),
            description: String::new(),
        }
    }

    #[test]
    fn monotone_interpolates_and_holds_its_ends() {
        let e = term(
            ExtensionObservable::Survival,
            ExtensionFunction::Monotone {
                knots: vec![10.0, 20.0, 40.0],
                values: vec![1.0, 0.8, 0.4],
            },
        );
        assert!(e.check().is_ok());
        let v = |x: f64| e.value_of(Some(&CovariateValue::Number(x)));
        assert_eq!((v(0.0), v(10.0), v(40.0), v(99.0)), (1.0, 1.0, 0.4, 0.4));
        assert!((v(15.0) - 0.9).abs() < 1e-12);
        assert!((v(30.0) - 0.6).abs() < 1e-12);
        let mut bad = e.clone();
        bad.function = ExtensionFunction::Monotone {
            knots: vec![10.0, 20.0, 40.0],
            values: vec![1.0, 0.8, 0.9],
        };
        assert!(bad.check().unwrap_err().contains("monotone"));
        bad.function = ExtensionFunction::Monotone {
            knots: vec![10.0, 10.0],
            values: vec![1.0, 0.8],
        };
        assert!(bad.check().unwrap_err().contains("ascending"));
        bad.function = ExtensionFunction::Monotone {
            knots: vec![],
            values: vec![],
        };
        assert!(bad.check().is_err());
    }

    #[test]
    fn attenuation_reads_the_mor_and_is_a_factor_only() {
        let e = term(
            ExtensionObservable::Intensity,
            ExtensionFunction::Attenuation {
                k: 2.0 * 20f64.ln(),
            },
        );
        assert!(e.check().is_ok());
        let p = PointCovariates::of_point(30.0, 0.0, 0.0, 20.0, 3);
        // Two-way extinction at α = ln 20 / MOR over 30 m at MOR 60 m:
        // exp(−2·ln 20·0.5) = 1/20.
        let v = e.value(Some(&p), &BTreeMap::new(), 60.0);
        assert!((v - 0.05).abs() < 1e-12, "{v}");
        // No MOR: the default.
        assert_eq!(e.value_of(Some(&CovariateValue::Number(30.0))), 1.0);
        assert_eq!(e.value(Some(&p), &BTreeMap::new(), 0.0), 1.0);
        let r = term(
            ExtensionObservable::Range,
            ExtensionFunction::Attenuation { k: 1.0 },
        );
        assert!(r.check().unwrap_err().contains("factor"));
        assert!(
            term(
                ExtensionObservable::Intensity,
                ExtensionFunction::Attenuation { k: f64::NAN }
            )
            .check()
            .is_err()
        );
    }

    #[test]
    fn linear_and_power_forms() {
        let mut e = term(
            ExtensionObservable::Range,
            ExtensionFunction::Linear {
                intercept: 0.1,
                slope: -0.01,
            },
        );
        let v = |e: &ModelExtension, x: f64| e.value_of(Some(&CovariateValue::Number(x)));
        assert!((v(&e, 20.0) + 0.1).abs() < 1e-12);
        // A factor is floored at 0.
        e.observable = ExtensionObservable::Survival;
        assert_eq!(v(&e, 20.0), 0.0);
        let mut p = term(
            ExtensionObservable::Range,
            ExtensionFunction::Power {
                scale: 2.0,
                exponent: -1.0,
            },
        );
        p.covariate = "mor".into();
        assert!(p.check().is_ok());
        assert!((p.value(None, &BTreeMap::new(), 40.0) - 0.05).abs() < 1e-12);
        // x ≤ 0: the default.
        assert_eq!(v(&p, 0.0), 0.0);
        p.observable = ExtensionObservable::Survival;
        p.function = ExtensionFunction::Power {
            scale: -1.0,
            exponent: 1.0,
        };
        assert!(p.check().unwrap_err().contains("negative"));
    }

    #[test]
    fn every_shape_round_trips_and_old_terms_load() {
        let old = r#"{"observable":"survival","covariate":"elevation","function":{"kind":"bins","edges":[-4.0],"values":[0.8,1.0]},"default":1.0}"#;
        let e: ModelExtension = serde_json::from_str(old).unwrap();
        assert_eq!(e.function.kind(), "bins");
        assert_eq!(e.function.parameter_count(), 3);
        for f in [
            ExtensionFunction::Monotone {
                knots: vec![1.0, 2.0],
                values: vec![0.5, 0.7],
            },
            ExtensionFunction::Attenuation { k: 6.0 },
            ExtensionFunction::Linear {
                intercept: 1.0,
                slope: 0.5,
            },
            ExtensionFunction::Power {
                scale: 1.0,
                exponent: 0.5,
            },
        ] {
            let t = term(ExtensionObservable::Intensity, f);
            let s = serde_json::to_string(&t).unwrap();
            assert!(
                s.contains(&format!("\"kind\":\"{}\"", t.function.kind())),
                "{s}"
            );
            let back: ModelExtension = serde_json::from_str(&s).unwrap();
            assert_eq!(back, t);
        }
        let bad = r#"{"observable":"intensity","covariate":"range","function":{"kind":"attenuation","k":1.0,"q":2},"default":1.0}"#;
        assert!(serde_json::from_str::<ModelExtension>(bad).is_err());
    }
}
