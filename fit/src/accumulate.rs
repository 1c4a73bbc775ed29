//! Per-weather statistics accumulated over recordings.
//!
//! A [`WeatherAcc`] is all the driver keeps of a weather's recordings: per
//! MOR bin the *no change* count per reference cell, the survival histogram
//! over `ln(r/MOR)`, histograms of ghost and ring distance and reflectivity,
//! and one small row of scalars per recording. Its size depends on the grid,
//! the MOR bins and the histogram resolutions, never on the number of points.
//! Every count is an integer, so merging accumulators in any order gives the
//! same result; float summaries are computed afterwards from the rows sorted
//! by recording index.

use std::collections::BTreeMap;

use crate::FitValidParams;
use crate::pairing::{RecordingTally, SceneSpans};
use crate::reference::ClearReference;
use crate::stats::truncnorm::Histogram;
use crate::survival::{Partition, SurvivalHistogram};

/// Resolution of the distance histograms, metres.
pub const DISTANCE_STEP_M: f64 = 0.001;
/// Resolution of the reflectivity histograms.
pub const REFLECTIVITY_STEP: f64 = 0.05;
/// Span of the reflectivity histograms above the floor.
pub const REFLECTIVITY_SPAN: f64 = 1024.0;
/// Resolution of the occluder histograms, metres.
pub const OCCLUDER_STEP_M: f64 = 0.01;
/// Unit of the masked lengths ([`RecordingRow::masked`],
/// [`NoiseAcc::masked`]), metres: integer sums, so that merging in any
/// order gives the same bytes.
pub const MASK_UNIT_M: f64 = 1e-4;

/// Adds to `out[k]` the length of each stretch `[a, b)` that falls in step
/// `k` (of `step` metres), in [`MASK_UNIT_M`], times `weight`; what lies
/// beyond the last step is dropped.
fn add_stretches(out: &mut [u64], step: f64, stretches: &[(f32, f32)], weight: u64) {
    let n = out.len();
    if n == 0 || weight == 0 {
        return;
    }
    let units = |len: f64| (len / MASK_UNIT_M).round().max(0.0) as u64 * weight;
    // Whole steps through a difference array, the partial ends directly.
    let mut whole = vec![0i64; n + 1];
    for &(a, b) in stretches {
        let (a, b) = (a.max(0.0) as f64, (b as f64).min(n as f64 * step));
        if b <= a {
            continue;
        }
        let ka = ((a / step).floor() as usize).min(n - 1);
        let kb = ((b / step).floor() as usize).min(n);
        if ka == kb {
            out[ka] += units(b - a);
            continue;
        }
        out[ka] += units((ka + 1) as f64 * step - a);
        if ka + 1 < kb {
            whole[ka + 1] += 1;
            whole[kb] -= 1;
        }
        if kb < n {
            out[kb] += units(b - kb as f64 * step);
        }
    }
    let full = units(step);
    let mut c = 0i64;
    for (o, w) in out.iter_mut().zip(&whole) {
        c += w;
        *o += c.max(0) as u64 * full;
    }
}

/// Share of rays on which a weather return would be seen and counted, per
/// step of `step` metres: open (`1 − Σ occluders before the step / rays`)
/// and not masked (`masked[k]`, lengths in [`MASK_UNIT_M`], over the step).
fn visible_shares(
    occluders: impl Iterator<Item = u64>,
    masked: &[u64],
    step: f64,
    rays: f64,
) -> Vec<f64> {
    let per_ray = step / MASK_UNIT_M;
    let mut acc = 0u64;
    occluders
        .enumerate()
        .map(|(k, c)| {
            let m = masked.get(k).copied().unwrap_or(0) as f64 / per_ray;
            let v = 1.0 - (acc as f64 + m) / rays;
            acc += c;
            v.max(0.0)
        })
        .collect()
}

