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
//! - **stable**: at least `reference_min_agreement` (0.8) of their
//!   per-recording ranges lie within the pairing tolerance of the median
//!   (robust to vegetation, moving objects, cells straddling a depth edge:
//!   a free-running unit fires at a new azimuth every revolution, so such a
//!   cell sees the near surface in some recordings and the far one in
//!   others, and the recordings on the minority surface would otherwise
//!   read as dropouts).
//!
//! A return pairs with a reference cell when its range lies within the
//! cell's *tolerance*: the campaign's pairing tolerance at the cell's range,
//! widened by how far the cell's range wanders between revolutions — the
//! reach of its agreeing clear ranges beyond their median, or the ring's
//! range gradient times how far its firings wander across a cell (half a
//! cell for a free-running unit, nearly nothing for a phase-locked one,
//! from the measured phase locking), whichever is larger, and at most the
//! tolerance again. A free-running unit on a surface seen at a grazing angle
//! (the road, a wall along the street) reads ranges metres apart across a
//! cell; without the widening its recordings lost 1–4 % of their returns
//! there (clear no-change 0.961 with four clear recordings, 0.985 with it).
//!
//! Cells that returned in some clear recording but fail either test keep a
//! range *envelope* `[min, max]`, so that a degraded return inside it is
//! counted as unpaired scene rather than as a ghost or ring.
//!
//! The same per-cell stacks give each clear recording's no-change rate against
//! a reference built **without** it (leave-one-out), the clear-weather
//! baseline of Table 7 and the dropout ε.

use murk_types::{LidarSpec, PointCloud, SensorGeometry};
use std::path::Path;

use crate::{FitError, FitValidParams};

/// The (ring, azimuth bin) grid of a LiDAR: per ring, `bins` cells of
/// `360 / bins` degrees centred on `phase + k · width` (the ring's firings,
/// see [`observe::measure_geometry`](crate::observe::measure_geometry)).
#[derive(Debug, Clone, PartialEq)]
pub struct CellGrid {
    /// Per ring: (first cell, bins, width in degrees, phase in degrees).
    rings: Vec<RingBins>,
    cells: usize,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct RingBins {
    offset: usize,
    bins: usize,
    width: f64,
    phase: f64,
    /// How far (in bins, at most ½) the ring's firings wander about the
    /// cell centres between revolutions; see [`firing_wander`].
    wander: f64,
}

/// How far a ring's firings wander about their cell's centre between
/// revolutions, in cells (0 to ½), from the resultant length `R` of their
/// phases ([`RingGeometry::phase_locking`](murk_types::RingGeometry)): two
/// standard deviations of the wrapped normal with that resultant length
/// (`σ = √(−2 ln R)` radians of the cell's circle), at most half a cell (a
/// free-running unit, `R ≈ 0`, fires anywhere in the cell). A phase-locked
/// ring (`R` 0.99) wanders by 0.05 cells; a geometry that was not measured
/// (`R` 0) is taken to wander, the cautious reading.
pub fn firing_wander(phase_locking: f64) -> f64 {
    let r = phase_locking.clamp(0.0, 1.0);
    if r <= 0.0 {
        return 0.5;
    }
    let sigma = (-2.0 * r.ln()).sqrt() / std::f64::consts::TAU;
    (2.0 * sigma).min(0.5)
}

impl CellGrid {
    /// The declared grid of `spec` (rings × 360°/azimuth resolution), cells
    /// centred on multiples of the resolution.
    pub fn new(spec: &LidarSpec) -> Self {
        CellGrid::from_geometry(&crate::geometry::declared(spec))
    }

    /// The grid of a (measured) geometry: each ring its own step and phase.
    pub fn from_geometry(g: &SensorGeometry) -> Self {
        let mut rings = Vec::with_capacity(g.rings.len());
        let mut offset = 0;
        for r in &g.rings {
            let bins = (360.0 / r.azimuth_step_deg).round().max(1.0) as usize;
            let width = 360.0 / bins as f64;
            rings.push(RingBins {
                offset,
                bins,
                width,
                phase: r.azimuth_phase_deg.rem_euclid(width),
                wander: firing_wander(r.phase_locking),
            });
            offset += bins;
        }
        CellGrid {
            rings,
            cells: offset,
        }
    }

    /// Number of cells.
    pub fn cells(&self) -> usize {
        self.cells
    }

    /// Number of rings.
    pub fn rings(&self) -> usize {
        self.rings.len()
    }

    /// Azimuth bins of `ring` (0 outside the grid).
    pub fn azimuth_bins(&self, ring: usize) -> usize {
        self.rings.get(ring).map_or(0, |r| r.bins)
    }

    /// The ring of `cell`.
    #[inline]
    pub fn ring_of(&self, cell: usize) -> usize {
        self.rings
            .partition_point(|r| r.offset <= cell)
            .saturating_sub(1)
    }

    /// The azimuth of the centre of `cell`, degrees in `[0, 360)`.
    pub fn azimuth_deg(&self, cell: usize) -> f64 {
        let r = &self.rings[self.ring_of(cell)];
        (r.phase + (cell - r.offset) as f64 * r.width).rem_euclid(360.0)
    }

    /// The cell of a point, `None` when its ring is outside the grid.
    #[inline]
    pub fn cell_of(&self, ring: u16, x: f32, y: f32) -> Option<usize> {
        let r = self.rings.get(ring as usize)?;
        let az = crate::geometry::azimuth_deg(x, y);
        let k = ((az - r.phase) / r.width + 0.5).floor() as i64;
        Some(r.offset + k.rem_euclid(r.bins as i64) as usize)
    }

