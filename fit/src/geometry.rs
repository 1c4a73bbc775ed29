//! Measured sensor geometry: each ring's firing step, phase and elevation,
//! read from the clear recordings themselves.
//!
//! `campaign.toml` declares an azimuth resolution and ring elevations, but
//! a unit may fire at another step than its datasheet says (a VLP-16 at
//! 20 Hz fires every 0.4°, not 0.2°), each ring fires at its own azimuth
//! offset, and a phase-locked sensor fires at the same azimuths every
//! revolution. Pairing cells must hold one firing per revolution and be
//! *centred* on the firings: a grid whose bin edges fall on the firings
//! splits each direction between two cells at random (jitter), and halves
//! the clear no-change rate.
//!
//! Per ring, from up to [`MAX_RECORDINGS`] clear recordings (campaign order):
//!
//! - **step**: the mode of the azimuth differences between consecutive returns
//!   of the ring (file order, which is firing order for every sensor format;
//!   and, when that gives no clear mode, sorted order within a scan), by
//!   [`murk_types::firing::mode_step`] (the estimator murk-infer measures
//!   each scan's firings with); missing returns only add multiples of the
//!   step, which the mode ignores. The number of cells per
//!   revolution is `round(360 / step)` and the cell width `360 / cells`.
//! - **phase**: the circular mean of `azimuth mod width`; its resultant length
//!   says whether the sensor is phase-locked (≈ 1) or free-running (≈ 0; any
//!   phase is then as good, and pairing relies on the azimuth neighbours).
//! - **elevation**: the median of `atan2(z, √(x² + y²))` of the ring's returns.
//!
//! A ring with fewer than [`MIN_DIFFS`] usable differences takes the median
//! step of the measured rings. Disagreements with `campaign.toml` beyond
//! [`STEP_TOLERANCE`] (relative) or [`ELEVATION_TOLERANCE_DEG`] are warned with
//! both values; the fit pairs on the measured grid (the readings are the
//! evidence) unless asked to use the declared one.

pub use murk_types::firing::{MIN_DIFFS, azimuth_deg};
use murk_types::firing::{MIN_STEP_DEG, circ_diff, median, mode_step};
use murk_types::{
    LidarSpec, NEAR_POINT_M, PointCloud, RingGeometry, SensorGeometry, near_point_share,
};

/// Clear recordings the geometry is measured from (the first, in campaign
/// order).
pub const MAX_RECORDINGS: usize = 8;
/// Scans read per recording at most (revolutions of a `.pcap`).
pub const MAX_FRAMES_PER_RECORDING: usize = 20;
/// Relative disagreement of the azimuth step that is warned.
pub const STEP_TOLERANCE: f64 = 0.02;
/// Disagreement of a ring elevation that is warned, degrees.
pub const ELEVATION_TOLERANCE_DEG: f64 = 0.5;
/// Samples kept per ring and kind (differences, azimuths, elevations).
const MAX_SAMPLES: usize = 200_000;

#[derive(Debug, Clone, Default)]
struct RingSamples {
    file_diffs: Vec<f32>,
    sorted_diffs: Vec<f32>,
    azimuths: Vec<f32>,
    elevations: Vec<f32>,
    returns: u64,
}

fn push_capped(v: &mut Vec<f32>, x: f32) {
    if v.len() < MAX_SAMPLES {
        v.push(x);
    }
}

/// Accumulates the scans a geometry is measured from.
#[derive(Debug, Clone, Default)]
pub struct GeometryAcc {
    rings: Vec<RingSamples>,
    frames: u32,
    recordings: u32,
    /// Points added, and those nearer than [`NEAR_POINT_M`].
    points: u64,
    near_points: u64,
}

impl GeometryAcc {
    /// An empty accumulator.
    pub fn new() -> Self {
        GeometryAcc::default()
    }

    /// Counts one more recording (its scans follow with [`Self::add_frame`]).
    pub fn start_recording(&mut self) {
        self.recordings += 1;
    }

