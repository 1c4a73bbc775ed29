//! What an application did, per scan and per batch: counts a user (or a
//! script reading the JSON) checks against expectations.

use serde::Serialize;

use crate::near::NearRangeCounts;

/// The format tag of a batch report.
pub const SUMMARY_FORMAT: &str = "murk-apply-summary/1";

/// Counts of one reflectivity band.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[non_exhaustive]
pub struct BandSummary {
    /// Lower edge (inclusive), calibrated reflectivity.
    pub reflectivity_min: f64,
    /// Upper edge (exclusive); null when unbounded.
    pub reflectivity_max: Option<f64>,
    /// Input points in the band (points above the highest band are counted
    /// in it, see `above_bands`; points below the lowest are not, see
    /// `below_bands`).
    pub points_in: u64,
    /// Of those, points that vanished.
    pub vanished: u64,
}

/// What applying did to one scan (or, summed, to a batch).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[non_exhaustive]
pub struct ApplySummary {
    /// The scan's key (its relative path in a batch; `total` for sums).
    pub scan: String,
    /// True when the weather is clear (MOR ≥ the clear threshold, or a rain
    /// rate of 0) and the output is the input.
    pub identity: bool,
    /// Points read.
    pub points_in: u64,
    /// Points written.
    pub points_out: u64,
    /// Input points removed by vanishing.
    pub vanished: u64,
    /// Per reflectivity band of the model.
    pub bands: Vec<BandSummary>,
    /// Input points whose reflectivity lies below the lowest band (they
    /// follow the lowest band's slope but are not counted in its
    /// `points_in`).
    pub below_bands: u64,
    /// Of those, points that vanished.
    pub below_bands_vanished: u64,
    /// Input points at or above the highest band's upper edge (they follow
    /// the highest band's slope).
    pub above_bands: u64,
    /// Ghost returns (null when near-range returns are off or the table has
    /// no ghost law).
    pub ghost: Option<NearRangeCounts>,
    /// Ring returns (null likewise).
    pub ring: Option<NearRangeCounts>,
    /// Kept points whose range got Gaussian noise (0 when off).
    pub range_noise_points: u64,
    /// Kept points whose intensity was attenuated (0 when off).
    pub attenuated_points: u64,
    /// Input points nearer than the sensor description's `min_range_m`:
    /// not returns of the scene (no-return firings kept as points at the
    /// origin, the vehicle's body), written as they were and counted in
    /// `points_in` and `points_out` only.
    pub not_returns: u64,
    /// Without a minimum range: of the scan's first 16,384 points (those
    /// checked, `near_origin_checked`), the ones within
    /// [`murk_types::NEAR_POINT_M`] of the sensor — no scene return comes
    /// that close, so a share of them says the file keeps no-return firings
    /// or the vehicle as points (0 with a minimum range).
    pub near_origin: u64,
    /// Points checked for `near_origin`.
    pub near_origin_checked: u64,
    /// Anything the user should know (e.g. near-range returns not placed).
    pub warnings: Vec<String>,
}

impl ApplySummary {
    /// An all-zero summary named `scan` with the given bands.
    pub(crate) fn empty(scan: &str, bands: &[crate::BandRule]) -> Self {
        ApplySummary {
            scan: scan.to_string(),
            identity: false,
            points_in: 0,
            points_out: 0,
            vanished: 0,
            bands: bands
                .iter()
                .map(|b| BandSummary {
                    reflectivity_min: b.reflectivity_min,
                    reflectivity_max: b.reflectivity_max,
                    points_in: 0,
                    vanished: 0,
                })
                .collect(),
            below_bands: 0,
            below_bands_vanished: 0,
            above_bands: 0,
            ghost: None,
            ring: None,
            range_noise_points: 0,
            attenuated_points: 0,
            not_returns: 0,
            near_origin: 0,
            near_origin_checked: 0,
            warnings: Vec::new(),
        }
    }

    /// Adds another scan's counts (warnings are concatenated; `identity`
    /// stays true only if both are).
    pub fn add(&mut self, o: &ApplySummary) {
        self.identity &= o.identity;
        self.points_in += o.points_in;
        self.points_out += o.points_out;
        self.vanished += o.vanished;
        for (a, b) in self.bands.iter_mut().zip(&o.bands) {
            a.points_in += b.points_in;
            a.vanished += b.vanished;
        }
        self.below_bands += o.below_bands;
        self.below_bands_vanished += o.below_bands_vanished;
        self.above_bands += o.above_bands;
        for (mine, theirs) in [(&mut self.ghost, &o.ghost), (&mut self.ring, &o.ring)] {
            if let Some(t) = theirs {
                mine.get_or_insert_with(NearRangeCounts::default).add(t);
            }
        }
        self.range_noise_points += o.range_noise_points;
        self.attenuated_points += o.attenuated_points;
        self.not_returns += o.not_returns;
        self.near_origin += o.near_origin;
        self.near_origin_checked += o.near_origin_checked;
        self.warnings.extend(o.warnings.iter().cloned());
    }

    /// The warning that the points checked hold at least
    /// [`murk_types::NEAR_POINT_SHARE`] within [`murk_types::NEAR_POINT_M`]
    /// of the sensor (no minimum range was given), or `None`.
    pub fn near_origin_warning(&self) -> Option<String> {
        let share = murk_types::near_point_share(self.near_origin, self.near_origin_checked)?;
        Some(format!(
            "{} of the {} points checked ({:.1} %) lie within {} m of the sensor — no scene return comes that close: no-return firings written as points (nuScenes, Ouster) or the vehicle itself; give the minimum range (--min-range, min_range_m; nuScenes' tools use 1 m) so that they are written as they were and their rays stay open",
            self.near_origin,
            self.near_origin_checked,
            share * 100.0,
            murk_types::NEAR_POINT_M
        ))
    }

    /// Fraction of input points kept unchanged by vanishing (1 for an empty
    /// scan).
    pub fn kept_fraction(&self) -> f64 {
        if self.points_in == 0 {
            1.0
        } else {
            (self.points_in - self.vanished) as f64 / self.points_in as f64
        }
    }
}