/// The scalars of one recording.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RecordingRow {
    /// Position in the fit's recording list (the merge order).
    pub index: usize,
    /// Recording id.
    pub id: String,
    /// MOR, metres.
    pub mor: f64,
    /// Rain rate, mm/h, when known.
    pub rain_rate: Option<f64>,
    /// *No change* returns.
    pub kept: u64,
    /// Expected clear returns (the reference's).
    pub total: u64,
    /// Ghost returns.
    pub ghosts: u64,
    /// Ring returns.
    pub rings: u64,
    /// Unpaired returns inside a clear envelope.
    pub scene: u64,
    /// Unpaired returns beyond the ghost window.
    pub far: u64,
    /// Returns in the file.
    pub points: u64,
    /// This recording's returns nearer than the noise windows' far end, per
    /// step of `ROW_OCCLUDER_STEP_M` (0.1 m): what could hide its own ghost and
    /// ring returns (their visibility varies with the weather's density).
    pub occluders: Vec<u32>,
    /// Length of this recording's rays masked by the near scene, per step
    /// of `ROW_OCCLUDER_STEP_M` (in `MASK_UNIT_M`, 0.1 mm): the stretches in front
    /// of each ray's first return where a weather return would pair or fall
    /// in a clear envelope (`pairing::masked_stretches`), each counted once
    /// per scan and revolution of the ray. Divided by the step, the rays
    /// masked there, on average over the step.
    pub masked: Vec<u64>,
    /// Rays of the recording (cells × revolutions of the reference).
    pub rays: u64,
    /// Scans of the recording (revolutions of a `.pcap`, 1 for other files).
    pub frames: u32,
    /// Revolutions of the recording: its scans times the reference's
    /// revolutions per scan. Near-range counts per revolution are
    /// `ghosts / revolutions`.
    pub revolutions: u64,
    /// This recording's share of the survival histogram, sparse:
    /// `(cell index of the histogram, kept, trials)` sorted by index. The
    /// pooled histogram is the sum over recordings; intervals and the
    /// held-out edge test resample or leave out whole recordings from it
    /// (returns of one recording share its MOR reading and sensor state).
    pub survival: Vec<(u32, u32, u32)>,
    /// Beside each entry of `survival`, the trials it would have kept
    /// without weather: `Σ trials × clear survival` over its cells (the
    /// reference's [`ClearReference::clear_survival`], 1 where unknown).
    /// The held-out edge test uses it so that both of its models know the
    /// scene's own flicker.
    pub survival_clear: Vec<f64>,
    /// `ln(MOR · range_scale)` the recording's trials were binned with.
    pub ln_mor_scaled: f64,
    /// Clear returns hidden behind a ghost or ring return (they left the
    /// trials of `survival`), sparse by histogram index like `survival`:
    /// `(index, hidden, hidden × clear survival)`. A fit that finds the
    /// weather's near returns *replace* lost ones (the occlusion test)
    /// counts them as lost.
    pub hidden: Vec<(u32, u32, f64)>,
    /// The cells at or beyond the far end of the noise windows (every ghost
    /// and ring return of their ray lies in front of them), by histogram
    /// index: `(index, hidden, expected)`. What the occlusion test compares.
    pub beyond_windows: Vec<(u32, u32, u32)>,
}

/// Resolution of the per-recording occluder histograms, metres.
pub const ROW_OCCLUDER_STEP_M: f64 = 0.1;

impl RecordingRow {
    /// Share of this recording's rays on which a weather return would be
    /// seen and counted as one, per step of `ROW_OCCLUDER_STEP_M` (0.1 m):
    /// open (no return nearer than the step's start) and not masked by the
    /// near scene (on average over the step).
    pub fn open_rays(&self) -> Vec<f64> {
        visible_shares(
            self.occluders.iter().map(|&c| c as u64),
            &self.masked,
            ROW_OCCLUDER_STEP_M,
            self.rays.max(1) as f64,
        )
    }
}

/// Sorts sparse histogram cells `(index, kept, trials, clear-expected
/// kept)` by index (stable: equal indices keep their cell order, so the
/// float sums are the same on every run) and sums duplicates.
#[allow(clippy::type_complexity)]
pub(crate) fn merge_cells(mut v: Vec<(u32, u32, u32, f64)>) -> (Vec<(u32, u32, u32)>, Vec<f64>) {
    v.sort_by_key(|c| c.0);
    let mut out: Vec<(u32, u32, u32)> = Vec::with_capacity(v.len());
    let mut clear: Vec<f64> = Vec::with_capacity(v.len());
    for c in v {
        match out.last_mut() {
            Some(l) if l.0 == c.0 => {
                l.1 += c.1;
                l.2 += c.2;
                *clear.last_mut().expect("same length") += c.3;
            }
            _ => {
                out.push((c.0, c.1, c.2));
                clear.push(c.3);
            }
        }
    }
    // Sized for every cell, filled with one entry per survival bin: a row is
    // kept per recording, so the cells' capacity would grow a fit's memory
    // by about a megabyte per recording of HDL-64 size.
    out.shrink_to_fit();
    clear.shrink_to_fit();
    (out, clear)
}