    /// Appends `other`'s samples after this one's (call in a fixed order:
    /// samples beyond the cap are dropped).
    pub fn merge(&mut self, other: GeometryAcc) {
        if other.rings.len() > self.rings.len() {
            self.rings
                .resize_with(other.rings.len(), RingSamples::default);
        }
        for (a, b) in self.rings.iter_mut().zip(other.rings) {
            for (x, y) in [
                (&mut a.file_diffs, b.file_diffs),
                (&mut a.sorted_diffs, b.sorted_diffs),
                (&mut a.azimuths, b.azimuths),
                (&mut a.elevations, b.elevations),
            ] {
                let room = MAX_SAMPLES.saturating_sub(x.len());
                x.extend(y.into_iter().take(room));
            }
            a.returns += b.returns;
        }
        self.frames += other.frames;
        self.recordings += other.recordings;
        self.points += other.points;
        self.near_points += other.near_points;
    }

    /// Adds one scan (a revolution of a `.pcap`, or a whole file).
    pub fn add_frame(&mut self, cloud: &PointCloud) {
        self.frames += 1;
        let n = cloud.len();
        self.points += n as u64;
        self.near_points += (0..n)
            .filter(|&i| cloud.range(i) < NEAR_POINT_M as f32)
            .count() as u64;
        let mut last: Vec<Option<f64>> = Vec::new();
        let mut per_ring: Vec<Vec<f32>> = Vec::new();
        for i in 0..n {
            let (x, y, z) = (cloud.x[i], cloud.y[i], cloud.z[i]);
            if !(x.is_finite() && y.is_finite() && z.is_finite()) || (x == 0.0 && y == 0.0) {
                continue;
            }
            let r = cloud.ring[i] as usize;
            if r >= self.rings.len() {
                self.rings.resize_with(r + 1, RingSamples::default);
            }
            if r >= last.len() {
                last.resize(r + 1, None);
                per_ring.resize_with(r + 1, Vec::new);
            }
            let az = azimuth_deg(x, y);
            let s = &mut self.rings[r];
            s.returns += 1;
            if let Some(prev) = last[r] {
                let d = circ_diff(az, prev);
                if d >= MIN_STEP_DEG {
                    push_capped(&mut s.file_diffs, d as f32);
                }
            }
            last[r] = Some(az);
            per_ring[r].push(az as f32);
            push_capped(&mut s.azimuths, az as f32);
            let el = (z as f64).atan2((x as f64).hypot(y as f64)).to_degrees();
            push_capped(&mut s.elevations, el as f32);
        }
        for (r, mut az) in per_ring.into_iter().enumerate() {
            if az.len() < 2 {
                continue;
            }
            az.sort_by(f32::total_cmp);
            let s = &mut self.rings[r];
            for w in az.windows(2) {
                let d = (w[1] - w[0]) as f64;
                if d >= MIN_STEP_DEG {
                    push_capped(&mut s.sorted_diffs, d as f32);
                }
            }
            let wrap = az[0] as f64 + 360.0 - *az.last().unwrap_or(&0.0) as f64;
            if wrap >= MIN_STEP_DEG {
                push_capped(&mut s.sorted_diffs, wrap as f32);
            }
        }
    }

