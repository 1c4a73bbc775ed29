//! The checked model: one weather at one MOR, ready to apply to scans.
//!
//! Order of the steps on a scan (each optional one off by default):
//!
//! 1. **Vanishing** (always): a return disappears when its range exceeds
//!    `slope(band) × MOR × range_scale`, the band taken from the return's
//!    calibrated reflectivity (hard threshold), or with the survival
//!    probability of the table's fitted edge (`soft_edge`).
//! 2. **Range noise** (`range_noise_m`): N(0, σ²) added to the range of each
//!    kept return (seed 004 §4.2 step 2).
//! 3. **Intensity attenuation** (`attenuate_intensity`): calibrated
//!    reflectivity × `exp(−2·α·r)` with `α = ln(20)/MOR`.
//! 4. **Near-range returns** (`near_range`): ghost and ring returns, each
//!    replacing the return of its ray when closer (seed 004 §4.2 step 3;
//!    see [`crate::near`]'s rules in the crate docs) — or, where the table
//!    found the weather's near returns replace the returns it loses (a
//!    strongest-return sensor), only on rays without a kept return.
//!
//! Kept returns are otherwise untouched: the seed's "no change" class keeps
//! its range and reflectivity, and the output keeps the input's order,
//! intensity scale and time column.

use murk_types::{EdgeShape, LidarSpec, PointCloud, WeatherClass};

use crate::error::InferError;
use crate::kernel::{self, Hard};
use crate::model::{
    BandRule, BandSummaryRule, ModelSummary, NearLaw, RainUse, SlopeSource, SoftEdge,
};
use crate::near::{NearSettings, add_near_range};
use crate::sampling::ScanSeed;
use crate::summary::ApplySummary;

/// A weather model checked against a coefficient table: applies one
/// weather at one MOR to any number of scans.
///
/// Built by [`crate::ApplyParams::build`]; plain data, cheap to share
/// between threads.
#[derive(Debug, Clone)]
pub struct Applier {
    pub(crate) weather: WeatherClass,
    pub(crate) mor_m: f64,
    pub(crate) rain: Option<RainUse>,
    pub(crate) identity: bool,
    pub(crate) clear_mor_threshold_m: f64,
    pub(crate) range_scale: f64,
    pub(crate) slope_source: SlopeSource,
    pub(crate) bands: Vec<BandRule>,
    pub(crate) soft: Option<SoftEdge>,
    pub(crate) near_range: bool,
    /// The table's weather found its near returns replace lost ones
    /// ([`murk_types::OcclusionTest`]): a near return goes only on a ray
    /// without a kept return.
    pub(crate) near_replaces_lost: bool,
    pub(crate) ghost: Option<NearLaw>,
    pub(crate) ring: Option<NearLaw>,
    pub(crate) range_noise_m: f64,
    pub(crate) attenuation_alpha: Option<f64>,
    pub(crate) lidar: Option<LidarSpec>,
    pub(crate) azimuth_resolution_deg: f64,
    /// A replacing weather counts the sky on each scan's measured firing
    /// step (no explicit `azimuth_resolution_deg`).
    pub(crate) measure_azimuth_step: bool,
    /// Points nearer than this are not returns.
    pub(crate) min_range_m: Option<f64>,
    pub(crate) seed: u64,
    pub(crate) warnings: Vec<String>,
    pub(crate) extensions: Vec<murk_types::ModelExtension>,
    /// Where near-range returns fall: the point-level count terms of
    /// `extensions`, gathered once.
    pub(crate) density: murk_types::RayDensity,
    pub(crate) scan_covariates: std::collections::BTreeMap<String, murk_types::CovariateValue>,
}

/// Points of a scan checked for points at the origin (the first ones, in
/// file order: a firing order that covers every ring).
const NEAR_CHECK_POINTS: usize = 16_384;

fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

impl Applier {
    /// The weather applied.
    pub fn weather(&self) -> WeatherClass {
        self.weather
    }

    /// The applied MOR in metres (infinite for a rain rate of 0).
    pub fn mor_m(&self) -> f64 {
        self.mor_m
    }

    /// True when applying leaves every scan unchanged.
    pub fn is_identity(&self) -> bool {
        self.identity
    }

    /// The range-scale coefficient used.
    pub fn range_scale(&self) -> f64 {
        self.range_scale
    }

    /// The reflectivity bands with their vanishing distances.
    pub fn bands(&self) -> &[BandRule] {
        &self.bands
    }

