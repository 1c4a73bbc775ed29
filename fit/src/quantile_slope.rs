//! The seed's estimator (§3.4.3), with censoring.
//!
//! Per MOR bin, the `quantile` (0.99) of the clear range of the *no change*
//! returns; then the zero-intercept least-squares line of those quantiles on
//! MOR (linfa-linear); its slope is the vanishing slope. Per reflectivity band,
//! a return's band is its reference cell's clear reflectivity.
//!
//! **Censoring.** Where the vanishing distance reaches the far end of what the
//! clear scene offers, the quantile measures the scene, not the weather: with
//! no weather at all the quantile of the survivors would be the scene's own
//! 0.99 quantile. A bin is censored (left out of the regression, reported with
//! its reason) when fewer than `censor_fraction` of the band's clear returns —
//! or fewer than `censor_min_points` — lie beyond its quantile, or beyond the
//! maximum-likelihood vanishing distance `s × MOR` when that is known.
//!
//! The statistics per MOR bin are the number of *no change* returns per
//! reference cell, summed over the bin's recordings: the quantile of the
//! clear range of no-change returns is a weighted quantile over cells sorted
//! by reference range, exact and independent of how many recordings went in.

use crate::FitValidParams;
use crate::hyperparams::Band;
use crate::reference::ClearReference;
use crate::stats::quantile::weighted_quantile_sorted;
use crate::stats::regress::zero_intercept_slope;

/// The reference cells of one reflectivity band, sorted by clear range.
#[derive(Debug, Clone, PartialEq)]
pub struct BandCells {
    cells: Vec<u32>,
    ranges: Vec<f64>,
    hits: Vec<u64>,
    /// `suffix[i]` = Σ hits of cells `i..`.
    suffix: Vec<u64>,
}

impl BandCells {
    /// The reference cells whose clear reflectivity lies in `band`.
    pub fn new(reference: &ClearReference, band: &Band) -> Self {
        let mut cells: Vec<u32> = reference
            .present()
            .iter()
            .copied()
            .filter(|&c| band.contains(reference.reflectivity(c as usize) as f64))
            .collect();
        cells.sort_by(|&a, &b| {
            reference
                .range(a as usize)
                .total_cmp(&reference.range(b as usize))
                .then(a.cmp(&b))
        });
        let ranges: Vec<f64> = cells
            .iter()
            .map(|&c| reference.range(c as usize) as f64)
            .collect();
        let hits: Vec<u64> = cells
            .iter()
            .map(|&c| reference.hits(c as usize) as u64)
            .collect();
        let mut suffix = vec![0u64; hits.len() + 1];
        for i in (0..hits.len()).rev() {
            suffix[i] = suffix[i + 1] + hits[i];
        }
        BandCells {
            cells,
            ranges,
            hits,
            suffix,
        }
    }

    /// Clear returns per recording in the band.
    pub fn hits_per_recording(&self) -> u64 {
        self.suffix[0]
    }

    /// Clear returns per recording beyond range `x`.
    pub fn hits_beyond(&self, x: f64) -> u64 {
        let i = self.ranges.partition_point(|r| *r <= x);
        self.suffix[i]
    }

    /// Cells, sorted by clear range.
    pub fn cells(&self) -> &[u32] {
        &self.cells
    }

    /// Clear ranges of [`BandCells::cells`].
    pub fn ranges(&self) -> &[f64] {
        &self.ranges
    }

    /// Expected hits of [`BandCells::cells`].
    pub fn hits(&self) -> &[u64] {
        &self.hits
    }
}

/// The statistics of one MOR bin: its recordings and their paired returns.
#[derive(Debug, Clone, PartialEq)]
pub struct MorBinStats<'a> {
    /// Lower edge, metres.
    pub lo: f64,
    /// Upper edge, metres.
    pub hi: f64,
    /// Mean MOR of its recordings, metres.
    pub mor_mean: f64,
    /// Recordings in the bin.
    pub recordings: u32,
    /// *No change* returns per cell, summed over the bin's recordings.
    pub kept: &'a [u32],
}

/// The quantile of one band in one MOR bin.
#[derive(Debug, Clone, PartialEq)]
pub struct BinQuantile {
    /// Mean MOR of the bin.
    pub mor_mean: f64,
    /// Bin edges.
    pub lo: f64,
    /// Bin edges.
    pub hi: f64,
    /// Recordings.
    pub recordings: u32,
    /// The quantile, metres.
    pub quantile: Option<f64>,
    /// *No change* returns.
    pub points: u64,
    /// Left out because the scene, not the weather, bounds it.
    pub censored: bool,
    /// Entered the regression.
    pub used: bool,
    /// Why it is censored, unused or null.
    pub reason: Option<String>,
}