    /// The geometry, compared with what `declared` says.
    pub fn finish(&self, declared: &LidarSpec) -> SensorGeometry {
        // Rings beyond the declared ones are an input error the reading
        // reports with the file and point; the grid has the declared rings.
        let n_rings = declared.rings();
        let mut rings: Vec<RingGeometry> = Vec::with_capacity(n_rings);
        let mut steps = Vec::new();
        for r in 0..n_rings {
            let s = self.rings.get(r);
            let step = s.and_then(|s| {
                let a = mode_step(&s.file_diffs);
                let b = mode_step(&s.sorted_diffs);
                match (a, b) {
                    (Some(a), Some(b)) => Some(if a.1 >= b.1 { a } else { b }),
                    (a, b) => a.or(b),
                }
            });
            if let Some((st, _)) = step {
                steps.push(st);
            }
            rings.push(RingGeometry {
                ring: r as u16,
                azimuth_step_deg: step.map_or(f64::NAN, |s| s.0),
                azimuth_phase_deg: 0.0,
                phase_locking: 0.0,
                elevation_deg: s
                    .filter(|s| !s.elevations.is_empty())
                    .map(|s| median(&s.elevations)),
                declared_elevation_deg: declared.elevation_deg.get(r).copied(),
                returns: s.map_or(0, |s| s.returns),
                measured: step.is_some(),
            });
        }
        let source = if steps.is_empty() {
            "declared"
        } else {
            "measured"
        };
        steps.sort_by(f64::total_cmp);
        let fallback = if steps.is_empty() {
            declared.azimuth_resolution_deg
        } else {
            steps[(steps.len() - 1) / 2]
        };
        for (r, g) in rings.iter_mut().enumerate() {
            let raw = if g.measured {
                g.azimuth_step_deg
            } else {
                fallback
            };
            let bins = (360.0 / raw).round().max(1.0);
            let width = 360.0 / bins;
            g.azimuth_step_deg = width;
            if let Some(s) = self.rings.get(r).filter(|s| !s.azimuths.is_empty()) {
                let (phase, locking) = circular_phase(&s.azimuths, width);
                g.azimuth_phase_deg = phase;
                g.phase_locking = locking;
            }
        }
        let mut med: Vec<f64> = rings
            .iter()
            .filter(|g| g.measured)
            .map(|g| g.azimuth_step_deg)
            .collect();
        med.sort_by(f64::total_cmp);
        SensorGeometry {
            source: source.to_string(),
            recordings: self.recordings,
            frames: self.frames,
            azimuth_step_deg: med
                .get(med.len().saturating_sub(1) / 2)
                .copied()
                .unwrap_or_else(|| 360.0 / (360.0 / fallback).round().max(1.0)),
            declared_azimuth_step_deg: declared.azimuth_resolution_deg,
            rings,
        }
    }
}

/// Circular mean of `azimuths mod width` (degrees, in `[0, width)`) and its
/// resultant length.
fn circular_phase(azimuths: &[f32], width: f64) -> (f64, f64) {
    let (mut s, mut c) = (0.0f64, 0.0f64);
    for &a in azimuths {
        let t = (a as f64).rem_euclid(width) / width * std::f64::consts::TAU;
        s += t.sin();
        c += t.cos();
    }
    let n = azimuths.len().max(1) as f64;
    let locking = (s * s + c * c).sqrt() / n;
    let mut phase = s.atan2(c) / std::f64::consts::TAU * width;
    if phase < 0.0 {
        phase += width;
    }
    if phase >= width {
        phase -= width;
    }
    (phase, locking.min(1.0))
}

/// What the measured `geometry` contradicts in `declared`, each with both
/// values (empty when they agree).
pub fn warnings(geometry: &SensorGeometry, declared: &LidarSpec) -> Vec<String> {
    let mut out = Vec::new();
    if geometry.source != "measured" {
        out.push(format!(
            "the clear recordings give no ring enough consecutive returns to measure the firing step: pairing uses the declared azimuth_resolution_deg = {}",
            declared.azimuth_resolution_deg
        ));
        return out;
    }
    let d = declared.azimuth_resolution_deg;
    let off: Vec<&RingGeometry> = geometry
        .rings
        .iter()
        .filter(|g| g.measured && ((g.azimuth_step_deg - d) / d).abs() > STEP_TOLERANCE)
        .collect();
    let measured = geometry.rings.iter().filter(|g| g.measured).count();
    if !off.is_empty() {
        let mut s: Vec<f64> = off.iter().map(|g| g.azimuth_step_deg).collect();
        s.sort_by(f64::total_cmp);
        let range = if s[s.len() - 1] - s[0] > 1e-3 {
            format!("{:.4}–{:.4}°", s[0], s[s.len() - 1])
        } else {
            format!("{:.4}°", s[0])
        };
        out.push(format!(
            "azimuth step: campaign.toml declares azimuth_resolution_deg = {d}, but the clear recordings fire every {range} ({} of {measured} measured rings); pairing uses the measured step",
            off.len()
        ));
    }
    let used = geometry.rings.iter().filter(|g| g.returns > 0).count();
    let last_used = geometry
        .rings
        .iter()
        .rposition(|g| g.returns > 0)
        .map_or(0, |r| r + 1);
    if declared.rings() > 2 * last_used.max(1) && used > 0 {
        out.push(format!(
            "rings: campaign.toml declares {} ring elevations, but the clear recordings use only rings 0–{} ({used} rings)",
            declared.rings(),
            last_used.saturating_sub(1)
        ));
    }
    let bad: Vec<String> = geometry
        .rings
        .iter()
        .filter_map(|g| {
            let (m, e) = (
                g.elevation_deg?,
                *declared.elevation_deg.get(g.ring as usize)?,
            );
            ((m - e).abs() > ELEVATION_TOLERANCE_DEG && g.returns >= MIN_DIFFS as u64)
                .then(|| format!("ring {} declared {e}°, measured {m:.2}°", g.ring))
        })
        .collect();
    if !bad.is_empty() {
        let shown: Vec<&str> = bad.iter().take(6).map(String::as_str).collect();
        out.push(format!(
            "ring elevations: {} of {} rings differ from campaign.toml by more than {ELEVATION_TOLERANCE_DEG}° ({}{})",
            bad.len(),
            geometry.rings.len(),
            shown.join("; "),
            if bad.len() > shown.len() { "; …" } else { "" }
        ));
    }
    out
}