    /// Warnings raised while checking the parameters (a clamp, an
    /// extrapolated MOR, a missing near-range law).
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// The vanishing distance (metres) of a return of calibrated
    /// reflectivity `reflectivity` (clamped into the lowest / highest band).
    pub fn vanishing_distance_m(&self, reflectivity: f64) -> f64 {
        self.bands[self.band_index(reflectivity)].distance_at(reflectivity)
    }

    /// What is applied, for reports.
    pub fn describe(&self) -> ModelSummary {
        ModelSummary {
            weather: self.weather,
            mor_m: finite(self.mor_m),
            rain_rate_requested_mm_h: self.rain.as_ref().map(|r| r.requested_mm_h),
            rain_rate_used_mm_h: self.rain.as_ref().map(|r| r.used_mm_h),
            identity: self.identity,
            clear_mor_threshold_m: self.clear_mor_threshold_m,
            range_scale: self.range_scale,
            slope_field: self.slope_source.field(),
            vanishing: match self.soft.map(|s| s.edge) {
                None => "hard",
                Some(EdgeShape::Probit) => "soft-probit",
                Some(EdgeShape::Logistic) => "soft-logistic",
            },
            near_range: self.near_range,
            range_noise_m: (self.range_noise_m > 0.0).then_some(self.range_noise_m),
            attenuation_alpha_per_m: self.attenuation_alpha,
            seed: self.seed,
            bands: self
                .bands
                .iter()
                .map(|b| BandSummaryRule {
                    reflectivity_min: b.reflectivity_min,
                    reflectivity_max: b.reflectivity_max,
                    slope: finite(b.slope),
                    vanishing_distance_m: finite(b.vanishing_distance_m),
                    reflectivity: b.reflectivity,
                })
                .collect(),
            warnings: self.warnings.clone(),
            extensions: if self.identity {
                vec![]
            } else {
                self.extensions.clone()
            },
            covariates: self.scan_covariates.clone(),
        }
    }

    fn check_cloud(cloud: &PointCloud, key: &str) -> Result<(), InferError> {
        cloud.check().map_err(|e| InferError::BadCloud {
            scan: key.to_string(),
            reason: e.to_string(),
        })
    }

    /// The vanishing mask of `cloud` (1 = kept) into `mask`; returns the
    /// number of kept points. With `soft_edge` the draws are seeded by
    /// (seed, `key`), as in [`Applier::apply`].
    pub fn mask(
        &self,
        cloud: &PointCloud,
        key: &str,
        mask: &mut Vec<u8>,
    ) -> Result<u64, InferError> {
        Self::check_cloud(cloud, key)?;
        if self.identity {
            mask.clear();
            mask.resize(cloud.len(), 1);
            return Ok(cloud.len() as u64);
        }
        let Some((returns, is_return)) = self.returns_only(cloud) else {
            return Ok(kernel::total(&self.vanish(cloud, key, mask)).kept);
        };
        let kept = kernel::total(&self.vanish(&returns, key, mask)).kept;
        let passed = scatter_mask(&is_return, mask);
        Ok(kept + passed)
    }

    /// Without a minimum range, counts the scan's first
    /// [`NEAR_CHECK_POINTS`] points and those within
    /// [`murk_types::NEAR_POINT_M`] into `summary`
    /// ([`ApplySummary::near_origin_warning`]).
    fn check_near_origin(&self, cloud: &PointCloud, summary: &mut ApplySummary) {
        if self.min_range_m.is_some() {
            return;
        }
        let n = cloud.len().min(NEAR_CHECK_POINTS);
        summary.near_origin_checked = n as u64;
        summary.near_origin = (0..n)
            .filter(|&i| f64::from(cloud.range(i)) < murk_types::NEAR_POINT_M)
            .count() as u64;
    }

    /// The scan's returns and each input point's flag (true: a return),
    /// when the sensor description says some of its points are not returns
    /// (nearer than `min_range_m`); `None` when every point is
    /// one or the weather is clear. Call on a checked cloud.
    fn returns_only(&self, cloud: &PointCloud) -> Option<(PointCloud, Vec<bool>)> {
        let min_range = self.min_range_m?;
        if self.identity {
            return None;
        }
        let is_return: Vec<bool> = (0..cloud.len())
            .map(|i| f64::from(cloud.range(i)) >= min_range)
            .collect();
        if is_return.iter().all(|&r| r) {
            return None;
        }
        let mut returns = cloud.clone();
        returns.retain_mask(&is_return);
        Some((returns, is_return))
    }

