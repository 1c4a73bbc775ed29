//! Pairing a degraded recording with the clear reference, cell by cell.
//!
//! Every degraded return is first offered to its own cell: it pairs with the
//! clear return when its range is within the cell's tolerance
//! ([`ClearReference::tolerance`]: the pairing tolerance, widened where the
//! cell's range wanders between revolutions) and the cell
//! still has an unpaired clear return (a cell expects as many returns per
//! scan as the clear scans had, times the recording's scans: a `.pcap` of 600
//! revolutions expects 600 times what a file of one does). Returns left over are offered to
//! the neighbouring azimuth bins (firing azimuths jitter across bin edges
//! between revolutions). What pairs is *no change*; clear returns left
//! unpaired have *disappeared*. A degraded return that pairs nowhere is
//!
//! - *scene* when its range lies within the clear envelope of its cell (a
//!   direction that is empty or unstable in clear weather, not a weather
//!   effect),
//! - *ring* inside the ring window, *ghost* inside the ghost window,
//! - *far* otherwise (new objects, noise beyond the ghost window).

use crate::FitValidParams;
use crate::reference::{CellPoint, ClearReference};

/// What one degraded recording contributes.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RecordingTally {
    /// Paired (no change) returns per cell, at most the cell's expected hits
    /// times [`RecordingTally::frames`].
    pub matched: Vec<u32>,
    /// Scans of the recording (revolutions of a `.pcap`, 1 otherwise).
    pub frames: u32,
    /// `(range, reflectivity)` of the ghost returns.
    pub ghosts: Vec<(f32, f32)>,
    /// `(range, reflectivity)` of the ring returns.
    pub rings: Vec<(f32, f32)>,
    /// Unpaired returns inside a cell's clear envelope.
    pub scene: u64,
    /// Unpaired returns beyond the ghost window.
    pub far: u64,
    /// Returns in the recording.
    pub points: u64,
    /// Cells of the ghost and ring returns: their clear return, if any, was
    /// hidden behind a closer weather return, so its fate is unknown.
    pub occluded: Vec<u32>,
    /// Ranges of the returns that are not ghost or ring (paired, scene, far)
    /// closer than the ghost window's far end: what can hide a weather return
    /// placed behind it on the same ray.
    pub occluders: Vec<f32>,
}

impl RecordingTally {
    /// Paired returns in total.
    pub fn kept(&self) -> u64 {
        self.matched.iter().map(|&m| m as u64).sum()
    }
}

/// Pairs the returns of one degraded (or clear) single-scan recording with
/// `reference` (the tests' shorthand for [`pair_frames`] on one scan).
#[cfg(test)]
pub fn pair_recording(
    reference: &ClearReference,
    points: &[CellPoint],
    params: &FitValidParams,
) -> RecordingTally {
    pair(reference, points, 1, params, None)
}

/// Pairs the returns of a recording of `frames` scans (all its points, any
/// order) with `reference`: each cell expects `frames` times its hits per
/// scan.
pub fn pair_frames(
    reference: &ClearReference,
    points: &[CellPoint],
    frames: u32,
    params: &FitValidParams,
) -> RecordingTally {
    pair(reference, points, frames, params, None)
}

/// A paired (no change) return: the reference cell it paired with and its
/// index in the recording's points.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pair {
    /// Reference cell (its own cell or an azimuth neighbour).
    pub cell: u32,
    /// Index of the degraded return in the points given.
    pub point: u32,
}

/// [`pair_recording`], also listing every pair (for per-return residuals of
/// range and reflectivity).
#[cfg(test)]
pub fn pair_recording_detailed(
    reference: &ClearReference,
    points: &[CellPoint],
    params: &FitValidParams,
) -> (RecordingTally, Vec<Pair>) {
    pair_frames_detailed(reference, points, 1, params)
}

/// [`pair_frames`], also listing every pair.
pub fn pair_frames_detailed(
    reference: &ClearReference,
    points: &[CellPoint],
    frames: u32,
    params: &FitValidParams,
) -> (RecordingTally, Vec<Pair>) {
    let mut pairs = Vec::new();
    let t = pair(reference, points, frames, params, Some(&mut pairs));
    (t, pairs)
}

