//! Checked parameters of the applier.
//!
//! [`ApplyParams`] is what a user asks for; [`ApplyParams::build`] checks it
//! against a [`CoefficientTable`] once, before any point is touched, and
//! returns the [`Applier`] that does the work. Every refusal names the
//! parameter or the table field and the allowed range.

use std::collections::BTreeMap;

use murk_types::{
    CoefficientTable, CovariateValue, ExtensionFunction, LidarSpec, NoiseLaw, WeatherClass,
    WeatherCoefficients,
};

use crate::applier::Applier;
use crate::error::InferError;
use crate::model::{BandRule, NearLaw, RainUse, SlopeSource, SoftEdge};

/// The MOR (metres) at and above which the weather is clear and applying is
/// the identity, unless the parameters say otherwise: the 2000 m of the PDD
/// selection rules (seed report §3.3). The coefficient table does not record
/// the threshold of the rules it was fitted under (a campaign's custom rules
/// need not define clear weather by one MOR), so it cannot supply one.
pub const DEFAULT_CLEAR_MOR_M: f64 = 2000.0;

/// Default azimuth grid (degrees) of near-range rays when no sensor
/// description is given: the VLP-16's 0.2° at 600 rpm.
pub const DEFAULT_AZIMUTH_RESOLUTION_DEG: f64 = 0.2;

/// How strong the weather is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Severity {
    /// Meteorological optical range in metres (fog, rain, snow).
    Mor(f64),
    /// Rain rate in mm/h, turned into a MOR by the table's
    /// `weathers.rain.mor_from_rain_rate` (rain only). A rate of 0 is no
    /// rain: the identity.
    RainRate(f64),
}

/// What to apply, before it is checked against a table.
///
/// | Name | Default | Purpose | Range |
/// |---|---|---|---|
/// | `weather` | (required) | which of the table's weathers | a weather present in the table |
/// | `severity` | (required) | MOR in m, or a rain rate in mm/h (rain only) | MOR > 0; rate inside the conversion's validity (see `clamp_rain_rate`) |
/// | `range_scale` | the table's `lidar.range_scale` | target sensor's range coefficient: vanishing distance = slope × MOR × range_scale | > 0 |
/// | `slope_source` | [`SlopeSource::Survival`] | which slope estimate decides vanishing | survival, quantile |
/// | `soft_edge` | off | stochastic survival edge from the table's `survival` fit (edge width per band, dropout, residual) instead of a hard threshold | needs `survival` and every band's `edge_width` |
/// | `near_range` | off | add ghost and ring returns from the table's laws; each replaces the return of its ray when closer | needs `ghost` or `ring` |
/// | `near_range_count_scale` | 1 | multiplies the expected ghost/ring count per scan; the table counts per revolution (`lidar.count_unit = per_revolution`, also what a table without the field meant), so 1 places one revolution's worth in each scan applied | ≥ 0, finite |
/// | `range_noise_m` | 0 (off) | σ of Gaussian noise added to the range of kept returns | ≥ 0, finite |
/// | `attenuate_intensity` | off | multiply kept intensities by the two-way loss exp(−2·α·r), α = ln(20)/MOR (Koschmieder) | — |
/// | `clamp_rain_rate` | off | clamp a rain rate outside the conversion's validity into it (with a warning) instead of failing | — |
/// | `clear_mor_threshold_m` | [`DEFAULT_CLEAR_MOR_M`] | MOR at and above which applying is the identity | > 0 |
/// | `lidar` | none | sensor description for near-range rays (ring elevations, azimuth grid); none: ring elevations are measured on each scan | a valid [`LidarSpec`] |
/// | `azimuth_resolution_deg` | `lidar`'s, else [`DEFAULT_AZIMUTH_RESOLUTION_DEG`] | azimuth grid of near-range rays; unless set, a replacing weather (the table's occlusion test) counts the sky's rays on each scan's own firing step, measured on its first 16,384 points by [`murk_types::firing::mode_step`] | (0, 45] |
/// | `min_range_m` | `lidar`'s `min_range_m`, else none | points nearer than this are not returns (no-return firings written as points at the origin, the vehicle's body): written as they were, in their places, and open rays for near-range returns | ≥ 0, finite |
/// | `seed` | 0 | master seed of every random draw | any |
///
/// ```
/// use murk_infer::{ApplyParams, Severity};
/// use murk_types::WeatherClass;
///
/// let p = ApplyParams::new(WeatherClass::Fog, Severity::Mor(60.0))
///     .near_range(true)
///     .range_noise_m(0.02)
///     .seed(7);
/// assert_eq!(p.weather(), WeatherClass::Fog);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct ApplyParams {
    weather: WeatherClass,
    severity: Severity,
    range_scale: Option<f64>,
    slope_source: SlopeSource,
    soft_edge: bool,
    near_range: bool,
    near_range_count_scale: f64,
    range_noise_m: f64,
    attenuate_intensity: bool,
    clamp_rain_rate: bool,
    clear_mor_threshold_m: Option<f64>,
    lidar: Option<LidarSpec>,
    azimuth_resolution_deg: Option<f64>,
    min_range_m: Option<f64>,
    seed: u64,
    covariates: BTreeMap<String, CovariateValue>,
    extensions: bool,
}