/// Ghost or ring returns: distance and reflectivity histograms, and what
/// could hide them.
///
/// A weather return placed on a ray is only seen when no other return of the
/// ray is closer (first-return sensors; the generator and appliers place
/// them that way). `occluders[k]` counts the returns (scene and noise) with range in
/// step `k` (of [`OCCLUDER_STEP_M`]), each recording weighted by its number
/// of ghost (or ring) returns; `exposure` is Σ weight × rays. The share of
/// rays open at distance `d` is then `1 − Σ_{k ≤ d} occluders / exposure`.
/// Of those, the ones whose stretch at `d` is masked by the near scene
/// (`masked`: a return there would be paired or called scene) do not show
/// a weather return as one either; what is left is the visibility by which
/// the distance law and the counts are seen.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NoiseAcc {
    /// Range histogram over the class window.
    pub distance: Histogram,
    /// Reflectivity histogram from the floor.
    pub reflectivity: Histogram,
    /// Weighted occluder counts from 0 m to the window's far end.
    pub occluders: Vec<u64>,
    /// Weighted masked lengths per occluder step, in `MASK_UNIT_M`
    /// ([`RecordingRow::masked`]).
    pub masked: Vec<u64>,
    /// Σ weight × rays per recording.
    pub exposure: u64,
}

impl NoiseAcc {
    fn new(window: [f64; 2], floor: f64) -> Self {
        let db = ((window[1] - window[0]) / DISTANCE_STEP_M).round().max(1.0) as usize;
        let rb = (REFLECTIVITY_SPAN / REFLECTIVITY_STEP).round() as usize;
        let ob = (window[1] / OCCLUDER_STEP_M).ceil().max(1.0) as usize;
        NoiseAcc {
            distance: Histogram::new(window[0], window[1], db),
            reflectivity: Histogram::new(floor, floor + REFLECTIVITY_SPAN, rb),
            occluders: vec![0; ob],
            masked: vec![0; ob],
            exposure: 0,
        }
    }

    fn add(
        &mut self,
        points: &[(f32, f32)],
        occluders: &[f32],
        masked: &[(f32, f32)],
        rays: u64,
        per_cell: u64,
    ) {
        for &(r, f) in points {
            self.distance.add(r as f64);
            self.reflectivity.add(f as f64);
        }
        let w = points.len() as u64;
        if w == 0 {
            return;
        }
        self.exposure += w * rays;
        let n = self.occluders.len();
        for &r in occluders {
            let k = (r as f64 / OCCLUDER_STEP_M).floor().max(0.0) as usize;
            if k < n {
                self.occluders[k] += w;
            }
        }
        add_stretches(&mut self.masked, OCCLUDER_STEP_M, masked, w * per_cell);
    }

    fn merge(&mut self, o: &NoiseAcc) {
        self.distance.merge(&o.distance);
        self.reflectivity.merge(&o.reflectivity);
        for (a, b) in self.occluders.iter_mut().zip(&o.occluders) {
            *a += b;
        }
        for (a, b) in self.masked.iter_mut().zip(&o.masked) {
            *a += b;
        }
        self.exposure += o.exposure;
    }

    /// Share of rays on which a weather return would be seen and counted,
    /// per occluder step: open (no closer return at the step's start) and
    /// not masked by the near scene (on average over the step); `None`
    /// without exposure.
    pub fn visibility(&self) -> Option<Vec<f64>> {
        if self.exposure == 0 {
            return None;
        }
        Some(visible_shares(
            self.occluders.iter().copied(),
            &self.masked,
            OCCLUDER_STEP_M,
            self.exposure as f64,
        ))
    }
}

/// Everything kept of one weather's recordings.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WeatherAcc {
    /// Per MOR bin index: recordings and *no change* count per cell.
    pub bins: BTreeMap<i64, (u32, Vec<u32>)>,
    /// Survival histogram.
    pub survival: SurvivalHistogram,
    /// Ghost returns.
    pub ghost: NoiseAcc,
    /// Ring returns.
    pub ring: NoiseAcc,
    /// One row per recording (any order until [`WeatherAcc::finish`]).
    pub rows: Vec<RecordingRow>,
}

/// What adding a recording needs from the reference, precomputed once.
#[derive(Debug, Clone)]
pub struct CellTable {
    cells: Vec<u32>,
    class: Vec<u16>,
    ln_r: Vec<f64>,
    hits: Vec<u16>,
    /// Clear survival of each cell (1 where unknown).
    clear: Vec<f64>,
    n_cells: usize,
    /// Rays per scan: cells × revolutions per scan (median expected hits).
    rays: u64,
    /// Revolutions per scan.
    revolutions: u64,
    /// Each cell's scene span, for the masked stretches.
    pub(crate) scene: SceneSpans,
}