impl GeometryAcc {
    /// The warning that the measured scans hold points no scene return
    /// could give (at least [`murk_types::NEAR_POINT_SHARE`] of them within
    /// [`NEAR_POINT_M`]) while `declared` has no `min_range_m`: left in,
    /// each such point's cell reads as "lost" whenever the weather puts a
    /// return of its own on that ray, which no vanishing edge explains.
    pub fn near_points_warning(&self, declared: &LidarSpec) -> Option<String> {
        if declared.min_range_m.is_some() {
            return None;
        }
        let share = near_point_share(self.near_points, self.points)?;
        Some(format!(
            "near points: {} of the {} points measured ({:.1} %) lie within {NEAR_POINT_M} m of the sensor — no scene return comes that close: they are firings without a return written as points (nuScenes, Ouster) or the vehicle itself; declare min_range_m under [lidar] in campaign.toml (nuScenes' tools use 1 m) so that murk leaves them out, or the weather's returns on those rays read as losses at the origin",
            self.near_points,
            self.points,
            share * 100.0
        ))
    }
}

/// The declared geometry of `spec` (cells centred on multiples of the
/// declared azimuth resolution), for fits told not to measure.
pub fn declared(spec: &LidarSpec) -> SensorGeometry {
    let bins = spec.azimuth_bins().max(1) as f64;
    let width = 360.0 / bins;
    SensorGeometry {
        source: "declared".into(),
        recordings: 0,
        frames: 0,
        azimuth_step_deg: width,
        declared_azimuth_step_deg: spec.azimuth_resolution_deg,
        rings: (0..spec.rings())
            .map(|r| RingGeometry {
                ring: r as u16,
                azimuth_step_deg: width,
                azimuth_phase_deg: 0.0,
                phase_locking: 0.0,
                elevation_deg: None,
                declared_elevation_deg: spec.elevation_deg.get(r).copied(),
                returns: 0,
                measured: false,
            })
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(step: f64, rings: usize) -> LidarSpec {
        let mut s = LidarSpec::vlp16();
        s.elevation_deg = (0..rings).map(|r| r as f64 * 2.0 - 15.0).collect();
        s.azimuth_resolution_deg = step;
        s
    }

    /// One revolution: ring `r` fires every `step` from `phase + r·0.01`,
    /// with a uniform azimuth jitter of ±`jitter`, dropping every 7th firing.
    fn scan(step: f64, phase: f64, jitter: f64, rings: usize, seed: u64) -> PointCloud {
        let mut c = PointCloud::default();
        let n = (360.0 / step).round() as usize;
        let mut x = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let mut u = || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        for k in 0..n {
            for r in 0..rings {
                let j = u();
                if (k + r) % 7 == 3 {
                    continue;
                }
                let az = (phase + r as f64 * 0.01 + k as f64 * step + jitter * (2.0 * j - 1.0))
                    .to_radians();
                let el = (r as f64 * 2.0 - 15.0).to_radians();
                let d = 10.0 + r as f64;
                c.push(
                    (d * el.cos() * az.cos()) as f32,
                    (d * el.cos() * az.sin()) as f32,
                    (d * el.sin()) as f32,
                    10.0,
                    r as u16,
                );
            }
        }
        c
    }

    #[test]
    fn measures_step_phase_and_elevation() {
        let mut acc = GeometryAcc::new();
        acc.start_recording();
        for s in 0..3 {
            acc.add_frame(&scan(0.4, 0.13, 0.0, 4, s));
        }
        let g = acc.finish(&spec(0.2, 4));
        assert_eq!(g.source, "measured");
        for (r, ring) in g.rings.iter().enumerate() {
            assert!((ring.azimuth_step_deg - 0.4).abs() < 1e-9, "{ring:?}");
            let want = 0.13 + r as f64 * 0.01;
            assert!((ring.azimuth_phase_deg - want).abs() < 1e-3, "{ring:?}");
            assert!(ring.phase_locking > 0.99);
            let e = ring.elevation_deg.unwrap();
            assert!((e - (r as f64 * 2.0 - 15.0)).abs() < 1e-3, "{e}");
        }
        let w = warnings(&g, &spec(0.2, 4));
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].contains("azimuth_resolution_deg = 0.2") && w[0].contains("0.4000°"),
            "{}",
            w[0]
        );
        assert!(warnings(&g, &spec(0.4, 4)).is_empty());
    }

    #[test]
    fn free_running_jittered_firings_give_the_step() {
        let mut acc = GeometryAcc::new();
        acc.start_recording();
        for s in 0..5 {
            // Each revolution starts at another phase (free-running).
            acc.add_frame(&scan(0.2, 0.037 * s as f64, 0.02, 3, s));
        }
        let g = acc.finish(&spec(0.2, 3));
        for ring in &g.rings {
            assert!((ring.azimuth_step_deg - 0.2).abs() < 1e-9, "{ring:?}");
        }
        assert!(warnings(&g, &spec(0.2, 3)).is_empty());
    }

    #[test]
    fn shuffled_points_fall_back_to_sorted_order() {
        let c = scan(1.0, 0.5, 0.0, 2, 1);
        // A pseudo-random permutation (Fisher–Yates on a fixed LCG).
        let n = c.len();
        let mut idx: Vec<usize> = (0..n).collect();
        let mut x = 12345u64;
        for k in (1..n).rev() {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            idx.swap(k, ((x >> 33) as usize) % (k + 1));
        }
        let mut d = PointCloud::default();
        for &i in &idx {
            d.push(c.x[i], c.y[i], c.z[i], c.intensity[i], c.ring[i]);
        }
        let mut acc = GeometryAcc::new();
        acc.add_frame(&d);
        let g = acc.finish(&spec(1.0, 2));
        assert!((g.rings[0].azimuth_step_deg - 1.0).abs() < 1e-9, "{g:?}");
    }

    #[test]
    fn a_ring_without_returns_takes_the_others_step() {
        let mut acc = GeometryAcc::new();
        acc.add_frame(&scan(0.5, 0.0, 0.0, 2, 1));
        let g = acc.finish(&spec(0.5, 4));
        assert!(g.rings[0].measured && !g.rings[3].measured);
        assert!((g.rings[3].azimuth_step_deg - 0.5).abs() < 1e-9);
        assert_eq!(g.rings[3].elevation_deg, None);
    }

    #[test]
    fn elevation_and_ring_count_disagreements_are_warned() {
        let mut acc = GeometryAcc::new();
        acc.add_frame(&scan(0.5, 0.0, 0.0, 2, 1));
        let g = acc.finish(&spec(0.5, 2));
        let mut s = spec(0.5, 2);
        s.elevation_deg[1] = -10.0; // measured -13
        let w = warnings(&g, &s);
        assert!(
            w.iter()
                .any(|w| w.contains("ring 1 declared -10°, measured -13.00°")),
            "{w:?}"
        );
        let g = acc.finish(&spec(0.5, 16));
        let w = warnings(&g, &spec(0.5, 16));
        assert!(
            w.iter()
                .any(|w| w.contains("declares 16 ring elevations") && w.contains("rings 0–1")),
            "{w:?}"
        );
    }
}