impl ApplyParams {
    /// Vanishing only, hard threshold, table defaults for everything else.
    pub fn new(weather: WeatherClass, severity: Severity) -> Self {
        ApplyParams {
            weather,
            severity,
            range_scale: None,
            slope_source: SlopeSource::default(),
            soft_edge: false,
            near_range: false,
            near_range_count_scale: 1.0,
            range_noise_m: 0.0,
            attenuate_intensity: false,
            clamp_rain_rate: false,
            clear_mor_threshold_m: None,
            lidar: None,
            azimuth_resolution_deg: None,
            min_range_m: None,
            seed: 0,
            covariates: BTreeMap::new(),
            extensions: true,
        }
    }

    /// The weather asked for.
    pub fn weather(&self) -> WeatherClass {
        self.weather
    }

    /// The severity asked for.
    pub fn severity(&self) -> Severity {
        self.severity
    }

    /// Sets the target sensor's range-scale coefficient.
    pub fn range_scale(mut self, k: f64) -> Self {
        self.range_scale = Some(k);
        self
    }

    /// Chooses the slope estimate.
    pub fn slope_source(mut self, s: SlopeSource) -> Self {
        self.slope_source = s;
        self
    }

    /// Turns the stochastic survival edge on or off.
    pub fn soft_edge(mut self, on: bool) -> Self {
        self.soft_edge = on;
        self
    }

    /// Turns ghost and ring returns on or off.
    pub fn near_range(mut self, on: bool) -> Self {
        self.near_range = on;
        self
    }

    /// Scales the expected ghost/ring count per scan.
    pub fn near_range_count_scale(mut self, s: f64) -> Self {
        self.near_range_count_scale = s;
        self
    }

    /// Sets the σ (metres) of Gaussian range noise; 0 turns it off.
    pub fn range_noise_m(mut self, sigma: f64) -> Self {
        self.range_noise_m = sigma;
        self
    }

    /// Turns two-way intensity attenuation on or off.
    pub fn attenuate_intensity(mut self, on: bool) -> Self {
        self.attenuate_intensity = on;
        self
    }

    /// Clamps an out-of-validity rain rate (with a warning) instead of failing.
    pub fn clamp_rain_rate(mut self, on: bool) -> Self {
        self.clamp_rain_rate = on;
        self
    }

    /// Overrides the clear-weather MOR threshold.
    pub fn clear_mor_threshold_m(mut self, m: f64) -> Self {
        self.clear_mor_threshold_m = Some(m);
        self
    }

    /// Sets the sensor description used for near-range rays.
    pub fn lidar(mut self, spec: LidarSpec) -> Self {
        self.lidar = Some(spec);
        self
    }

    /// Sets the azimuth grid of near-range rays.
    pub fn azimuth_resolution_deg(mut self, deg: f64) -> Self {
        self.azimuth_resolution_deg = Some(deg);
        self
    }

    /// Points nearer than `m` metres are not returns (overrides the
    /// `lidar` description's `min_range_m`).
    pub fn min_range_m(mut self, m: f64) -> Self {
        self.min_range_m = Some(m);
        self
    }