    fn vanish(&self, cloud: &PointCloud, key: &str, mask: &mut Vec<u8>) -> Vec<kernel::Counts> {
        match &self.soft {
            None if self.bands.iter().any(|b| b.reflectivity.is_some()) => {
                kernel::hard_mask_by_reflectivity(&self.bands, cloud, mask)
            }
            None => kernel::hard_mask(&Hard::new(&self.bands, cloud.intensity_scale), cloud, mask),
            Some(s) => kernel::soft_mask(
                &self.bands,
                s,
                self.mor_m * self.range_scale,
                cloud,
                ScanSeed::new(self.seed, key),
                mask,
            ),
        }
    }

    /// True when applying may change kept points or add points (near-range
    /// returns, range noise or intensity attenuation), not only drop some.
    pub fn changes_points(&self) -> bool {
        !self.identity
            && (self.near_range || self.range_noise_m > 0.0 || self.attenuation_alpha.is_some())
    }

    /// Applies the model to one scan.
    ///
    /// `key` names the scan: it seeds every random draw (with the master
    /// seed) and labels errors and the summary. Use a name that is stable
    /// across runs, such as the file's path relative to the batch input, so
    /// that a scan gets the same output whatever else is in the batch.
    ///
    /// Points nearer than `min_range_m` ([`crate::ApplyParams::min_range_m`],
    /// else the sensor description's) are not returns: they are written
    /// as they were, in their places, and the weather's near returns may
    /// show on their rays.
    pub fn apply(
        &self,
        cloud: &PointCloud,
        key: &str,
    ) -> Result<(PointCloud, ApplySummary), InferError> {
        Self::check_cloud(cloud, key)?;
        let mut mask = Vec::new();
        let Some((returns, is_return)) = self.returns_only(cloud) else {
            let (out, mut summary) = self.apply_returns(cloud, key, &mut mask)?;
            self.check_near_origin(cloud, &mut summary);
            return Ok((out, summary));
        };
        let (out, mut summary) = self.apply_returns(&returns, key, &mut mask)?;
        pass_through(&is_return, &mut mask, &mut summary);
        let out = merge_non_returns(cloud, &is_return, &mask, out, &mut []);
        Ok((out, summary))
    }

    /// [`Applier::apply`] on a checked cloud of returns only; `mask` gets
    /// each point's fate.
    fn apply_returns(
        &self,
        cloud: &PointCloud,
        key: &str,
        mask: &mut Vec<u8>,
    ) -> Result<(PointCloud, ApplySummary), InferError> {
        if !self.identity && !self.extensions.is_empty() {
            let mut summary = ApplySummary::empty(key, &self.bands);
            summary.points_in = cloud.len() as u64;
            return self.apply_extended(cloud, key, summary, mask);
        }
        let (out, summary) = self.marked_returns(cloud, key, mask, true, &mut Vec::new())?;
        Ok((out.unwrap_or_else(|| cloud.clone()), summary))
    }

