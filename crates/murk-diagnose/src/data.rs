//! Reading a campaign for diagnosis: the clear reference, and every degraded
//! recording of one weather reduced to what it shows per reference cell.
//!
//! Pairing is murk-fit's own ([`murk_fit::observe`]), so the diagnosis sees
//! exactly the classes the fit saw: per reference cell, how many of its
//! expected returns were kept (*no change*); for each kept return, its
//! measured range and reflectivity, or for a cell that kept many (a
//! `.pcap`'s revolutions) their sums ([`KeptReturns`], in memory up to a
//! budget and beyond it in a temporary file); per recording, the number of ghost and
//! ring returns, also per laser, azimuth sector and range bin
//! ([`NearHistogram`]). Cells whose clear return is hidden behind a nearer weather
//! return (their fate is unknown) are left out of the survival units, as the
//! fit leaves them out.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use murk_campaign::{Campaign, Cell};
use murk_fit::FitValidParams;
use murk_fit::observe::pair_frames_detailed;
use murk_fit::observe::{CellGrid, CellImage, CellPoint, ClearReference, cell_points};
use murk_fit::observe::{
    FitInputs, RecordingInput, measure_geometry, read_lidar_frames, read_scans,
};
use murk_types::{CovariateValue, LidarSpec, PointCloud, PointCovariates, WeatherClass};
use rayon::prelude::*;

use crate::DiagnoseError;

/// A reference cell: the clear return expected in it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellInfo {
    /// Expected returns per recording.
    pub hits: u16,
    /// The clear return's point-level covariates (range, reflectivity, ring,
    /// elevation of the ring, azimuth of the bin centre).
    pub cov: PointCovariates,
    /// Mean of (kept range − reference range) over the clear recordings'
    /// returns paired with this cell, metres: what pairing alone does to the
    /// range (azimuth jitter, neighbour cells, edges), subtracted from the
    /// degraded residuals so that only weather remains.
    pub clear_range_offset: f64,
    /// The same for the log reflectivity ratio.
    pub clear_log_reflectivity_offset: f64,
}

/// One survival unit: a reference cell in one recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Unit {
    /// Reference cell.
    pub cell: u32,
    /// Expected returns: the cell's returns per scan times the recording's
    /// scans (revolutions of a `.pcap`).
    pub trials: u32,
    /// Returns kept (paired).
    pub kept: u32,
}

/// The reference cells and their expected returns per scan, shared by every
/// recording's [`Units`].
pub type SharedCells = std::sync::Arc<[(u32, u16)]>;

/// A recording's survival units, held compactly: a bit per reference cell
/// (is it a unit, or hidden behind a nearer weather return?) and its kept
/// count in the narrowest integer that holds every count of the recording
/// (a bit when every count is 0 or 1).
/// The cells and their expected returns are the reference's, shared by all
/// recordings; a unit's trials are its cell's returns per scan times the
/// recording's scans. Two bits per reference cell for a single scan of a
/// sensor that fires each cell once (about 1.1 bytes when a cell holds
/// several returns), against 12 bytes for a list of [`Unit`]s: at a
/// thousand recordings of HDL-64 size the difference is about a gigabyte.
#[derive(Debug, Clone, PartialEq)]
pub struct Units {
    cells: SharedCells,
    frames: u32,
    /// Bit `j` set: reference cell `j` is a unit (or a hidden cell).
    open: Vec<u64>,
    /// Bit `j` set: reference cell `j`'s clear return was hidden behind a
    /// nearer weather return; it is a unit only when the weather's near
    /// returns replace lost ones ([`Units::count_hidden_as_lost`]). Empty
    /// when no cell was hidden.
    hidden: Vec<u64>,
    /// Hidden cells are units (kept as paired, the rest lost).
    count_hidden: bool,
    kept: KeptCounts,
}

/// Kept counts, one per reference cell (0 where it is not a unit).
#[derive(Debug, Clone, PartialEq)]
enum KeptCounts {
    /// Every count 0 or 1 (a single scan of a sensor firing each cell
    /// once, the common case): a bit per cell.
    Bit(Vec<u64>),
    U8(Vec<u8>),
    U16(Vec<u16>),
    U32(Vec<u32>),
}

impl KeptCounts {
    fn get(&self, j: usize) -> u32 {
        match self {
            KeptCounts::Bit(v) => (v[j / 64] >> (j % 64) & 1) as u32,
            KeptCounts::U8(v) => v[j] as u32,
            KeptCounts::U16(v) => v[j] as u32,
            KeptCounts::U32(v) => v[j],
        }
    }

    fn bytes(&self) -> usize {
        match self {
            KeptCounts::Bit(v) => 8 * v.len(),
            KeptCounts::U8(v) => v.len(),
            KeptCounts::U16(v) => 2 * v.len(),
            KeptCounts::U32(v) => 4 * v.len(),
        }
    }
}

impl Units {
    /// The units of a recording of `frames` scans: `unit(j)` says whether
    /// reference cell `j` (of `cells`) is a unit and, if so, its kept
    /// count.
    pub fn new(cells: SharedCells, frames: u32, unit: impl Fn(usize) -> Option<u32>) -> Units {
        Units::with_hidden(cells, frames, unit, |_| None)
    }

    /// [`Units::new`] with the hidden cells: `hidden(j)` is `Some(kept)`
    /// for a reference cell whose clear return was hidden behind a nearer
    /// weather return (not a unit until [`Units::count_hidden_as_lost`]).
    pub fn with_hidden(
        cells: SharedCells,
        frames: u32,
        unit: impl Fn(usize) -> Option<u32>,
        hidden: impl Fn(usize) -> Option<u32>,
    ) -> Units {
        let n = cells.len();
        let mut open = vec![0u64; n.div_ceil(64)];
        let mut hide = Vec::new();
        let mut counts = vec![0u32; n];
        for (j, k) in counts.iter_mut().enumerate() {
            if let Some(kept) = unit(j) {
                open[j / 64] |= 1 << (j % 64);
                *k = kept;
            } else if let Some(kept) = hidden(j) {
                if hide.is_empty() {
                    hide = vec![0u64; n.div_ceil(64)];
                }
                open[j / 64] |= 1 << (j % 64);
                hide[j / 64] |= 1 << (j % 64);
                *k = kept;
            }
        }
        let max = counts.iter().copied().max().unwrap_or(0);
        let kept = if max <= 1 {
            let mut bits = vec![0u64; n.div_ceil(64)];
            for (j, &k) in counts.iter().enumerate() {
                bits[j / 64] |= (k as u64) << (j % 64);
            }
            KeptCounts::Bit(bits)
        } else if max <= u8::MAX as u32 {
            KeptCounts::U8(counts.iter().map(|&k| k as u8).collect())
        } else if max <= u16::MAX as u32 {
            KeptCounts::U16(counts.iter().map(|&k| k as u16).collect())
        } else {
            KeptCounts::U32(counts)
        };
        Units {
            cells,
            frames,
            open,
            hidden: hide,
            count_hidden: false,
            kept,
        }
    }