    /// Sets the master seed.
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// The value of a scan-level covariate (a `weather.csv` column) for the
    /// table's extension terms; terms whose covariate is not given use their
    /// fitted default, with a warning.
    pub fn covariate(mut self, name: impl Into<String>, value: CovariateValue) -> Self {
        self.covariates.insert(name.into(), value);
        self
    }

    /// Whether to apply the table's extension terms (on by default; off
    /// applies the baseline model of an extended table).
    pub fn extensions(mut self, on: bool) -> Self {
        self.extensions = on;
        self
    }

    /// Checks the parameters against `table` and returns the applier.
    ///
    /// `table` errors are labelled with the table's campaign; use
    /// [`ApplyParams::build_labelled`] to name its file instead.
    pub fn build(&self, table: &CoefficientTable) -> Result<Applier, InferError> {
        self.build_labelled(table, &format!("table of campaign {:?}", table.campaign))
    }

    /// Reads the table at `path` and checks the parameters against it.
    pub fn build_from_file(&self, path: &std::path::Path) -> Result<Applier, InferError> {
        let table = CoefficientTable::read(path)?;
        self.build_labelled(&table, &path.display().to_string())
    }

    /// [`ApplyParams::build`], naming the table `label` in errors.
    ///
    /// The steps: the weather's coefficients, the scalar parameters, the
    /// severity as a MOR, the band rules, the soft edge, the near-range
    /// laws and the extension terms; each refuses what it cannot apply.
    pub fn build_labelled(
        &self,
        table: &CoefficientTable,
        label: &str,
    ) -> Result<Applier, InferError> {
        let w = self.weather;
        let coeffs = weather_coefficients(table, w, label)?;
        let scalars = self.scalars(table)?;
        let mut warnings = Vec::new();
        let (mor, rain) = self.effective_mor(coeffs, label, &mut warnings)?;
        let identity = mor >= scalars.clear_mor;
        if !identity
            && let (Some(lo), Some(hi)) = (coeffs.mor_min_m, coeffs.mor_max_m)
            && (mor < lo || mor > hi)
        {
            warnings.push(format!(
                "MOR {} m is outside the {}–{} m of the {w} recordings the table was fitted on: the vanishing law extrapolates",
                short_number(mor, Toward::Nearest),
                short_number(lo, Toward::Nearest),
                short_number(hi, Toward::Nearest)
            ));
        }
        let bands = self.band_rules(
            coeffs,
            mor,
            scalars.range_scale,
            identity,
            label,
            &mut warnings,
        )?;
        let soft = if self.soft_edge && !identity {
            Some(soft_edge(coeffs, w, label)?)
        } else {
            None
        };
        if self.near_range
            && !identity
            && table.lidar.count_unit == murk_types::CountUnit::PerRecording
        {
            warnings.push(format!(
                "{label}: the table counts near-range returns per recording (lidar.count_unit = per_recording), not per revolution: set near_range_count_scale to 1 / revolutions per recording"
            ));
        }
        let (ghost, ring) = if self.near_range && !identity {
            self.near_laws(coeffs, mor, label, &mut warnings)?
        } else {
            (None, None)
        };
        let extensions = self.extension_terms(coeffs, identity, label, &mut warnings)?;
        let density = murk_types::RayDensity::new(&extensions);
        let (ghost, ring) = (
            ghost.map(|l| l.with_range_terms(&density)),
            ring.map(|l| l.with_range_terms(&density)),
        );

        Ok(Applier {
            weather: w,
            mor_m: mor,
            rain,
            identity,
            clear_mor_threshold_m: scalars.clear_mor,
            range_scale: scalars.range_scale,
            slope_source: self.slope_source,
            bands,
            soft,
            near_range: self.near_range && !identity,
            near_replaces_lost: coeffs.occlusion.as_ref().is_some_and(|o| o.replaced),
            ghost,
            ring,
            range_noise_m: if identity { 0.0 } else { self.range_noise_m },
            attenuation_alpha: (self.attenuate_intensity && !identity).then(|| 20f64.ln() / mor),
            lidar: self.lidar.clone(),
            azimuth_resolution_deg: scalars.azimuth_resolution_deg,
            measure_azimuth_step: self.azimuth_resolution_deg.is_none(),
            min_range_m: scalars.min_range_m,
            seed: self.seed,
            warnings,
            extensions,
            density,
            scan_covariates: self.covariates.clone(),
        })
    }

