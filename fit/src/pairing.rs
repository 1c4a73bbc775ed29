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
//!
//! So a weather return is only counted as one where it is neither behind
//! a nearer return of its ray (the *occluders*) nor at the distance of a
//! clear return of its cell or a neighbour (the *masked* stretches, from
//! the reference's envelopes and pairing windows). The count and distance
//! laws are fitted through both: a real scene with targets a metre or two
//! from the sensor masks a large share of the ring returns (on the real
//! VLP-16 capture, counts came out 0.71 of the truth without the mask).

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

/// Per cell of a reference, its [`ClearReference::scene_span`] when it
/// starts nearer than the noise windows' far end (NaN otherwise): what
/// [`masked_stretches`] reads, computed once per reference.
#[derive(Debug, Clone)]
pub(crate) struct SceneSpans {
    spans: Vec<[f32; 2]>,
    reach: f32,
    neighbours: i64,
}

impl SceneSpans {
    /// The spans of `reference`'s cells under `params`.
    pub(crate) fn new(reference: &ClearReference, params: &FitValidParams) -> SceneSpans {
        let reach = params.noise_reach_m() as f32;
        SceneSpans {
            spans: (0..reference.grid().cells())
                .map(|c| {
                    reference
                        .scene_span(c, params)
                        .filter(|s| s[0] < reach)
                        .unwrap_or([f32::NAN; 2])
                })
                .collect(),
            reach,
            neighbours: params.azimuth_neighbours() as i64,
        }
    }
}

/// Stretches `[from, to)` of a recording's rays, nearer than the noise
/// windows' far end and than the ray's first return, where a weather return
/// would not be counted as one: it would pair with a clear return of its
/// cell or a neighbour's, or fall inside their clear envelope (*scene*). A
/// scene with targets near the sensor masks the weather's near returns in
/// front of them; the count and distance laws see the weather through what
/// is left. For every cell of the grid: the union of its own and its
/// azimuth neighbours' spans (the cells pairing offers a return to),
/// clipped to `[0, reach)` and cut at the cell's first return in `points`
/// (behind it the ray is hidden, which the occluders already count). One
/// entry per cell and stretch, for every scan of the recording alike (a
/// recording of several scans is cut at its nearest return per cell over
/// them all).
pub(crate) fn masked_stretches(
    reference: &ClearReference,
    spans: &SceneSpans,
    points: &[CellPoint],
) -> Vec<(f32, f32)> {
    let grid = reference.grid();
    let mut first = vec![f32::INFINITY; grid.cells()];
    for p in points {
        let f = &mut first[p.cell as usize];
        *f = f.min(p.range);
    }
    let k = spans.neighbours;
    let mut here: Vec<[f32; 2]> = Vec::with_capacity(2 * k as usize + 1);
    let mut out = Vec::new();
    for (cell, &f) in first.iter().enumerate() {
        let end = f.min(spans.reach);
        here.clear();
        for off in -k..=k {
            let [a, b] = spans.spans[grid.shifted(cell, off)];
            if a.is_finite() {
                let (a, b) = (a.max(0.0), b.min(end));
                if a < b {
                    here.push([a, b]);
                }
            }
        }
        if here.is_empty() {
            continue;
        }
        here.sort_by(|x, y| x[0].total_cmp(&y[0]).then(x[1].total_cmp(&y[1])));
        let mut cur = here[0];
        for s in &here[1..] {
            if s[0] <= cur[1] {
                cur[1] = cur[1].max(s[1]);
            } else {
                out.push((cur[0], cur[1]));
                cur = *s;
            }
        }
        out.push((cur[0], cur[1]));
    }
    out
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

    /// The masked stretches of each cell, by hand: its own and its two
    /// neighbours' envelopes widened by the pairing tolerance (0.5 m at
    /// these ranges) and their pairing windows (1 m either side of a stable
    /// cell here: the tolerance widened to twice on this coarse grid),
    /// clipped to the 10 m reach and cut at the cell's first return.
    #[test]
    fn masked_stretches_by_hand() {
        let r = reference();
        let p = FitParams::default().check().unwrap();
        assert_eq!(r.tolerance(0, &p), 1.0);
        assert_eq!(r.tolerance(3, &p), 1.0);
        let spans = SceneSpans::new(&r, &p);
        assert_eq!(
            masked_stretches(&r, &spans, &[pt(6, 7.0)]),
            vec![
                (9.0, 10.0), // cell 0 (10 m)
                (9.0, 10.0), // cell 1: neighbour 0
                (4.0, 6.0),  // cell 2: neighbour 3 (5 m)
                (4.0, 6.0),  // cell 3
                (3.5, 8.5),  // cell 4: cells 3 and 5 (4–8 m) joined
                (3.5, 8.5),  // cell 5
                (3.5, 7.0),  // cell 6: cut at its return at 7 m
                (9.0, 10.0), // cell 7: neighbour 0
            ]
        );
    }

    /// What the stretches say is what pairing does: a lone return at `d`
    /// in a cell is counted as a ring or ghost exactly where `d` is not
    /// in the cell's masked stretch (of a recording without returns),
    /// except within a millimetre of a stretch's end.
    #[test]
    fn masked_stretches_are_where_pairing_does_not_count_weather() {
        let r = reference();
        let p = FitParams::default().check().unwrap();
        let empty = masked_stretches(&r, &SceneSpans::new(&r, &p), &[]);
        let stretch = |cell: usize| empty[cell];
        for cell in 0..8u32 {
            for i in 0..200 {
                let d = 0.025 + 0.05 * i as f32;
                let (a, b) = stretch(cell as usize);
                if (d - a).abs() < 1e-3 || (d - b).abs() < 1e-3 {
                    continue;
                }
                let t = pair_recording(&r, &[pt(cell, d)], &p);
                let weather = t.rings.len() + t.ghosts.len() == 1;
                assert_eq!(weather, !(a..b).contains(&d), "cell {cell} at {d} m: {t:?}");
            }
        }
    }
}
