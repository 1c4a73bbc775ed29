//! What the figures show besides the table: aggregated, plain data (no
//! plotting here — `murk-figures` draws it).

use std::collections::BTreeMap;

use murk_types::WeatherClass;

use crate::accumulate::{NoiseAcc, WeatherAcc};
use crate::quantile_slope::BandCells;

/// Step of the range axis of [`RangeMorDensity`], metres.
pub const DENSITY_RANGE_STEP_M: f64 = 0.5;

/// Clear returns by MOR bin and clear range, split into *no change* and
/// *disappeared* (the data of the seed's Figure 26).
#[derive(Debug, Clone, PartialEq)]
pub struct RangeMorDensity {
    /// Mean MOR of each bin, metres.
    pub mor: Vec<f64>,
    /// Width of a MOR bin, metres.
    pub mor_bin_width_m: f64,
    /// Range step, metres.
    pub range_step_m: f64,
    /// `kept[bin][k]`: *no change* returns with clear range in step `k`.
    pub kept: Vec<Vec<u64>>,
    /// `lost[bin][k]`: disappeared returns with clear range in step `k`.
    pub lost: Vec<Vec<u64>>,
}

impl RangeMorDensity {
    pub(crate) fn new(
        acc: &WeatherAcc,
        means: &[(i64, f64)],
        cells: &BandCells,
        width: f64,
    ) -> Self {
        let max_r = cells.ranges().last().copied().unwrap_or(0.0);
        let steps = (max_r / DENSITY_RANGE_STEP_M).floor() as usize + 1;
        let mut kept = Vec::new();
        let mut lost = Vec::new();
        for (k, _) in means {
            let (n, per_cell) = &acc.bins[k];
            let mut a = vec![0u64; steps];
            let mut b = vec![0u64; steps];
            for ((&c, &r), &h) in cells.cells().iter().zip(cells.ranges()).zip(cells.hits()) {
                let s = ((r / DENSITY_RANGE_STEP_M).floor() as usize).min(steps - 1);
                let kk = per_cell[c as usize] as u64;
                a[s] += kk;
                b[s] += (*n as u64 * h).saturating_sub(kk);
            }
            kept.push(a);
            lost.push(b);
        }
        RangeMorDensity {
            mor: means.iter().map(|m| m.1).collect(),
            mor_bin_width_m: width,
            range_step_m: DENSITY_RANGE_STEP_M,
            kept,
            lost,
        }
    }
}

/// A histogram for plotting: `counts[i]` over `[lo + i·step, lo + (i+1)·step)`.
#[derive(Debug, Clone, PartialEq)]
pub struct PlotHistogram {
    /// Lower edge.
    pub lo: f64,
    /// Bin width.
    pub step: f64,
    /// Counts.
    pub counts: Vec<u64>,
}

impl PlotHistogram {
    /// Rebins a fine histogram by `factor`, trimming empty bins at the top.
    fn rebin(lo: f64, step: f64, fine: &[u64], factor: usize) -> Self {
        let mut counts: Vec<u64> = fine.chunks(factor).map(|c| c.iter().sum()).collect();
        while counts.len() > 1 && counts.last() == Some(&0) {
            counts.pop();
        }
        PlotHistogram {
            lo,
            step: step * factor as f64,
            counts,
        }
    }
}

/// Ghost or ring histograms for Figure 29.
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseHistograms {
    /// Range, 5 cm bins.
    pub distance: PlotHistogram,
    /// Reflectivity, unit bins.
    pub reflectivity: PlotHistogram,
}

impl NoiseHistograms {
    pub(crate) fn from_acc(acc: &NoiseAcc) -> Option<Self> {
        if acc.distance.total() == 0 {
            return None;
        }
        let d = &acc.distance;
        let r = &acc.reflectivity;
        Some(NoiseHistograms {
            distance: PlotHistogram::rebin(d.lo(), d.width(), d.counts(), 50),
            reflectivity: PlotHistogram::rebin(r.lo(), r.width(), r.counts(), 20),
        })
    }
}

/// Plot data of one degraded weather.
#[derive(Debug, Clone, PartialEq)]
pub struct WeatherDiagnostics {
    /// MOR of every recording, in campaign order (Figure 24).
    pub mor: Vec<f64>,
    /// Figure 26 data.
    pub density: RangeMorDensity,
    /// The seed's slope over all reflectivities (the grey line of Figure 26).
    pub q99_all_slope: Option<f64>,
    /// Ghost histograms.
    pub ghost: Option<NoiseHistograms>,
    /// Ring histograms.
    pub ring: Option<NoiseHistograms>,
}

/// Plot data of a fit.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Diagnostics {
    /// Per degraded weather.
    pub weathers: BTreeMap<WeatherClass, WeatherDiagnostics>,
    /// MOR of the clear recordings that have one (Figure 24).
    pub clear_mor: Vec<f64>,
}