    /// The scalar parameters, checked, with the table's defaults filled in.
    fn scalars(&self, table: &CoefficientTable) -> Result<Scalars, InferError> {
        let range_scale = self.range_scale.unwrap_or(table.lidar.range_scale);
        if !(range_scale.is_finite() && range_scale > 0.0) {
            return Err(invalid(
                "range_scale",
                range_scale,
                "must be finite and > 0",
            ));
        }
        if !(self.range_noise_m.is_finite() && self.range_noise_m >= 0.0) {
            return Err(invalid(
                "range_noise_m",
                self.range_noise_m,
                "σ must be finite and ≥ 0 (0 turns noise off)",
            ));
        }
        if !(self.near_range_count_scale.is_finite() && self.near_range_count_scale >= 0.0) {
            return Err(invalid(
                "near_range_count_scale",
                self.near_range_count_scale,
                "must be finite and ≥ 0",
            ));
        }
        let clear_mor = self.clear_mor_threshold_m.unwrap_or(DEFAULT_CLEAR_MOR_M);
        if !(clear_mor.is_finite() && clear_mor > 0.0) {
            return Err(invalid(
                "clear_mor_threshold_m",
                clear_mor,
                "must be finite and > 0",
            ));
        }
        if let Some(spec) = &self.lidar {
            spec.validate().map_err(|e| InferError::InvalidParam {
                name: "lidar",
                value: spec.model.clone(),
                reason: e.to_string(),
            })?;
        }
        let az_res = self
            .azimuth_resolution_deg
            .or(self.lidar.as_ref().map(|l| l.azimuth_resolution_deg))
            .unwrap_or(DEFAULT_AZIMUTH_RESOLUTION_DEG);
        if !(az_res.is_finite() && az_res > 0.0 && az_res <= 45.0) {
            return Err(invalid(
                "azimuth_resolution_deg",
                az_res,
                "must be in (0, 45] degrees",
            ));
        }
        let min_range_m = self
            .min_range_m
            .or(self.lidar.as_ref().and_then(|l| l.min_range_m));
        if let Some(m) = min_range_m
            && !(m.is_finite() && m >= 0.0)
        {
            return Err(invalid("min_range_m", m, "must be finite and ≥ 0"));
        }
        if self.soft_edge && self.slope_source == SlopeSource::Quantile {
            return Err(InferError::Conflict(
                "soft_edge uses the survival fit's edge widths, which belong to vanishing_slope: it cannot be combined with slope_source = quantile".into(),
            ));
        }
        Ok(Scalars {
            range_scale,
            clear_mor,
            azimuth_resolution_deg: az_res,
            min_range_m,
        })
    }

    /// The severity as the applied MOR (a rain rate through the table's
    /// conversion), with how the rain rate was used.
    fn effective_mor(
        &self,
        coeffs: &WeatherCoefficients,
        label: &str,
        warnings: &mut Vec<String>,
    ) -> Result<(f64, Option<RainUse>), InferError> {
        match self.severity {
            Severity::Mor(m) => {
                if !(m.is_finite() && m > 0.0) {
                    return Err(invalid("mor_m", m, "MOR must be finite and > 0 metres"));
                }
                Ok((m, None))
            }
            Severity::RainRate(r) => {
                if self.weather != WeatherClass::Rain {
                    return Err(InferError::Conflict(format!(
                        "a rain rate only applies to weather rain, not {}; give a MOR",
                        self.weather
                    )));
                }
                let (m, use_) = rain_to_mor(r, coeffs, self.clamp_rain_rate, label)?;
                if let Some(wm) = &use_.warning {
                    warnings.push(wm.clone());
                }
                Ok((m, Some(use_)))
            }
        }
    }