    /// Makes the hidden cells units: the weather's near returns replace
    /// the returns it loses (the fit's occlusion test,
    /// [`murk_types::OcclusionTest`]), so a hidden return is a lost one, as
    /// the fit then counts it.
    pub fn count_hidden_as_lost(&mut self) {
        self.count_hidden = true;
    }

    /// Bit `w` of the units: open, and not hidden unless hidden cells count.
    #[inline]
    fn word(&self, w: usize) -> u64 {
        match self.hidden.get(w) {
            Some(&h) if !self.count_hidden => self.open[w] & !h,
            _ => self.open[w],
        }
    }

    /// The units in ascending cell order.
    pub fn iter(&self) -> impl Iterator<Item = Unit> + '_ {
        self.cells
            .iter()
            .enumerate()
            .filter(|(j, _)| self.word(j / 64) >> (j % 64) & 1 == 1)
            .map(|(j, &(cell, hits))| Unit {
                cell,
                trials: hits as u32 * self.frames,
                kept: self.kept.get(j),
            })
    }

    /// Number of units.
    pub fn len(&self) -> usize {
        (0..self.open.len())
            .map(|w| self.word(w).count_ones() as usize)
            .sum()
    }

    /// Whether there is no unit.
    pub fn is_empty(&self) -> bool {
        (0..self.open.len()).all(|w| self.word(w) == 0)
    }

    /// Bytes the recording's units hold on the heap (the shared cells
    /// not counted).
    pub fn heap_bytes(&self) -> usize {
        8 * (self.open.len() + self.hidden.len()) + self.kept.bytes()
    }
}

/// A kept (paired) return.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kept {
    /// Reference cell it paired with.
    pub cell: u32,
    /// Measured range, metres.
    pub range: f32,
    /// Measured calibrated reflectivity.
    pub reflectivity: f32,
}

/// The kept returns of one reference cell of a recording that kept
/// [`SUM_FROM`] or more there (a `.pcap` of many revolutions keeps one per
/// revolution): their count and the sums a residual needs, centred on the
/// reference so the sums stay small. Every consumer of kept returns is a
/// sum over them (means, mean squares, least squares, binned sums), so
/// these are sufficient, at 40 bytes per cell instead of 12 per return.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KeptCell {
    /// Reference cell they paired with.
    pub cell: u32,
    /// Kept returns (≥ [`SUM_FROM`]).
    pub n: u32,
    /// Σ (measured range − the cell's reference range), metres.
    pub range: f64,
    /// Σ of its squares.
    pub range_sq: f64,
    /// Σ [`log_ratio`] (measured, the cell's reference reflectivity).
    pub log_ratio: f64,
    /// Σ of its squares.
    pub log_ratio_sq: f64,
}

/// Bytes a [`Kept`] takes in memory and in a spill file (cell, range and
/// reflectivity, little-endian).
const KEPT_BYTES: usize = 12;
/// Bytes a [`KeptCell`] takes (cell, count, four sums).
const KEPT_CELL_BYTES: usize = 40;
/// Returns of one cell from which they are held as a [`KeptCell`]: where 40
/// bytes of sums take less than 12 per return.
pub const SUM_FROM: usize = 4;

/// The file the kept returns of a diagnosis spill to: an anonymous
/// temporary file (unlinked at creation where the system allows, so a
/// killed run leaves nothing), written once while the campaign loads and
/// read back, one recording at a time, by every pass over kept returns.
///
/// A read that fails (the disk, not the data) is latched here instead of
/// threaded through every pass: the pass sees no kept returns for that
/// recording, and [`Loaded::spill_error`] turns the latched error into the
/// diagnosis's error before anything is reported.
#[derive(Debug)]
pub struct SpillFile {
    file: std::fs::File,
    /// Where it was created (for messages).
    dir: PathBuf,
    error: std::sync::Mutex<Option<String>>,
}

impl SpillFile {
    /// Creates the anonymous spill file in `dir` (the system's temporary
    /// folder when `None`).
    pub fn create(dir: Option<&Path>) -> Result<SpillFile, DiagnoseError> {
        let dir = dir.map_or_else(std::env::temp_dir, Path::to_path_buf);
        let file = tempfile::tempfile_in(&dir).map_err(|e| DiagnoseError::Read {
            path: dir.clone(),
            reason: format!("cannot create the spill file of the kept returns: {e}"),
        })?;
        Ok(SpillFile {
            file,
            dir,
            error: std::sync::Mutex::new(None),
        })
    }

    fn latch(&self, reason: String) {
        let mut e = self.error.lock().unwrap_or_else(|p| p.into_inner());
        e.get_or_insert(reason);
    }

    /// The first read error, if any.
    fn error(&self) -> Option<String> {
        self.error.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    fn read_at(&self, buf: &mut [u8], offset: u64) -> std::io::Result<()> {
        murk_io::read_exact_at(&self.file, buf, offset)
    }
}

/// A recording's kept returns: one [`Kept`] per return of a reference cell
/// that kept fewer than [`SUM_FROM`], in pairing order, and one
/// [`KeptCell`] per cell that kept more (their sums), so a recording holds
/// at most 12 bytes per return and 40 per cell. Held in memory, or in the diagnosis's
/// [`SpillFile`] (when the campaign's kept returns exceed the memory
/// budget, `DiagnoseParams::kept_memory_mb`), read back by [`Self::get`].
/// Either way the same values in the same order, so a diagnosis gives the
/// same bytes spilled or not.
#[derive(Debug, Clone)]
pub struct KeptReturns {
    store: KeptStore,
    /// Kept returns in all (listed ones and the cells' counts).
    returns: usize,
}

#[derive(Debug, Clone)]
enum KeptStore {
    Memory(Vec<Kept>, Vec<KeptCell>),
    Spilled {
        file: std::sync::Arc<SpillFile>,
        offset: u64,
        singles: usize,
        cells: usize,
    },
}

/// A recording's kept returns as read: the returns listed one by one and
/// the cells of many ([`KeptReturns`]).
#[derive(Debug, Clone, PartialEq)]
pub struct KeptView<'a> {
    /// Returns of cells that kept fewer than [`SUM_FROM`], in pairing
    /// order.
    pub singles: std::borrow::Cow<'a, [Kept]>,
    /// Cells of [`SUM_FROM`] kept returns or more, in cell order.
    pub cells: std::borrow::Cow<'a, [KeptCell]>,
}