impl CellTable {
    /// Class and `ln r` of every reference cell.
    pub fn new(reference: &ClearReference, partition: &Partition, params: &FitValidParams) -> Self {
        let cells = reference.present().to_vec();
        CellTable {
            class: cells
                .iter()
                .map(|&c| partition.class_of(reference.reflectivity(c as usize) as f64) as u16)
                .collect(),
            ln_r: cells
                .iter()
                .map(|&c| (reference.range(c as usize) as f64).ln())
                .collect(),
            hits: cells.iter().map(|&c| reference.hits(c as usize)).collect(),
            clear: cells
                .iter()
                .map(|&c| reference.clear_survival(c as usize).unwrap_or(1.0))
                .collect(),
            rays: reference.grid().cells() as u64 * reference.revolutions() as u64,
            revolutions: reference.revolutions() as u64,
            scene: SceneSpans::new(reference, params),
            cells,
            n_cells: reference.grid().cells(),
        }
    }
}

impl WeatherAcc {
    /// An empty accumulator.
    pub fn new(params: &FitValidParams, partition: &Partition) -> Self {
        WeatherAcc {
            bins: BTreeMap::new(),
            survival: SurvivalHistogram::new(partition.classes(), params.survival_log_step()),
            ghost: NoiseAcc::new(params.ghost_range_m(), params.reflectivity_floor()),
            ring: NoiseAcc::new(params.ring_range_m(), params.reflectivity_floor()),
            rows: Vec::new(),
        }
    }

    /// Adds one degraded recording of MOR `mor` (metres).
    #[allow(clippy::too_many_arguments)]
    pub fn add(
        &mut self,
        index: usize,
        id: &str,
        mor: f64,
        rain_rate: Option<f64>,
        tally: &RecordingTally,
        masked: &[(f32, f32)],
        cells: &CellTable,
        params: &FitValidParams,
        range_scale: f64,
    ) {
        let bin = (mor / params.mor_bin_width_m()).floor() as i64;
        let entry = self
            .bins
            .entry(bin)
            .or_insert_with(|| (0, vec![0; cells.n_cells]));
        entry.0 += 1;
        let ln_m = (mor * range_scale).ln();
        let mut kept = 0u64;
        let mut total = 0u64;
        let mut own: Vec<(u32, u32, u32, f64)> = Vec::with_capacity(cells.cells.len());
        let mut hidden = vec![0u32; 0];
        if !tally.occluded.is_empty() {
            hidden = vec![0u32; cells.n_cells];
            for &c in &tally.occluded {
                hidden[c as usize] = hidden[c as usize].saturating_add(1);
            }
        }
        let frames = tally.frames.max(1);
        let rays = cells.rays * frames as u64;
        let ln_reach = params.noise_reach_m().ln();
        let mut hid: Vec<(u32, u32, u32, f64)> = Vec::new();
        let mut beyond: Vec<(u32, u32, u32, f64)> = Vec::new();
        for (j, &c) in cells.cells.iter().enumerate() {
            let k = tally.matched[c as usize];
            entry.1[c as usize] += k;
            let h = cells.hits[j] as u32 * frames;
            // Clear returns hidden behind a ghost or ring return are neither
            // kept nor lost: they leave the survival trials.
            let gone = hidden.get(c as usize).copied().unwrap_or(0);
            let trials = h - gone.min(h - k.min(h));
            let b = self.survival.bin_of(cells.ln_r[j] - ln_m);
            self.survival
                .add(cells.class[j] as usize, b, k as u64, trials as u64);
            let idx = self.survival.index(cells.class[j] as usize, b) as u32;
            if trials > 0 || k > 0 {
                own.push((idx, k, trials, trials as f64 * cells.clear[j]));
            }
            let hidden_here = h - trials;
            if hidden_here > 0 {
                hid.push((idx, hidden_here, 0, hidden_here as f64 * cells.clear[j]));
            }
            if cells.ln_r[j] >= ln_reach {
                beyond.push((idx, hidden_here, h, 0.0));
            }
            kept += k as u64;
            total += h as u64;
        }
        // Each cell's masked stretches stand for its rays: one per scan and
        // revolution.
        let per_cell = frames as u64 * cells.revolutions.max(1);
        self.ghost
            .add(&tally.ghosts, &tally.occluders, masked, rays, per_cell);
        self.ring
            .add(&tally.rings, &tally.occluders, masked, rays, per_cell);
        let reach = params.noise_reach_m();
        let mut occluders = vec![0u32; (reach / ROW_OCCLUDER_STEP_M).ceil().max(1.0) as usize];
        let mut row_masked = vec![0u64; occluders.len()];
        add_stretches(&mut row_masked, ROW_OCCLUDER_STEP_M, masked, per_cell);
        for &r in &tally.occluders {
            let k = (r as f64 / ROW_OCCLUDER_STEP_M).floor().max(0.0) as usize;
            if let Some(o) = occluders.get_mut(k) {
                *o += 1;
            }
        }
        let (survival, survival_clear) = merge_cells(own);
        let (hidden, hidden_clear) = merge_cells(hid);
        let hidden = hidden
            .into_iter()
            .zip(hidden_clear)
            .map(|((i, n, _), c)| (i, n, c))
            .collect();
        let (beyond_windows, _) = merge_cells(beyond);
        self.rows.push(RecordingRow {
            index,
            id: id.to_string(),
            mor,
            rain_rate,
            kept,
            total,
            ghosts: tally.ghosts.len() as u64,
            rings: tally.rings.len() as u64,
            scene: tally.scene,
            far: tally.far,
            points: tally.points,
            occluders,
            masked: row_masked,
            rays,
            frames,
            revolutions: frames as u64 * cells.revolutions.max(1),
            survival,
            survival_clear,
            ln_mor_scaled: ln_m,
            hidden,
            beyond_windows,
        });
    }

