//! Applying a table's extension terms ([`murk_types::ModelExtension`], added
//! by `murk diagnose`): the vanishing distance, the range and reflectivity of
//! kept returns and the near-range counts made to depend on one more
//! covariate.
//!
//! This path runs only when the weather has extension terms; plain tables
//! keep the fast kernel. Per point it computes the clear return's covariates
//! (range, calibrated reflectivity, ring, elevation, azimuth), then:
//!
//! 1. **survival**: the vanishing distance (hard) or the soft edge's centre
//!    and width are multiplied by the product of the survival terms;
//! 2. **range**: the kept return moves along its ray by the sum of the range
//!    terms (metres);
//! 3. **intensity**: the kept return's calibrated reflectivity is multiplied
//!    by the product of the intensity terms (stored back in the input's
//!    scale);
//! 4. **count**: the expected ghost and ring counts are multiplied by the
//!    product of the scan-level count terms; the point-level ones choose
//!    the rays the returns fall on (along `ring`, `elevation`, `azimuth`)
//!    and reshape their distance law (along their own `range`), scaling
//!    the counts by their means (`near`, [`murk_types::RayDensity`]).
//!
//! Draws are seeded per fixed-size chunk by (seed, scan key), so outputs do
//! not depend on the thread count.

use murk_types::{
    CovariateValue, ExtensionObservable, ModelExtension, PointCloud, PointCovariates,
    combine_extensions,
};
use rand::RngExt;
use rayon::prelude::*;
use std::collections::BTreeMap;

use crate::applier::Applier;
use crate::error::InferError;
use crate::sampling::{Purpose, ScanSeed};
use crate::summary::ApplySummary;

/// Points per seeded chunk.
const CHUNK: usize = 4096;

/// The scan-level product (or sum) of the terms on `obs` that do not depend
/// on the point.
pub(crate) fn scan_value(
    terms: &[ModelExtension],
    obs: ExtensionObservable,
    scan: &BTreeMap<String, CovariateValue>,
    mor: f64,
) -> f64 {
    combine_extensions(
        obs,
        terms
            .iter()
            .filter(|t| t.observable == obs && !t.is_point_level())
            .map(|t| t.value(None, scan, mor)),
    )
}

/// Per-point value of the point-level terms on `obs` at the applied MOR
/// `mor` (a term such as `exp(−k·r/MOR)` reads both) times (plus) the scan
/// value `base`.
fn point_value(
    terms: &[&ModelExtension],
    obs: ExtensionObservable,
    p: &PointCovariates,
    mor: f64,
    base: f64,
) -> f64 {
    if terms.is_empty() {
        return base;
    }
    let scan = BTreeMap::new();
    let v = terms.iter().map(|t| t.value(Some(p), &scan, mor));
    if obs.multiplicative() {
        base * v.product::<f64>()
    } else {
        base + v.sum::<f64>()
    }
}

impl Applier {
    /// The band index of a calibrated reflectivity (clamped into the lowest
    /// and highest band).
    pub(crate) fn band_index(&self, reflectivity: f64) -> usize {
        let mut k = 0;
        for (i, b) in self.bands.iter().enumerate().skip(1) {
            if reflectivity >= b.reflectivity_min {
                k = i;
            }
        }
        k
    }

    /// Probability that a return at `range_m` with calibrated
    /// `reflectivity` is kept when the vanishing distance is multiplied by
    /// `distance_factor` (1 for the table as fitted).
    ///
    /// With the soft edge this is the fitted survival law
    /// `residual + (1 − dropout − residual)·(1 − F((r − D)/(w·D)))`; when
    /// `given_clear_presence` is true it is conditioned on the return being
    /// present in a clear recording (what [`Applier::apply`] uses, since its
    /// input already lost the clear-weather dropout). With the hard threshold
    /// it is 1 up to the vanishing distance and 0 beyond. Identity models
    /// keep everything.
    pub fn survival_probability(
        &self,
        range_m: f64,
        reflectivity: f64,
        distance_factor: f64,
        given_clear_presence: bool,
    ) -> f64 {
        if self.identity {
            return 1.0;
        }
        let b = &self.bands[self.band_index(reflectivity)];
        let d = b.distance_at(reflectivity) * distance_factor;
        match &self.soft {
            None => {
                if range_m <= d {
                    1.0
                } else {
                    0.0
                }
            }
            Some(s) => {
                let z = murk_types::EdgeShape::z(range_m, d, b.edge_width.unwrap_or(f64::NAN));
                if given_clear_presence {
                    s.keep_probability_given_clear(z)
                } else {
                    s.keep_probability(z)
                }
            }
        }
    }