impl PartialEq for KeptReturns {
    fn eq(&self, other: &Self) -> bool {
        self.returns == other.returns
            && match (&self.store, &other.store) {
                (KeptStore::Memory(a, b), KeptStore::Memory(c, d)) => a == c && b == d,
                (
                    KeptStore::Spilled {
                        file,
                        offset,
                        singles,
                        cells,
                    },
                    KeptStore::Spilled {
                        file: f2,
                        offset: o2,
                        singles: s2,
                        cells: c2,
                    },
                ) => std::sync::Arc::ptr_eq(file, f2) && (offset, singles, cells) == (o2, s2, c2),
                _ => false,
            }
    }
}

impl KeptReturns {
    /// A recording's kept returns, in pairing order, held in memory: the
    /// returns of a cell that kept fewer than [`SUM_FROM`] as they are,
    /// those of a cell that kept more as the cell's sums, centred on
    /// `cells`' reference range and reflectivity (every pair is with a
    /// reference cell). `kept_per_cell[c]` is how many of them cell `c` kept
    /// (the pairing tally's count), so only the summed cells' returns are
    /// gathered.
    pub fn new(kept: Vec<Kept>, cells: &[Option<CellInfo>], kept_per_cell: &[u32]) -> KeptReturns {
        let returns = kept.len();
        let summed = |c: u32| kept_per_cell[c as usize] as usize >= SUM_FROM;
        // The summed cells' returns by cell; stable, so in pairing order
        // within a cell.
        let mut order: Vec<usize> = (0..kept.len()).filter(|&i| summed(kept[i].cell)).collect();
        order.sort_by_key(|&i| kept[i].cell);
        let mut sums = Vec::new();
        for group in order.chunk_by(|&a, &b| kept[a].cell == kept[b].cell) {
            let cell = kept[group[0]].cell;
            debug_assert_eq!(group.len(), kept_per_cell[cell as usize] as usize);
            let info = cells[cell as usize]
                .as_ref()
                .expect("pairs are reference cells");
            let mut s = KeptCell {
                cell,
                n: group.len() as u32,
                range: 0.0,
                range_sq: 0.0,
                log_ratio: 0.0,
                log_ratio_sq: 0.0,
            };
            for &i in group {
                let d = kept[i].range as f64 - info.cov.range;
                let l = log_ratio(kept[i].reflectivity as f64, info.cov.reflectivity);
                s.range += d;
                s.range_sq += d * d;
                s.log_ratio += l;
                s.log_ratio_sq += l * l;
            }
            sums.push(s);
        }
        let mut singles: Vec<Kept> = kept.into_iter().filter(|k| !summed(k.cell)).collect();
        // The collect may reuse the whole list's allocation.
        singles.shrink_to_fit();
        sums.shrink_to_fit();
        KeptReturns {
            store: KeptStore::Memory(singles, sums),
            returns,
        }
    }

    /// Number of kept returns.
    pub fn len(&self) -> usize {
        self.returns
    }

    /// Whether there is none.
    pub fn is_empty(&self) -> bool {
        self.returns == 0
    }

    /// Whether they are in the spill file.
    pub fn is_spilled(&self) -> bool {
        matches!(self.store, KeptStore::Spilled { .. })
    }

    /// Bytes they take, in memory or in the spill file (12 per listed
    /// return, 40 per cell of sums).
    pub fn bytes(&self) -> usize {
        let (singles, cells) = match &self.store {
            KeptStore::Memory(a, b) => (a.len(), b.len()),
            KeptStore::Spilled { singles, cells, .. } => (*singles, *cells),
        };
        KEPT_BYTES * singles + KEPT_CELL_BYTES * cells
    }

    /// Bytes they hold in memory (0 once spilled).
    pub fn heap_bytes(&self) -> usize {
        match &self.store {
            KeptStore::Memory(a, b) => {
                std::mem::size_of::<Kept>() * a.capacity()
                    + std::mem::size_of::<KeptCell>() * b.capacity()
            }
            KeptStore::Spilled { .. } => 0,
        }
    }

    /// The kept returns: borrowed from memory, or read from the spill
    /// file. A failed read gives none and is latched (see [`SpillFile`]).
    pub fn get(&self) -> KeptView<'_> {
        use std::borrow::Cow;
        let (file, offset, singles, cells) = match &self.store {
            KeptStore::Memory(a, b) => {
                return KeptView {
                    singles: Cow::Borrowed(a),
                    cells: Cow::Borrowed(b),
                };
            }
            KeptStore::Spilled {
                file,
                offset,
                singles,
                cells,
            } => (file, *offset, *singles, *cells),
        };
        let mut buf = vec![0u8; singles * KEPT_BYTES + cells * KEPT_CELL_BYTES];
        if let Err(e) = file.read_at(&mut buf, offset) {
            file.latch(format!(
                "reading {} kept returns back at byte {offset}: {e}",
                self.returns
            ));
            return KeptView {
                singles: Cow::Owned(Vec::new()),
                cells: Cow::Owned(Vec::new()),
            };
        }
        let w4 = |b: &[u8], i: usize| [b[i], b[i + 1], b[i + 2], b[i + 3]];
        let f8 = |b: &[u8], i: usize| {
            let mut w = [0u8; 8];
            w.copy_from_slice(&b[i..i + 8]);
            f64::from_le_bytes(w)
        };
        let (a, b) = buf.split_at(singles * KEPT_BYTES);
        KeptView {
            singles: Cow::Owned(
                a.chunks_exact(KEPT_BYTES)
                    .map(|b| Kept {
                        cell: u32::from_le_bytes(w4(b, 0)),
                        range: f32::from_le_bytes(w4(b, 4)),
                        reflectivity: f32::from_le_bytes(w4(b, 8)),
                    })
                    .collect(),
            ),
            cells: Cow::Owned(
                b.chunks_exact(KEPT_CELL_BYTES)
                    .map(|b| KeptCell {
                        cell: u32::from_le_bytes(w4(b, 0)),
                        n: u32::from_le_bytes(w4(b, 4)),
                        range: f8(b, 8),
                        range_sq: f8(b, 16),
                        log_ratio: f8(b, 24),
                        log_ratio_sq: f8(b, 32),
                    })
                    .collect(),
            ),
        }
    }

    /// Moves in-memory returns to the end of `file` (at `*end`, which it
    /// advances); spilled ones stay where they are.
    fn spill(
        &mut self,
        file: &std::sync::Arc<SpillFile>,
        end: &mut u64,
    ) -> Result<(), DiagnoseError> {
        use std::io::Write;
        let KeptStore::Memory(a, b) = &self.store else {
            return Ok(());
        };
        let mut buf = Vec::with_capacity(self.bytes());
        for k in a {
            buf.extend_from_slice(&k.cell.to_le_bytes());
            buf.extend_from_slice(&k.range.to_le_bytes());
            buf.extend_from_slice(&k.reflectivity.to_le_bytes());
        }
        for c in b {
            buf.extend_from_slice(&c.cell.to_le_bytes());
            buf.extend_from_slice(&c.n.to_le_bytes());
            for x in [c.range, c.range_sq, c.log_ratio, c.log_ratio_sq] {
                buf.extend_from_slice(&x.to_le_bytes());
            }
        }
        (&file.file)
            .write_all(&buf)
            .map_err(|e| DiagnoseError::Read {
                path: file.dir.clone(),
                reason: format!("cannot write kept returns to the spill file there: {e}"),
            })?;
        self.store = KeptStore::Spilled {
            file: std::sync::Arc::clone(file),
            offset: *end,
            singles: a.len(),
            cells: b.len(),
        };
        *end += buf.len() as u64;
        Ok(())
    }
}