fn pair(
    reference: &ClearReference,
    points: &[CellPoint],
    frames: u32,
    params: &FitValidParams,
    mut pairs: Option<&mut Vec<Pair>>,
) -> RecordingTally {
    let grid = reference.grid();
    let frames = frames.max(1);
    let mut t = RecordingTally {
        matched: vec![0; grid.cells()],
        frames,
        points: points.len() as u64,
        ..Default::default()
    };
    let try_pair = |matched: &mut [u32], cell: usize, range: f32| -> bool {
        let h = reference.hits(cell) as u32 * frames;
        if h == 0 || matched[cell] >= h {
            return false;
        }
        let r0 = reference.range(cell);
        if (range - r0).abs() <= reference.tolerance(cell, params) {
            matched[cell] += 1;
            true
        } else {
            false
        }
    };
    let mut left = Vec::new();
    for (i, p) in points.iter().enumerate() {
        if try_pair(&mut t.matched, p.cell as usize, p.range) {
            if let Some(v) = pairs.as_deref_mut() {
                v.push(Pair {
                    cell: p.cell,
                    point: i as u32,
                });
            }
        } else {
            left.push(i);
        }
    }
    let k = params.azimuth_neighbours() as i64;
    let [rlo, rhi] = params.ring_range_m();
    let [glo, ghi] = params.ghost_range_m();
    'points: for i in left {
        let p = points[i];
        let cell = p.cell as usize;
        for d in 1..=k {
            for off in [-d, d] {
                let c = grid.shifted(cell, off);
                if try_pair(&mut t.matched, c, p.range) {
                    if let Some(v) = pairs.as_deref_mut() {
                        v.push(Pair {
                            cell: c as u32,
                            point: i as u32,
                        });
                    }
                    continue 'points;
                }
            }
        }
        let tol = params.pairing_tolerance(p.range as f64) as f32;
        let in_scene =
            (-k..=k).any(|off| reference.in_envelope(grid.shifted(cell, off), p.range, tol));
        let r = p.range as f64;
        if in_scene {
            t.scene += 1;
        } else if r >= rlo && r < rhi {
            t.rings.push((p.range, p.reflectivity));
            t.occluded.push(p.cell);
        } else if r >= glo && r < ghi {
            t.ghosts.push((p.range, p.reflectivity));
            t.occluded.push(p.cell);
        } else {
            t.far += 1;
        }
    }
    // Every return seen nearer than the far end of the noise windows, noise
    // included: a weather return is hidden by whatever its ray shows first,
    // a ring or another ghost as much as a wall (at dense weather that
    // crowding hides ~10 % of the ghosts, which the count law must restore).
    let reach = params.noise_reach_m() as f32;
    t.occluders = points
        .iter()
        .filter(|p| p.range < reach)
        .map(|p| p.range)
        .collect();
    t
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::FitParams;
    use crate::reference::{CellGrid, CellImage};
    use murk_types::LidarSpec;

    fn reference() -> ClearReference {
        let mut spec = LidarSpec::vlp16();
        spec.elevation_deg = vec![0.0];
        spec.azimuth_resolution_deg = 45.0; // 8 cells
        let grid = CellGrid::new(&spec);
        let p = FitParams::default().check().unwrap();
        // Cells 0..4 at 10, 20, 30, 5 m; cell 5 unstable (4, 8, 6 m); 6, 7 empty.
        let a = CellImage {
            cells: vec![0, 1, 2, 3, 5],
            range: vec![10.0, 20.0, 30.0, 5.0, 4.0],
            reflectivity: vec![5.0, 15.0, 50.0, 2.0, 3.0],
            hits: vec![1; 5],
            frames: 1,
        };
        let mut b = a.clone();
        b.range[4] = 8.0;
        let mut c = a.clone();
        c.range[4] = 6.0;
        ClearReference::build(grid, &[a, b, c], &p)
    }

    fn pt(cell: u32, range: f32) -> CellPoint {
        CellPoint {
            cell,
            range,
            reflectivity: 1.0,
        }
    }

    #[test]
    fn classes_of_returns() {
        let r = reference();
        let p = FitParams::default().check().unwrap();
        let pts = [
            pt(0, 10.2), // pairs with cell 0
            pt(2, 19.9), // own cell 2 is at 30 m: pairs with neighbour cell 1
            pt(0, 10.1), // cell 0 already paired, neighbours differ: scene (envelope)
            pt(6, 1.5),  // ring
            pt(7, 6.0),  // ghost
            pt(6, 50.0), // far
            pt(5, 6.0),  // unstable cell 5: inside its 4–8 m envelope → scene
        ];
        let t = pair_recording(&r, &pts, &p);
        assert_eq!(&t.matched[..5], &[1, 1, 0, 0, 0]);
        assert_eq!(t.kept(), 2);
        assert_eq!(t.rings, vec![(1.5, 1.0)]);
        assert_eq!(t.ghosts, vec![(6.0, 1.0)]);
        assert_eq!((t.scene, t.far, t.points), (2, 1, 7));
        assert_eq!(t.occluded, vec![6, 7]);
        // Every return closer than 10 m, in input order: the ring, the ghost
        // and the scene one at 6 m in cell 5.
        assert_eq!(t.occluders, vec![1.5, 6.0, 6.0]);
        // The detailed pairing gives the same tally and names the pairs:
        // point 0 with its own cell, point 1 with neighbour cell 1.
        let (t2, pairs) = pair_recording_detailed(&r, &pts, &p);
        assert_eq!(t2, t);
        assert_eq!(
            pairs,
            vec![Pair { cell: 0, point: 0 }, Pair { cell: 1, point: 1 }]
        );
    }

    #[test]
    fn without_neighbours_a_shifted_return_is_not_paired() {
        let r = reference();
        let p = FitParams::default().azimuth_neighbours(0).check().unwrap();
        let t = pair_recording(&r, &[pt(2, 19.9)], &p);
        assert_eq!(t.kept(), 0);
        assert_eq!(t.far, 1);
    }
}
