//! The clear-weather reference: one expected return per direction.
//!
//! A *cell* is a (ring, azimuth bin) pair of the campaign's LiDAR. Each clear
//! recording is first reduced to a [`CellImage`] (per cell: the median range
//! and reflectivity of its returns and how many there were). The
//! [`ClearReference`] then keeps, per cell, the median over clear recordings,
//! but only for cells that are
//!
//! - **present**: returned in at least `reference_min_presence` of the clear
//!   recordings (robust to clear-weather dropouts and to directions that see
//!   the sky), and
//! - **stable**: the median absolute deviation of their per-recording ranges
//!   is within the pairing tolerance (robust to vegetation, moving objects,
//!   cells straddling an edge).
//!
//! Cells that returned in some clear recording but fail either test keep a
//! range *envelope* `[min, max]`, so that a degraded return inside it is
//! counted as unpaired scene rather than as a ghost or ring.
//!
//! The same per-cell stacks give each clear recording's no-change rate against
//! a reference built **without** it (leave-one-out), the clear-weather
//! baseline of Table 7 and the dropout ε.

use murk_types::{LidarSpec, PointCloud};
use std::path::Path;

use crate::{FitError, FitValidParams};

/// The (ring, azimuth bin) grid of a LiDAR.
#[derive(Debug, Clone, PartialEq)]
pub struct CellGrid {
    rings: usize,
    az_bins: usize,
    az_res_deg: f64,
}

impl CellGrid {
    /// The grid of `spec` (rings × 360°/azimuth resolution).
    pub fn new(spec: &LidarSpec) -> Self {
        CellGrid {
            rings: spec.rings(),
            az_bins: spec.azimuth_bins(),
            az_res_deg: 360.0 / spec.azimuth_bins() as f64,
        }
    }

    /// Number of cells.
    pub fn cells(&self) -> usize {
        self.rings * self.az_bins
    }

    /// Number of rings.
    pub fn rings(&self) -> usize {
        self.rings
    }

    /// Azimuth bins per ring.
    pub fn azimuth_bins(&self) -> usize {
        self.az_bins
    }

    /// The cell of a point, `None` when its ring is outside the grid.
    #[inline]
    pub fn cell_of(&self, ring: u16, x: f32, y: f32) -> Option<usize> {
        let ring = ring as usize;
        if ring >= self.rings {
            return None;
        }
        let mut az = (y as f64).atan2(x as f64).to_degrees();
        if az < 0.0 {
            az += 360.0;
        }
        let bin = ((az / self.az_res_deg) as usize) % self.az_bins;
        Some(ring * self.az_bins + bin)
    }

    /// The cell `offset` azimuth bins away on the same ring (wrapping).
    #[inline]
    pub fn shifted(&self, cell: usize, offset: i64) -> usize {
        let ring = cell / self.az_bins;
        let bin = (cell % self.az_bins) as i64;
        let n = self.az_bins as i64;
        ring * self.az_bins + (bin + offset).rem_euclid(n) as usize
    }
}

/// One point reduced to what the fit needs: its cell, range and calibrated
/// reflectivity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellPoint {
    /// Cell index in the [`CellGrid`].
    pub cell: u32,
    /// Range, metres.
    pub range: f32,
    /// Calibrated reflectivity.
    pub reflectivity: f32,
}

/// Places every point of `cloud` (calibrated intensity expected) in `grid`.
/// A non-finite value or a ring outside the grid is an error naming `path` and
/// the point.
pub fn cell_points(
    grid: &CellGrid,
    cloud: &PointCloud,
    path: &Path,
) -> Result<Vec<CellPoint>, FitError> {
    cloud.check().map_err(|e| FitError::BadPoint {
        path: path.to_path_buf(),
        point: 0,
        reason: e.to_string(),
    })?;
    let mut out = Vec::with_capacity(cloud.len());
    for i in 0..cloud.len() {
        let (x, y, z, refl) = (cloud.x[i], cloud.y[i], cloud.z[i], cloud.intensity[i]);
        if !(x.is_finite() && y.is_finite() && z.is_finite() && refl.is_finite()) {
            return Err(FitError::BadPoint {
                path: path.to_path_buf(),
                point: i,
                reason: format!("non-finite value (x {x}, y {y}, z {z}, intensity {refl})"),
            });
        }
        let ring = cloud.ring[i];
        let cell = grid.cell_of(ring, x, y).ok_or_else(|| FitError::BadPoint {
            path: path.to_path_buf(),
            point: i,
            reason: format!(
                "ring {ring} is outside the campaign's LiDAR ({} rings)",
                grid.rings()
            ),
        })?;
        out.push(CellPoint {
            cell: cell as u32,
            range: (x * x + y * y + z * z).sqrt(),
            reflectivity: refl,
        });
    }
    Ok(out)
}