/// A degraded recording as the diagnosis sees it.
#[derive(Debug, Clone, PartialEq)]
pub struct Rec {
    /// Recording id.
    pub id: String,
    /// Position in `weather.csv`.
    pub order: usize,
    /// MOR, metres (the rule set's visibility sensors).
    pub mor: f64,
    /// Every `weather.csv` column with a value (the timestamp as seconds
    /// since 1970).
    pub scan: BTreeMap<String, CovariateValue>,
    /// The point-cloud file.
    pub lidar: PathBuf,
    /// Survival units.
    pub units: Units,
    /// Kept returns (in memory or spilled; [`KeptReturns::get`]).
    pub kept: KeptReturns,
    /// Ghost and ring returns measured.
    pub near: u64,
    /// The same returns by laser, azimuth sector and range bin.
    pub near_bins: NearHistogram,
    /// Index of the nearest clear recording in time (into `Loaded::clear`).
    pub clear: usize,
}

/// Azimuth sectors of a [`NearHistogram`] (30° each, the first from 0°).
pub const AZIMUTH_SECTORS: usize = 12;
/// Range bins of a [`NearHistogram`], [`RANGE_BIN_M`] wide from 0 m (the
/// last one open above).
pub const RANGE_BINS: usize = 12;
/// Width of a range bin, metres.
pub const RANGE_BIN_M: f64 = 1.0;

/// The ghost and ring returns of one recording (measured, or the mean of its
/// simulations) counted per laser, per azimuth sector and per range bin: a
/// fixed-size summary (three marginal histograms), not the points. The
/// laser and azimuth are those of the return's cell, the range its own.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct NearHistogram {
    /// Per ring (laser id), one entry per ring of the grid.
    pub ring: Vec<f64>,
    /// Per azimuth sector ([`AZIMUTH_SECTORS`]).
    pub sector: [f64; AZIMUTH_SECTORS],
    /// Per range bin ([`RANGE_BINS`]).
    pub range: [f64; RANGE_BINS],
}

impl NearHistogram {
    /// Counts the ghost and ring returns of a pairing tally on `grid`.
    pub fn of_tally(tally: &murk_fit::observe::RecordingTally, grid: &CellGrid) -> NearHistogram {
        let mut h = NearHistogram {
            ring: vec![0.0; grid.rings()],
            ..NearHistogram::default()
        };
        // `occluded` holds the cells of the ghost and ring returns.
        for &c in &tally.occluded {
            let c = c as usize;
            if let Some(x) = h.ring.get_mut(grid.ring_of(c)) {
                *x += 1.0;
            }
            h.sector[Self::sector_of(grid.azimuth_deg(c))] += 1.0;
        }
        for &(r, _) in tally.ghosts.iter().chain(&tally.rings) {
            h.range[Self::range_bin_of(r as f64)] += 1.0;
        }
        h
    }

    /// The sector of an azimuth in degrees.
    pub fn sector_of(azimuth_deg: f64) -> usize {
        let a = azimuth_deg.rem_euclid(360.0);
        ((a / (360.0 / AZIMUTH_SECTORS as f64)) as usize).min(AZIMUTH_SECTORS - 1)
    }

    /// Centre of sector `k`, degrees.
    pub fn sector_centre(k: usize) -> f64 {
        (k as f64 + 0.5) * 360.0 / AZIMUTH_SECTORS as f64
    }

    /// Centre of range bin `k`, metres.
    pub fn range_centre(k: usize) -> f64 {
        (k as f64 + 0.5) * RANGE_BIN_M
    }

    /// The range bin of a range in metres.
    pub fn range_bin_of(range_m: f64) -> usize {
        ((range_m.max(0.0) / RANGE_BIN_M) as usize).min(RANGE_BINS - 1)
    }

    /// Adds `o` times `w` (for means over simulations).
    pub fn add_scaled(&mut self, o: &NearHistogram, w: f64) {
        if self.ring.len() < o.ring.len() {
            self.ring.resize(o.ring.len(), 0.0);
        }
        for (a, b) in self.ring.iter_mut().zip(&o.ring) {
            *a += w * b;
        }
        for (a, b) in self.sector.iter_mut().zip(&o.sector) {
            *a += w * b;
        }
        for (a, b) in self.range.iter_mut().zip(&o.range) {
            *a += w * b;
        }
    }
}

/// A clear recording. Its points are not held (a campaign's clear clouds
/// would grow memory with every recording): [`ClearRec::read`] reads them
/// again when a simulation needs them.
#[derive(Debug, Clone, PartialEq)]
pub struct ClearRec {
    /// Recording id.
    pub id: String,
    /// Position in `weather.csv`.
    pub order: usize,
    /// The point-cloud file.
    pub lidar: PathBuf,
    /// Its scans (revolutions of a `.pcap`, 1 for any other file).
    pub frames: u32,
}

impl ClearRec {
    /// Its points in calibrated reflectivity (the input of the
    /// simulations), read from its file as [`load`] read them.
    pub fn read(&self, spec: &LidarSpec) -> Result<PointCloud, DiagnoseError> {
        read_calibrated(&self.lidar, spec)
    }
}

/// Recordings read at once where `load` reads recordings in order and
/// folds what they give in that order: enough to keep every thread busy,
/// few enough that memory does not grow with the campaign.
const READ_CHUNK: usize = 16;

/// Degraded recordings read at once by [`load_with`] before their kept
/// returns are accounted against the memory budget.
const LOAD_CHUNK: usize = 32;

