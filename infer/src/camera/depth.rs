//! Dense per-pixel depth maps (metres) for the rain renderer: from memory,
//! from a 16-bit PNG, or from a LiDAR scan projected with a KITTI
//! calibration and densified.
//!
//! **Densification (nearest-neighbour fill).** Pixels with no measurement
//! are filled in three passes, all deterministic:
//! 1. *rows*: a gap of at most [`Densify::max_row_gap_px`] pixels between
//!    two measured pixels of a row takes the value of the nearer one (ties:
//!    the smaller depth, so thin foreground objects are not eaten);
//! 2. *columns*: every remaining hole takes the value of the nearest
//!    measured pixel in its column (ties: the smaller depth), so holes
//!    *above* the column's highest measurement take that highest value
//!    (façades and trees above a LiDAR's top beam are about as far as what
//!    the beam hit) unless [`Densify::above_scan_m`] gives a fixed depth
//!    (e.g. a far one for open sky); holes below the lowest measurement take
//!    that lowest value;
//! 3. columns with no measurement at all copy the nearest column that has
//!    one (ties: the left one).
//!
//! When several LiDAR points land on one pixel the nearest wins (z-buffer).
//!
//! **See-through returns.** A LiDAR beam passes through glass and through
//! gaps a camera does not see through at its resolution: a car's windows
//! give returns from the street behind the car. Projected, they are far
//! measurements inside a near object, and the fill above would paint a block
//! of far depth (thick rain haze) on the car's window. Before filling, a
//! measured pixel is taken for such a return when, within
//! [`Densify::see_through_px`] pixels, it is enclosed on two opposite sides
//! (above and below, or left and right) by nearer measurements — nearer by
//! more than [`Densify::see_through_margin`] — that agree with each other
//! within the same margin (one surface around it, not a tree above and the
//! road below). It then takes the farther of the two enclosing depths. The
//! same idea as the hole closing of classical depth completion (Ku et al.,
//! 2018, "In Defense of Classical Image Processing"), written for sparse
//! LiDAR rows. `see_through_px = 0` turns it off.

use std::path::Path;

use murk_types::PointCloud;

use super::calib::KittiCalib;
use crate::error::InferError;

/// How holes of a sparse depth map are filled (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Densify {
    /// Longest run of empty pixels in a row that is filled from its row
    /// neighbours (default 8 px).
    pub max_row_gap_px: usize,
    /// Depth given to pixels above a column's highest measurement; `None`
    /// (default) extends the highest measurement upwards. A fixed far value
    /// (say 1000 m) fogs everything above the scan out, which suits open
    /// sky but not the trees and façades of a street.
    pub above_scan_m: Option<f32>,
    /// How far (pixels, each way) a measurement is checked for being a
    /// see-through return enclosed by a nearer surface (module docs);
    /// default 96, 0 turns the check off.
    pub see_through_px: usize,
    /// Relative margin of that check: the enclosing measurements are nearer
    /// than `d / (1 + margin)` and agree with each other within the same
    /// relative margin (default 0.3).
    pub see_through_margin: f32,
}

impl Default for Densify {
    fn default() -> Self {
        Densify {
            max_row_gap_px: 8,
            above_scan_m: None,
            see_through_px: 96,
            see_through_margin: 0.3,
        }
    }
}

/// A dense depth map: one distance along the optical axis per pixel, in
/// metres, row major. Values are finite and positive, or `+∞` (sky).
#[derive(Debug, Clone, PartialEq)]
pub struct DepthMap {
    width: u32,
    height: u32,
    metres: Vec<f32>,
}

impl DepthMap {
    /// Wraps row-major depths in metres; `source` names the data in errors.
    /// Every value must be positive (`+∞` allowed for sky).
    pub fn from_metres(
        width: u32,
        height: u32,
        metres: Vec<f32>,
        source: &str,
    ) -> Result<Self, InferError> {
        let n = width as usize * height as usize;
        if metres.len() != n || n == 0 {
            return Err(InferError::Depth {
                source_name: source.to_string(),
                x: 0,
                y: 0,
                reason: format!(
                    "{} values given for a {width}x{height} map (need {n}, at least 1)",
                    metres.len()
                ),
            });
        }
        if let Some(i) = metres.iter().position(|d| d.is_nan() || *d <= 0.0) {
            return Err(InferError::Depth {
                source_name: source.to_string(),
                x: i % width as usize,
                y: i / width as usize,
                reason: format!(
                    "depth {} m: depths must be positive (use +inf for sky)",
                    metres[i]
                ),
            });
        }
        Ok(DepthMap {
            width,
            height,
            metres,
        })
    }