/// A clear recording reduced to one value per occupied cell.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CellImage {
    /// Occupied cells, ascending.
    pub cells: Vec<u32>,
    /// Median range of the cell's returns, metres.
    pub range: Vec<f32>,
    /// Median calibrated reflectivity of the cell's returns.
    pub reflectivity: Vec<f32>,
    /// Number of returns in the cell (revolutions that hit it).
    pub hits: Vec<u16>,
}

fn median_f32(v: &mut [f32]) -> f32 {
    v.sort_by(f32::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

impl CellImage {
    /// Reduces the points of one recording (any order) to a cell image.
    pub fn from_points(points: &[CellPoint], n_cells: usize) -> CellImage {
        // Counting sort by cell: O(n), no allocation per cell.
        let mut start = vec![0u32; n_cells + 1];
        for p in points {
            start[p.cell as usize + 1] += 1;
        }
        for i in 0..n_cells {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let mut r = vec![0f32; points.len()];
        let mut f = vec![0f32; points.len()];
        for p in points {
            let k = &mut fill[p.cell as usize];
            r[*k as usize] = p.range;
            f[*k as usize] = p.reflectivity;
            *k += 1;
        }
        let mut img = CellImage::default();
        for c in 0..n_cells {
            let (a, b) = (start[c] as usize, start[c + 1] as usize);
            if a == b {
                continue;
            }
            img.cells.push(c as u32);
            img.range.push(median_f32(&mut r[a..b]));
            img.reflectivity.push(median_f32(&mut f[a..b]));
            img.hits.push((b - a).min(u16::MAX as usize) as u16);
        }
        img
    }
}

/// The reference: per cell, the expected clear return (or none).
#[derive(Debug, Clone, PartialEq)]
pub struct ClearReference {
    grid: CellGrid,
    /// Reference range per cell, NaN when the cell is not in the reference.
    range: Vec<f32>,
    /// Reference reflectivity per cell.
    reflectivity: Vec<f32>,
    /// Expected returns per recording in the cell (0 when not in the reference).
    hits: Vec<u16>,
    /// Envelope of clear ranges of cells that returned at all (NaN otherwise).
    env_lo: Vec<f32>,
    env_hi: Vec<f32>,
    /// Cells in the reference, ascending.
    present: Vec<u32>,
    clear_recordings: usize,
    /// Per clear recording: (kept, total) against the leave-one-out reference.
    loo: Vec<(u64, u64)>,
}

impl ClearReference {
    /// Builds the reference from the clear recordings' images.
    ///
    /// `images` must be non-empty (the caller reports "no clear reference").
    pub fn build(grid: CellGrid, images: &[CellImage], params: &FitValidParams) -> ClearReference {
        let n_cells = grid.cells();
        let n = images.len();
        // Transpose: per cell, the entries of every recording that hit it.
        let mut start = vec![0usize; n_cells + 1];
        for img in images {
            for &c in &img.cells {
                start[c as usize + 1] += 1;
            }
        }
        for i in 0..n_cells {
            start[i + 1] += start[i];
        }
        let total = start[n_cells];
        let mut fill = start.clone();
        let mut e_rec = vec![0u32; total];
        let mut e_r = vec![0f32; total];
        let mut e_f = vec![0f32; total];
        let mut e_h = vec![0u16; total];
        for (ri, img) in images.iter().enumerate() {
            for j in 0..img.cells.len() {
                let c = img.cells[j] as usize;
                let k = fill[c];
                e_rec[k] = ri as u32;
                e_r[k] = img.range[j];
                e_f[k] = img.reflectivity[j];
                e_h[k] = img.hits[j];
                fill[c] += 1;
            }
        }

        let mut reference = ClearReference {
            grid,
            range: vec![f32::NAN; n_cells],
            reflectivity: vec![f32::NAN; n_cells],
            hits: vec![0; n_cells],
            env_lo: vec![f32::NAN; n_cells],
            env_hi: vec![f32::NAN; n_cells],
            present: Vec::new(),
            clear_recordings: n,
            loo: vec![(0, 0); n],
        };
        let min_presence = params.reference_min_presence();
        // Sum of h over cells that a recording *missing* from the cell would
        // still be scored on (leave-one-out presence holds without it).
        let mut missing_total = 0u64;
        let mut member_missing_total = vec![0u64; n];
        let mut order: Vec<usize> = Vec::new();
        let mut rs: Vec<f32> = Vec::new();
        let mut fs: Vec<f32> = Vec::new();
        let mut hs: Vec<u16> = Vec::new();
        let mut dev: Vec<f32> = Vec::new();
        for c in 0..n_cells {
            let (a, b) = (start[c], start[c + 1]);
            let m = b - a;
            if m == 0 {
                continue;
            }
            rs.clear();
            rs.extend_from_slice(&e_r[a..b]);
            order.clear();
            order.extend(0..m);
            order.sort_by(|&i, &j| e_r[a + i].total_cmp(&e_r[a + j]).then(i.cmp(&j)));
            rs.sort_by(f32::total_cmp);
            reference.env_lo[c] = rs[0];
            reference.env_hi[c] = rs[m - 1];
            let med = median_f32(&mut rs.clone());
            dev.clear();
            dev.extend(rs.iter().map(|r| (r - med).abs()));
            let mad = median_f32(&mut dev);
            let tol = params.pairing_tolerance(med as f64) as f32;
            let stable = mad <= tol;
            hs.clear();
            hs.extend_from_slice(&e_h[a..b]);
            hs.sort_unstable();
            let h = hs[(m - 1) / 2].max(1);
            if stable && m as f64 >= min_presence * n as f64 {
                fs.clear();
                fs.extend_from_slice(&e_f[a..b]);
                reference.range[c] = med;
                reference.reflectivity[c] = median_f32(&mut fs);
                reference.hits[c] = h;
                reference.present.push(c as u32);
            }
            if !stable || n < 2 {
                continue;
            }
            // Leave-one-out: members of the cell.
            let loo_present_member = (m - 1) as f64 >= min_presence * (n - 1) as f64 && m >= 2;
            if loo_present_member {
                for (pos, &i) in order.iter().enumerate() {
                    let rec = e_rec[a + i] as usize;
                    let med_loo = median_without(&rs, pos);
                    let tol = params.pairing_tolerance(med_loo as f64) as f32;
                    let kept = if (e_r[a + i] - med_loo).abs() <= tol {
                        e_h[a + i].min(h) as u64
                    } else {
                        0
                    };
                    reference.loo[rec].0 += kept;
                    reference.loo[rec].1 += h as u64;
                }
            }
            // Non-members: the cell stays in their reference when m/(n−1)
            // reaches the presence share; they lost all h returns.
            if m as f64 >= min_presence * (n - 1) as f64 {
                missing_total += h as u64;
                for i in 0..m {
                    member_missing_total[e_rec[a + i] as usize] += h as u64;
                }
            }
        }
        for (i, t) in member_missing_total.iter().enumerate() {
            reference.loo[i].1 += missing_total - t;
        }
        reference
    }

    /// The grid.
    pub fn grid(&self) -> &CellGrid {
        &self.grid
    }

    /// Cells in the reference, ascending.
    pub fn present(&self) -> &[u32] {
        &self.present
    }

    /// Reference range of `cell` (NaN when not in the reference).
    #[inline]
    pub fn range(&self, cell: usize) -> f32 {
        self.range[cell]
    }

    /// Reference reflectivity of `cell`.
    #[inline]
    pub fn reflectivity(&self, cell: usize) -> f32 {
        self.reflectivity[cell]
    }

    /// Expected returns per recording in `cell` (0 when not in the reference).
    #[inline]
    pub fn hits(&self, cell: usize) -> u16 {
        self.hits[cell]
    }

    /// True when `range` lies within the clear envelope of `cell` widened by
    /// the pairing tolerance.
    #[inline]
    pub fn in_envelope(&self, cell: usize, range: f32, tol: f32) -> bool {
        let (lo, hi) = (self.env_lo[cell], self.env_hi[cell]);
        lo.is_finite() && range >= lo - tol && range <= hi + tol
    }

    /// Number of clear recordings behind the reference.
    pub fn clear_recordings(&self) -> usize {
        self.clear_recordings
    }

    /// `(kept, total)` of each clear recording against the reference built
    /// without it (empty totals with a single clear recording).
    pub fn leave_one_out(&self) -> &[(u64, u64)] {
        &self.loo
    }

    /// Revolutions per recording: the median expected hits of the reference
    /// cells (1 for single-revolution recordings).
    pub fn revolutions(&self) -> u16 {
        let mut h: Vec<u16> = self
            .present
            .iter()
            .map(|&c| self.hits[c as usize])
            .collect();
        if h.is_empty() {
            return 1;
        }
        h.sort_unstable();
        h[(h.len() - 1) / 2].max(1)
    }

    /// Expected returns per recording summed over the reference.
    pub fn total_hits(&self) -> u64 {
        self.present
            .iter()
            .map(|&c| self.hits[c as usize] as u64)
            .sum()
    }
}

/// Median of sorted `v` without the element at `skip`.
fn median_without(v: &[f32], skip: usize) -> f32 {
    let m = v.len() - 1;
    let at = |k: usize| if k < skip { v[k] } else { v[k + 1] };
    if m % 2 == 1 {
        at(m / 2)
    } else {
        0.5 * (at(m / 2 - 1) + at(m / 2))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::FitParams;

    fn grid() -> CellGrid {
        let mut spec = LidarSpec::vlp16();
        spec.elevation_deg = vec![0.0, 2.0];
        spec.azimuth_resolution_deg = 90.0;
        CellGrid::new(&spec)
    }

    fn img(cells: &[(u32, f32, f32)]) -> CellImage {
        CellImage {
            cells: cells.iter().map(|c| c.0).collect(),
            range: cells.iter().map(|c| c.1).collect(),
            reflectivity: cells.iter().map(|c| c.2).collect(),
            hits: vec![1; cells.len()],
        }
    }

    #[test]
    fn cells_follow_ring_and_azimuth() {
        let g = grid();
        assert_eq!(g.cells(), 8);
        assert_eq!(g.cell_of(0, 1.0, 0.1), Some(0));
        assert_eq!(g.cell_of(1, -1.0, 0.1), Some(4 + 1));
        assert_eq!(g.cell_of(1, 0.1, -1.0), Some(4 + 3));
        assert_eq!(g.cell_of(2, 1.0, 0.0), None);
        assert_eq!(g.shifted(4, -1), 7);
        assert_eq!(g.shifted(7, 1), 4);
    }

    #[test]
    fn image_takes_the_median_per_cell() {
        let pts = [
            CellPoint {
                cell: 2,
                range: 10.0,
                reflectivity: 5.0,
            },
            CellPoint {
                cell: 2,
                range: 12.0,
                reflectivity: 7.0,
            },
            CellPoint {
                cell: 0,
                range: 3.0,
                reflectivity: 1.0,
            },
            CellPoint {
                cell: 2,
                range: 11.0,
                reflectivity: 9.0,
            },
        ];
        let i = CellImage::from_points(&pts, 8);
        assert_eq!(i.cells, vec![0, 2]);
        assert_eq!(i.range, vec![3.0, 11.0]);
        assert_eq!(i.reflectivity, vec![1.0, 7.0]);
        assert_eq!(i.hits, vec![1, 3]);
    }

    #[test]
    fn reference_keeps_present_stable_cells() {
        let p = FitParams::default().check().unwrap();
        // Cell 0: stable at 10 m in 3/3. Cell 1: in 1/3 only (absent).
        // Cell 2: unstable (5, 20, 40 m). Cell 3: 2/3 present, stable.
        let imgs = vec![
            img(&[
                (0, 10.0, 5.0),
                (1, 7.0, 1.0),
                (2, 5.0, 3.0),
                (3, 30.0, 50.0),
            ]),
            img(&[(0, 10.1, 6.0), (2, 20.0, 3.0), (3, 30.2, 52.0)]),
            img(&[(0, 9.9, 7.0), (2, 40.0, 3.0)]),
        ];
        let r = ClearReference::build(grid(), &imgs, &p);
        assert_eq!(r.present(), &[0, 3]);
        assert_eq!(r.range(0), 10.0);
        assert_eq!(r.reflectivity(0), 6.0);
        assert_eq!(r.range(3), 30.1);
        assert!(r.range(2).is_nan());
        // The unstable cell keeps its envelope: 4.5–40.5 m with 0.5 m tolerance.
        assert!(r.in_envelope(2, 30.0, 0.5) && !r.in_envelope(2, 41.0, 0.5));
        assert!(r.in_envelope(1, 7.2, 0.5));
    }

    #[test]
    fn leave_one_out_counts_own_dropouts() {
        let p = FitParams::default().check().unwrap();
        // Cell 0 returns in all four; cell 1 in three (recording 3 dropped it).
        let imgs = vec![
            img(&[(0, 10.0, 5.0), (1, 20.0, 5.0)]),
            img(&[(0, 10.0, 5.0), (1, 20.0, 5.0)]),
            img(&[(0, 10.0, 5.0), (1, 20.0, 5.0)]),
            img(&[(0, 10.0, 5.0)]),
        ];
        let r = ClearReference::build(grid(), &imgs, &p);
        assert_eq!(r.leave_one_out(), &[(2, 2), (2, 2), (2, 2), (1, 2)]);
    }

    #[test]
    fn ring_outside_the_grid_is_an_error() {
        let mut c = PointCloud::with_capacity(2);
        c.push(1.0, 0.0, 0.0, 5.0, 0);
        c.push(1.0, 0.0, 0.0, 5.0, 9);
        let e = cell_points(&grid(), &c, Path::new("x.pcd"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("x.pcd") && e.contains("point 1") && e.contains("ring 9"),
            "{e}"
        );
    }

    #[test]
    fn non_finite_point_is_an_error() {
        let mut c = PointCloud::with_capacity(1);
        c.push(f32::NAN, 0.0, 0.0, 5.0, 0);
        let e = cell_points(&grid(), &c, Path::new("y.pcd"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("y.pcd") && e.contains("point 0"), "{e}");
    }
}