    /// Adds another accumulator (integer sums: order does not matter).
    pub fn merge(&mut self, o: WeatherAcc) {
        for (k, (n, v)) in o.bins {
            match self.bins.get_mut(&k) {
                Some((m, w)) => {
                    *m += n;
                    for (a, b) in w.iter_mut().zip(&v) {
                        *a += b;
                    }
                }
                None => {
                    self.bins.insert(k, (n, v));
                }
            }
        }
        self.survival.merge(&o.survival);
        self.ghost.merge(&o.ghost);
        self.ring.merge(&o.ring);
        self.rows.extend(o.rows);
    }

    /// Sorts the rows by recording index (the deterministic order of every
    /// float summary).
    pub fn finish(&mut self) {
        self.rows.sort_by_key(|r| r.index);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Stretches split over steps: partial ends directly, whole steps
    /// between, what lies beyond the last step dropped, times the weight.
    #[test]
    fn stretches_are_added_per_step() {
        let mut out = vec![0u64; 4];
        add_stretches(&mut out, 0.1, &[(0.05, 0.25), (0.31, 0.33), (0.35, 0.9)], 2);
        // 0.05 m, 0.1 m, 0.05 m of the first; 0.02 m and 0.05 m in step 3.
        assert_eq!(out, vec![1000, 2000, 1000, 1400]);
        let mut one = vec![0u64; 3];
        add_stretches(&mut one, 0.1, &[(0.0, 0.3)], 1);
        assert_eq!(one, vec![1000; 3]);
        add_stretches(&mut one, 0.1, &[(0.2, 0.1), (0.5, 0.7)], 1);
        assert_eq!(one, vec![1000; 3], "empty and out-of-range stretches");
    }

    /// A recording whose rays are all masked over a stretch sees nothing
    /// there: the row's visibility is 1 before it, 0 inside, and 1 − the
    /// occluded share after an occluder.
    #[test]
    fn masked_rays_are_not_open() {
        let mut masked = vec![0u64; 5];
        // 10 rays, each masked over [0.1, 0.3).
        add_stretches(&mut masked, ROW_OCCLUDER_STEP_M, &[(0.1, 0.3); 10], 1);
        let row = RecordingRow {
            index: 0,
            id: "r".into(),
            mor: 50.0,
            rain_rate: None,
            kept: 0,
            total: 0,
            ghosts: 0,
            rings: 0,
            scene: 0,
            far: 0,
            points: 0,
            occluders: vec![0, 0, 0, 2, 0],
            masked,
            rays: 10,
            frames: 1,
            revolutions: 1,
            survival: Vec::new(),
            survival_clear: Vec::new(),
            ln_mor_scaled: 0.0,
            hidden: Vec::new(),
            beyond_windows: Vec::new(),
        };
        let v = row.open_rays();
        let want = [1.0, 0.0, 0.0, 1.0, 0.8];
        for (a, b) in v.iter().zip(want) {
            assert!((a - b).abs() < 1e-9, "{v:?}");
        }
    }
}
