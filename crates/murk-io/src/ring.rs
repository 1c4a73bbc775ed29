//! Ring ids for formats that carry none, from each point's elevation.
//!
//! [`LidarSpec::nearest_ring`] computes an `atan2` and scans every ring per
//! call; at 100 M points/s that is the whole time budget. [`RingLookup`]
//! gives the same answer from precomputed thresholds: the ring elevations are
//! sorted, the midpoints between neighbours are turned into slopes
//! `tan(mid)`, and a point lies above a midpoint exactly when
//! `z > tan(mid) · hypot(x, y)` ([`RingLookup::ring`], in `f64`). Ties (a
//! point exactly on a midpoint) go to the lower ring id, as in
//! `nearest_ring`. Only points within float rounding of a midpoint can get a
//! different answer from `nearest_ring`.
//!
//! **The fast path** ([`RingLookup::fill`]) answers most points with one
//! table load instead of one compare per ring: the slope `t = z / hypot(x,
//! y)` is computed in `f32` (vectorised), and a table of [`CELLS`] equal cells
//! over the thresholds' slope range says the ring of every cell that lies
//! clearly between two thresholds. Cells that hold a threshold, or lie within
//! a margin of one that is far wider than the `f32` rounding of `t`, are
//! marked "exact", and their points (and points with extreme coordinates)
//! go through [`RingLookup::ring`]; so `fill` gives exactly what `ring`
//! gives, point for point (tested on millions of points, many within a few
//! ulps of a threshold).
//!
//! ```text
//! let lookup = RingLookup::new(&LidarSpec::vlp16());
//! let mut ring = vec![0u16; x.len()];
//! lookup.fill(&mut ring, &x, &y, &z);
//! ```

use murk_types::LidarSpec;

/// Above this many thresholds a binary search beats a branch-free count.
const LINEAR_MAX: usize = 32;

/// Cells of the slope table between the lowest and highest threshold.
const CELLS: usize = 4096;

/// Table entry: decide with [`RingLookup::ring`].
const EXACT: u32 = u32::MAX;

/// Relative margin around a threshold inside which the `f32` slope is not
/// trusted (its rounding error is below 1e-6 relative).
const REL_MARGIN: f32 = 1e-4;

/// Points per pass of [`RingLookup::fill`] (stack buffer of cell indices).
const FILL_BLOCK: usize = 1024;

/// Precomputed ring-from-elevation thresholds of one sensor.
#[derive(Debug, Clone)]
pub(crate) struct RingLookup {
    /// `tan` of the midpoints between consecutive distinct elevations, ascending.
    slopes: Vec<f64>,
    /// For each threshold, whether a point exactly on it takes the upper ring.
    tie_up: Vec<bool>,
    /// Ring id of each sorted position (`slopes.len() + 1` entries).
    ring_of: Vec<u16>,
    /// Ring of a point at the origin (elevation 0, as `atan2(0, 0)` gives).
    at_origin: u16,
    /// The slope table: entry 0 for slopes below `t_lo`, entries
    /// `1..=CELLS` for the cells, `CELLS + 1` above `t_hi`, `CELLS + 2` for
    /// points that must go the exact way; each entry a ring id or [`EXACT`].
    table: Vec<u32>,
    /// Slope at the lower edge of cell 1.
    t_lo: f32,
    /// Cells per unit slope.
    inv_w: f32,
}

impl RingLookup {
    /// Builds the lookup; `spec` must have passed [`LidarSpec::validate`].
    pub(crate) fn new(spec: &LidarSpec) -> Self {
        // (elevation, ring id), sorted by elevation; equal elevations keep the
        // lowest id, which is the one `nearest_ring` returns.
        let mut rings: Vec<(f64, u16)> = spec
            .elevation_deg
            .iter()
            .enumerate()
            .map(|(i, &e)| (e, i as u16))
            .collect();
        rings.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        rings.dedup_by(|later, earlier| later.0 == earlier.0);
        let mut slopes = Vec::with_capacity(rings.len().saturating_sub(1));
        let mut tie_up = Vec::with_capacity(slopes.capacity());
        for w in rings.windows(2) {
            let mid = 0.5 * (w[0].0 + w[1].0);
            slopes.push(mid.to_radians().tan());
            tie_up.push(w[1].1 < w[0].1);
        }
        let ring_of: Vec<u16> = rings.iter().map(|r| r.1).collect();
        let (table, t_lo, inv_w) = slope_table(&slopes, &ring_of);
        RingLookup {
            slopes,
            tie_up,
            ring_of,
            at_origin: spec.nearest_ring(0.0),
            table,
            t_lo,
            inv_w,
        }
    }