/// Quantile and censoring of one band in one bin. `ml_edge_m` is the
/// maximum-likelihood vanishing distance at the bin's MOR, when known.
pub fn bin_quantile(
    band: &BandCells,
    bin: &MorBinStats<'_>,
    params: &FitValidParams,
    ml_edge_m: Option<f64>,
) -> BinQuantile {
    let w: Vec<u64> = band
        .cells
        .iter()
        .map(|&c| bin.kept[c as usize] as u64)
        .collect();
    let points: u64 = w.iter().sum();
    let q = weighted_quantile_sorted(&band.ranges, &w, params.quantile());
    let mut out = BinQuantile {
        mor_mean: bin.mor_mean,
        lo: bin.lo,
        hi: bin.hi,
        recordings: bin.recordings,
        quantile: q,
        points,
        censored: false,
        used: false,
        reason: None,
    };
    let Some(qv) = q else {
        out.reason = Some("no no-change return in this band and bin".into());
        return out;
    };
    let n = bin.recordings as u64;
    let total = n * band.hits_per_recording();
    let floor = (params.censor_fraction() * total as f64).max(params.censor_min_points() as f64);
    let beyond_q = n * band.hits_beyond(qv);
    if (beyond_q as f64) < floor {
        out.censored = true;
        out.reason = Some(format!(
            "censored: only {beyond_q} of {total} clear returns of this band lie beyond the quantile ({qv:.2} m); it measures the far end of the scene, not the weather"
        ));
        return out;
    }
    if let Some(edge) = ml_edge_m {
        let beyond_e = n * band.hits_beyond(edge);
        if (beyond_e as f64) < floor {
            out.censored = true;
            out.reason = Some(format!(
                "censored: the vanishing distance ({edge:.2} m) lies at the far end of the clear scene (only {beyond_e} of {total} clear returns beyond it)"
            ));
            return out;
        }
    }
    if points < params.min_points_per_bin() {
        out.reason = Some(format!(
            "too few no-change returns ({points} < {})",
            params.min_points_per_bin()
        ));
        return out;
    }
    out.used = true;
    out
}

/// The regression's points: `(MOR × range_scale, quantile)` of the used bins.
fn used_points(bins: &[BinQuantile], range_scale: f64) -> impl Iterator<Item = (f64, f64)> + '_ {
    bins.iter()
        .filter(|b| b.used)
        .filter_map(move |b| b.quantile.map(|q| (b.mor_mean * range_scale, q)))
}

/// The seed's slope from the bins' quantiles: zero-intercept least squares of
/// the used bins' quantile on `MOR × range_scale`.
pub fn quantile_slope(bins: &[BinQuantile], range_scale: f64) -> Result<f64, String> {
    let (x, y): (Vec<f64>, Vec<f64>) = used_points(bins, range_scale).unzip();
    if x.is_empty() {
        let censored = bins.iter().filter(|b| b.censored).count();
        return Err(if bins.is_empty() {
            "no MOR bin".to_string()
        } else if censored == bins.len() {
            format!("every MOR bin ({censored}) is censored by the far end of the clear scene")
        } else {
            format!(
                "no usable MOR bin: {censored} of {} censored, the others have too few no-change returns",
                bins.len()
            )
        });
    }
    zero_intercept_slope(&x, &y).ok_or_else(|| "the regression has no solution".to_string())
}