    /// A map with the same depth everywhere.
    pub fn constant(width: u32, height: u32, metres: f32) -> Result<Self, InferError> {
        Self::from_metres(
            width,
            height,
            vec![metres; width as usize * height as usize],
            "constant depth",
        )
    }

    /// Reads a 16-bit grayscale PNG whose value × `metres_per_unit` is the
    /// depth (KITTI's depth benchmark: `1/256`). Zero means "no
    /// measurement" and is filled as described in the module docs.
    pub fn from_png16(
        path: &Path,
        metres_per_unit: f32,
        densify: &Densify,
    ) -> Result<Self, InferError> {
        let input = |reason: String| InferError::Input {
            path: path.to_path_buf(),
            reason,
        };
        if !(metres_per_unit.is_finite() && metres_per_unit > 0.0) {
            return Err(input(format!(
                "metres per unit {metres_per_unit} must be positive"
            )));
        }
        let img =
            image::open(path).map_err(|e| input(format!("cannot decode the depth PNG: {e}")))?;
        let image::DynamicImage::ImageLuma16(gray) = img else {
            return Err(input(format!(
                "a depth PNG must be 16-bit grayscale, this one is {:?}",
                img.color()
            )));
        };
        let (w, h) = gray.dimensions();
        let sparse: Vec<f32> = gray
            .as_raw()
            .iter()
            .map(|&v| {
                if v == 0 {
                    f32::NAN
                } else {
                    f32::from(v) * metres_per_unit
                }
            })
            .collect();
        let metres = fill(sparse, w as usize, h as usize, densify)
            .ok_or_else(|| input("every pixel is 0 (no depth at all)".to_string()))?;
        Self::from_metres(w, h, metres, &path.display().to_string())
    }