    /// The vanishing rule of each band of the chosen slope estimate at
    /// `mor`.
    fn band_rules(
        &self,
        coeffs: &WeatherCoefficients,
        mor: f64,
        range_scale: f64,
        identity: bool,
        label: &str,
        warnings: &mut Vec<String>,
    ) -> Result<Vec<BandRule>, InferError> {
        let source = match self.slope_source {
            SlopeSource::Survival => &coeffs.vanishing_slope,
            SlopeSource::Quantile => &coeffs.vanishing_slope_q99,
        };
        let field = format!("weathers.{}.{}", self.weather, self.slope_source.field());
        if source.is_empty() {
            return Err(missing(label, field, "has no band".into()));
        }
        if source.len() > crate::kernel::MAX_BANDS {
            return Err(missing(
                label,
                field,
                format!(
                    "has {} bands; murk-infer applies at most {}",
                    source.len(),
                    crate::kernel::MAX_BANDS
                ),
            ));
        }
        let mut bands = Vec::with_capacity(source.len());
        // A band with no clear return in the campaign (a sensor whose
        // reflectivities never fall in it) has no slope to fit; it borrows
        // the nearest band that has one, said in a warning, so that a table
        // fitted on such a sensor applies (no point of that sensor falls in
        // the band) and a point that does fall in it is not left untouched.
        let empty = |b: &murk_types::SlopeBand| b.slope.is_none() && b.points == 0;
        let borrow = |i: usize| -> Option<(usize, &murk_types::SlopeBand)> {
            (1..source.len())
                .flat_map(|d| [i.checked_sub(d), Some(i + d)])
                .flatten()
                .filter_map(|j| source.get(j).map(|b| (j, b)))
                .find(|(_, b)| b.slope.is_some())
        };
        let band_name = |b: &murk_types::SlopeBand| {
            format!(
                "[{}, {})",
                b.reflectivity_min,
                b.reflectivity_max
                    .map_or("∞".to_string(), |m| m.to_string())
            )
        };
        for (i, b) in source.iter().enumerate() {
            let borrowed = (empty(b) && !identity).then(|| borrow(i)).flatten();
            if let Some((_, from)) = borrowed {
                warnings.push(format!(
                    "{field}[{i}]: the band {} had no clear return in the campaign (no slope to fit); points in it use the slope of the band {}",
                    band_name(b),
                    band_name(from)
                ));
            }
            let b_edge_width = borrowed.map_or(b.edge_width, |(_, f)| f.edge_width);
            // The band's vanishing law (murk-types owns it): a law that
            // bends applies as the slope of the line that gives its
            // distance at this MOR.
            let law = borrowed
                .and_then(|(_, f)| f.vanishing_law())
                .or(b.vanishing_law());
            // A reflectivity term carries the edge width fitted with it.
            let b_edge_width = law
                .and_then(|l| l.reflectivity())
                .and_then(|r| r.edge_width)
                .or(b_edge_width);
            let slope = match law {
                Some(l) => l.effective_slope(mor),
                None if identity => f64::NAN,
                None => {
                    return Err(missing(
                        label,
                        format!("{field}[{i}].slope"),
                        format!(
                            "is null ({}): the band [{}, {}) cannot be applied",
                            b.reason.as_deref().unwrap_or("no reason given"),
                            b.reflectivity_min,
                            b.reflectivity_max
                                .map_or("∞".to_string(), |m| m.to_string())
                        ),
                    ));
                }
            };
            if self.soft_edge
                && !identity
                && b_edge_width.is_none_or(|e| !(e.is_finite() && e > 0.0))
            {
                return Err(missing(
                    label,
                    format!("{field}[{i}].edge_width"),
                    "soft_edge needs a finite edge width > 0 in every band".into(),
                ));
            }
            bands.push(BandRule {
                reflectivity_min: b.reflectivity_min,
                reflectivity_max: b.reflectivity_max,
                slope,
                vanishing_distance_m: slope * mor * range_scale,
                edge_width: b_edge_width,
                // The term at this MOR (its exponent may change with MOR).
                reflectivity: if identity {
                    None
                } else {
                    law.and_then(|l| l.reflectivity()).map(|r| r.at_mor(mor))
                },
            });
        }
        Ok(bands)
    }