    /// Ring of the point `(x, y, z)`.
    #[inline]
    pub(crate) fn ring(&self, x: f32, y: f32, z: f32) -> u16 {
        let (x, y, z) = (f64::from(x), f64::from(y), f64::from(z));
        let h = (x * x + y * y).sqrt();
        if h == 0.0 && z == 0.0 {
            return self.at_origin;
        }
        let above = |k: usize| {
            let edge = self.slopes[k] * h;
            z > edge || (self.tie_up[k] && z == edge)
        };
        let pos = if self.slopes.len() <= LINEAR_MAX {
            // Branch-free count: thresholds are ascending, so the number a
            // point is above is its sorted position.
            let mut pos = 0usize;
            for (&s, &up) in self.slopes.iter().zip(&self.tie_up) {
                let edge = s * h;
                pos += usize::from(z > edge || (up && z == edge));
            }
            pos
        } else {
            let (mut lo, mut hi) = (0usize, self.slopes.len());
            while lo < hi {
                let mid = (lo + hi) / 2;
                if above(mid) {
                    lo = mid + 1;
                } else {
                    hi = mid;
                }
            }
            lo
        };
        self.ring_of[pos]
    }

    /// Appends the ring of every point of the columns to `out`.
    pub(crate) fn extend(&self, out: &mut Vec<u16>, x: &[f32], y: &[f32], z: &[f32]) {
        let start = out.len();
        out.resize(start + x.len(), 0);
        self.fill(&mut out[start..], x, y, z);
    }

    /// Writes the ring of point `i` of the columns to `out[i]`: exactly
    /// [`RingLookup::ring`] of every point, mostly by one table load.
    pub(crate) fn fill(&self, out: &mut [u16], x: &[f32], y: &[f32], z: &[f32]) {
        let n = out.len();
        let (x, y, z) = (&x[..n], &y[..n], &z[..n]);
        let mut cell = [0u32; FILL_BLOCK];
        let last = (CELLS + 1) as f32;
        for lo in (0..n).step_by(FILL_BLOCK) {
            let hi = (lo + FILL_BLOCK).min(n);
            let cell = &mut cell[..hi - lo];
            let (bx, by, bz) = (&x[lo..hi], &y[lo..hi], &z[lo..hi]);
            // Vectorisable: slope, then cell index; extreme coordinates (where
            // the f32 squares could overflow or lose all precision) go exact.
            for (k, c) in cell.iter_mut().enumerate() {
                let (px, py, pz) = (bx[k], by[k], bz[k]);
                let h2 = px * px + py * py;
                let t = pz / h2.sqrt();
                let f = ((t - self.t_lo) * self.inv_w + 1.0).clamp(0.0, last);
                let fast = (1e-30..=1e30).contains(&h2) & (pz.abs() <= 1e15);
                // `f` is in [0, CELLS + 1], so the i32 cast (which vectorises) is exact.
                *c = if fast {
                    f as i32 as u32
                } else {
                    (CELLS + 2) as u32
                };
            }
            for (k, (o, &c)) in out[lo..hi].iter_mut().zip(cell.iter()).enumerate() {
                let r = self.table[c as usize];
                *o = if r == EXACT {
                    self.ring(bx[k], by[k], bz[k])
                } else {
                    r as u16
                };
            }
        }
    }
}