    /// [`Applier::apply`] for a weather with extension terms.
    pub(crate) fn apply_extended(
        &self,
        cloud: &PointCloud,
        key: &str,
        mut summary: ApplySummary,
        mask: &mut Vec<u8>,
    ) -> Result<(PointCloud, ApplySummary), InferError> {
        let seed = ScanSeed::new(self.seed, key);
        let scan = &self.scan_covariates;
        let terms = &self.extensions;
        let of = |obs| -> Vec<&ModelExtension> {
            terms
                .iter()
                .filter(|t| t.observable == obs && t.is_point_level())
                .collect()
        };
        let (surv_pt, range_pt, int_pt) = (
            of(ExtensionObservable::Survival),
            of(ExtensionObservable::Range),
            of(ExtensionObservable::Intensity),
        );
        // The angles (two `atan2` per point, most of this pass's time) only
        // when a point-level term reads them; a table whose point-level
        // terms are all counts (or along range, reflectivity or ring) needs
        // the range alone, computed as `PointCovariates::of_point` does.
        let needs_angles = surv_pt
            .iter()
            .chain(&range_pt)
            .chain(&int_pt)
            .any(|t| matches!(t.covariate.as_str(), "elevation" | "azimuth"));
        let mor = self.mor_m;
        let surv0 = scan_value(terms, ExtensionObservable::Survival, scan, mor);
        let range0 = scan_value(terms, ExtensionObservable::Range, scan, mor);
        let int0 = scan_value(terms, ExtensionObservable::Intensity, scan, mor);
        let count = scan_value(terms, ExtensionObservable::Count, scan, mor);
        let scale = cloud.intensity_scale;

        // Per point: keep?, band, new range factor, new intensity.
        struct Out {
            keep: bool,
            band: usize,
            /// Below the lowest band (follows its slope, counted apart).
            below: bool,
            range_factor: f32,
            intensity: f32,
        }
        let n = cloud.len();
        let per_chunk: Vec<Vec<Out>> = (0..n.div_ceil(CHUNK))
            .into_par_iter()
            .map(|c| {
                let mut rng = seed.rng(Purpose::Extension, c as u64);
                (c * CHUNK..((c + 1) * CHUNK).min(n))
                    .map(|i| {
                        let raw = cloud.intensity[i];
                        let refl = scale.to_calibrated(raw) as f64;
                        let (x, y, z) = (cloud.x[i] as f64, cloud.y[i] as f64, cloud.z[i] as f64);
                        let p = if needs_angles {
                            PointCovariates::of_point(x, y, z, refl, cloud.ring[i])
                        } else {
                            PointCovariates {
                                range: x.hypot(y).hypot(z),
                                reflectivity: refl,
                                ring: cloud.ring[i],
                                elevation: f64::NAN,
                                azimuth: f64::NAN,
                            }
                        };
                        let f =
                            point_value(&surv_pt, ExtensionObservable::Survival, &p, mor, surv0);
                        let prob = self.survival_probability(p.range, refl, f, true);
                        // One draw per point whatever the law, so the stream
                        // does not depend on which points are certain.
                        let u: f64 = rng.random();
                        let keep = u < prob;
                        let bias =
                            point_value(&range_pt, ExtensionObservable::Range, &p, mor, range0);
                        let range_factor = if p.range > 0.0 {
                            ((p.range + bias).max(0.0) / p.range) as f32
                        } else {
                            1.0
                        };
                        let fi =
                            point_value(&int_pt, ExtensionObservable::Intensity, &p, mor, int0);
                        let intensity = if fi == 1.0 {
                            raw
                        } else {
                            scale.from_calibrated((refl * fi) as f32)
                        };
                        Out {
                            keep,
                            band: self.band_index(refl),
                            below: refl < self.bands[0].reflectivity_min,
                            range_factor,
                            intensity,
                        }
                    })
                    .collect()
            })
            .collect();

        let mut out = PointCloud::with_capacity(n);
        out.intensity_scale = scale;
        let timed = cloud.time.is_some();
        if timed {
            out.time = Some(Vec::with_capacity(n));
        }
        let mut per_band = vec![(0u64, 0u64); self.bands.len()];
        let (mut below, mut below_kept) = (0u64, 0u64);
        for (i, o) in per_chunk.iter().flatten().enumerate() {
            if o.below {
                below += 1;
                below_kept += o.keep as u64;
            } else {
                per_band[o.band].0 += 1;
                per_band[o.band].1 += o.keep as u64;
            }
            if !o.keep {
                continue;
            }
            let k = o.range_factor;
            out.x.push(cloud.x[i] * k);
            out.y.push(cloud.y[i] * k);
            out.z.push(cloud.z[i] * k);
            out.intensity.push(o.intensity);
            out.ring.push(cloud.ring[i]);
            if let (Some(t), Some(src)) = (out.time.as_mut(), cloud.time.as_ref()) {
                t.push(src[i]);
            }
        }
        summary.vanished = (n - out.len()) as u64;
        summary.below_bands = below;
        summary.below_bands_vanished = below - below_kept;
        for (b, (pts, kept)) in summary.bands.iter_mut().zip(&per_band) {
            b.points_in = *pts;
            b.vanished = pts - kept;
        }

        let sigma = (self.range_noise_m > 0.0).then_some(self.range_noise_m);
        if sigma.is_some() || self.attenuation_alpha.is_some() {
            crate::kernel::perturb(&mut out, sigma, self.attenuation_alpha, seed);
            if sigma.is_some() {
                summary.range_noise_points = out.len() as u64;
            }
            if self.attenuation_alpha.is_some() {
                summary.attenuated_points = out.len() as u64;
            }
        }
        mask.clear();
        mask.extend(per_chunk.iter().flatten().map(|o| u8::from(o.keep)));
        if self.near_range {
            let scaled = |l: &Option<crate::model::NearLaw>| {
                l.clone().map(|mut l| {
                    l.expected *= count;
                    l
                })
            };
            let (ghost, ring) = (scaled(&self.ghost), scaled(&self.ring));
            self.add_near(
                (cloud, mask),
                &mut out,
                (ghost.as_ref(), ring.as_ref()),
                (seed, key),
                &mut summary,
                &mut Vec::new(),
            )?;
        }
        summary.points_out = out.len() as u64;
        Ok((out, summary))
    }
}