    /// [`Applier::apply`], also giving the vanishing mask: `mask[i]` is 1
    /// when input point `i` is kept (its row of the output is the kept
    /// points in order, then the added near-range points).
    ///
    /// With `want_cloud` false and a model that only drops points
    /// ([`Applier::changes_points`] false) the output cloud is not built
    /// (`None`): the mask says all. This is how `murk apply` copies the kept
    /// rows of a CSV file byte for byte. The result is the same as
    /// [`Applier::apply`]'s in every case.
    ///
    /// ```
    /// use murk_infer::{ApplyParams, CoefficientTable, PointCloud, Severity};
    /// use murk_types::WeatherClass;
    ///
    /// # let json = r#"{"format": "weather-noise-coefficients/1", "campaign": "doc",
    /// #   "lidar": {"model": "VLP16", "range_scale": 1.0},
    /// #   "weathers": {"fog": {"recordings": 1, "quantile": 0.99, "no_change_rate": null,
    /// #     "vanishing_slope": [{"reflectivity_min": 0, "reflectivity_max": null, "slope": 0.5, "points": 1}],
    /// #     "ghost": null, "ring": null}},
    /// #   "provenance": {"tool": "doc", "inputs_sha256": "", "parameters": {}}}"#;
    /// let table = CoefficientTable::from_json(json)?;
    /// let fog = ApplyParams::new(WeatherClass::Fog, Severity::Mor(40.0)).build(&table)?;
    /// let mut cloud = PointCloud::with_capacity(2);
    /// cloud.push(10.0, 0.0, 0.0, 50.0, 0); // 10 m: kept (vanishes beyond 0.5 × 40 = 20 m)
    /// cloud.push(30.0, 0.0, 0.0, 50.0, 0); // 30 m: gone
    /// let mut mask = Vec::new();
    /// let (out, summary) = fog.apply_masked(&cloud, "scan", &mut mask, false)?;
    /// assert_eq!(mask, vec![1, 0]);
    /// assert!(out.is_none());
    /// assert_eq!(summary.points_out, 1);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn apply_masked(
        &self,
        cloud: &PointCloud,
        key: &str,
        mask: &mut Vec<u8>,
        want_cloud: bool,
    ) -> Result<(Option<PointCloud>, ApplySummary), InferError> {
        self.apply_marked(cloud, key, mask, want_cloud, &mut Vec::new())
    }

    /// [`Applier::apply_masked`], also giving in `replaced` the indices of
    /// the output (ascending, kept points only) whose point a near-range
    /// return replaced: the point there is a fog or rain echo on the
    /// original's ray, not the original return, so a writer that carries a
    /// row's other cells (labels, colours) leaves them empty for it.
    pub fn apply_marked(
        &self,
        cloud: &PointCloud,
        key: &str,
        mask: &mut Vec<u8>,
        want_cloud: bool,
        replaced: &mut Vec<usize>,
    ) -> Result<(Option<PointCloud>, ApplySummary), InferError> {
        replaced.clear();
        Self::check_cloud(cloud, key)?;
        let Some((returns, is_return)) = self.returns_only(cloud) else {
            let (out, mut summary) = self.marked_returns(cloud, key, mask, want_cloud, replaced)?;
            self.check_near_origin(cloud, &mut summary);
            return Ok((out, summary));
        };
        let (out, mut summary) = self.marked_returns(&returns, key, mask, want_cloud, replaced)?;
        pass_through(&is_return, mask, &mut summary);
        let out = out.map(|o| merge_non_returns(cloud, &is_return, mask, o, replaced));
        Ok((out, summary))
    }

    /// [`Applier::apply_marked`] on a checked cloud of returns only.
    fn marked_returns(
        &self,
        cloud: &PointCloud,
        key: &str,
        mask: &mut Vec<u8>,
        want_cloud: bool,
        replaced: &mut Vec<usize>,
    ) -> Result<(Option<PointCloud>, ApplySummary), InferError> {
        let mut summary = ApplySummary::empty(key, &self.bands);
        summary.points_in = cloud.len() as u64;
        if self.identity {
            summary.identity = true;
            summary.points_out = cloud.len() as u64;
            // Every point in its band, none vanished.
            let counts = kernel::total(&kernel::hard_mask(
                &Hard::new(&self.bands, cloud.intensity_scale),
                cloud,
                mask,
            ));
            mask.clear();
            mask.resize(cloud.len(), 1);
            for (b, (n, _)) in summary
                .bands
                .iter_mut()
                .zip(counts.per_band(self.bands.len()))
            {
                b.points_in = n;
            }
            summary.below_bands = counts.below();
            summary.above_bands = counts.above;
            return Ok((want_cloud.then(|| cloud.clone()), summary));
        }
        if !self.extensions.is_empty() {
            // Extension terms move and rescale returns per point: there is no
            // mask-only form of them; callers use `apply`.
            return Err(InferError::Conflict(
                "apply_masked does not apply extension terms; use apply".into(),
            ));
        }
        let seed = ScanSeed::new(self.seed, key);
        let chunks = self.vanish(cloud, key, mask);
        let counts = kernel::total(&chunks);
        summary.vanished = counts.n - counts.kept;
        for (b, (n, kept)) in summary
            .bands
            .iter_mut()
            .zip(counts.per_band(self.bands.len()))
        {
            b.points_in = n;
            b.vanished = n - kept;
        }
        summary.below_bands = counts.below();
        summary.below_bands_vanished = counts.below_vanished();
        summary.above_bands = counts.above;
        if !want_cloud && !self.changes_points() {
            summary.points_out = counts.kept;
            return Ok((None, summary));
        }
        let mut out = kernel::compact(cloud, mask, &chunks);

        let sigma = (self.range_noise_m > 0.0).then_some(self.range_noise_m);
        if sigma.is_some() || self.attenuation_alpha.is_some() {
            kernel::perturb(&mut out, sigma, self.attenuation_alpha, seed);
            if sigma.is_some() {
                summary.range_noise_points = out.len() as u64;
            }
            if self.attenuation_alpha.is_some() {
                summary.attenuated_points = out.len() as u64;
            }
        }

        if self.near_range {
            self.add_near(
                (cloud, mask),
                &mut out,
                (self.ghost.as_ref(), self.ring.as_ref()),
                (seed, key),
                &mut summary,
                replaced,
            )?;
        }
        summary.points_out = out.len() as u64;
        Ok((Some(out), summary))
    }

    /// Adds the ghost and ring returns of `laws` to `out` (rays of `cloud`,
    /// whose points `kept` flags as kept by vanishing) and records them in
    /// `summary`.
    pub(crate) fn add_near(
        &self,
        (cloud, kept): (&PointCloud, &[u8]),
        out: &mut PointCloud,
        laws: (Option<&NearLaw>, Option<&NearLaw>),
        (seed, key): (ScanSeed, &str),
        summary: &mut ApplySummary,
        replaced: &mut Vec<usize>,
    ) -> Result<(), InferError> {
        let settings = NearSettings {
            ghost: laws.0,
            ring: laws.1,
            lidar: self.lidar.as_ref(),
            azimuth_resolution_deg: self.azimuth_resolution_deg,
            measure_azimuth_step: self.measure_azimuth_step,
            density: &self.density,
            replaces_lost: self.near_replaces_lost,
            kept,
        };
        let (g, r) = add_near_range(
            cloud,
            out,
            &settings,
            seed,
            key,
            &mut summary.warnings,
            replaced,
        )?;
        summary.ghost = g;
        summary.ring = r;
        Ok(())
    }
}