/// Builds the slope table of [`RingLookup`]: returns the table, the slope at
/// the lower edge of cell 1 and the cells per unit slope.
///
/// A cell (and the two end entries) gets a ring id only when every slope it
/// can be reached with lies on one side of every threshold with a margin of
/// half a cell plus [`REL_MARGIN`] of the threshold: far beyond the `f32`
/// rounding of the slope and of the cell index.
fn slope_table(slopes: &[f64], ring_of: &[u16]) -> (Vec<u32>, f32, f32) {
    let mut table = vec![EXACT; CELLS + 3];
    if slopes.is_empty() {
        // One ring: every point is on it (the origin too).
        table.fill(u32::from(ring_of[0]));
        return (table, 0.0, 1.0);
    }
    let q = slopes;
    let (qmin, qmax) = (q[0], q[q.len() - 1]);
    // Pad the range so the end entries are far from every threshold.
    let pad = 0.05 * (qmax - qmin) + 1e-3 + f64::from(REL_MARGIN) * qmin.abs().max(qmax.abs());
    let t_lo = (qmin - pad) as f32;
    let t_hi = (qmax + pad) as f32;
    let w = (f64::from(t_hi) - f64::from(t_lo)) / CELLS as f64;
    let inv_w = (1.0 / w) as f32;
    // Ring of a slope interval, if no threshold (with its margin) touches it.
    let ring_in = |a: f64, b: f64| -> u32 {
        let mut pos = 0usize;
        for &s in q {
            let m = 0.5 * w + f64::from(REL_MARGIN) * s.abs();
            if s + m < a {
                pos += 1;
            } else if s - m <= b {
                return EXACT;
            }
        }
        u32::from(ring_of[pos])
    };
    let (lo, hi) = (f64::from(t_lo), f64::from(t_hi));
    table[0] = ring_in(f64::NEG_INFINITY, lo);
    for c in 0..CELLS {
        table[c + 1] = ring_in(lo + c as f64 * w, lo + (c + 1) as f64 * w);
    }
    table[CELLS + 1] = ring_in(hi, f64::INFINITY);
    (table, t_lo, inv_w)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Elevation of a point in radians, as `PointCloud::elevation_deg` computes it.
    fn elevation(x: f32, y: f32, z: f32) -> f32 {
        z.atan2((x * x + y * y).sqrt())
    }

    fn agrees_with_nearest_ring(spec: &LidarSpec) {
        let lookup = RingLookup::new(spec);
        let mut mids: Vec<f64> = spec.elevation_deg.clone();
        mids.sort_by(f64::total_cmp);
        let mids: Vec<f64> = mids.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect();
        // A deterministic sweep of elevations and azimuths, finer than the rings.
        for i in 0..20_000 {
            let el = -89.0 + 178.0 * (i as f64) / 20_000.0;
            let az = (i as f64) * 0.731;
            let r = 1.0 + (i % 97) as f64;
            let (x, y, z) = (
                (r * el.to_radians().cos() * az.cos()) as f32,
                (r * el.to_radians().cos() * az.sin()) as f32,
                (r * el.to_radians().sin()) as f32,
            );
            let want = spec.nearest_ring(elevation(x, y, z));
            let got = lookup.ring(x, y, z);
            if got != want {
                // Only a point within rounding of a midpoint may disagree.
                let e = f64::from(elevation(x, y, z).to_degrees());
                let near = mids.iter().any(|m| (m - e).abs() < 1e-4);
                assert!(near, "elevation {e}: lookup {got}, nearest_ring {want}");
            }
        }
    }

    /// A 128-ring sensor with unsorted ids, uneven spacing and one duplicate
    /// elevation (past the linear-scan limit, so lookups binary-search).
    fn irregular_128_rings() -> LidarSpec {
        let mut spec = LidarSpec::vlp16();
        spec.elevation_deg = (0..128)
            .map(|i| {
                let k = (i * 37) % 128;
                -25.0 + 40.0 * (k as f64 / 127.0).powf(1.3)
            })
            .collect();
        spec.elevation_deg[5] = spec.elevation_deg[6];
        spec
    }

    #[test]
    fn lookup_matches_nearest_ring_on_vlp16() {
        agrees_with_nearest_ring(&LidarSpec::vlp16());
    }

    #[test]
    fn lookup_matches_nearest_ring_on_a_128_ring_sensor_with_binary_search() {
        let spec = irregular_128_rings();
        assert!(spec.elevation_deg.len() - 1 > LINEAR_MAX);
        agrees_with_nearest_ring(&spec);
    }

    /// xorshift64* in [0, 1).
    fn uniform(s: &mut u64) -> f64 {
        *s ^= *s >> 12;
        *s ^= *s << 25;
        *s ^= *s >> 27;
        (s.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// `f32` `k` ulps away from `v` (towards +∞ for k > 0).
    fn ulps(v: f32, k: i32) -> f32 {
        let mut v = v;
        for _ in 0..k.abs() {
            v = if k > 0 { v.next_up() } else { v.next_down() };
        }
        v
    }

    /// Points on, and a few ulps either side of, every threshold, at many
    /// ranges and azimuths; random points over every elevation; the origin,
    /// the axes, tiny, huge and non-finite coordinates.
    /// Returns the columns and where the random points start and end.
    #[allow(clippy::type_complexity)]
    fn hard_points(lookup: &RingLookup) -> (Vec<f32>, Vec<f32>, Vec<f32>, std::ops::Range<usize>) {
        let (mut x, mut y, mut z) = (Vec::new(), Vec::new(), Vec::new());
        let mut s = 0x1234_5678_9ABC_DEF1u64;
        for &slope in &lookup.slopes {
            for _ in 0..400 {
                let az = uniform(&mut s) * std::f64::consts::TAU;
                let h = 10f64.powf(-3.0 + 6.0 * uniform(&mut s));
                let (px, py) = ((h * az.cos()) as f32, (h * az.sin()) as f32);
                let hh = (f64::from(px).powi(2) + f64::from(py).powi(2)).sqrt();
                let pz = (slope * hh) as f32;
                for k in -6..=6 {
                    x.push(px);
                    y.push(py);
                    z.push(ulps(pz, k));
                }
            }
        }
        let random_start = x.len();
        for _ in 0..300_000 {
            let el = (uniform(&mut s) - 0.5) * std::f64::consts::PI;
            let az = uniform(&mut s) * std::f64::consts::TAU;
            let r = 10f64.powf(-2.0 + 5.0 * uniform(&mut s));
            x.push((r * el.cos() * az.cos()) as f32);
            y.push((r * el.cos() * az.sin()) as f32);
            z.push((r * el.sin()) as f32);
        }
        let odd = [
            (0.0, 0.0, 0.0),
            (0.0, 0.0, 1.0),
            (0.0, 0.0, -1.0),
            (1.0, 0.0, 0.0),
            (-0.0, 0.0, -0.0),
            (1e-20, 0.0, 1e-20),
            (1e-20, 1e-20, -1e-21),
            (1e20, 0.0, 1e18),
            (3e38, 3e38, 1.0),
            (1.0, 1.0, 1e30),
            (f32::NAN, 1.0, 1.0),
            (1.0, 1.0, f32::NAN),
            (f32::INFINITY, 0.0, 1.0),
            (1.0, 0.0, f32::NEG_INFINITY),
            (f32::MIN_POSITIVE, 0.0, f32::MIN_POSITIVE),
        ];
        let random = random_start..x.len();
        for (px, py, pz) in odd {
            x.push(px);
            y.push(py);
            z.push(pz);
        }
        (x, y, z, random)
    }

    fn fill_equals_ring(spec: &LidarSpec) {
        let lookup = RingLookup::new(spec);
        let (x, y, z, random) = hard_points(&lookup);
        let mut got = vec![u16::MAX; x.len()];
        lookup.fill(&mut got, &x, &y, &z);
        let (mut exact_path, mut exact_random) = (0usize, 0usize);
        for i in 0..x.len() {
            let want = lookup.ring(x[i], y[i], z[i]);
            assert_eq!(got[i], want, "point {i}: ({}, {}, {})", x[i], y[i], z[i]);
            let h2 = x[i] * x[i] + y[i] * y[i];
            let t = z[i] / h2.sqrt();
            let f = ((t - lookup.t_lo) * lookup.inv_w + 1.0).clamp(0.0, (CELLS + 1) as f32);
            let exact = !(f >= 0.0) || lookup.table[f as usize] == EXACT;
            exact_path += usize::from(exact);
            exact_random += usize::from(exact && random.contains(&i));
        }
        // The sweep must exercise both paths: the threshold points the exact
        // one, nearly all random points the table.
        assert!(exact_path >= lookup.slopes.len() * 400, "{exact_path}");
        assert!(
            exact_random < random.len() / 20,
            "{exact_random} of {random:?}"
        );
    }

    #[test]
    fn fill_equals_ring_on_vlp16() {
        fill_equals_ring(&LidarSpec::vlp16());
    }

    #[test]
    fn fill_equals_ring_on_a_128_ring_sensor_and_a_one_ring_sensor() {
        let mut spec = irregular_128_rings();
        fill_equals_ring(&spec);
        // Wide-angle sensor: thresholds up to ±80°.
        spec.elevation_deg = (0..32).map(|i| -85.0 + 170.0 * i as f64 / 31.0).collect();
        fill_equals_ring(&spec);
        spec.elevation_deg = vec![2.0];
        let lookup = RingLookup::new(&spec);
        let mut out = vec![9u16; 3];
        lookup.fill(&mut out, &[1.0, 0.0, f32::NAN], &[0.0; 3], &[5.0, 0.0, 1.0]);
        assert_eq!(out, vec![0, 0, 0]);
    }

    #[test]
    fn ties_and_origin_follow_nearest_ring() {
        let spec = LidarSpec::vlp16();
        let lookup = RingLookup::new(&spec);
        // Exactly on the horizon: 1° (id 1) and -1° (id 14) tie; id 1 wins.
        assert_eq!(lookup.ring(10.0, 0.0, 0.0), 1);
        assert_eq!(spec.nearest_ring(0.0), 1);
        assert_eq!(lookup.ring(0.0, 0.0, 0.0), 1);
        // Straight up and straight down: the extreme rings.
        assert_eq!(lookup.ring(0.0, 0.0, 5.0), 15);
        assert_eq!(lookup.ring(0.0, 0.0, -5.0), 0);
    }
}