/// A campaign read for one weather.
#[derive(Debug, Clone)]
pub struct Loaded {
    /// The weather.
    pub weather: WeatherClass,
    /// The LiDAR.
    pub spec: LidarSpec,
    /// The clear reference.
    pub reference: ClearReference,
    /// Per cell of the grid (`None` outside the reference).
    pub cells: Vec<Option<CellInfo>>,
    /// The clear recordings.
    pub clear: Vec<ClearRec>,
    /// The degraded recordings of the weather, in campaign order.
    pub recs: Vec<Rec>,
    /// The scan-level covariate names: `mor`, then every `weather.csv`
    /// column (with `timestamp`) in header order.
    pub columns: Vec<String>,
    /// The fit's view of the selected recordings.
    pub inputs: FitInputs,
    /// The fit's clear part of the campaign (reference, digests, no
    /// images) under each parameter set the baselines will be fitted with,
    /// mapped once for every fit ([`load_with`]).
    pub clear_parts: Vec<std::sync::Arc<murk_fit::ClearPart>>,
    /// Recordings of the weather left out, with the reason.
    pub skipped: Vec<(String, String)>,
    /// The file the kept returns beyond the memory budget went to
    /// ([`KeptMemory`]), if any did.
    pub spill: Option<std::sync::Arc<SpillFile>>,
}

impl Loaded {
    /// Makes every recording's hidden cells survival units
    /// ([`Units::count_hidden_as_lost`]): the weather's near returns
    /// replace the returns it loses, as the baseline table's occlusion test
    /// found.
    pub fn count_hidden_as_lost(&mut self) {
        for r in &mut self.recs {
            r.units.count_hidden_as_lost();
        }
    }

    /// The first failed read of spilled kept returns, as the diagnosis's
    /// error (see [`SpillFile`]); `Ok` when none failed or nothing spilled.
    pub fn spill_error(&self) -> Result<(), DiagnoseError> {
        match self.spill.as_ref().and_then(|f| f.error().map(|e| (f, e))) {
            Some((f, reason)) => Err(DiagnoseError::Read {
                path: f.dir.clone(),
                reason: format!("the spill file of the kept returns there: {reason}"),
            }),
            None => Ok(()),
        }
    }
}

/// Reflectivity below which the log ratio is floored.
pub const REFLECTIVITY_FLOOR: f64 = 0.5;

/// `ln(measured / reference)` with both floored at [`REFLECTIVITY_FLOOR`].
pub fn log_ratio(measured: f64, reference: f64) -> f64 {
    measured.max(REFLECTIVITY_FLOOR).ln() - reference.max(REFLECTIVITY_FLOOR).ln()
}

/// Reads a recording into grid cells and pairs it with the reference.
fn read_and_pair(
    r: &RecordingInput,
    spec: &LidarSpec,
    reference: &ClearReference,
    params: &FitValidParams,
) -> Result<PairedRecording, DiagnoseError> {
    let (points, frames, _) =
        read_lidar_frames(&r.lidar, spec, reference.grid()).map_err(|e| DiagnoseError::Read {
            path: r.lidar.clone(),
            reason: e.to_string(),
        })?;
    let (tally, pairs) = pair_frames_detailed(reference, &points, frames, params);
    Ok((points, tally, pairs))
}

type PairedRecording = (
    Vec<murk_fit::observe::CellPoint>,
    murk_fit::observe::RecordingTally,
    Vec<murk_fit::observe::Pair>,
);

/// Reads a point cloud in calibrated reflectivity: the revolutions the fit
/// pairs (a `.pcap`'s full revolutions, joined; any other file whole).
pub fn read_calibrated(path: &Path, spec: &LidarSpec) -> Result<PointCloud, DiagnoseError> {
    read_revolutions(path, spec).map(|(c, _)| c)
}

/// [`read_calibrated`] and the number of scans joined (revolutions of a
/// `.pcap`, 1 for any other file), as murk-fit's `read_scans` reads them.
pub fn read_revolutions(path: &Path, spec: &LidarSpec) -> Result<(PointCloud, u32), DiagnoseError> {
    let err = |reason: String| DiagnoseError::Read {
        path: path.to_path_buf(),
        reason,
    };
    let (scans, _) = read_scans(path, spec).map_err(|e| err(e.to_string()))?;
    let mut cloud = PointCloud::default();
    if let Some(f) = scans.first() {
        cloud.intensity_scale = f.intensity_scale;
    }
    for f in &scans {
        cloud
            .extend_from(f)
            .map_err(|e| err(format!("cannot join the capture's revolutions: {e}")))?;
    }
    Ok((cloud, scans.len().max(1) as u32))
}

/// Reads `campaign` for `weather`: the reference from every clear recording
/// and the observations of every degraded recording of the weather (no
/// clear part mapped for fits: [`load_with`]).
pub fn load(
    campaign: &Campaign,
    weather: WeatherClass,
    params: &FitValidParams,
) -> Result<Loaded, DiagnoseError> {
    load_with(campaign, weather, params, &[], &KeptMemory::default())
}

/// Where [`load_with`] holds the degraded recordings' kept returns (12 bytes
/// each: at a thousand recordings of 100 k points, over a gigabyte).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KeptMemory {
    /// Bytes of kept returns held in memory; the recordings (in campaign
    /// order) whose returns would go beyond it spill to a [`SpillFile`].
    /// `u64::MAX` (the default) holds everything, 0 spills everything.
    pub budget_bytes: u64,
    /// The folder of the spill file (the system's temporary folder when
    /// `None`).
    pub spill_dir: Option<PathBuf>,
}

impl Default for KeptMemory {
    fn default() -> Self {
        KeptMemory {
            budget_bytes: u64::MAX,
            spill_dir: None,
        }
    }
}