/// The 95 % interval of [`quantile_slope`] over the recordings, grouped by
/// MOR bin: the slope again with each used bin (its recordings) left out,
/// a delete-a-group jackknife with Student's t on `k − 1` degrees of
/// freedom (`stats::jackknife`). A bin's quantile carries its recordings'
/// shared MOR reading and sensor state, so the bins, not the returns, are
/// the independent units; which bins are used (censoring) is kept as
/// fitted. Returns `(standard error, [low, high])`, or why there is none
/// (fewer than three used bins).
pub fn quantile_slope_interval(
    bins: &[BinQuantile],
    range_scale: f64,
) -> Result<(f64, [f64; 2]), String> {
    let slope = quantile_slope(bins, range_scale)?;
    let pts: Vec<(f64, f64)> = used_points(bins, range_scale).collect();
    let k = pts.len();
    if k < 3 {
        return Err(format!(
            "{k} used MOR bins are too few for an interval over them (the jackknife needs 3)"
        ));
    }
    let leave_out: Option<Vec<f64>> = (0..k)
        .map(|i| {
            let (x, y): (Vec<f64>, Vec<f64>) = pts
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .map(|(_, p)| *p)
                .unzip();
            zero_intercept_slope(&x, &y)
        })
        .collect();
    let leave_out = leave_out.ok_or("the slope has no solution with a MOR bin left out")?;
    let (se, half) = crate::stats::jackknife(&leave_out)
        .ok_or("the slope is not finite with a MOR bin left out")?;
    Ok((se, [slope - half, slope + half]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::FitParams;
    use crate::reference::{CellGrid, CellImage};
    use murk_types::LidarSpec;

    /// One ring of 100 cells at ranges 1..=100 m, reflectivity 5 (cells < 50)
    /// or 50.
    fn reference() -> ClearReference {
        let mut spec = LidarSpec::vlp16();
        spec.elevation_deg = vec![0.0];
        spec.azimuth_resolution_deg = 3.6;
        let grid = CellGrid::new(&spec);
        let img = CellImage {
            cells: (0..100).collect(),
            range: (1..=100).map(|r| r as f32).collect(),
            reflectivity: (0..100).map(|c| if c < 50 { 5.0 } else { 50.0 }).collect(),
            hits: vec![1; 100],
            frames: 1,
        };
        let p = FitParams::default().check().unwrap();
        ClearReference::build(grid, &[img.clone(), img], &p)
    }

    fn all() -> Band {
        Band {
            min: 0.0,
            max: None,
        }
    }

    #[test]
    fn quantile_of_survivors_and_regression() {
        let r = reference();
        let p = FitParams::default().min_points_per_bin(10).check().unwrap();
        let band = BandCells::new(&r, &all());
        assert_eq!(band.hits_per_recording(), 100);
        assert_eq!(band.hits_beyond(97.5), 3);
        // One recording at MOR 100 where every return up to 30 m survived:
        // q99 of {1..30} (type 7) = 29 + 0.71.
        let kept: Vec<u32> = (0..100).map(|c| if c < 30 { 1 } else { 0 }).collect();
        let bin = MorBinStats {
            lo: 95.0,
            hi: 105.0,
            mor_mean: 100.0,
            recordings: 1,
            kept: &kept,
        };
        let q = bin_quantile(&band, &bin, &p, None);
        assert!((q.quantile.unwrap() - 29.71).abs() < 1e-9, "{q:?}");
        assert!(q.used && !q.censored);
        let q2 = BinQuantile {
            mor_mean: 50.0,
            quantile: Some(15.0),
            ..q.clone()
        };
        let s = quantile_slope(&[q, q2], 1.0).unwrap();
        // Σxy/Σx² = (100·29.71 + 50·15)/(100² + 50²)
        assert!((s - (2971.0 + 750.0) / 12500.0).abs() < 1e-12);
    }

    #[test]
    fn bin_bounded_by_the_scene_is_censored() {
        let r = reference();
        let p = FitParams::default().min_points_per_bin(10).check().unwrap();
        let band = BandCells::new(&r, &all());
        // Nothing vanished: the quantile is the scene's own (99.01 m) and
        // only 1 % of clear returns lie beyond it.
        let kept = vec![1u32; 100];
        let bin = MorBinStats {
            lo: 0.0,
            hi: 10.0,
            mor_mean: 500.0,
            recordings: 1,
            kept: &kept,
        };
        let q = bin_quantile(&band, &bin, &p, None);
        assert!(q.censored && !q.used, "{q:?}");
        assert!(q.reason.unwrap().contains("far end"));
        let e = quantile_slope(&[bin_quantile(&band, &bin, &p, None)], 1.0).unwrap_err();
        assert!(e.contains("every MOR bin"), "{e}");
    }

    #[test]
    fn edge_beyond_the_scene_censors_via_the_ml_slope() {
        let r = reference();
        let p = FitParams::default().min_points_per_bin(10).check().unwrap();
        let band = BandCells::new(&r, &all());
        let kept: Vec<u32> = (0..100).map(|c| if c < 90 { 1 } else { 0 }).collect();
        let bin = MorBinStats {
            lo: 0.0,
            hi: 10.0,
            mor_mean: 300.0,
            recordings: 1,
            kept: &kept,
        };
        assert!(bin_quantile(&band, &bin, &p, None).used);
        let q = bin_quantile(&band, &bin, &p, Some(120.0));
        assert!(q.censored, "{q:?}");
    }

    #[test]
    fn bin_with_too_few_points_is_not_used() {
        let r = reference();
        let p = FitParams::default().min_points_per_bin(50).check().unwrap();
        let band = BandCells::new(&r, &all());
        let kept: Vec<u32> = (0..100).map(|c| if c < 20 { 1 } else { 0 }).collect();
        let bin = MorBinStats {
            lo: 0.0,
            hi: 10.0,
            mor_mean: 60.0,
            recordings: 1,
            kept: &kept,
        };
        let q = bin_quantile(&band, &bin, &p, None);
        assert!(!q.used && !q.censored);
        assert!(q.reason.unwrap().contains("too few"));
    }

    #[test]
    fn bands_split_cells_by_clear_reflectivity() {
        let r = reference();
        let low = BandCells::new(
            &r,
            &Band {
                min: 0.0,
                max: Some(10.0),
            },
        );
        let high = BandCells::new(
            &r,
            &Band {
                min: 10.0,
                max: None,
            },
        );
        assert_eq!(low.hits_per_recording(), 50);
        assert_eq!(high.ranges()[0], 51.0);
    }
}