    /// The ghost and ring laws at `mor`; at least one is needed, a missing
    /// one is a warning.
    fn near_laws(
        &self,
        coeffs: &WeatherCoefficients,
        mor: f64,
        label: &str,
        warnings: &mut Vec<String>,
    ) -> Result<(Option<NearLaw>, Option<NearLaw>), InferError> {
        let w = self.weather;
        let law = |l: &Option<NoiseLaw>, name: &str| -> Result<Option<NearLaw>, InferError> {
            match l {
                Some(l) => NearLaw::new(l, mor, self.near_range_count_scale)
                    .map(Some)
                    .map_err(|r| missing(label, format!("weathers.{w}.{name}"), r)),
                None => Ok(None),
            }
        };
        let ghost = law(&coeffs.ghost, "ghost")?;
        let ring = law(&coeffs.ring, "ring")?;
        if ghost.is_none() && ring.is_none() {
            return Err(missing(
                label,
                format!("weathers.{w}.ghost, weathers.{w}.ring"),
                format!(
                    "near_range needs at least one of the two laws; both are null (ghost: {}; ring: {})",
                    coeffs.ghost_reason.as_deref().unwrap_or("no reason given"),
                    coeffs.ring_reason.as_deref().unwrap_or("no reason given")
                ),
            ));
        }
        for (l, name, reason) in [
            (&ghost, "ghost", &coeffs.ghost_reason),
            (&ring, "ring", &coeffs.ring_reason),
        ] {
            if l.is_none() {
                warnings.push(format!(
                    "no {name} returns added: the table has no {name} law ({})",
                    reason.as_deref().unwrap_or("no reason given")
                ));
            }
        }
        Ok((ghost, ring))
    }

    /// The table's extension terms (from `murk diagnose`), checked; a
    /// scan-level term without its covariate's value is a warning.
    fn extension_terms(
        &self,
        coeffs: &WeatherCoefficients,
        identity: bool,
        label: &str,
        warnings: &mut Vec<String>,
    ) -> Result<Vec<murk_types::ModelExtension>, InferError> {
        let w = self.weather;
        let extensions = if self.extensions && !identity {
            coeffs.extensions.clone()
        } else {
            Vec::new()
        };
        for (i, e) in extensions.iter().enumerate() {
            e.check().map_err(|r| {
                missing(
                    label,
                    format!("weathers.{}.extensions[{i}]", self.weather),
                    r,
                )
            })?;
            if e.is_point_level() || e.covariate == "mor" {
                continue;
            }
            // A value the term cannot place would silently fall back to
            // the default: refuse it, naming what the term knows.
            match (&e.function, self.covariates.get(&e.covariate)) {
                (ExtensionFunction::Categories { values }, Some(CovariateValue::Text(t)))
                    if !values.contains_key(t) =>
                {
                    return Err(InferError::InvalidParam {
                        name: "covariate",
                        value: format!("{}={t}", e.covariate),
                        reason: format!(
                            "{t:?} is not a category of the table's extension term along {:?} \
                             (weathers.{w}.extensions[{i}]); its categories are {}",
                            e.covariate,
                            values
                                .keys()
                                .map(|k| format!("{k:?}"))
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    });
                }
                (f, Some(CovariateValue::Text(t))) if f.is_numeric() => {
                    return Err(InferError::InvalidParam {
                        name: "covariate",
                        value: format!("{}={t}", e.covariate),
                        reason: format!(
                            "the table's extension term along {:?} (weathers.{w}.extensions[{i}]) \
                             is a function of a number; {t:?} is not one",
                            e.covariate
                        ),
                    });
                }
                _ => {}
            }
            if !self.covariates.contains_key(&e.covariate) {
                warnings.push(format!(
                    "extension term on {} along {:?}: no value given (--covariate), using its fitted default {}",
                    e.observable.name(),
                    e.covariate,
                    e.default
                ));
            }
        }
        for name in self
            .covariates
            .keys()
            .filter(|_| self.extensions && !identity)
        {
            if !extensions.iter().any(|e| &e.covariate == name) {
                warnings.push(format!(
                    "covariate {name:?} given, but no extension term of weathers.{w} uses it: ignored"
                ));
            }
        }
        if !extensions.is_empty() && self.slope_source == SlopeSource::Quantile {
            return Err(InferError::Conflict(
                "the table's extension terms were fitted on vanishing_slope; use slope_source = survival or turn extensions off".into(),
            ));
        }
        Ok(extensions)
    }
}

/// The checked scalar parameters.
struct Scalars {
    range_scale: f64,
    clear_mor: f64,
    azimuth_resolution_deg: f64,
    min_range_m: Option<f64>,
}

/// A parameter outside its range.
fn invalid(name: &'static str, value: f64, reason: &str) -> InferError {
    InferError::InvalidParam {
        name,
        value: value.to_string(),
        reason: reason.to_string(),
    }
}

/// A table field the parameters need but the table `label` lacks.
fn missing(label: &str, field: String, reason: String) -> InferError {
    InferError::MissingCoefficient {
        table: label.to_string(),
        field,
        reason,
    }
}

/// The coefficients of weather `w` (clear is refused: it is the identity).
fn weather_coefficients<'t>(
    table: &'t CoefficientTable,
    w: WeatherClass,
    label: &str,
) -> Result<&'t WeatherCoefficients, InferError> {
    if w == WeatherClass::Clear {
        return Err(InferError::Conflict(
            "weather clear is the reference: applying it is the identity; choose fog, rain or snow"
                .into(),
        ));
    }
    table
        .weathers
        .get(&w)
        .ok_or_else(|| InferError::WeatherAbsent {
            table: label.to_string(),
            weather: w.to_string(),
            reason: table
                .absent
                .get(&w)
                .cloned()
                .unwrap_or_else(|| "not fitted".into()),
            available: if table.weathers.is_empty() {
                "none".into()
            } else {
                table
                    .weathers
                    .keys()
                    .map(|k| k.name())
                    .collect::<Vec<_>>()
                    .join(", ")
            },
        })
}