/// [`load`], with the fit's clear part ([`Loaded::clear_parts`]) mapped
/// under each of `fit_params`, the parameters the baselines will be
/// fitted with. They are mapped before any degraded recording is read, so
/// that their clear images (released once the reference is built) are
/// never held beside the degraded recordings' summaries, and no baseline
/// fit reads a clear recording again.
pub fn load_with(
    campaign: &Campaign,
    weather: WeatherClass,
    params: &FitValidParams,
    fit_params: &[FitValidParams],
    memory: &KeptMemory,
) -> Result<Loaded, DiagnoseError> {
    let inputs = FitInputs::from_campaign(campaign);
    let spec = inputs.lidar.clone();
    // The fit's grid: the firing geometry measured from the clear recordings.
    let geometry = if params.declared_geometry() {
        murk_fit::observe::declared(&spec)
    } else {
        measure_geometry(&inputs)
            .map_err(|e| DiagnoseError::Campaign {
                weather: weather.to_string(),
                reason: e.to_string(),
            })?
            .0
    };
    let grid = CellGrid::from_geometry(&geometry);
    let order: BTreeMap<&str, usize> = campaign
        .recordings()
        .iter()
        .enumerate()
        .map(|(i, r)| (r.id(), i))
        .collect();
    let clear_in: Vec<&RecordingInput> = inputs
        .recordings
        .iter()
        .filter(|r| r.class == WeatherClass::Clear)
        .collect();
    if clear_in.is_empty() {
        return Err(DiagnoseError::Campaign {
            weather: weather.to_string(),
            reason: "no clear recording was selected (rules and review): nothing to simulate from"
                .into(),
        });
    }
    // Each clear recording is read twice, its points held only while it is
    // read: once for its cell image (the reference is built from every
    // image, as murk-fit's `build_reference` builds it), once, against the
    // finished reference, for what pairing does to it (the per-cell
    // offsets).
    let clear_points = |r: &RecordingInput| -> Result<(Vec<CellPoint>, u32), DiagnoseError> {
        let (cloud, frames) = read_revolutions(&r.lidar, &spec)?;
        let points = cell_points(&grid, &cloud, &r.lidar).map_err(|e| DiagnoseError::Read {
            path: r.lidar.clone(),
            reason: e.to_string(),
        })?;
        Ok((points, frames))
    };
    // The baselines' clear parts: one per parameter set, except that sets
    // differing only in what a fit's finish reads share one
    // (`ClearPart::serves`: the folds' fits and the fit on every recording).
    let mut clear_parts: Vec<std::sync::Arc<murk_fit::ClearPart>> =
        Vec::with_capacity(fit_params.len());
    for p in fit_params {
        if let Some(part) = clear_parts.iter().find(|c| c.serves(p)) {
            clear_parts.push(std::sync::Arc::clone(part));
            continue;
        }
        let part = p.map_clear(&inputs).map_err(|e| DiagnoseError::Fit {
            what: "the clear recordings".into(),
            source: Box::new(e),
        })?;
        clear_parts.push(std::sync::Arc::new(part));
    }
    // The reference: a clear part's where one serves these parameters on
    // this grid (the same images and rule, so the same reference; reading
    // every clear recording into images once more would only cost time
    // and memory), else built here.
    let from_part = match clear_parts.iter().find(|c| c.serves(params)) {
        Some(part) => Some(part.reference().map_err(|e| DiagnoseError::Fit {
            what: "the clear recordings".into(),
            source: Box::new(e),
        })?),
        None => None,
    };
    let (reference, clear_frames) = match from_part.filter(|r| *r.grid() == grid) {
        Some(r) => {
            let frames: Vec<u32> = r.frames().iter().map(|&f| f as u32).collect();
            ((*r).clone(), frames)
        }
        None => {
            let read: Vec<Result<(CellImage, u32), DiagnoseError>> = clear_in
                .par_iter()
                .map(|r| {
                    let (points, frames) = clear_points(r)?;
                    Ok((
                        CellImage::from_frames(&points, frames, grid.cells()),
                        frames,
                    ))
                })
                .collect();
            let mut images = Vec::with_capacity(read.len());
            let mut clear_frames = Vec::with_capacity(read.len());
            for r in read {
                let (image, frames) = r?;
                images.push(image);
                clear_frames.push(frames);
            }
            (
                ClearReference::build(grid.clone(), &images, params),
                clear_frames,
            )
        }
    };
    // What pairing does to range and reflectivity in clear weather, per
    // cell, summed in recording order (a few recordings at a time).
    let mut off = vec![(0.0f64, 0.0f64, 0u32); grid.cells()];
    for chunk in clear_in.chunks(READ_CHUNK) {
        // Per kept return of a clear recording: cell, range and log
        // reflectivity offsets.
        type Offsets = Vec<(u32, f64, f64)>;
        let offsets: Vec<Result<Offsets, DiagnoseError>> = chunk
            .par_iter()
            .map(|r| {
                let (points, frames) = clear_points(r)?;
                let (_, pairs) = pair_frames_detailed(&reference, &points, frames, params);
                Ok(pairs
                    .iter()
                    .map(|p| {
                        let q = points[p.point as usize];
                        let c = p.cell as usize;
                        (
                            p.cell,
                            q.range as f64 - reference.range(c) as f64,
                            log_ratio(q.reflectivity as f64, reference.reflectivity(c) as f64),
                        )
                    })
                    .collect())
            })
            .collect();
        for o in offsets {
            for (c, dr, dl) in o? {
                let e = &mut off[c as usize];
                e.0 += dr;
                e.1 += dl;
                e.2 += 1;
            }
        }
    }
    let mut cells = vec![None; grid.cells()];
    for &c in reference.present() {
        let c = c as usize;
        let ring = grid.ring_of(c) as u16;
        cells[c] = Some(CellInfo {
            hits: reference.hits(c),
            cov: PointCovariates {
                range: reference.range(c) as f64,
                reflectivity: reference.reflectivity(c) as f64,
                ring,
                elevation: spec.elevation_deg[ring as usize],
                azimuth: grid.azimuth_deg(c),
            },
            clear_range_offset: if off[c].2 > 0 {
                off[c].0 / off[c].2 as f64
            } else {
                0.0
            },
            clear_log_reflectivity_offset: if off[c].2 > 0 {
                off[c].1 / off[c].2 as f64
            } else {
                0.0
            },
        });
    }
    let clear: Vec<ClearRec> = clear_in
        .iter()
        .zip(clear_frames)
        .map(|(r, frames)| ClearRec {
            frames,
            id: r.id.clone(),
            order: order.get(r.id.as_str()).copied().unwrap_or(0),
            lidar: r.lidar.clone(),
        })
        .collect();

    let mut columns = vec!["mor".to_string(), "timestamp".to_string()];
    columns.extend(campaign.columns().iter().map(|c| c.name.clone()));

    let mut skipped = Vec::new();
    let wanted: Vec<&RecordingInput> = inputs
        .recordings
        .iter()
        .filter(|r| r.class == weather)
        .filter(|r| match r.mor {
            Some(m) if m.is_finite() && m > 0.0 => true,
            _ => {
                skipped.push((
                    r.id.clone(),
                    "no MOR from the visibility sensors (outage)".to_string(),
                ));
                false
            }
        })
        .collect();
    let shared: SharedCells = reference
        .present()
        .iter()
        .map(|&c| (c, reference.hits(c as usize)))
        .collect();
    let load_one = |r: &&RecordingInput| -> Result<Rec, DiagnoseError> {
        let (points, tally, pairs) = read_and_pair(r, &spec, &reference, params)?;
        let mut occluded = vec![false; grid.cells()];
        for &c in &tally.occluded {
            occluded[c as usize] = true;
        }
        let units = Units::with_hidden(
            shared.clone(),
            tally.frames,
            |j| {
                let c = shared[j].0 as usize;
                (!occluded[c]).then(|| tally.matched[c])
            },
            |j| {
                let c = shared[j].0 as usize;
                occluded[c].then(|| tally.matched[c])
            },
        );
        let kept = pairs
            .iter()
            .map(|p| {
                let q = points[p.point as usize];
                Kept {
                    cell: p.cell,
                    range: q.range,
                    reflectivity: q.reflectivity,
                }
            })
            .collect();
        let kept = KeptReturns::new(kept, &cells, &tally.matched);
        let rec = campaign
            .recording(&r.id)
            .ok_or_else(|| DiagnoseError::Campaign {
                weather: weather.to_string(),
                reason: format!("recording {} vanished from the campaign", r.id),
            })?;
        let mut scan = BTreeMap::new();
        scan.insert(
            "timestamp".to_string(),
            CovariateValue::Number(rec.timestamp().timestamp() as f64),
        );
        for (name, v) in rec.values() {
            match v {
                Some(Cell::Numeric(x)) => {
                    scan.insert(name.to_string(), CovariateValue::Number(*x));
                }
                Some(Cell::Categorical(t)) => {
                    scan.insert(name.to_string(), CovariateValue::Text(t.clone()));
                }
                None => {}
            }
        }
        let mor = r.mor.unwrap_or(f64::NAN);
        scan.insert("mor".to_string(), CovariateValue::Number(mor));
        let order_j = order.get(r.id.as_str()).copied().unwrap_or(0);
        let nearest = clear
            .iter()
            .enumerate()
            .min_by_key(|(_, c)| (c.order.abs_diff(order_j), c.order))
            .map(|(i, _)| i)
            .unwrap_or(0);
        Ok(Rec {
            id: r.id.clone(),
            order: order_j,
            mor,
            scan,
            lidar: r.lidar.clone(),
            units,
            kept,
            near: (tally.ghosts.len() + tally.rings.len()) as u64,
            near_bins: NearHistogram::of_tally(&tally, &grid),
            clear: nearest,
        })
    };
    // Read in chunks, in parallel within each, and account the kept
    // returns in campaign order: those beyond the budget spill, so memory
    // stays within the budget plus one chunk whatever the campaign's size,
    // and which recordings spill does not depend on the thread count (nor
    // does the output, which is the same spilled or not).
    let mut spill: Option<std::sync::Arc<SpillFile>> = None;
    let (mut held, mut end) = (0u64, 0u64);
    let mut recs = Vec::with_capacity(wanted.len());
    for chunk in wanted.chunks(LOAD_CHUNK) {
        let read: Vec<Result<Rec, DiagnoseError>> = chunk.par_iter().map(load_one).collect();
        for r in read {
            let mut r = r?;
            let bytes = r.kept.bytes() as u64;
            if held.saturating_add(bytes) > memory.budget_bytes {
                let file = match &spill {
                    Some(f) => f,
                    None => spill.insert(std::sync::Arc::new(SpillFile::create(
                        memory.spill_dir.as_deref(),
                    )?)),
                };
                r.kept.spill(file, &mut end)?;
            } else {
                held += bytes;
            }
            recs.push(r);
        }
    }
    Ok(Loaded {
        weather,
        spec,
        reference,
        cells,
        clear,
        recs,
        columns,
        inputs,
        clear_parts,
        skipped,
        spill,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reference cells 0..8 at 10 m + cell, reflectivity 20 + cell.
    fn cells() -> Vec<Option<CellInfo>> {
        (0..8)
            .map(|c| {
                Some(CellInfo {
                    hits: 1,
                    cov: PointCovariates {
                        range: 10.0 + c as f64,
                        reflectivity: 20.0 + c as f64,
                        ring: 0,
                        elevation: 0.0,
                        azimuth: 0.0,
                    },
                    clear_range_offset: 0.0,
                    clear_log_reflectivity_offset: 0.0,
                })
            })
            .collect()
    }

    fn kept(cell: u32, range: f32, reflectivity: f32) -> Kept {
        Kept {
            cell,
            range,
            reflectivity,
        }
    }

    /// Kept returns per cell of [`cells`], as the pairing tally counts them.
    fn counts(v: &[Kept]) -> Vec<u32> {
        let mut n = vec![0; 8];
        for k in v {
            n[k.cell as usize] += 1;
        }
        n
    }

    #[test]
    fn a_cell_of_four_returns_or_more_is_summed_and_the_rest_listed_in_order() {
        let cells = cells();
        // Cell 3 keeps four returns (interleaved with others), cell 5 two:
        // cell 3's are summed, cell 5's listed (two take 24 bytes, sums 40).
        let v = vec![
            kept(6, 16.1, 26.0),
            kept(3, 13.2, 24.0),
            kept(5, 14.9, 25.0),
            kept(1, 11.0, 21.5),
            kept(3, 12.9, 22.0),
            kept(5, 15.0, 0.1),
            kept(3, 13.0, 23.0),
            kept(3, 13.1, 0.2),
        ];
        let k = KeptReturns::new(v.clone(), &cells, &counts(&v));
        assert_eq!(k.len(), 8);
        assert_eq!(k.bytes(), 4 * 12 + 40);
        let g = k.get();
        assert_eq!(
            &*g.singles,
            &[
                kept(6, 16.1, 26.0),
                kept(5, 14.9, 25.0),
                kept(1, 11.0, 21.5),
                kept(5, 15.0, 0.1)
            ]
        );
        assert_eq!(g.cells.len(), 1);
        let c3 = g.cells[0];
        assert_eq!((c3.cell, c3.n), (3, 4));
        let d: Vec<f64> = [13.2f32, 12.9, 13.0, 13.1]
            .iter()
            .map(|&r| r as f64 - 13.0)
            .collect();
        assert!((c3.range - d.iter().sum::<f64>()).abs() < 1e-12);
        assert!((c3.range_sq - d.iter().map(|x| x * x).sum::<f64>()).abs() < 1e-12);
        // The floor of the log ratio holds inside the sums too (0.2).
        let l: Vec<f64> = [24.0, 22.0, 23.0, 0.2]
            .iter()
            .map(|&x| log_ratio(x, 23.0))
            .collect();
        assert_eq!(l[3], REFLECTIVITY_FLOOR.ln() - 23f64.ln());
        assert!((c3.log_ratio - l.iter().sum::<f64>()).abs() < 1e-12);
        assert!((c3.log_ratio_sq - l.iter().map(|x| x * x).sum::<f64>()).abs() < 1e-12);
    }

    #[test]
    fn spilled_returns_come_back_and_a_failed_read_is_latched() {
        let dir = tempfile::tempdir().unwrap();
        let file = std::sync::Arc::new(SpillFile::create(Some(dir.path())).unwrap());
        let cells = cells();
        let a: Vec<Kept> = (0..5)
            .map(|i| kept(i, 10.5 + i as f32 / 3.0, f32::from_bits(0x41a0_0001 + i)))
            .chain((0..4).map(|i| kept(7, 17.0 + i as f32 / 8.0, 30.0 + i as f32)))
            .collect();
        let b = vec![kept(2, f32::MIN_POSITIVE, -0.0)];
        let mut end = 0;
        let (mut ka, mut kb) = (
            KeptReturns::new(a.clone(), &cells, &counts(&a)),
            KeptReturns::new(b.clone(), &cells, &counts(&b)),
        );
        assert_eq!((ka.get().singles.len(), ka.get().cells.len()), (5, 1));
        type Bits = (Vec<(u32, u32, u32)>, Vec<(u32, u32, [u64; 4])>);
        let bits = |v: &KeptView<'_>| -> Bits {
            (
                v.singles
                    .iter()
                    .map(|k| (k.cell, k.range.to_bits(), k.reflectivity.to_bits()))
                    .collect(),
                v.cells
                    .iter()
                    .map(|c| {
                        (
                            c.cell,
                            c.n,
                            [c.range, c.range_sq, c.log_ratio, c.log_ratio_sq].map(f64::to_bits),
                        )
                    })
                    .collect(),
            )
        };
        let (ga, gb) = (bits(&ka.get()), bits(&kb.get()));
        ka.spill(&file, &mut end).unwrap();
        kb.spill(&file, &mut end).unwrap();
        assert_eq!(end, (5 * 12 + 40 + 12) as u64);
        assert!(ka.is_spilled() && kb.is_spilled());
        assert_eq!((ka.len(), kb.len(), ka.heap_bytes()), (9, 1, 0));
        assert_eq!(ka.bytes(), 5 * 12 + 40);
        assert_eq!(bits(&ka.get()), ga);
        assert_eq!(bits(&kb.get()), gb);
        // Spilling again leaves them where they are.
        ka.spill(&file, &mut end).unwrap();
        assert_eq!(end, (5 * 12 + 40 + 12) as u64);
        // A read past the file's end: none, and the error is latched.
        let beyond = KeptReturns {
            store: KeptStore::Spilled {
                file: std::sync::Arc::clone(&file),
                offset: end,
                singles: 2,
                cells: 0,
            },
            returns: 2,
        };
        let g = beyond.get();
        assert!(g.singles.is_empty() && g.cells.is_empty());
        let msg = file.error().unwrap();
        assert!(
            msg.contains("reading 2 kept returns back at byte 112"),
            "{msg}"
        );
        // Later reads still work; the first error stays.
        assert_eq!(bits(&kb.get()), gb);
        assert_eq!(file.error().unwrap(), msg);
    }

    #[test]
    fn hidden_cells_are_units_only_when_they_count_as_lost() {
        // 70 cells: every fifth hidden (one of them kept its return), every
        // seventh lost, the rest kept.
        let cells: SharedCells = (0..70u32).map(|c| (c * 2, 1u16)).collect::<Vec<_>>().into();
        let mut u = Units::with_hidden(
            cells,
            1,
            |j| (j % 5 != 0).then_some(u32::from(j % 7 != 0)),
            |j| (j % 5 == 0).then_some(u32::from(j == 35)),
        );
        let visible: Vec<u32> = (0..70u32).filter(|j| j % 5 != 0).map(|j| j * 2).collect();
        assert_eq!(u.iter().map(|x| x.cell).collect::<Vec<_>>(), visible);
        assert_eq!(u.len(), 56);
        u.count_hidden_as_lost();
        assert_eq!(u.len(), 70);
        let hidden: Vec<(u32, u32)> = u
            .iter()
            .filter(|x| (x.cell / 2) % 5 == 0)
            .map(|x| (x.cell, x.kept))
            .collect();
        assert_eq!(hidden.len(), 14);
        assert!(
            hidden.iter().all(|&(c, k)| k == u32::from(c == 70)),
            "{hidden:?}"
        );
        // Without hidden cells nothing changes, and nothing is held for them.
        let plain = Units::new(
            (0..3u32).map(|c| (c, 1u16)).collect::<Vec<_>>().into(),
            1,
            |_| Some(1),
        );
        assert_eq!(plain.heap_bytes(), 8 + 8);
    }

    #[test]
    fn units_give_back_the_list_they_were_built_from_at_every_width() {
        // 130 cells (three bit words, the last partial), every third hidden,
        // kept counts spread to the width under test; a list built the
        // plain way is the truth.
        // The last cell keeps all its trials: the largest count, which sets
        // the width (a bit, then 1, 2 and 4 bytes per cell).
        for (frames, hits_max, scale, kept_bytes) in [
            (1u32, 1u16, 1u32, 8 * 3usize),
            (1, 3, 1, 130),
            (40, 9, 7, 2 * 130),
            (600, 200, 997, 4 * 130),
        ] {
            let cells: SharedCells = (0..130u32)
                .map(|j| (7 * j + 2, 1 + (j % hits_max as u32) as u16))
                .collect();
            let unit = |j: usize| {
                let trials = cells[j].1 as u32 * frames;
                (j % 3 != 1).then(|| {
                    if j == 129 {
                        trials
                    } else {
                        (j as u32 * scale) % (trials + 1)
                    }
                })
            };
            let units = Units::new(cells.clone(), frames, unit);
            let truth: Vec<Unit> = (0..cells.len())
                .filter_map(|j| {
                    unit(j).map(|kept| Unit {
                        cell: cells[j].0,
                        trials: cells[j].1 as u32 * frames,
                        kept,
                    })
                })
                .collect();
            assert_eq!(units.iter().collect::<Vec<_>>(), truth, "frames {frames}");
            assert_eq!(units.len(), truth.len());
            assert!(!units.is_empty());
            assert_eq!(units.heap_bytes(), 8 * 3 + kept_bytes, "frames {frames}");
        }
        let none = Units::new(SharedCells::from(vec![(0, 1)]), 1, |_| None);
        assert!(none.is_empty());
        assert_eq!(none.iter().count(), 0);
    }

    #[test]
    fn histogram_bins_and_means() {
        assert_eq!(NearHistogram::sector_of(0.0), 0);
        assert_eq!(NearHistogram::sector_of(29.999), 0);
        assert_eq!(NearHistogram::sector_of(30.0), 1);
        assert_eq!(NearHistogram::sector_of(-1.0), AZIMUTH_SECTORS - 1);
        assert_eq!(NearHistogram::sector_of(360.0), 0);
        assert_eq!(NearHistogram::sector_centre(0), 15.0);
        assert_eq!(NearHistogram::range_bin_of(2.5), 2);
        assert_eq!(NearHistogram::range_bin_of(99.0), RANGE_BINS - 1);
        let mut a = NearHistogram {
            ring: vec![2.0, 4.0],
            ..NearHistogram::default()
        };
        a.sector[3] = 6.0;
        let mut m = NearHistogram::default();
        m.add_scaled(&a, 0.5);
        m.add_scaled(&a, 0.5);
        assert_eq!(m, a);
    }
}