/// Widens `mask`, the fate of each return, to every input point (`is_return`
/// flags them): a point that is not a return is kept. Returns how many are
/// not returns.
fn scatter_mask(is_return: &[bool], mask: &mut Vec<u8>) -> u64 {
    let of_returns = std::mem::take(mask);
    let mut fate = of_returns.iter();
    mask.reserve(is_return.len());
    let mut passed = 0;
    for &r in is_return {
        if r {
            mask.push(fate.next().copied().unwrap_or(1));
        } else {
            mask.push(1);
            passed += 1;
        }
    }
    passed
}

/// Widens `mask` to every input point (those that are not returns kept)
/// and counts those in and out of `summary`.
fn pass_through(is_return: &[bool], mask: &mut Vec<u8>, summary: &mut ApplySummary) {
    let passed = scatter_mask(is_return, mask);
    summary.points_in += passed;
    summary.points_out += passed;
    summary.not_returns = passed;
}

/// `out` (the kept returns in order, then the added near returns) with the
/// points of `cloud` that are not returns put back in their places as they
/// were; `mask` is every input point's fate ([`pass_through`]), and the
/// output indices in `replaced` move with the points.
fn merge_non_returns(
    cloud: &PointCloud,
    is_return: &[bool],
    mask: &[u8],
    out: PointCloud,
    replaced: &mut [usize],
) -> PointCloud {
    let passed = cloud.len() - is_return.iter().filter(|&&r| r).count();
    let mut merged = PointCloud::with_capacity(out.len() + passed);
    merged.intensity_scale = out.intensity_scale;
    if out.time.is_some() {
        merged.time = Some(Vec::with_capacity(out.len() + passed));
    }
    let push = |dst: &mut PointCloud, src: &PointCloud, i: usize| {
        dst.x.push(src.x[i]);
        dst.y.push(src.y[i]);
        dst.z.push(src.z[i]);
        dst.intensity.push(src.intensity[i]);
        dst.ring.push(src.ring[i]);
        if let (Some(t), Some(s)) = (dst.time.as_mut(), src.time.as_ref()) {
            t.push(s[i]);
        }
    };
    // Output position of each kept return.
    let mut at = Vec::with_capacity(out.len());
    let mut k = 0;
    for (i, &r) in is_return.iter().enumerate() {
        if !r {
            push(&mut merged, cloud, i);
        } else if mask[i] != 0 {
            at.push(merged.len());
            push(&mut merged, &out, k);
            k += 1;
        }
    }
    for j in k..out.len() {
        push(&mut merged, &out, j);
    }
    for r in replaced.iter_mut() {
        *r = at[*r];
    }
    merged
}