/// The soft survival edge from the table's survival fit.
fn soft_edge(
    coeffs: &WeatherCoefficients,
    w: WeatherClass,
    label: &str,
) -> Result<SoftEdge, InferError> {
    let s = coeffs.survival.as_ref().ok_or_else(|| {
        missing(
            label,
            format!("weathers.{w}.survival"),
            "soft_edge needs the survival fit, which this table lacks".into(),
        )
    })?;
    SoftEdge::new(s).map_err(|r| missing(label, format!("weathers.{w}.survival"), r))
}

/// Converts a rain rate with the table's conversion, checking its validity.
fn rain_to_mor(
    rate: f64,
    coeffs: &WeatherCoefficients,
    clamp: bool,
    label: &str,
) -> Result<(f64, RainUse), InferError> {
    if !(rate.is_finite() && rate >= 0.0) {
        return Err(InferError::InvalidParam {
            name: "rain_rate",
            value: rate.to_string(),
            reason: "must be finite and ≥ 0 mm/h".into(),
        });
    }
    if rate == 0.0 {
        // No rain: the identity, whatever the conversion says at R = 0.
        return Ok((
            f64::INFINITY,
            RainUse {
                requested_mm_h: 0.0,
                used_mm_h: 0.0,
                warning: None,
            },
        ));
    }
    let conv = coeffs.mor_from_rain_rate.as_ref().ok_or_else(|| {
        InferError::MissingCoefficient {
            table: label.to_string(),
            field: "weathers.rain.mor_from_rain_rate".into(),
            reason: format!(
                "a rain rate needs the table's rate → MOR conversion, which is missing ({}); give a MOR instead",
                coeffs
                    .mor_from_rain_rate_reason
                    .as_deref()
                    .unwrap_or("no reason given")
            ),
        }
    })?;
    // Validity: the fitted rates when the table records them; otherwise
    // [0, the rate where the line reaches MOR = 0).
    let zero = conv.zero_mor_rain_rate.or_else(|| {
        (conv.slope < 0.0 && conv.intercept > 0.0).then(|| -conv.intercept / conv.slope)
    });
    let lo = conv.rain_rate_min.unwrap_or(0.0);
    let (hi, hi_exclusive, why) = match (conv.rain_rate_max, zero) {
        (Some(h), Some(z)) if z <= h => (z, true, "the fitted rates, up to where MOR reaches 0"),
        (Some(h), _) => (h, false, "the rain rates the conversion was fitted on"),
        (None, Some(z)) => (
            z,
            true,
            "up to the rate where the conversion reaches MOR = 0",
        ),
        (None, None) => (f64::INFINITY, false, "the conversion is unbounded"),
    };
    let why = if conv.rain_rate_min.is_some() || conv.rain_rate_max.is_some() {
        why.to_string()
    } else {
        format!("{why}; the table records no fitted rate range")
    };
    let inside = rate >= lo && if hi_exclusive { rate < hi } else { rate <= hi };
    let lo_text = short_number(lo, Toward::Up);
    let max_text = if hi.is_finite() {
        format!(
            "{}{}",
            short_number(hi, Toward::Down),
            if hi_exclusive { " (exclusive)" } else { "" }
        )
    } else {
        "inf".into()
    };
    let mut used = rate;
    let mut warning = None;
    if !inside {
        if !clamp {
            return Err(InferError::RainRateOutOfRange {
                table: label.to_string(),
                rate,
                min: lo_text.clone(),
                max: max_text,
                reason: why,
            });
        }
        if rate > hi && hi_exclusive {
            return Err(InferError::RainRateOutOfRange {
                table: label.to_string(),
                rate,
                min: lo_text.clone(),
                max: max_text,
                reason: format!(
                    "{why}; cannot clamp to a rate whose MOR is 0 (everything would vanish)"
                ),
            });
        }
        used = rate.clamp(lo, hi);
        warning = Some(format!(
            "rain rate {rate} mm/h clamped to {} mm/h, the nearest rate inside the conversion's validity [{lo_text}, {max_text}] mm/h",
            short_number(used, Toward::Nearest)
        ));
    }
    let mor = conv.mor(used);
    if !(mor.is_finite() && mor > 0.0) {
        return Err(InferError::RainRateOutOfRange {
            table: label.to_string(),
            rate,
            min: lo_text,
            max: max_text,
            reason: format!(
                "the conversion gives MOR {mor:.4} m at {} mm/h, which is not > 0",
                short_number(used, Toward::Nearest)
            ),
        });
    }
    Ok((
        mor,
        RainUse {
            requested_mm_h: rate,
            used_mm_h: used,
            warning,
        },
    ))
}