    /// Projects a LiDAR scan (sensor frame, metres) into a `width`×`height`
    /// image with `calib` and densifies it. Points behind the camera or
    /// outside the image are ignored (they are not part of the image);
    /// `source` names the scan in errors.
    pub fn from_lidar(
        cloud: &PointCloud,
        calib: &KittiCalib,
        width: u32,
        height: u32,
        densify: &Densify,
        source: &str,
    ) -> Result<Self, InferError> {
        let (w, h) = (width as usize, height as usize);
        let mut sparse = vec![f32::NAN; w * h];
        for i in 0..cloud.x.len() {
            let (x, y, z) = (cloud.x[i], cloud.y[i], cloud.z[i]);
            if !(x.is_finite() && y.is_finite() && z.is_finite()) {
                return Err(InferError::BadCloud {
                    scan: source.to_string(),
                    reason: format!("point {i}: coordinate is not finite ({x}, {y}, {z})"),
                });
            }
            let Some((u, v, d)) = calib.project(f64::from(x), f64::from(y), f64::from(z)) else {
                continue;
            };
            // Pixel (c, r) covers [c, c+1) × [r, r+1).
            let (c, r) = (u.floor(), v.floor());
            if c < 0.0 || r < 0.0 || c >= w as f64 || r >= h as f64 || d < 0.1 {
                continue;
            }
            let k = r as usize * w + c as usize;
            let d = d as f32;
            if sparse[k].is_nan() || d < sparse[k] {
                sparse[k] = d;
            }
        }
        let sparse = drop_see_through(&sparse, w, h, densify);
        let metres = fill(sparse, w, h, densify).ok_or_else(|| InferError::Depth {
            source_name: source.to_string(),
            x: 0,
            y: 0,
            reason: format!("no LiDAR point projects into the {width}x{height} image"),
        })?;
        Self::from_metres(width, height, metres, source)
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Depth at column `x`, row `y`, metres.
    pub fn get(&self, x: u32, y: u32) -> f32 {
        self.metres[y as usize * self.width as usize + x as usize]
    }

    /// All depths, row major.
    pub fn as_slice(&self) -> &[f32] {
        &self.metres
    }
}

/// Replaces see-through returns of a sparse map (NaN: no measurement) by the
/// surface that encloses them (module docs). Reads `m`, writes a copy, so
/// replacements never feed each other.
fn drop_see_through(m: &[f32], w: usize, h: usize, densify: &Densify) -> Vec<f32> {
    let win = densify.see_through_px;
    let margin = densify.see_through_margin.max(0.0);
    let mut out = m.to_vec();
    if win == 0 {
        return out;
    }
    // The nearest depth in a 3-pixel band across the walk at step k of a
    // direction, if any pixel of the band is measured.
    let band = |x: isize, y: isize, vertical: bool| -> Option<f32> {
        let mut best: Option<f32> = None;
        for o in -1..=1isize {
            let (cx, cy) = if vertical { (x + o, y) } else { (x, y + o) };
            if cx < 0 || cy < 0 || cx >= w as isize || cy >= h as isize {
                continue;
            }
            let v = m[cy as usize * w + cx as usize];
            if !v.is_nan() && best.is_none_or(|b| v < b) {
                best = Some(v);
            }
        }
        best
    };
    // Depth of the first measurement nearer than `limit` walking from
    // (x, y) by (dx, dy), at most `win` steps.
    let first_nearer = |x: usize, y: usize, dx: isize, dy: isize, limit: f32| -> Option<f32> {
        (1..=win as isize).find_map(|k| {
            band(x as isize + dx * k, y as isize + dy * k, dx == 0).filter(|&v| v < limit)
        })
    };
    let same = |a: f32, b: f32| (a - b).abs() <= margin * a.min(b);
    for y in 0..h {
        for x in 0..w {
            let d = m[y * w + x];
            if !d.is_finite() {
                continue;
            }
            let limit = d / (1.0 + margin);
            let mut best: Option<f32> = None;
            for ((ax, ay), (bx, by)) in [((0, -1), (0, 1)), ((-1, 0), (1, 0))] {
                let (Some(a), Some(b)) = (
                    first_nearer(x, y, ax, ay, limit),
                    first_nearer(x, y, bx, by, limit),
                ) else {
                    continue;
                };
                if same(a, b) {
                    let r = a.max(b);
                    best = Some(best.map_or(r, |c: f32| c.max(r)));
                }
            }
            if let Some(r) = best {
                out[y * w + x] = r;
            }
        }
    }
    out
}

/// Nearest-neighbour fill of the NaN holes (module docs); `None` when there
/// is no value at all.
fn fill(mut m: Vec<f32>, w: usize, h: usize, densify: &Densify) -> Option<Vec<f32>> {
    let pick = |a: (usize, f32), b: (usize, f32)| -> f32 {
        // a and b are (distance, depth); nearer wins, ties to the smaller depth.
        if a.0 < b.0 || (a.0 == b.0 && a.1 <= b.1) {
            a.1
        } else {
            b.1
        }
    };
    // 1. short gaps in rows.
    for row in m.chunks_mut(w) {
        let mut prev: Option<usize> = None;
        for x in 0..w {
            if row[x].is_nan() {
                continue;
            }
            if let Some(p) = prev
                && x - p > 1
                && x - p - 1 <= densify.max_row_gap_px
            {
                let (dl, dr) = (row[p], row[x]);
                for (k, cell) in row.iter_mut().enumerate().take(x).skip(p + 1) {
                    *cell = pick((k - p, dl), (x - k, dr));
                }
            }
            prev = Some(x);
        }
    }
    // 2. columns.
    let mut has = vec![false; w];
    let mut col = vec![0f32; h];
    for (x, has_x) in has.iter_mut().enumerate() {
        let samples: Vec<usize> = (0..h).filter(|&y| !m[y * w + x].is_nan()).collect();
        let (Some(&top), Some(&bottom)) = (samples.first(), samples.last()) else {
            continue;
        };
        *has_x = true;
        for (y, c) in col.iter_mut().enumerate() {
            *c = m[y * w + x];
        }
        let above = densify.above_scan_m.unwrap_or(col[top]);
        for c in col.iter_mut().take(top) {
            *c = above;
        }
        let bottom_v = col[bottom];
        for c in col.iter_mut().skip(bottom + 1) {
            *c = bottom_v;
        }
        for pair in samples.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            let (da, db) = (col[a], col[b]);
            for (y, c) in col.iter_mut().enumerate().take(b).skip(a + 1) {
                *c = pick((y - a, da), (b - y, db));
            }
        }
        for (y, c) in col.iter().enumerate() {
            m[y * w + x] = *c;
        }
    }
    // 3. empty columns copy the nearest filled column.
    let filled: Vec<usize> = (0..w).filter(|&x| has[x]).collect();
    if filled.is_empty() {
        return None;
    }
    for x in 0..w {
        if has[x] {
            continue;
        }
        let src = *filled
            .iter()
            .min_by_key(|&&c| (c.abs_diff(x), c))
            .expect("non-empty");
        for y in 0..h {
            m[y * w + x] = m[y * w + src];
        }
    }
    Some(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fill_takes_nearest_and_sky_above() {
        let n = f32::NAN;
        // 3 columns × 5 rows; only column 1 has samples at rows 2 and 4.
        #[rustfmt::skip]
        let m = vec![
            n, n, n,
            n, n, n,
            n, 4.0, n,
            n, n, n,
            n, 8.0, n,
        ];
        let d = Densify {
            max_row_gap_px: 0,
            above_scan_m: Some(500.0),
            ..Densify::default()
        };
        let f = fill(m, 3, 5, &d).unwrap();
        let col1: Vec<f32> = (0..5).map(|y| f[y * 3 + 1]).collect();
        // Row 3 is equidistant from 4 and 8: tie goes to the nearer object.
        assert_eq!(col1, vec![500.0, 500.0, 4.0, 4.0, 8.0]);
        // Empty columns copy column 1.
        for y in 0..5 {
            assert_eq!(f[y * 3], f[y * 3 + 1]);
            assert_eq!(f[y * 3 + 2], f[y * 3 + 1]);
        }
    }

    /// A sparse map like projected LiDAR: measured rows every `step` pixels,
    /// every pixel of those rows measured, depth given by `depth(x, y)`.
    fn rows(w: usize, h: usize, step: usize, depth: impl Fn(usize, usize) -> f32) -> Vec<f32> {
        let mut m = vec![f32::NAN; w * h];
        for y in (0..h).step_by(step) {
            for x in 0..w {
                m[y * w + x] = depth(x, y);
            }
        }
        m
    }

    #[test]
    fn a_window_in_a_near_car_takes_the_car_depth() {
        // A car at 5 m covers x 20..80, y 10..50; its window (x 30..70,
        // y 20..36) lets the beams through to a wall at 30 m. Rows every 4 px.
        let car = |x: usize, y: usize| (20..80).contains(&x) && (10..50).contains(&y);
        let window = |x: usize, y: usize| (30..70).contains(&x) && (20..36).contains(&y);
        let m = rows(100, 60, 4, |x, y| {
            if car(x, y) && !window(x, y) {
                5.0
            } else {
                30.0
            }
        });
        let f = fill(
            drop_see_through(&m, 100, 60, &Densify::default()),
            100,
            60,
            &Densify::default(),
        )
        .unwrap();
        for y in 20..36 {
            for x in 30..70 {
                assert_eq!(f[y * 100 + x], 5.0, "window pixel ({x}, {y})");
            }
        }
        // The wall beside the car stays where it is.
        for y in 0..60 {
            assert_eq!(f[y * 100 + 5], 30.0, "wall pixel (5, {y})");
            assert_eq!(f[y * 100 + 95], 30.0, "wall pixel (95, {y})");
        }
        // Off, the window shows the wall: the block this pass removes.
        let off = Densify {
            see_through_px: 0,
            ..Densify::default()
        };
        let g = fill(drop_see_through(&m, 100, 60, &off), 100, 60, &off).unwrap();
        assert_eq!(g[28 * 100 + 50], 30.0);
    }

    #[test]
    fn a_far_house_between_a_tree_and_the_road_is_kept() {
        // Rows 0..20: a tree at 8 m; rows 20..40: a house at 30 m seen
        // between the tree and the road; rows 40..60: road at 15 m. The two
        // nearer surfaces disagree (8 vs 15 m): the house is real.
        let m = rows(50, 60, 4, |_, y| match y {
            0..20 => 8.0,
            20..40 => 30.0,
            _ => 15.0,
        });
        let out = drop_see_through(&m, 50, 60, &Densify::default());
        for y in (20..40).step_by(4) {
            assert_eq!(out[y * 50 + 25], 30.0, "house row {y}");
        }
        // A gap wider than the window is not closed either: a 5 m surface
        // with a 240-px opening onto 30 m keeps the opening's far middle.
        let m = rows(
            400,
            12,
            4,
            |x, _| if (80..320).contains(&x) { 30.0 } else { 5.0 },
        );
        let out = drop_see_through(&m, 400, 12, &Densify::default());
        assert_eq!(out[4 * 400 + 200], 30.0);
        // A small opening (20 px) in the same surface is closed.
        let m = rows(
            200,
            12,
            4,
            |x, _| if (90..110).contains(&x) { 30.0 } else { 5.0 },
        );
        let out = drop_see_through(&m, 200, 12, &Densify::default());
        assert_eq!(out[4 * 200 + 100], 5.0);
    }

    #[test]
    fn fill_of_nothing_is_none() {
        assert!(fill(vec![f32::NAN; 6], 3, 2, &Densify::default()).is_none());
    }

    #[test]
    fn default_fill_extends_the_top_measurement_upwards() {
        let n = f32::NAN;
        let f = fill(vec![n, n, 7.0, n], 1, 4, &Densify::default()).unwrap();
        assert_eq!(f, vec![7.0, 7.0, 7.0, 7.0]);
    }
}