    /// The cell `offset` azimuth bins away on the same ring (wrapping).
    #[inline]
    pub fn shifted(&self, cell: usize, offset: i64) -> usize {
        let r = &self.rings[self.ring_of(cell)];
        let bin = (cell - r.offset) as i64;
        r.offset + (bin + offset).rem_euclid(r.bins as i64) as usize
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
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct CellImage {
    /// Occupied cells, ascending.
    pub cells: Vec<u32>,
    /// Median range of the cell's returns, metres.
    pub range: Vec<f32>,
    /// Median calibrated reflectivity of the cell's returns.
    pub reflectivity: Vec<f32>,
    /// Number of returns in the cell (revolutions that hit it).
    pub hits: Vec<u32>,
    /// Scans the image was made from (revolutions of a `.pcap`, 1 for any
    /// other file); 0 is read as 1.
    pub frames: u32,
}

/// Lets [`ClearReference::build`] take images or references to them.
impl AsRef<CellImage> for CellImage {
    fn as_ref(&self) -> &CellImage {
        self
    }
}

/// `img` with its cells in ascending order (duplicates kept, in their
/// order).
pub(crate) fn sorted_image(img: &CellImage) -> CellImage {
    let mut idx: Vec<usize> = (0..img.cells.len()).collect();
    idx.sort_by_key(|&j| img.cells[j]);
    CellImage {
        cells: idx.iter().map(|&j| img.cells[j]).collect(),
        range: idx.iter().map(|&j| img.range[j]).collect(),
        reflectivity: idx.iter().map(|&j| img.reflectivity[j]).collect(),
        hits: idx.iter().map(|&j| img.hits[j]).collect(),
        frames: img.frames,
    }
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
    /// Appends entries `from .. from + n` to `out`.
    pub(crate) fn entries(&self, from: usize, n: usize, out: &mut Vec<ImageEntry>) {
        out.extend((from..from + n).map(|q| ImageEntry {
            cell: self.cells[q],
            range: self.range[q],
            reflectivity: self.reflectivity[q],
            hits: self.hits[q],
        }));
    }

    /// Reduces the points of one single-scan recording (any order) to a cell
    /// image.
    pub fn from_points(points: &[CellPoint], n_cells: usize) -> CellImage {
        CellImage::from_frames(points, 1, n_cells)
    }

    /// Reduces the points of a recording of `frames` scans (any order) to a
    /// cell image.
    pub fn from_frames(points: &[CellPoint], frames: u32, n_cells: usize) -> CellImage {
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
        // Sized to the occupied cells: images are held (in memory up to the
        // fit's budget, `crate::images`) until the reference is built.
        let occupied = start.windows(2).filter(|w| w[0] != w[1]).count();
        let mut img = CellImage {
            cells: Vec::with_capacity(occupied),
            range: Vec::with_capacity(occupied),
            reflectivity: Vec::with_capacity(occupied),
            hits: Vec::with_capacity(occupied),
            frames: frames.max(1),
        };
        for c in 0..n_cells {
            let (a, b) = (start[c] as usize, start[c + 1] as usize);
            if a == b {
                continue;
            }
            img.cells.push(c as u32);
            img.range.push(median_f32(&mut r[a..b]));
            img.reflectivity.push(median_f32(&mut f[a..b]));
            img.hits.push((b - a).min(u32::MAX as usize) as u32);
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
    /// Expected returns per scan in the cell (0 when not in the reference).
    hits: Vec<u16>,
    /// Scans of each clear recording.
    frames: Vec<u64>,
    /// Per stable cell: how far its agreeing clear ranges (those within the
    /// pairing tolerance of the median) reach beyond the median, 0
    /// elsewhere. See [`ClearReference::tolerance`].
    slack: Vec<f32>,
    /// Envelope of clear ranges of cells that returned at all (NaN otherwise).
    env_lo: Vec<f32>,
    env_hi: Vec<f32>,
    /// Cells in the reference, ascending.
    present: Vec<u32>,
    clear_recordings: usize,
    /// Per clear recording: (kept, total) against the leave-one-out reference.
    loo: Vec<(u64, u64)>,
    /// Per cell: (kept, expected) of the clear recordings, each scored
    /// against the reference built without it ((0, 0) where no recording
    /// could be scored).
    cell_loo: Vec<(u64, u64)>,
}

impl ClearReference {
    /// Builds the reference from the clear recordings' images.
    ///
    /// Each cell expects `h` returns per scan: the median over the
    /// recordings that hit it of their hits per scan (rounded, at least 1),
    /// so that recordings of different lengths (a `.pcap` of many
    /// revolutions, a file of one) agree on what a scan holds. A cell is
    /// present when its returns reach `reference_min_presence` of the
    /// `h × scans` expected over all clear recordings.
    ///
    /// `images` must be non-empty (the caller reports "no clear reference").
    pub fn build<I: AsRef<CellImage>>(
        grid: CellGrid,
        images: &[I],
        params: &FitValidParams,
    ) -> ClearReference {
        let images: Vec<&CellImage> = images.iter().map(AsRef::as_ref).collect();
        // The build reads each image's cells in ascending order (as
        // `CellImage` promises); an image from elsewhere (a state file) that
        // is not is sorted first.
        let sorted: Vec<Option<CellImage>> = images
            .iter()
            .map(|img| (!img.cells.is_sorted_by(|a, b| a < b)).then(|| sorted_image(img)))
            .collect();
        let images: Vec<&CellImage> = images
            .iter()
            .zip(&sorted)
            .map(|(&img, s)| s.as_ref().unwrap_or(img))
            .collect();
        let Ok(reference) = ClearReference::build_from(grid, &MemoryImages(images), params);
        reference
    }

    /// Builds the reference from images read through `src` (see
    /// [`ClearReference::build`] for the rule).
    ///
    /// The images are read once, a block of whole rings at a time: every
    /// recording's entries of the block's cells (a cursor per recording,
    /// [`READ_CHUNK`] entries of lookahead), the cells' medians, and each
    /// recording scored against the reference without it on those rings
    /// (the leave-one-out matching is per ring). What the build holds is
    /// per cell, per recording, and one block's entries (at most about
    /// [`BLOCK_ENTRIES`], or one ring of every recording), not every
    /// recording's image: with the images in a file ([`crate::images`]) its
    /// memory does not grow with the number of clear recordings but for a
    /// few bytes each.
    pub(crate) fn build_from<S: ImageSource>(
        grid: CellGrid,
        src: &S,
        params: &FitValidParams,
    ) -> Result<ClearReference, S::Error> {
        ClearReference::build_blocks(grid, src, params, BLOCK_ENTRIES)
    }

    /// [`ClearReference::build_from`] with blocks of about `block_entries`
    /// entries (the reference does not depend on it).
    fn build_blocks<S: ImageSource>(
        grid: CellGrid,
        src: &S,
        params: &FitValidParams,
        block_entries: usize,
    ) -> Result<ClearReference, S::Error> {
        let n_cells = grid.cells();
        let n = src.count();
        let frames: Vec<u64> = (0..n).map(|i| src.frames(i).max(1) as u64).collect();
        let all_frames: u64 = frames.iter().sum();

        let mut reference = ClearReference {
            grid,
            range: vec![f32::NAN; n_cells],
            reflectivity: vec![f32::NAN; n_cells],
            hits: vec![0; n_cells],
            slack: vec![0.0; n_cells],
            env_lo: vec![f32::NAN; n_cells],
            env_hi: vec![f32::NAN; n_cells],
            present: Vec::new(),
            clear_recordings: n,
            loo: vec![(0, 0); n],
            cell_loo: vec![(0, 0); n_cells],
            frames: frames.clone(),
        };
        let min_presence = params.reference_min_presence();
        let min_agreement = params.reference_min_agreement();
        // What the leave-one-out scoring needs per cell: stable, its median
        // and expected hits per scan, its hit sum (the per-entry medians
        // without the entry's recording are the block's).
        let mut cells = LooCells {
            stable: vec![false; n_cells],
            median: vec![f32::NAN; n_cells],
            h: vec![0; n_cells],
            hit_sum: vec![0; n_cells],
            gradient_slack: vec![0.0; n_cells],
        };
        let mut block = Block::default();
        let mut readers: Vec<Reader> = (0..n).map(|_| Reader::default()).collect();
        let mut order: Vec<usize> = Vec::new();
        let mut rs: Vec<f32> = Vec::new();
        let mut fs: Vec<f32> = Vec::new();
        let mut hs: Vec<u32> = Vec::new();
        let mut dev: Vec<f32> = Vec::new();
        let mut start: Vec<usize> = Vec::new();
        let mut fill: Vec<usize> = Vec::new();
        // Per cell of the block, the entries of every recording that hit
        // it, in recording order (indices into `block.entries`).
        let mut by_cell: Vec<u32> = Vec::new();
        let mut scorer = Scorer::new(n_cells, params);
        let rings = reference.grid.rings.clone();
        let mut r0 = 0;
        while r0 < rings.len() {
            let c0 = rings[r0].offset;
            let mut r1 = r0 + 1;
            while r1 < rings.len()
                && (rings[r1].offset + rings[r1].bins - c0).saturating_mul(n) <= block_entries
            {
                r1 += 1;
            }
            let c1 = rings[r1 - 1].offset + rings[r1 - 1].bins;
            block.entries.clear();
            block.start.clear();
            block.start.push(0);
            for (i, reader) in readers.iter_mut().enumerate() {
                reader.take_below(src, i, c1, &mut block.entries)?;
                block.start.push(block.entries.len());
            }
            let total = block.entries.len();
            start.clear();
            start.resize(c1 - c0 + 1, 0);
            for e in &block.entries {
                start[e.cell as usize - c0 + 1] += 1;
            }
            for k in 0..c1 - c0 {
                start[k + 1] += start[k];
            }
            fill.clear();
            fill.extend_from_slice(&start[..c1 - c0]);
            by_cell.clear();
            by_cell.resize(total, 0);
            for (k, e) in block.entries.iter().enumerate() {
                let at = &mut fill[e.cell as usize - c0];
                by_cell[*at] = k as u32;
                *at += 1;
            }
            block.median_without.clear();
            block.median_without.resize(total, f32::NAN);
            block.slack_without.clear();
            block.slack_without.resize(total, 0);
            for c in c0..c1 {
                let ks = &by_cell[start[c - c0]..start[c - c0 + 1]];
                let m = ks.len();
                if m == 0 {
                    continue;
                }
                let entry = |x: usize| &block.entries[ks[x] as usize];
                rs.clear();
                rs.extend((0..m).map(|x| entry(x).range));
                order.clear();
                order.extend(0..m);
                order.sort_by(|&x, &y| entry(x).range.total_cmp(&entry(y).range).then(x.cmp(&y)));
                rs.sort_by(f32::total_cmp);
                reference.env_lo[c] = rs[0];
                reference.env_hi[c] = rs[m - 1];
                let med = median_f32(&mut rs.clone());
                let tol = params.pairing_tolerance(med as f64) as f32;
                // `rs` is sorted: the ranges within the tolerance of the
                // median are one run of it. The median absolute deviation
                // is only needed when enough of them agree.
                let agree =
                    rs.partition_point(|r| r - med <= tol) - rs.partition_point(|r| r - med < -tol);
                let stable = agree as f64 >= min_agreement * m as f64 && {
                    dev.clear();
                    dev.extend(rs.iter().map(|r| (r - med).abs()));
                    median_f32(&mut dev) <= tol
                };
                hs.clear();
                hs.extend((0..m).map(|x| {
                    let k = ks[x] as usize;
                    let f = frames[block.recording_of(k)];
                    ((block.entries[k].hits as u64 + f / 2) / f).max(1) as u32
                }));
                hs.sort_unstable();
                let h = hs[(m - 1) / 2].max(1);
                let hit_sum: u64 = (0..m).map(|x| entry(x).hits as u64).sum();
                if stable && presence_holds(min_presence, h, all_frames as f64, hit_sum as f64) {
                    fs.clear();
                    fs.extend((0..m).map(|x| entry(x).reflectivity));
                    reference.range[c] = med;
                    reference.reflectivity[c] = median_f32(&mut fs);
                    reference.hits[c] = h.min(u16::MAX as u32) as u16;
                    reference.present.push(c as u32);
                }
                if stable {
                    reference.slack[c] = agreeing_slack(&rs, None, med, tol);
                }
                cells.stable[c] = stable;
                cells.median[c] = med;
                cells.h[c] = h;
                cells.hit_sum[c] = hit_sum;
                if m >= 2 {
                    for (pos, &x) in order.iter().enumerate() {
                        let k = ks[x] as usize;
                        let m_without = median_without(&rs, pos);
                        block.median_without[k] = m_without;
                        if stable {
                            let tol = params.pairing_tolerance(m_without as f64) as f32;
                            let slack = agreeing_slack(&rs, Some(pos), m_without, tol);
                            block.slack_without[k] = slack_cm(slack);
                        }
                    }
                }
            }
            // The range a cell's firings can read as they wander across it:
            // the gradient along the ring (from the stable neighbours'
            // medians: the central difference, or the one side there is)
            // times the ring's wander, at most the tolerance (at a depth
            // edge the "gradient" is the jump, and the cap keeps the window
            // within twice the tolerance there).
            for ring in &rings[r0..r1] {
                let at = |p: i64| {
                    let c = ring.offset + p.rem_euclid(ring.bins as i64) as usize;
                    (cells.stable[c] && ring.bins > 2).then_some(cells.median[c])
                };
                for p in 0..ring.bins {
                    let c = ring.offset + p;
                    let Some(r) = at(p as i64) else {
                        continue;
                    };
                    let step = match (at(p as i64 - 1), at(p as i64 + 1)) {
                        (Some(a), Some(b)) => (b - a).abs() / 2.0,
                        (Some(a), None) | (None, Some(a)) => (r - a).abs(),
                        (None, None) => 0.0,
                    };
                    let tol = params.pairing_tolerance(r as f64) as f32;
                    let wander = (ring.wander as f32 * step).min(tol);
                    cells.gradient_slack[c] = wander;
                    reference.slack[c] = reference.slack[c].max(wander);
                }
            }
            if n >= 2 {
                scorer.score_block(&mut reference, &rings[r0..r1], &block, &cells, all_frames);
            }
            r0 = r1;
        }
        Ok(reference)
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

    /// Expected returns per scan in `cell` (0 when not in the reference).
    #[inline]
    pub fn hits(&self, cell: usize) -> u16 {
        self.hits[cell]
    }

    /// The pairing tolerance of `cell`: the campaign's tolerance at its
    /// reference range, widened by how far the cell's agreeing clear ranges
    /// reach beyond their median (its *slack*).
    ///
    /// Why the slack: a free-running unit fires at another azimuth inside
    /// the cell every revolution, and on a surface seen at a grazing angle
    /// (the road, a wall along the street) the range changes by metres
    /// across a 1° cell, so a degraded revolution that fires near the
    /// cell's edge reads a range off the median by more than the tolerance
    /// and would count as a loss. The clear recordings already show how far
    /// the cell's range wanders between revolutions; a phase-locked unit's
    /// cells wander by their range noise only (centimetres), so the slack
    /// changes nothing there. Bounded by the tolerance itself (only ranges
    /// that agree with the median count), so the window is at most twice
    /// the campaign's.
    #[inline]
    pub fn tolerance(&self, cell: usize, params: &FitValidParams) -> f32 {
        params.pairing_tolerance(self.range[cell] as f64) as f32 + self.slack[cell]
    }

    /// True when `range` lies within the clear envelope of `cell` widened by
    /// the pairing tolerance.
    #[inline]
    pub fn in_envelope(&self, cell: usize, range: f32, tol: f32) -> bool {
        let (lo, hi) = (self.env_lo[cell], self.env_hi[cell]);
        lo.is_finite() && range >= lo - tol && range <= hi + tol
    }

    /// The ranges at which a degraded return offered to `cell` (as its own
    /// cell or as an azimuth neighbour) is not counted as weather: the
    /// cell's clear envelope widened by the pairing tolerance (a return
    /// there is *scene*) joined with the reference range within the cell's
    /// own tolerance (a return there may pair). `None` for a cell in which
    /// no clear recording returned.
    pub fn scene_span(&self, cell: usize, params: &FitValidParams) -> Option<[f32; 2]> {
        let (lo, hi) = (self.env_lo[cell], self.env_hi[cell]);
        if !lo.is_finite() {
            return None;
        }
        let [mut a, mut b] = params.tolerance_span(lo as f64, hi as f64);
        if self.hits[cell] > 0 {
            let (r0, t) = (self.range[cell] as f64, self.tolerance(cell, params) as f64);
            a = a.min(r0 - t);
            b = b.max(r0 + t);
        }
        Some([a as f32, b as f32])
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

    /// The clear survival of `cell`: the share of its expected returns that
    /// the clear recordings kept, each scored against the reference built
    /// without it (a static scene's own flicker: a cell seen in 3 of 5
    /// clear recordings survives 0.6 of the time without any weather).
    /// `None` where no clear recording could be scored on it (a single
    /// clear recording, or a cell that only one recording saw).
    pub fn clear_survival(&self, cell: usize) -> Option<f64> {
        let (k, e) = self.cell_loo[cell];
        (e > 0).then(|| k as f64 / e as f64)
    }

    /// Revolutions per scan: the median expected hits per scan of the
    /// reference cells (1 for `.pcap` revolutions and single-revolution files;
    /// `k` for files that accumulate `k` revolutions, since a cell of the
    /// measured grid holds one firing per revolution).
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

    /// Scans of each clear recording, in the order given to [`Self::build`].
    pub fn frames(&self) -> &[u64] {
        &self.frames
    }

    /// Expected returns per scan summed over the reference.
    pub fn total_hits(&self) -> u64 {
        self.present
            .iter()
            .map(|&c| self.hits[c as usize] as u64)
            .sum()
    }
}

/// What the leave-one-out scoring reads per cell.
struct LooCells {
    /// The cell's clear ranges agree (`reference_min_agreement` of them
    /// within the pairing tolerance of their median).
    stable: Vec<bool>,
    /// Median range over every clear recording that hit the cell.
    median: Vec<f32>,
    /// Expected returns per scan.
    h: Vec<u32>,
    /// Returns of every clear recording in the cell.
    hit_sum: Vec<u64>,
    /// Per stable cell: the range its firings read as they wander across
    /// it (the ring's gradient times its wander, at most the tolerance).
    gradient_slack: Vec<f32>,
}

/// One entry of a cell image: a clear recording's returns in one cell.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ImageEntry {
    /// The cell.
    pub cell: u32,
    /// Median range of its returns, metres.
    pub range: f32,
    /// Median calibrated reflectivity of its returns.
    pub reflectivity: f32,
    /// Number of returns.
    pub hits: u32,
}

/// The clear recordings' cell images as [`ClearReference::build_from`]
/// reads them: each image's entries in ascending cell order, a run at a
/// time, so that they can sit in memory or in a file.
pub(crate) trait ImageSource {
    /// A failed read.
    type Error;
    /// Number of images (clear recordings).
    fn count(&self) -> usize;
    /// Scans image `i` was made from (0 read as 1).
    fn frames(&self, i: usize) -> u32;
    /// Entries of image `i`.
    fn len(&self, i: usize) -> usize;
    /// Appends entries `from .. from + n` of image `i` to `out`.
    fn read(
        &self,
        i: usize,
        from: usize,
        n: usize,
        out: &mut Vec<ImageEntry>,
    ) -> Result<(), Self::Error>;
}

/// Images in memory, each with its cells ascending.
struct MemoryImages<'a>(Vec<&'a CellImage>);

impl ImageSource for MemoryImages<'_> {
    type Error = std::convert::Infallible;

    fn count(&self) -> usize {
        self.0.len()
    }

    fn frames(&self, i: usize) -> u32 {
        self.0[i].frames
    }

    fn len(&self, i: usize) -> usize {
        self.0[i].cells.len()
    }

    fn read(
        &self,
        i: usize,
        from: usize,
        n: usize,
        out: &mut Vec<ImageEntry>,
    ) -> Result<(), Self::Error> {
        self.0[i].entries(from, n, out);
        Ok(())
    }
}

/// Entries read ahead per recording while the reference is built (16
/// bytes each: 4 kB per clear recording).
pub(crate) const READ_CHUNK: usize = 256;

/// About how many entries (cells × clear recordings) one block of the
/// build holds; a block is at least one ring.
pub(crate) const BLOCK_ENTRIES: usize = 1 << 20;

/// A cursor into one recording's image.
#[derive(Default)]
struct Reader {
    buf: Vec<ImageEntry>,
    pos: usize,
    /// The next entry of the image to read into `buf`.
    next: usize,
}

impl Reader {
    /// Moves the image's entries of cells below `end` to `out`.
    fn take_below<S: ImageSource>(
        &mut self,
        src: &S,
        i: usize,
        end: usize,
        out: &mut Vec<ImageEntry>,
    ) -> Result<(), S::Error> {
        loop {
            if self.pos == self.buf.len() {
                let len = src.len(i);
                if self.next >= len {
                    return Ok(());
                }
                let m = READ_CHUNK.min(len - self.next);
                self.buf.clear();
                src.read(i, self.next, m, &mut self.buf)?;
                self.next += m;
                self.pos = 0;
                continue;
            }
            let e = self.buf[self.pos];
            if e.cell as usize >= end {
                return Ok(());
            }
            out.push(e);
            self.pos += 1;
        }
    }
}

/// The entries of one block of rings, recording by recording.
#[derive(Default)]
struct Block {
    entries: Vec<ImageEntry>,
    /// Recording `i`'s entries are `start[i] .. start[i + 1]`.
    start: Vec<usize>,
    /// Per entry: the cell's median without the entry's recording (NaN
    /// when no other recording hit the cell).
    median_without: Vec<f32>,
    /// Per entry of a stable cell: the slack of the other recordings'
    /// agreeing ranges about `median_without`, in whole centimetres
    /// rounded up.
    slack_without: Vec<u16>,
}

impl Block {
    /// The recording of entry `k`.
    fn recording_of(&self, k: usize) -> usize {
        self.start.partition_point(|&s| s <= k) - 1
    }
}

/// How far the ranges of sorted `rs` (leaving out position `skip`) that lie
/// within `tol` of `med` reach beyond it: the largest `|r − med|` among
/// them, 0 when none does. The agreeing ranges are one run of `rs`, so its
/// two ends (stepping over `skip`) are all that is read.
fn agreeing_slack(rs: &[f32], skip: Option<usize>, med: f32, tol: f32) -> f32 {
    let mut lo = rs.partition_point(|&r| r < med - tol);
    let mut hi = rs.partition_point(|&r| r <= med + tol);
    if skip == Some(lo) {
        lo += 1;
    }
    if hi > 0 && skip == Some(hi - 1) {
        hi -= 1;
    }
    if lo >= hi {
        return 0.0;
    }
    (med - rs[lo]).max(rs[hi - 1] - med).max(0.0)
}

/// A slack in metres as whole centimetres, rounded up (saturating).
fn slack_cm(slack: f32) -> u16 {
    (slack * 100.0).ceil().clamp(0.0, u16::MAX as f32) as u16
}

/// The presence rule: `hits` reach `min_presence` of the `h × frames`
/// returns expected.
fn presence_holds(min_presence: f64, h: u32, frames: f64, hits: f64) -> bool {
    frames > 0.0 && hits >= min_presence * h as f64 * frames
}

/// Scores each clear recording against the reference built without it, the
/// way a degraded recording is paired: its return in a cell pairs with the
/// cell's reference return or, failing that, with an azimuth neighbour's
/// (up to `azimuth_neighbours` bins away), each reference cell pairing at
/// most once. Among all such pairings the one keeping the most returns is
/// taken (ties: the most own-cell pairs), found exactly per ring by dynamic
/// programming over which neighbouring reference cells are taken, so that a
/// revolution whose firings all fall one bin off (a free-running unit)
/// pairs whole: a chain of shifts along the ring, not a loss at every range
/// edge. The ring is matched as a path from its first bin: at most one pair
/// across the seam is missed.
struct Scorer {
    min_presence: f64,
    params: FitValidParams,
    /// The recording being scored, per cell: its median range, hits and
    /// entry of the block (`u32::MAX` where it has none).
    rec_range: Vec<f32>,
    rec_hits: Vec<u32>,
    rec_entry: Vec<u32>,
    matcher: RingMatcher,
}

impl Scorer {
    fn new(n_cells: usize, params: &FitValidParams) -> Scorer {
        Scorer {
            min_presence: params.reference_min_presence(),
            params: params.clone(),
            rec_range: vec![f32::NAN; n_cells],
            rec_hits: vec![0; n_cells],
            rec_entry: vec![u32::MAX; n_cells],
            matcher: RingMatcher::new(params.azimuth_neighbours() as usize),
        }
    }

    /// Adds every recording's scores on `rings` (the block's) to `loo`
    /// (per recording) and `cell_loo` (per reference cell).
    fn score_block(
        &mut self,
        reference: &mut ClearReference,
        rings: &[RingBins],
        block: &Block,
        cells: &LooCells,
        all_frames: u64,
    ) {
        let (min_presence, params) = (self.min_presence, &self.params);
        for i in 0..reference.loo.len() {
            let f = reference.frames[i];
            let own = &block.entries[block.start[i]..block.start[i + 1]];
            for (j, e) in own.iter().enumerate() {
                let c = e.cell as usize;
                self.rec_range[c] = e.range;
                self.rec_hits[c] = e.hits;
                self.rec_entry[c] = (block.start[i] + j) as u32;
            }
            let frames_without = (all_frames - f) as f64;
            for ring in rings {
                let matcher = &mut self.matcher;
                matcher.clear();
                for p in 0..ring.bins {
                    let c = ring.offset + p;
                    let (median, slack, ok) = if !cells.stable[c] {
                        (f32::NAN, 0.0, false)
                    } else if self.rec_entry[c] != u32::MAX {
                        let k = self.rec_entry[c] as usize;
                        let med = block.median_without[k];
                        let hits_without = (cells.hit_sum[c] - self.rec_hits[c] as u64) as f64;
                        let ok = med.is_finite()
                            && presence_holds(
                                min_presence,
                                cells.h[c],
                                frames_without,
                                hits_without,
                            );
                        let slack = (f32::from(block.slack_without[k]) / 100.0)
                            .max(cells.gradient_slack[c]);
                        (med, slack, ok)
                    } else {
                        let ok = presence_holds(
                            min_presence,
                            cells.h[c],
                            frames_without,
                            cells.hit_sum[c] as f64,
                        );
                        (cells.median[c], reference.slack[c], ok)
                    };
                    matcher.reference.push(if ok {
                        Some(RefCell {
                            range: median,
                            tol: params.pairing_tolerance(median as f64) as f32 + slack,
                            expected: cells.h[c] as u64 * f,
                        })
                    } else {
                        None
                    });
                    matcher.returns.push(
                        (self.rec_entry[c] != u32::MAX)
                            .then(|| (self.rec_range[c], self.rec_hits[c] as u64)),
                    );
                }
                matcher.solve();
                for p in 0..ring.bins {
                    if let Some(r) = matcher.reference[p] {
                        let c = ring.offset + p;
                        let kept = matcher.kept[p];
                        reference.loo[i].0 += kept;
                        reference.loo[i].1 += r.expected;
                        reference.cell_loo[c].0 += kept;
                        reference.cell_loo[c].1 += r.expected;
                    }
                }
            }
            for e in own {
                let c = e.cell as usize;
                self.rec_range[c] = f32::NAN;
                self.rec_hits[c] = 0;
                self.rec_entry[c] = u32::MAX;
            }
        }
    }
}

/// A reference cell as the leave-one-out matching sees it.
#[derive(Debug, Clone, Copy)]
struct RefCell {
    range: f32,
    tol: f32,
    expected: u64,
}

/// Maximum-weight matching of one ring's returns (bin `j`) to its reference
/// cells (bins `j − k ..= j + k`), exact by dynamic programming: the state
/// is the set of the `2k + 1` reference bins around `j` already taken, so a
/// ring costs `O(bins · 2^(2k+1))` at worst and about `O(bins)` when the
/// returns sit in their own cells (few states are reachable). A bin that
/// holds two returns or more (a revolution whose firings straddle the bin
/// edge puts two in one bin and none in the next) may pair with two
/// reference cells, its median range standing for both. A matching crate
/// would solve a general bipartite graph; this one is a band of width
/// `2k + 1`, which the state machine solves exactly and in place.
struct RingMatcher {
    k: usize,
    /// Per bin: the reference cell, if the recording is scored on it.
    reference: Vec<Option<RefCell>>,
    /// Per bin: the recording's return (median range, hits), if any.
    returns: Vec<Option<(f32, u64)>>,
    /// Per bin: returns kept by the reference cell of that bin.
    kept: Vec<u64>,
    /// Per bin and state after it: (previous state, window bits taken).
    back: Vec<(u16, u16)>,
    value: Vec<Option<(u64, u32)>>,
    next: Vec<Option<(u64, u32)>>,
    active: Vec<u16>,
    next_active: Vec<u16>,
    /// Window bits of the current bin that have an edge, with its weight.
    edges: Vec<(usize, u64)>,
}

impl RingMatcher {
    fn new(k: usize) -> Self {
        let states = 1usize << (2 * k + 1);
        RingMatcher {
            k,
            reference: Vec::new(),
            returns: Vec::new(),
            kept: Vec::new(),
            back: Vec::new(),
            value: vec![None; states],
            next: vec![None; states],
            active: Vec::new(),
            next_active: Vec::new(),
            edges: Vec::new(),
        }
    }

    fn clear(&mut self) {
        self.reference.clear();
        self.returns.clear();
    }

    /// The weight of pairing the return of bin `j` with reference bin `q`.
    fn weight(&self, j: usize, q: usize) -> Option<u64> {
        let (range, hits) = self.returns[j]?;
        let r = self.reference.get(q).copied().flatten()?;
        ((range - r.range).abs() <= r.tol).then(|| hits.min(r.expected))
    }

    /// Splits the returns of bin `j` over the reference bins of `taken`
    /// (window bits), nearest bins first: `(bin, kept)` pairs.
    fn split(&self, j: usize, taken: u16) -> impl Iterator<Item = (usize, u64)> + '_ {
        let k = self.k;
        let mut left = self.returns[j].map_or(0, |r| r.1);
        let mut bits: Vec<usize> = (0..=2 * k).filter(|b| taken & (1 << b) != 0).collect();
        bits.sort_by_key(|&b| (b.abs_diff(k), b));
        bits.into_iter().map(move |b| {
            let q = j + b - k;
            let w = self
                .weight(j, q)
                .expect("a chosen pair has a weight")
                .min(left);
            left -= w;
            (q, w)
        })
    }

    fn solve(&mut self) {
        let bins = self.returns.len();
        let (k, states) = (self.k, self.value.len());
        self.back.clear();
        self.back.resize(bins * states, (0, 0));
        self.kept.clear();
        self.kept.resize(bins, 0);
        self.value.iter_mut().for_each(|v| *v = None);
        self.value[0] = Some((0, 0));
        self.active.clear();
        self.active.push(0);
        for j in 0..bins {
            self.next_active.clear();
            self.edges.clear();
            let hits = self.returns[j].map_or(0, |r| r.1);
            for b in 0..=2 * k {
                if j + b >= k
                    && let Some(w) = self.weight(j, j + b - k)
                {
                    self.edges.push((b, w));
                }
            }
            let most = hits.min(2) as usize;
            for ai in 0..self.active.len() {
                let s = self.active[ai] as usize;
                let (w, own) = self.value[s].expect("active state has a value");
                // Nothing taken: the returns of bin j pair with nothing.
                self.offer(j, s, s >> 1, (w, own), 0);
                // The bin's edges to reference bins this state leaves free
                // (taken out of `self` for the loop: `offer` borrows it).
                let edges = std::mem::take(&mut self.edges);
                let free = |b: usize| s & (1 << b) == 0;
                for (x, &(b1, w1)) in edges.iter().enumerate().filter(|(_, e)| free(e.0)) {
                    let own1 = u32::from(b1 == k);
                    let add = w1.min(hits);
                    self.offer(j, s, (s | 1 << b1) >> 1, (w + add, own + own1), 1 << b1);
                    if most < 2 {
                        continue;
                    }
                    for &(b2, w2) in edges[x + 1..].iter().filter(|e| free(e.0)) {
                        let add = (w1 + w2).min(hits);
                        let own2 = own1 + u32::from(b2 == k);
                        let taken = (1u16 << b1) | (1 << b2);
                        self.offer(j, s, (s | taken as usize) >> 1, (w + add, own2), taken);
                    }
                }
                self.edges = edges;
            }
            for ai in 0..self.active.len() {
                let s = self.active[ai] as usize;
                self.value[s] = None;
            }
            std::mem::swap(&mut self.active, &mut self.next_active);
            std::mem::swap(&mut self.value, &mut self.next);
            self.active.sort_unstable();
        }
        let Some(&best) = self.active.iter().max_by(|&&a, &&b| {
            self.value[a as usize]
                .cmp(&self.value[b as usize])
                .then(b.cmp(&a))
        }) else {
            return;
        };
        let mut s = best as usize;
        let mut kept = std::mem::take(&mut self.kept);
        for j in (0..bins).rev() {
            let (prev, taken) = self.back[j * states + s];
            for (q, w) in self.split(j, taken) {
                kept[q] = w;
            }
            s = prev as usize;
        }
        self.kept = kept;
        for ai in 0..self.active.len() {
            let s = self.active[ai] as usize;
            self.value[s] = None;
        }
    }

    /// Offers state `to` after bin `j`, reached from `from` with `value`.
    fn offer(&mut self, j: usize, from: usize, to: usize, value: (u64, u32), taken: u16) {
        let states = self.value.len();
        match self.next[to] {
            Some(v) if v >= value => {}
            old => {
                if old.is_none() {
                    self.next_active.push(to as u16);
                }
                self.next[to] = Some(value);
                self.back[j * states + to] = (from as u16, taken);
            }
        }
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
pub(crate) mod tests {
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
            frames: 1,
        }
    }

    #[test]
    fn cells_follow_ring_and_azimuth() {
        let g = grid();
        assert_eq!(g.cells(), 8);
        assert_eq!(g.cell_of(0, 1.0, 0.1), Some(0));
        // Cells are centred on multiples of 90°: 95.7° is in bin 1, 174.3°
        // in bin 2 (the old grid had its edges there).
        assert_eq!(g.cell_of(1, -0.1, 1.0), Some(4 + 1));
        assert_eq!(g.cell_of(1, -1.0, 0.1), Some(4 + 2));
        assert_eq!(g.ring_of(6), 1);
        assert!((g.azimuth_deg(6) - 180.0).abs() < 1e-9);
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
    fn firing_wander_follows_the_phase_locking() {
        assert_eq!(firing_wander(1.0), 0.0);
        assert_eq!(firing_wander(0.0), 0.5);
        // R 0.99: σ = √(−2 ln 0.99)/2π = 0.0225 cells, two of them.
        assert!((firing_wander(0.99) - 0.0450).abs() < 1e-3);
        let w: Vec<f64> = [0.999, 0.99, 0.9, 0.5, 0.2, 0.01]
            .iter()
            .map(|&r| firing_wander(r))
            .collect();
        assert!(w.windows(2).all(|p| p[0] < p[1] || p[1] == 0.5), "{w:?}");
        assert_eq!(firing_wander(0.01), 0.5);
    }

    #[test]
    fn the_slack_is_the_reach_of_the_agreeing_ranges() {
        let rs = [9.0f32, 9.8, 10.0, 10.3, 14.0];
        assert!((agreeing_slack(&rs, None, 10.0, 0.5) - 0.3).abs() < 1e-6);
        // Without the 10.3 m entry the reach is the 9.8 m one's.
        assert!((agreeing_slack(&rs, Some(3), 10.0, 0.5) - 0.2).abs() < 1e-6);
        assert!((agreeing_slack(&rs, Some(1), 10.0, 0.5) - 0.3).abs() < 1e-6);
        assert_eq!(agreeing_slack(&rs, None, 12.0, 0.5), 0.0);
        assert_eq!(agreeing_slack(&[10.0], Some(0), 10.0, 0.5), 0.0);
        assert_eq!(slack_cm(0.301), 31);
        assert_eq!(slack_cm(0.0), 0);
    }

    /// A ring of 36 cells, 12 of them on a surface seen at a grazing angle
    /// (range 10 + 1.6 m per cell, tolerance 0.5–0.55 m), the rest sky,
    /// recorded five times, the last
    /// fired 0.45 cells off the others (0.72 m further). A free-running ring
    /// (as measured, or unknown) pairs that recording's every cell in the
    /// leave-one-out, and a degraded revolution fired 0.45 cells off; the
    /// same recordings from a ring measured as phase-locked lose them.
    #[test]
    fn a_free_running_ring_pairs_across_a_range_gradient() {
        let mut spec = LidarSpec::vlp16();
        spec.elevation_deg = vec![0.0];
        spec.azimuth_resolution_deg = 10.0;
        let p = FitParams::default().check().unwrap();
        let at = |bin: u32, offset: f32| 10.0 + 1.6 * (bin as f32 + offset);
        let imgs: Vec<CellImage> = [0.0f32, 0.0, 0.0, 0.0, 0.45]
            .iter()
            .map(|&o| img(&(0..12).map(|b| (b, at(b, o), 20.0)).collect::<Vec<_>>()))
            .collect();
        let degraded: Vec<CellPoint> = (0..12)
            .map(|b| CellPoint {
                cell: b,
                range: at(b, 0.45),
                reflectivity: 20.0,
            })
            .collect();
        for (locking, pairs) in [(0.0, true), (0.2, true), (1.0, false)] {
            let mut g = crate::geometry::declared(&spec);
            g.rings[0].phase_locking = locking;
            let r = ClearReference::build(CellGrid::from_geometry(&g), &imgs, &p);
            assert_eq!(r.present().len(), 12);
            let loo = r.leave_one_out();
            assert!(loo[..4].iter().all(|l| l.0 == l.1), "{loo:?}");
            let t = crate::pairing::pair_recording(&r, &degraded, &p);
            // The ends of the surface have one neighbour: their gradient is
            // that side's.
            if pairs {
                assert_eq!(loo[4], (12, 12), "R {locking}");
                assert_eq!(t.kept(), 12, "R {locking}");
            } else {
                assert_eq!(loo[4], (0, 12), "R {locking}");
                assert_eq!(t.kept(), 0, "R {locking}");
            }
        }
    }

    #[test]
    fn a_cell_on_a_depth_edge_is_stable_only_if_enough_recordings_agree() {
        // Cell 0 sees the near wall (10 m) in 7 of 10 clear recordings and
        // the far one (30 m) in 3: its median absolute deviation is within
        // the tolerance, but 30 % of its recordings would read as dropouts.
        // Cell 1 sees the wall in 9 of 10.
        let imgs: Vec<CellImage> = (0..10)
            .map(|i| {
                img(&[
                    (0, if i < 7 { 10.0 } else { 30.0 }, 5.0),
                    (1, if i < 9 { 12.0 } else { 40.0 }, 5.0),
                ])
            })
            .collect();
        let strict = FitParams::default().check().unwrap();
        let r = ClearReference::build(grid(), &imgs, &strict);
        assert_eq!(r.present(), &[1], "default agreement 0.8");
        assert!(
            r.in_envelope(0, 20.0, 0.5),
            "the edge cell keeps its envelope"
        );
        let lax = FitParams::default()
            .reference_min_agreement(0.7)
            .check()
            .unwrap();
        let r = ClearReference::build(grid(), &imgs, &lax);
        assert_eq!(r.present(), &[0, 1], "agreement 0.7");
        assert_eq!(r.range(0), 10.0);
    }

    #[test]
    fn a_reference_of_many_blocks_and_unsorted_images_is_the_per_cell_median() {
        // 16 rings at 0.1°: 57,600 cells, each image longer than a read
        // ahead.
        let mut spec = LidarSpec::vlp16();
        spec.azimuth_resolution_deg = 0.1;
        let g = CellGrid::new(&spec);
        assert!(g.cells() > 10 * 4096, "{}", g.cells());
        let p = FitParams::default().check().unwrap();
        // Five recordings; each misses every fifth cell at its own phase,
        // and its ranges differ by a millimetre per recording.
        let ranges = |i: usize, c: usize| 10.0 + (c % 97) as f32 * 0.5 + i as f32 * 1e-3;
        let imgs: Vec<CellImage> = (0..5)
            .map(|i| {
                let cells: Vec<(u32, f32, f32)> = (0..g.cells())
                    .filter(|c| (c * 7 + i) % 5 != 0)
                    .map(|c| (c as u32, ranges(i, c), (c % 50) as f32))
                    .collect();
                img(&cells)
            })
            .collect();
        let r = ClearReference::build(g.clone(), &imgs, &p);
        let mut checked = 0;
        for c in 0..g.cells() {
            let mut rs: Vec<f32> = (0..5)
                .filter(|i| (c * 7 + i) % 5 != 0)
                .map(|i| ranges(i, c))
                .collect();
            // Four of five recordings hit every cell: all are present.
            assert_eq!(rs.len(), 4);
            assert_eq!(r.range(c), median_f32(&mut rs), "cell {c}");
            assert_eq!(r.reflectivity(c), (c % 50) as f32, "cell {c}");
            checked += 1;
        }
        assert_eq!(r.present().len(), checked);
        // The same images with their cells in descending order: the same
        // reference, leave-one-out included.
        let reversed: Vec<CellImage> = imgs
            .iter()
            .map(|m| CellImage {
                cells: m.cells.iter().rev().copied().collect(),
                range: m.range.iter().rev().copied().collect(),
                reflectivity: m.reflectivity.iter().rev().copied().collect(),
                hits: m.hits.iter().rev().copied().collect(),
                frames: m.frames,
            })
            .collect();
        let refs: Vec<&CellImage> = reversed.iter().collect();
        assert_eq!(ClearReference::build(g.clone(), &refs, &p), r);
        // Built a ring at a time: the same reference.
        let mem = MemoryImages(imgs.iter().collect());
        let Ok(by_ring) = ClearReference::build_blocks(g, &mem, &p, 1);
        assert_eq!(by_ring, r);
        // Each recording is scored on every reference cell and keeps at
        // least its own four fifths.
        for &(k, t) in r.leave_one_out() {
            assert_eq!(t as usize, checked);
            assert!(k as usize >= 4 * checked / 5 - 1 && k <= t, "{k} of {t}");
        }
    }

    /// The two references are the same value, bit for bit (`NaN` marks
    /// cells out of the reference, so `==` cannot say it).
    pub(crate) fn same(a: &ClearReference, b: &ClearReference) -> bool {
        format!("{a:?}") == format!("{b:?}")
    }

    /// Clear images of a scene with what makes the reference work: dropouts,
    /// cells flickering between two surfaces (some stable, some not),
    /// range noise, recordings of one to three scans. Seeded.
    pub(crate) fn noisy_images(g: &CellGrid, n: usize, seed: u64) -> Vec<CellImage> {
        use rand::{RngExt, SeedableRng, rngs::ChaCha8Rng};
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let scene: Vec<(f32, f32, f64)> = (0..g.cells())
            .map(|_| {
                let r = rng.random_range(2.0f32..80.0);
                let far = if rng.random_bool(0.15) {
                    r + rng.random_range(1.0f32..20.0)
                } else {
                    r
                };
                (r, far, rng.random_range(0.0..0.5))
            })
            .collect();
        (0..n)
            .map(|_| {
                let frames = rng.random_range(1u32..=3);
                let mut img = CellImage {
                    frames,
                    ..CellImage::default()
                };
                for (c, &(near, far, p_far)) in scene.iter().enumerate() {
                    if rng.random_bool(0.12) {
                        continue;
                    }
                    let surface = if rng.random_bool(p_far) { far } else { near };
                    img.cells.push(c as u32);
                    img.range.push(surface + rng.random_range(-0.03f32..0.03));
                    img.reflectivity.push(rng.random_range(0.0f32..100.0));
                    img.hits.push(rng.random_range(1..=frames));
                }
                img
            })
            .collect()
    }

    #[test]
    fn blocks_of_one_ring_or_of_all_give_the_same_reference() {
        // 16 rings of 360 cells; images longer than a read-ahead, blocks
        // of one ring against one block of all. Three seeds.
        let mut spec = LidarSpec::vlp16();
        spec.azimuth_resolution_deg = 1.0;
        let g = CellGrid::new(&spec);
        let p = FitParams::default().check().unwrap();
        for seed in 1..=3 {
            let imgs = noisy_images(&g, 6 + seed as usize, seed);
            assert!(imgs.iter().all(|m| m.cells.len() > READ_CHUNK));
            let mem = MemoryImages(imgs.iter().collect());
            let Ok(one) = ClearReference::build_blocks(g.clone(), &mem, &p, usize::MAX);
            let Ok(rings) = ClearReference::build_blocks(g.clone(), &mem, &p, 1);
            let Ok(three) = ClearReference::build_blocks(g.clone(), &mem, &p, 3 * 360 * imgs.len());
            assert!(same(&rings, &one), "seed {seed}: a ring per block differs");
            assert!(
                same(&three, &one),
                "seed {seed}: three rings per block differ"
            );
            // The scene is not trivial: some cells out, some scored.
            assert!(one.present().len() > g.cells() / 2 && one.present().len() < g.cells());
            assert!(one.leave_one_out().iter().all(|&(k, t)| k > 0 && k < t));
        }
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

    /// One ring of 12 bins seeing three walls (10, 20, 30 m, then 10 m
    /// again): five recordings on the grid and one whose firings all fall
    /// one bin on (each bin holds the return of the bin before it).
    fn walls_with_one_shifted(shift: usize) -> Vec<CellImage> {
        let scene = [
            10.0, 10.0, 10.0, 20.0, 20.0, 20.0, 30.0, 30.0, 30.0, 10.0, 10.0, 10.0,
        ];
        let on_grid: Vec<(u32, f32, f32)> = (0..12).map(|c| (c as u32, scene[c], 5.0)).collect();
        let shifted: Vec<(u32, f32, f32)> = (0..12)
            .map(|c| (c as u32, scene[(c + 12 - shift) % 12], 5.0))
            .collect();
        let mut imgs = vec![img(&on_grid); 5];
        imgs.push(img(&shifted));
        imgs
    }

    fn one_ring_grid() -> CellGrid {
        let mut spec = LidarSpec::vlp16();
        spec.elevation_deg = vec![0.0];
        spec.azimuth_resolution_deg = 30.0;
        CellGrid::new(&spec)
    }

    #[test]
    fn a_revolution_one_bin_off_pairs_whole_by_a_chain_of_shifts() {
        let p = FitParams::default().check().unwrap();
        let r = ClearReference::build(one_ring_grid(), &walls_with_one_shifted(1), &p);
        // Every bin pairs with the bin before it; only the pair across the
        // ring's seam (bin 0 with bin 11) is out of reach.
        assert_eq!(r.leave_one_out()[5], (11, 12));
        assert!(r.leave_one_out()[..5].iter().all(|&x| x == (12, 12)));
        // Without neighbours it loses the three bins at the walls' edges.
        let p0 = FitParams::default().azimuth_neighbours(0).check().unwrap();
        let r0 = ClearReference::build(one_ring_grid(), &walls_with_one_shifted(1), &p0);
        assert_eq!(r0.leave_one_out()[5], (9, 12));
    }

    #[test]
    fn a_revolution_two_bins_off_needs_two_neighbours() {
        let imgs = walls_with_one_shifted(2);
        let p1 = FitParams::default().check().unwrap();
        let r1 = ClearReference::build(one_ring_grid(), &imgs, &p1);
        // Two bins off, one neighbour: each wall's first return lies two
        // bins past the edge and pairs nowhere (bins 4, 7, 10), and four
        // 10 m returns (bins 0–3) compete for three 10 m cells.
        assert_eq!(r1.leave_one_out()[5], (8, 12));
        let p2 = FitParams::default().azimuth_neighbours(2).check().unwrap();
        let r2 = ClearReference::build(one_ring_grid(), &imgs, &p2);
        assert_eq!(r2.leave_one_out()[5], (10, 12));
    }

    #[test]
    fn a_bin_holding_two_returns_pairs_with_its_empty_neighbour() {
        let p = FitParams::default().check().unwrap();
        let mut imgs = walls_with_one_shifted(0);
        // The last recording's firing for bin 4 fell into bin 3 (both on the
        // 20 m wall): bin 3 holds two returns, bin 4 none.
        let last = imgs.last_mut().unwrap();
        last.cells.remove(4);
        last.range.remove(4);
        last.reflectivity.remove(4);
        last.hits.remove(4);
        last.hits[3] = 2;
        let r = ClearReference::build(one_ring_grid(), &imgs, &p);
        assert_eq!(r.leave_one_out()[5], (12, 12));
        // Without neighbours bin 4 is lost.
        let p0 = FitParams::default().azimuth_neighbours(0).check().unwrap();
        let r0 = ClearReference::build(one_ring_grid(), &imgs, &p0);
        assert_eq!(r0.leave_one_out()[5], (11, 12));
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