/// Which way [`short_number`] rounds.
#[derive(Clone, Copy, PartialEq)]
enum Toward {
    /// To the nearest.
    Nearest,
    /// Up: for a lower bound, so a rate copied from the message is inside.
    Up,
    /// Down: for an upper bound.
    Down,
}

/// A rate or a MOR for a message: 4 significant digits, without the tail
/// of a binary fraction (`0.9450000000000001` prints as `0.945`, or `0.9451`
/// as a lower bound: 0.945 itself is below it).
fn short_number(v: f64, toward: Toward) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    // 4 significant digits through the shortest decimal, so the printed
    // number has no tail of its own.
    let four = |x: f64| format!("{x:.3e}").parse::<f64>().unwrap_or(x);
    // The decimal exponent of `v` itself (`log10` can round 99.999… up to 2).
    let exp: i32 = format!("{v:e}")
        .split_once('e')
        .and_then(|(_, e)| e.parse().ok())
        .unwrap_or(0);
    let step = 10f64.powi(exp - 3);
    let mut r = four(v);
    if toward == Toward::Up && r < v {
        r = four(r + step);
    } else if toward == Toward::Down && r > v {
        r = four(r - step);
    }
    format!("{r}")
}

#[cfg(test)]
mod short_number_tests {
    use super::{Toward, short_number};

    #[test]
    fn rates_print_with_four_significant_digits_on_the_inside_of_the_range() {
        assert_eq!(short_number(0.9450000000000001, Toward::Up), "0.9451");
        assert_eq!(short_number(0.9450000000000001, Toward::Nearest), "0.945");
        assert_eq!(short_number(0.9450000000000001, Toward::Down), "0.945");
        assert_eq!(short_number(0.945, Toward::Up), "0.945");
        assert_eq!(short_number(99.99999999999999, Toward::Down), "99.99");
        assert_eq!(short_number(100.0, Toward::Down), "100");
        assert_eq!(short_number(191.57, Toward::Down), "191.5");
        assert_eq!(short_number(191.57, Toward::Up), "191.6");
        assert_eq!(short_number(0.0, Toward::Up), "0");
    }
}
