//! Ring ids for formats that carry none, from each point's elevation.
//!
//! [`LidarSpec::nearest_ring`] computes an `atan2` and scans every ring per
//! call; at 100 M points/s that is the whole time budget. [`RingLookup`]
//! gives the same answer from precomputed thresholds: the ring elevations are
//! sorted, the midpoints between neighbours are turned into slopes
//! `tan(mid)`, and a point lies above a midpoint exactly when
//! `z > tan(mid) · hypot(x, y)`. Ties (a point exactly on a midpoint) go to
//! the lower ring id, as in `nearest_ring`. Only points within float
//! rounding of a midpoint can get a different answer from `nearest_ring`.

use murk_types::LidarSpec;

/// Above this many thresholds a binary search beats a branch-free count.
const LINEAR_MAX: usize = 32;

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
        RingLookup {
            slopes,
            tie_up,
            ring_of: rings.iter().map(|r| r.1).collect(),
            at_origin: spec.nearest_ring(0.0),
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
        out.extend(
            x.iter()
                .zip(y)
                .zip(z)
                .map(|((&x, &y), &z)| self.ring(x, y, z)),
        );
    }
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

    #[test]
    fn lookup_matches_nearest_ring_on_vlp16() {
        agrees_with_nearest_ring(&LidarSpec::vlp16());
    }

    #[test]
    fn lookup_matches_nearest_ring_on_a_128_ring_sensor_with_binary_search() {
        let mut spec = LidarSpec::vlp16();
        // Unsorted ids, uneven spacing, one duplicate elevation.
        spec.elevation_deg = (0..128)
            .map(|i| {
                let k = (i * 37) % 128;
                -25.0 + 40.0 * (k as f64 / 127.0).powf(1.3)
            })
            .collect();
        spec.elevation_deg[5] = spec.elevation_deg[6];
        assert!(spec.elevation_deg.len() - 1 > LINEAR_MAX);
        agrees_with_nearest_ring(&spec);
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
