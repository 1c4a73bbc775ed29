//! CSV point clouds: `x,y,z,intensity,ring[,time]` and VeloView exports.
//!
//! Columns are matched by name, case-insensitively, after trimming spaces
//! and quotes, in any order; other columns are ignored:
//!
//! | field | accepted headers |
//! |---|---|
//! | x, y, z | `x`, `y`, `z`; VeloView `Points_m_XYZ:0..2`; ParaView `Points:0..2` |
//! | intensity | `intensity` |
//! | ring (optional) | `ring`, VeloView `laser_id` |
//! | time (optional) | `time` (seconds; VeloView's `timestamp`/`adjustedtime` are not read) |
//!
//! When an export has several columns for one coordinate (VeloView writes
//! `Points_m_XYZ:0` and, in some versions, `X` too), `Points_m_XYZ` wins
//! over `Points`, which wins over a plain `x`; two columns of the same kind
//! for one field are an error.
//!
//! Without a ring column the ring comes from each point's elevation.
//!
//! **Two parsers, one result.** A file whose data rows hold no `"` (what
//! murk, pandas, VeloView and most tools write) is split at newlines into
//! [`PIECE`]-byte pieces parsed in parallel (rayon, results joined in file
//! order, so the cloud and any error are the same on any thread count):
//! pieces are taken two at a time, one cell of a row of each in turn (a
//! row is a chain of dependent loads; two chains keep the core busy), each
//! row is walked cell by cell straight from the piece's bytes (no separate
//! line search, and where each row ends is kept) and only the cells murk
//! reads are parsed, plain
//! decimals by the `decimal` module's reader (exactly `str::parse::<f32>`'s
//! result, eight digits at a time), anything else by the standard library. Files with quoted
//! data cells go through the `csv` crate. Both accept and refuse the same
//! inputs (tested against each other) and both trim spaces around cells and
//! skip blank lines.
//!
//! [`parse_csv_rows`] also keeps where each row lies in the file, so that a
//! caller that drops or edits some points can write the others back byte for
//! byte ([`CsvRows::encode_subset`], used by `murk apply`).
//!
//! ```
//! use std::path::Path;
//! use murk_io::{parse_csv_rows, CsvNeeds, ReadOptions};
//!
//! let text = b"x,y,z,intensity,ring,note\n1.5,0,0,7,3,a\n30,0,0,9,4,b\n";
//! let rows = parse_csv_rows(text, Path::new("a.csv"), &ReadOptions::default(), CsvNeeds::default())?
//!     .expect("no quoted cells");
//! assert_eq!(rows.cloud.x, vec![1.5, 30.0]);
//! // Keep the first point only: its row comes back untouched, header included.
//! let out = rows.encode_subset(text, &[1, 0], &[], None);
//! assert_eq!(out, b"x,y,z,intensity,ring,note\n1.5,0,0,7,3,a\n");
//! # Ok::<(), murk_io::IoError>(())
//! ```

use std::fmt::Write as _;
use std::ops::Range;
use std::path::Path;

use murk_types::{PointCloud, PointFormat};
use rayon::prelude::*;

use crate::columns;
use crate::decimal::{fast_f32, fast_f32_prefix};
use crate::{IoError, ReadOptions, ring_lookup};

/// Bytes per parallel piece of the data section (cut at the next newline).
/// Fixed, so pieces never depend on the thread count.
const PIECE: usize = 256 * 1024;

/// The fields murk reads, in `FIELDS` order.
const FIELDS: [&str; 6] = ["x", "y", "z", "intensity", "ring", "time"];

/// Which field a header names, if any, and its precedence (lower wins).
fn field_of(header: &str) -> Option<(usize, u8)> {
    let h = header.trim().trim_matches('"').trim().to_ascii_lowercase();
    Some(match h.as_str() {
        "points_m_xyz:0" => (0, 0),
        "points_m_xyz:1" => (1, 0),
        "points_m_xyz:2" => (2, 0),
        "points:0" => (0, 1),
        "points:1" => (1, 1),
        "points:2" => (2, 1),
        "x" => (0, 2),
        "y" => (1, 2),
        "z" => (2, 2),
        "intensity" => (3, 0),
        "ring" | "laser_id" => (4, 0),
        "time" => (5, 0),
        _ => return None,
    })
}

/// Parses a CSV point cloud held in memory.
///
/// ```
/// use std::path::Path;
/// use murk_io::{parse_csv, ReadOptions};
///
/// let text = "\"Points_m_XYZ:0\",\"Points_m_XYZ:1\",\"Points_m_XYZ:2\",\"intensity\",\"laser_id\",\"azimuth\"\n\
///             1.5,-2.25,0.125,17,14,9001\n";
/// let cloud = parse_csv(text.as_bytes(), Path::new("veloview.csv"), &ReadOptions::default())?;
/// assert_eq!((cloud.x[0], cloud.y[0], cloud.z[0]), (1.5, -2.25, 0.125));
/// assert_eq!((cloud.intensity[0], cloud.ring[0]), (17.0, 14));
/// # Ok::<(), murk_io::IoError>(())
/// ```
pub fn parse_csv(bytes: &[u8], source: &Path, opts: &ReadOptions) -> Result<PointCloud, IoError> {
    match parse_csv_rows(bytes, source, opts, CsvNeeds::ALL)? {
        Some(rows) => Ok(rows.cloud),
        None => parse_csv_quoted(bytes, source, opts),
    }
}

/// The columns of a CSV file that a cloud does not carry (every column but
/// the ones murk reads); empty when the header cannot be read (the parse
/// reports that).
pub(crate) fn extra_columns(bytes: &[u8], source: &Path, opts: &ReadOptions) -> Vec<String> {
    let text = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    match parse_header(text, source, opts.declared_csv_columns()) {
        Ok(h) => h
            .names
            .iter()
            .enumerate()
            .filter(|(j, _)| !h.col.contains(&Some(*j)))
            .map(|(_, n)| n.clone())
            .collect(),
        Err(_) => Vec::new(),
    }
}

/// Which optional columns [`parse_csv_rows`] decodes (x, y, z and intensity
/// always are).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CsvNeeds {
    /// Decode the ring (from its column, else from elevation). When false
    /// and the file has no ring column, the cloud's ring is 0 for every
    /// point (no derivation from elevation). Ring cells are checked either
    /// way: a file `murk convert` refuses (ring 70000) is refused here too.
    pub ring: bool,
    /// Decode the time column when there is one. When false the cloud has
    /// no time; time cells are still checked (finite numbers).
    pub time: bool,
}

impl CsvNeeds {
    /// Every column murk reads (what [`parse_csv`] uses).
    pub const ALL: CsvNeeds = CsvNeeds {
        ring: true,
        time: true,
    };
}

impl Default for CsvNeeds {
    /// Only x, y, z and intensity.
    fn default() -> Self {
        CsvNeeds {
            ring: false,
            time: false,
        }
    }
}

/// A run of consecutive data rows of a CSV file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RowPiece {
    /// Bytes of the file holding the rows (and any blank lines between them).
    pub bytes: Range<usize>,
    /// Index of the piece's first row (= point).
    pub first_row: usize,
    /// Number of rows.
    pub rows: usize,
}

/// A CSV point cloud with where its rows lie in the file (see
/// [`parse_csv_rows`]).
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct CsvRows {
    /// The points, one per data row in file order.
    pub cloud: PointCloud,
    /// The header line with its line break (and a leading byte-order mark).
    pub header: Range<usize>,
    /// The data rows in file order.
    pub pieces: Vec<RowPiece>,
    /// Per row (point), where it ends (after its line break) as an offset
    /// from the start of its piece, so that writing kept rows back needs no
    /// second search for line breaks. Empty when a piece is 4 GiB or more
    /// (one enormous line); rows are then found by scanning.
    pub row_ends: Vec<u32>,
    /// The line break the header uses (`\n` or `\r\n`), used after a last
    /// row that has none when rows follow it.
    pub newline: &'static [u8],
    /// Number of columns.
    pub columns: usize,
    /// Column index of x, y, z, intensity, ring and time (if present).
    pub column_of: [Option<usize>; 6],
    /// What was subtracted from the time column to make it relative (see
    /// [`crate`]'s "Time"); 0 when it was kept.
    pub time_origin: f64,
}

/// One cell of a row that [`CsvRows::encode_subset`] rewrites.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RowEdit {
    /// The row (= point index).
    pub row: usize,
    /// New x, y, z and intensity of the point.
    pub values: [f32; 4],
    /// True when the point is a new return on the row's ray (a near-range
    /// echo replacing the original): its ring and time cells are kept,
    /// every other column not read by murk (labels, colours) is left
    /// **empty**, as for added points. False for the same return moved or
    /// rescaled (range noise, attenuation): all its other cells are kept.
    pub fresh: bool,
}

/// The byte ranges of the data rows in `bytes[range]` (blank lines
/// skipped), each with its line break.
fn row_spans(bytes: &[u8], range: Range<usize>) -> impl Iterator<Item = Range<usize>> + '_ {
    let (base, end) = (range.start, range.end);
    let mut pos = base;
    // One vectorised scan over the whole range, not a search call per row.
    let mut breaks = memchr::memchr_iter(b'\n', &bytes[range]);
    std::iter::from_fn(move || {
        while pos < end {
            let stop = breaks.next().map_or(end, |k| base + k + 1);
            let row = pos..stop;
            pos = stop;
            if !strip_newline(&bytes[row.clone()]).is_empty() {
                return Some(row);
            }
        }
        None
    })
}

/// The rows of a piece as byte ranges (see [`CsvRows::spans`]).
enum Spans<'a> {
    /// From the recorded row ends: each row runs from the previous row's
    /// end (`base`, the piece's start, for the first) to its own.
    Recorded {
        base: usize,
        prev: usize,
        ends: std::slice::Iter<'a, u32>,
    },
    /// Found by scanning for line breaks (no recorded ends).
    Scanned(Box<dyn Iterator<Item = Range<usize>> + 'a>),
}

impl Iterator for Spans<'_> {
    type Item = Range<usize>;

    #[inline]
    fn next(&mut self) -> Option<Range<usize>> {
        match self {
            Spans::Recorded { base, prev, ends } => {
                let end = *base + *ends.next()? as usize;
                Some(std::mem::replace(prev, end)..end)
            }
            Spans::Scanned(it) => it.next(),
        }
    }
}

/// `pos` moved past any blank lines (`\n` or `\r\n`) starting there.
#[inline(always)]
fn skip_blank_lines(bytes: &[u8], mut pos: usize) -> usize {
    while pos < bytes.len() {
        match bytes[pos] {
            b'\n' => pos += 1,
            b'\r' if bytes.get(pos + 1) == Some(&b'\n') => pos += 2,
            _ => break,
        }
    }
    pos
}

/// Writes the pending run of kept rows and empties it.
fn flush_run<W: std::io::Write + ?Sized>(
    out: &mut W,
    bytes: &[u8],
    run: &mut Range<usize>,
    ends_with_newline: &mut bool,
) -> std::io::Result<()> {
    if run.start < run.end {
        let rows = &bytes[run.clone()];
        out.write_all(rows)?;
        *ends_with_newline = rows.ends_with(b"\n");
        *run = 0..0;
    }
    Ok(())
}

/// `line` without its `\n` or `\r\n`.
#[inline]
fn strip_newline(line: &[u8]) -> &[u8] {
    let line = line.strip_suffix(b"\n").unwrap_or(line);
    line.strip_suffix(b"\r").unwrap_or(line)
}

impl CsvRows {
    /// The rows of `piece` in `bytes` (the parsed file), each with its line
    /// break (the file's last row may have none).
    pub fn rows<'a>(
        &'a self,
        bytes: &'a [u8],
        piece: &RowPiece,
    ) -> impl Iterator<Item = &'a [u8]> + 'a {
        self.spans(bytes, piece)
            .map(move |r| &bytes[skip_blank_lines(bytes, r.start)..r.end])
    }

    /// The byte ranges of `piece`'s rows in `bytes`, each with its line
    /// break, from the recorded row ends when there are some, else by
    /// scanning for line breaks. A range may start with blank lines (the
    /// ones before its row); [`skip_blank_lines`] on its start drops them,
    /// which callers do only for the rows they use.
    fn spans<'a>(&'a self, bytes: &'a [u8], piece: &RowPiece) -> Spans<'a> {
        if self.row_ends.is_empty() {
            return Spans::Scanned(Box::new(row_spans(bytes, piece.bytes.clone())));
        }
        Spans::Recorded {
            base: piece.bytes.start,
            prev: piece.bytes.start,
            ends: self.row_ends[piece.first_row..piece.first_row + piece.rows].iter(),
        }
    }

    /// Encodes the CSV file of the points `keep` marks (1 = kept; one entry
    /// per row), in file order, then `added` points, if any: what
    /// [`CsvRows::write_subset`] writes, as bytes.
    pub fn encode_subset(
        &self,
        bytes: &[u8],
        keep: &[u8],
        edits: &[RowEdit],
        added: Option<&PointCloud>,
    ) -> Vec<u8> {
        let mut out = Vec::with_capacity(bytes.len());
        self.write_subset(bytes, keep, edits, added, &mut out)
            .expect("writing to a Vec cannot fail");
        out
    }

    /// Writes the CSV file of the points `keep` marks (1 = kept; one entry
    /// per row), in file order, then `added` points, if any, to `out`.
    ///
    /// `bytes` is the parsed file. The header and every kept row without an
    /// edit are copied byte for byte (consecutive kept rows as one slice of
    /// `bytes`, so a mostly kept file goes out in a few large writes); a row
    /// in `edits` (sorted by row, kept rows only) has its x, y, z and
    /// intensity cells rewritten (shortest decimal that reads back to the
    /// same `f32`), its other cells kept, except for a
    /// [`RowEdit::fresh`] point, whose cells of the columns murk does not
    /// read are left empty. Added points get x, y, z,
    /// intensity, ring and time cells (time in the file's own origin) and
    /// empty cells in every other column. Blank lines are not written.
    pub fn write_subset<W: std::io::Write + ?Sized>(
        &self,
        bytes: &[u8],
        keep: &[u8],
        edits: &[RowEdit],
        added: Option<&PointCloud>,
        out: &mut W,
    ) -> std::io::Result<()> {
        let header = &bytes[self.header.clone()];
        out.write_all(header)?;
        let mut ends_with_newline = header.is_empty() || header.ends_with(b"\n");
        let mut e = 0usize;
        let mut scratch = Vec::new();
        // The pending run of consecutive kept rows, as a byte range.
        let mut run = 0..0;
        for p in &self.pieces {
            let keep = &keep[p.first_row..p.first_row + p.rows];
            for (k, (row, &kept)) in self.spans(bytes, p).zip(keep).enumerate() {
                if kept == 0 {
                    continue;
                }
                let row = skip_blank_lines(bytes, row.start)..row.end;
                let i = p.first_row + k;
                if e < edits.len() && edits[e].row == i {
                    flush_run(out, bytes, &mut run, &mut ends_with_newline)?;
                    scratch.clear();
                    self.rewrite_row(&mut scratch, &bytes[row.clone()], &edits[e]);
                    out.write_all(&scratch)?;
                    ends_with_newline = scratch.ends_with(b"\n");
                    e += 1;
                } else if run.end == row.start && run.start < run.end {
                    run.end = row.end;
                } else {
                    flush_run(out, bytes, &mut run, &mut ends_with_newline)?;
                    run = row;
                }
            }
        }
        flush_run(out, bytes, &mut run, &mut ends_with_newline)?;
        if let Some(added) = added.filter(|a| !a.is_empty()) {
            if !ends_with_newline {
                out.write_all(self.newline)?;
            }
            let mut cells = vec![String::new(); self.columns];
            for i in 0..added.len() {
                for c in cells.iter_mut() {
                    c.clear();
                }
                let v = [added.x[i], added.y[i], added.z[i], added.intensity[i]];
                for (f, v) in v.iter().enumerate() {
                    if let Some(j) = self.column_of[f] {
                        let _ = write!(cells[j], "{v}");
                    }
                }
                if let Some(j) = self.column_of[4] {
                    let _ = write!(cells[j], "{}", added.ring[i]);
                }
                if let (Some(j), Some(t)) = (self.column_of[5], &added.time) {
                    // As murk writes times, or back on the file's clock.
                    let _ = if self.time_origin == 0.0 {
                        write!(cells[j], "{}", t[i])
                    } else {
                        write!(cells[j], "{}", f64::from(t[i]) + self.time_origin)
                    };
                }
                out.write_all(cells.join(",").as_bytes())?;
                out.write_all(self.newline)?;
            }
        }
        Ok(())
    }

    /// Appends `row` with its x, y, z and intensity cells replaced (and,
    /// for a fresh point, its cells of unread columns emptied).
    fn rewrite_row(&self, out: &mut Vec<u8>, row: &[u8], edit: &RowEdit) {
        let values = &edit.values;
        let body = strip_newline(row);
        let mut cell = String::new();
        for (j, c) in body.split(|&b| b == b',').enumerate() {
            if j > 0 {
                out.push(b',');
            }
            match (0..4).find(|&f| self.column_of[f] == Some(j)) {
                Some(f) => {
                    cell.clear();
                    let _ = write!(cell, "{}", values[f]);
                    out.extend_from_slice(cell.as_bytes());
                }
                None if edit.fresh
                    && self.column_of[4] != Some(j)
                    && self.column_of[5] != Some(j) => {}
                None => out.extend_from_slice(c),
            }
        }
        out.extend_from_slice(&row[body.len()..]);
    }
}

/// The header of a CSV file: its columns and where its data starts.
struct Header {
    /// Column names as written (trimmed, unquoted).
    names: Vec<String>,
    /// Column of each of [`FIELDS`].
    col: [Option<usize>; 6],
    /// Byte offset of the first data row (in the BOM-stripped bytes).
    data_start: usize,
    /// 1-based line of the first data row.
    data_line: u64,
}

fn parse_err(source: &Path, line: u64, column: &str, reason: String) -> IoError {
    IoError::Parse {
        path: source.to_path_buf(),
        line,
        column: column.to_string(),
        reason,
    }
}

fn csv_err(source: &Path) -> impl Fn(csv::Error) -> IoError + '_ {
    move |e: csv::Error| {
        let line = e.position().map_or(0, csv::Position::line);
        parse_err(source, line, "-", e.to_string())
    }
}

fn reader(bytes: &[u8], has_headers: bool) -> csv::Reader<&[u8]> {
    csv::ReaderBuilder::new()
        .has_headers(has_headers)
        .trim(csv::Trim::All)
        .from_reader(bytes)
}

/// Reads the header (with the `csv` crate: it may be quoted) and picks the
/// column of every field; with `declared` column names (a header-less file)
/// the names are those and the data start at the first line.
fn parse_header(
    bytes: &[u8],
    source: &Path,
    declared: Option<&[String]>,
) -> Result<Header, IoError> {
    let mut rdr = reader(bytes, true);
    let headers = match declared {
        Some(names) => csv::ByteRecord::from(names.to_vec()),
        None => rdr.byte_headers().map_err(csv_err(source))?.clone(),
    };
    let mut names = Vec::with_capacity(headers.len());
    // Column index and precedence of each field.
    let mut chosen: [Option<(usize, u8)>; 6] = [None; 6];
    for (j, h) in headers.iter().enumerate() {
        let name = std::str::from_utf8(h).map_err(|_| {
            parse_err(
                source,
                1,
                &(j + 1).to_string(),
                "header is not UTF-8".into(),
            )
        })?;
        names.push(name.to_string());
        if let Some((f, rank)) = field_of(name) {
            match chosen[f] {
                Some((prev, r)) if r == rank => {
                    return Err(parse_err(
                        source,
                        1,
                        name,
                        format!(
                            "column {} and column {} both give {}",
                            prev + 1,
                            j + 1,
                            FIELDS[f]
                        ),
                    ));
                }
                Some((_, r)) if r < rank => {}
                _ => chosen[f] = Some((j, rank)),
            }
        }
    }
    let col = chosen.map(|c| c.map(|(j, _)| j));
    for f in 0..4 {
        if col[f].is_none() {
            if declared.is_none()
                && !names.is_empty()
                && names.iter().all(|n| n.trim().parse::<f64>().is_ok())
            {
                return Err(IoError::NoHeader {
                    path: source.to_path_buf(),
                    first_line: names.join(","),
                });
            }
            return Err(IoError::MissingField {
                path: source.to_path_buf(),
                field: FIELDS[f],
                found: names.join(", "),
            });
        }
    }
    if declared.is_some() {
        return Ok(Header {
            names,
            col,
            data_start: 0,
            data_line: 1,
        });
    }
    let pos = rdr.position();
    let mut data_start = (pos.byte() as usize).min(bytes.len());
    // The `csv` crate stops after the `\r` of a `\r\n`: the `\n` belongs to
    // the header line.
    if data_start > 0 && bytes[data_start - 1] == b'\r' && bytes.get(data_start) == Some(&b'\n') {
        data_start += 1;
    }
    Ok(Header {
        names,
        col,
        data_start,
        // Counted here: the `csv` crate's count is one short after `\r\n`.
        data_line: 1 + memchr::memchr_iter(b'\n', &bytes[..data_start]).count() as u64,
    })
}

/// A row read by [`fast_row_at`]: x, y, z and intensity, where the ring
/// and time cells lie, and where the next row starts.
type FastRow = ([f32; 4], Range<usize>, Range<usize>, usize);

/// Where the cell starting at `p` ends (its `,`, line break or the end).
#[inline(always)]
fn cell_end(buf: &[u8], mut p: usize) -> usize {
    while p < buf.len() && !matches!(buf[p], b',' | b'\n' | b'\r') {
        p += 1;
    }
    p
}

/// Where the next row starts when the row's last cell ends at `p`: after a
/// `\n` or `\r\n`, or at the end of `buf`; `None` for anything else.
#[inline(always)]
fn next_row(buf: &[u8], p: usize) -> Option<usize> {
    if p == buf.len() {
        Some(p)
    } else if buf[p] == b'\n' {
        Some(p + 1)
    } else if buf[p] == b'\r' && buf.get(p + 1) == Some(&b'\n') {
        Some(p + 2)
    } else {
        None
    }
}

/// The common row in one pass, read from `buf[pos..]` (the row, its line
/// break and any rows after it): every cell of a read coordinate a plain
/// decimal, no spaces, the row ending in `\n`, `\r\n` or the end of `buf`.
/// Returns `None` for anything else (the caller's cell-by-cell path then
/// parses the row or names what is wrong with it).
///
/// Reading from the whole piece rather than from a line cut out first lets
/// the number reader take eight bytes at a time up to the row's end, and
/// the row's end is found by walking its cells instead of by a separate
/// newline search.
#[inline]
fn fast_row_at(buf: &[u8], pos: usize, roles: &[Role]) -> Option<FastRow> {
    let mut v = [0f32; 4];
    let (mut ring, mut time) = (0..0, 0..0);
    let mut p = pos;
    for (j, role) in roles.iter().enumerate() {
        if j > 0 {
            if p >= buf.len() || buf[p] != b',' {
                return None;
            }
            p += 1;
        }
        match *role {
            Role::Coord(f) => {
                let (val, len) = fast_f32_prefix(&buf[p..])?;
                v[f] = val;
                p += len;
            }
            other => {
                let start = p;
                p = cell_end(buf, p);
                match other {
                    Role::Ring => ring = start..p,
                    Role::Time => time = start..p,
                    _ => {}
                }
            }
        }
    }
    let next = next_row(buf, p)?;
    Some((v, ring, time, next))
}

/// [`fast_row_at`] of two rows at once, cell by cell: `Some` only when both
/// are common rows.
///
/// Why: where one cell ends decides where the next is read, so reading a
/// row is one chain of dependent loads and digit counts, and a single row
/// loop waits on their latency (a loop that only finds where cells end runs
/// at 32 ns per row alone, 17 with two rows interleaved). Taking the same
/// cell of two rows in turn gives the core two independent chains to run
/// side by side; a row at a time would not, as one row's work fills the
/// core's window before the other's starts. It repeats [`fast_row_at`]'s
/// steps on purpose: one const-generic reader of `N` rows, with a loop over
/// the rows inside each cell, parsed 25 % slower for both.
#[inline]
fn fast_row_pair(
    ba: &[u8],
    pa: usize,
    bb: &[u8],
    pb: usize,
    roles: &[Role],
) -> Option<(FastRow, FastRow)> {
    let (mut va, mut vb) = ([0f32; 4], [0f32; 4]);
    let (mut ra, mut ta, mut rb, mut tb) = (0..0, 0..0, 0..0, 0..0);
    let (mut p, mut q) = (pa, pb);
    for (j, role) in roles.iter().enumerate() {
        if j > 0 {
            if p >= ba.len() || ba[p] != b',' || q >= bb.len() || bb[q] != b',' {
                return None;
            }
            p += 1;
            q += 1;
        }
        match *role {
            Role::Coord(f) => {
                let (x, lx) = fast_f32_prefix(&ba[p..])?;
                let (y, ly) = fast_f32_prefix(&bb[q..])?;
                va[f] = x;
                vb[f] = y;
                p += lx;
                q += ly;
            }
            other => {
                let (sp, sq) = (p, q);
                p = cell_end(ba, p);
                q = cell_end(bb, q);
                match other {
                    Role::Ring => (ra, rb) = (sp..p, sq..q),
                    Role::Time => (ta, tb) = (sp..p, sq..q),
                    _ => {}
                }
            }
        }
    }
    let (na, nb) = (next_row(ba, p)?, next_row(bb, q)?);
    Some(((va, ra, ta, na), (vb, rb, tb, nb)))
}

/// What a column is read as.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Role {
    Skip,
    Coord(usize),
    Ring,
    Time,
}

/// One parsed row of a piece.
#[derive(Clone, Copy)]
struct PieceRow {
    /// x, y, z and intensity.
    xyzi: [f32; 4],
    /// Where the row ends (after its line break), from the piece's start;
    /// 0 when the piece does not record ends.
    end: u32,
}

/// The columns of one piece.
#[derive(Default)]
struct PieceCols {
    /// The rows: one push per row while parsing (a push per column costs a
    /// capacity check each); split into columns when pieces are joined.
    rows: Vec<PieceRow>,
    ring: Vec<u16>,
    time: Vec<f64>,
    /// Whether `rows[..].end` holds the row ends.
    ends: bool,
}

/// Where and why a piece failed.
struct PieceErr {
    /// Offset of the bad row in the data section.
    offset: usize,
    /// Row index inside the piece.
    row: usize,
    kind: ErrKind,
}

enum ErrKind {
    /// A cell that is not a number, an empty cell, a wrong cell count.
    Parse {
        column: String,
        reason: String,
    },
    NonFinite {
        field: &'static str,
        value: f64,
    },
    Ring(String),
}

/// The parsed value of a cell for `f32` fields, or why it has none.
#[inline]
fn cell_f32(cell: &[u8]) -> Result<f32, String> {
    if let Some(v) = fast_f32(cell) {
        return Ok(v);
    }
    let s = cell_str(cell)?;
    s.parse::<f32>()
        .map_err(|_| format!("{s:?} is not a number"))
}

/// The trimmed text of a cell.
fn cell_str(cell: &[u8]) -> Result<&str, String> {
    let s = std::str::from_utf8(cell.trim_ascii()).map_err(|_| "cell is not UTF-8".to_string())?;
    if s.is_empty() {
        return Err("empty cell".into());
    }
    Ok(s)
}

/// The ring id of a cell: plain digits directly, anything else as `f64`.
#[inline]
fn cell_ring(cell: &[u8]) -> Result<Result<u16, String>, String> {
    if !cell.is_empty() && cell.len() <= 5 && cell.iter().all(u8::is_ascii_digit) {
        let v = cell.iter().fold(0u32, |a, &b| a * 10 + u32::from(b - b'0'));
        if let Ok(r) = u16::try_from(v) {
            return Ok(Ok(r));
        }
    }
    let s = cell_str(cell)?;
    let v = s
        .parse::<f64>()
        .map_err(|_| format!("{s:?} is not a number"))?;
    Ok(columns::ring_id(v))
}

/// A piece being parsed: where it stands and what it has so far.
struct PieceParser<'a> {
    data: &'a [u8],
    /// The piece's bytes in `data` (whole lines).
    range: Range<usize>,
    /// Where the next row starts, in `data`.
    pos: usize,
    /// Rows parsed so far.
    row: usize,
    roles: &'a [Role],
    names: &'a [String],
    want_ring: bool,
    want_time: bool,
    /// Whether row ends fit `u32` offsets (a piece under 4 GiB).
    record_ends: bool,
    out: PieceCols,
}

impl<'a> PieceParser<'a> {
    fn new(data: &'a [u8], range: Range<usize>, roles: &'a [Role], names: &'a [String]) -> Self {
        // Rows the piece holds, from the length of its first lines (an
        // eighth more for longer-than-average lines further on): room for
        // every row without a reallocation, and without reserving far more
        // memory than the rows take (a fresh page costs a fault and zeroing
        // on first touch, and huge pages are touched 2 MiB at a time).
        let sample = &data[range.start..range.end.min(range.start + 4096)];
        let lines = memchr::memchr_iter(b'\n', sample).count().max(1);
        let per_row = (sample.len() / lines).max(1);
        let cap = range.len() / per_row + range.len() / per_row / 8 + 16;
        let record_ends = u32::try_from(range.len()).is_ok();
        PieceParser {
            data,
            pos: range.start,
            range,
            row: 0,
            roles,
            names,
            // Checked whatever the caller decodes: every reader of murk
            // accepts and refuses the same files.
            want_ring: roles.contains(&Role::Ring),
            want_time: roles.contains(&Role::Time),
            record_ends,
            out: PieceCols {
                rows: Vec::with_capacity(cap),
                ends: record_ends,
                ..PieceCols::default()
            },
        }
    }

    /// Skips blank lines; false at the piece's end.
    #[inline(always)]
    fn skip_blank(&mut self) -> bool {
        self.pos = skip_blank_lines(&self.data[..self.range.end], self.pos);
        self.pos < self.range.end
    }

    /// Skips blank lines, then parses the next row if [`fast_row_at`] takes
    /// it. False at the piece's end and for any row the fast path declines
    /// (nothing consumed then: [`PieceParser::finish`] parses it).
    #[inline(always)]
    fn step(&mut self) -> bool {
        if !self.skip_blank() {
            return false;
        }
        match fast_row_at(&self.data[..self.range.end], self.pos, self.roles) {
            Some(row) => self.accept(row),
            None => false,
        }
    }

    /// Stores a row [`fast_row_at`] read, once its ring and time cells (when
    /// wanted) are valid; false, with nothing consumed, when they are not.
    #[inline(always)]
    fn accept(&mut self, (v, ring, time, next): FastRow) -> bool {
        let bytes = self.data;
        let ring = if self.want_ring {
            match cell_ring(&bytes[ring]) {
                Ok(Ok(r)) => Some(r),
                _ => return false,
            }
        } else {
            None
        };
        let time = if self.want_time {
            match std::str::from_utf8(&bytes[time])
                .ok()
                .and_then(|t| t.parse::<f64>().ok())
            {
                Some(t) if t.is_finite() => Some(t),
                _ => return false,
            }
        } else {
            None
        };
        self.pos = next;
        self.push_row(v);
        if let Some(r) = ring {
            self.out.ring.push(r);
        }
        if let Some(t) = time {
            self.out.time.push(t);
        }
        self.row += 1;
        true
    }

    /// Stores a row's x, y, z and intensity; the row ends at `self.pos`.
    #[inline(always)]
    fn push_row(&mut self, xyzi: [f32; 4]) {
        let end = if self.record_ends {
            (self.pos - self.range.start) as u32
        } else {
            0
        };
        self.out.rows.push(PieceRow { xyzi, end });
    }

    /// Parses the rest of the piece: the fast path where it applies, the
    /// cell-by-cell path (which names what is wrong) where it does not.
    fn finish(mut self) -> Result<PieceCols, PieceErr> {
        let bytes = &self.data[..self.range.end];
        let roles = self.roles;
        let names = self.names;
        let ncols = roles.len();
        loop {
            while self.step() {}
            if self.pos >= self.range.end {
                return Ok(self.out);
            }
            let pos = self.pos;
            let row = self.row;
            let fail = |kind: ErrKind| PieceErr {
                offset: pos,
                row,
                kind,
            };
            let want_ring = self.want_ring;
            let want_time = self.want_time;
            let end = memchr::memchr(b'\n', &bytes[pos..]).map_or(bytes.len(), |k| pos + k + 1);
            let line = strip_newline(&bytes[pos..end]);
            self.pos = end;
            // Cells of the fields, in FIELDS order.
            let mut cells: [&[u8]; 6] = [&[]; 6];
            let mut j = 0usize;
            for cell in line.split(|&b| b == b',') {
                if j < ncols {
                    match roles[j] {
                        Role::Skip => {}
                        Role::Coord(f) => cells[f] = cell,
                        Role::Ring => cells[4] = cell,
                        Role::Time => cells[5] = cell,
                    }
                }
                j += 1;
            }
            if j != ncols {
                return Err(fail(ErrKind::Parse {
                    column: "-".into(),
                    reason: format!("the row has {j} cells, the header {ncols} columns"),
                }));
            }
            let name_of = |role: Role| {
                roles
                    .iter()
                    .position(|&r| r == role)
                    .map_or("-", |k| names[k].as_str())
            };
            let mut v = [0f32; 4];
            for (f, slot) in v.iter_mut().enumerate() {
                *slot = cell_f32(cells[f]).map_err(|reason| {
                    fail(ErrKind::Parse {
                        column: name_of(Role::Coord(f)).to_string(),
                        reason,
                    })
                })?;
                if !slot.is_finite() {
                    return Err(fail(ErrKind::NonFinite {
                        field: FIELDS[f],
                        value: f64::from(*slot),
                    }));
                }
            }
            self.push_row(v);
            if want_ring {
                let r = cell_ring(cells[4])
                    .map_err(|reason| {
                        fail(ErrKind::Parse {
                            column: name_of(Role::Ring).to_string(),
                            reason,
                        })
                    })?
                    .map_err(|reason| fail(ErrKind::Ring(reason)))?;
                self.out.ring.push(r);
            }
            if want_time {
                let t = cell_str(cells[5])
                    .and_then(|s| {
                        s.parse::<f64>()
                            .map_err(|_| format!("{s:?} is not a number"))
                    })
                    .map_err(|reason| {
                        fail(ErrKind::Parse {
                            column: name_of(Role::Time).to_string(),
                            reason,
                        })
                    })?;
                if !t.is_finite() {
                    return Err(fail(ErrKind::NonFinite {
                        field: "time",
                        value: t,
                    }));
                }
                self.out.time.push(t);
            }
            self.row += 1;
        }
    }
}

/// Parses two pieces ([`parse_piece`] of each), reading one common row of
/// each in turn through [`fast_row_pair`] for as long as both have one,
/// then finishing each on its own.
fn parse_pair(
    data: &[u8],
    a: Range<usize>,
    b: Range<usize>,
    roles: &[Role],
    names: &[String],
) -> [Result<PieceCols, PieceErr>; 2] {
    let mut pa = PieceParser::new(data, a, roles, names);
    let mut pb = PieceParser::new(data, b, roles, names);
    while pa.skip_blank() && pb.skip_blank() {
        let Some((ra, rb)) = fast_row_pair(
            &data[..pa.range.end],
            pa.pos,
            &data[..pb.range.end],
            pb.pos,
            roles,
        ) else {
            break;
        };
        if !(pa.accept(ra) && pb.accept(rb)) {
            break;
        }
    }
    [pa.finish(), pb.finish()]
}

/// Parses the rows of `data[range]` (whole lines).
fn parse_piece(
    data: &[u8],
    range: Range<usize>,
    roles: &[Role],
    names: &[String],
) -> Result<PieceCols, PieceErr> {
    PieceParser::new(data, range, roles, names).finish()
}

/// Parses a CSV point cloud held in memory and keeps where its rows are, or
/// returns `None` when a data row holds a `"` (quoted cells: use
/// [`parse_csv`], which handles them). `needs` says which optional columns
/// to decode; errors name the file, line and column or point, as
/// [`parse_csv`]'s do.
pub fn parse_csv_rows(
    bytes: &[u8],
    source: &Path,
    opts: &ReadOptions,
    needs: CsvNeeds,
) -> Result<Option<CsvRows>, IoError> {
    if bytes.is_empty() {
        return Err(IoError::Empty {
            path: source.to_path_buf(),
        });
    }
    let bom = if bytes.starts_with(b"\xEF\xBB\xBF") {
        3
    } else {
        0
    };
    let text = &bytes[bom..];
    let h = parse_header(text, source, opts.declared_csv_columns())?;
    let data = &text[h.data_start..];
    // Quoted cells, or a lone `\r` (which the `csv` crate takes as a line
    // break): the `csv` crate's path.
    let lone_cr = memchr::memchr_iter(b'\r', data).any(|k| data.get(k + 1) != Some(&b'\n'));
    if lone_cr || memchr::memchr(b'"', data).is_some() {
        return Ok(None);
    }
    let ncols = h.names.len();
    let mut roles = vec![Role::Skip; ncols];
    for (f, c) in h.col.iter().enumerate() {
        if let Some(j) = *c {
            roles[j] = match f {
                0..=3 => Role::Coord(f),
                4 => Role::Ring,
                _ => Role::Time,
            };
        }
    }
    let lookup = match (needs.ring, h.col[4]) {
        (true, None) => Some(ring_lookup(source, opts)?),
        _ => None,
    };
    // Piece boundaries: every PIECE bytes, moved to just after a newline.
    let mut cuts = vec![0usize];
    while let Some(&last) = cuts.last() {
        let target = last + PIECE;
        if target >= data.len() {
            break;
        }
        match memchr::memchr(b'\n', &data[target..]) {
            Some(k) => cuts.push(target + k + 1),
            None => break,
        }
    }
    cuts.push(data.len());
    cuts.dedup();
    let ranges: Vec<Range<usize>> = cuts.windows(2).map(|w| w[0]..w[1]).collect();
    let parsed: Vec<Result<PieceCols, PieceErr>> = ranges
        .par_chunks(2)
        .flat_map_iter(|pair| match pair {
            [a, b] => Vec::from(parse_pair(data, a.clone(), b.clone(), &roles, &h.names)),
            _ => vec![parse_piece(data, pair[0].clone(), &roles, &h.names)],
        })
        .collect();

    let mut pieces = Vec::with_capacity(ranges.len());
    let mut total = 0usize;
    let mut cols = Vec::with_capacity(parsed.len());
    for (r, p) in ranges.iter().zip(parsed) {
        match p {
            Ok(c) => {
                pieces.push(RowPiece {
                    bytes: bom + h.data_start + r.start..bom + h.data_start + r.end,
                    first_row: total,
                    rows: c.rows.len(),
                });
                total += c.rows.len();
                cols.push(c);
            }
            Err(e) => {
                let point = total + e.row;
                let line =
                    h.data_line + memchr::memchr_iter(b'\n', &data[..e.offset]).count() as u64;
                return Err(match e.kind {
                    ErrKind::Parse { column, reason } => parse_err(source, line, &column, reason),
                    ErrKind::NonFinite { field, value } => {
                        columns::non_finite(source, point, field, value)
                    }
                    ErrKind::Ring(reason) => IoError::BadValue {
                        path: source.to_path_buf(),
                        point,
                        field: "ring",
                        reason,
                    },
                });
            }
        }
    }
    let join_f32 = |k: usize| {
        let mut v = Vec::with_capacity(total);
        for c in &cols {
            v.extend(c.rows.iter().map(|r| r.xyzi[k]));
        }
        v
    };
    let mut cloud = PointCloud {
        x: join_f32(0),
        y: join_f32(1),
        z: join_f32(2),
        intensity: join_f32(3),
        ring: Vec::new(),
        time: None,
        intensity_scale: opts.scale_for(PointFormat::Csv),
    };
    cloud.ring = match (&lookup, h.col[4].is_some()) {
        (Some(lookup), _) => {
            let mut ring = vec![0u16; total];
            ring.par_chunks_mut(PIECE)
                .zip(cloud.x.par_chunks(PIECE))
                .zip(cloud.y.par_chunks(PIECE))
                .zip(cloud.z.par_chunks(PIECE))
                .for_each(|(((r, x), y), z)| lookup.fill(r, x, y, z));
            ring
        }
        (None, true) => {
            let mut ring = Vec::with_capacity(total);
            for c in &cols {
                ring.extend_from_slice(&c.ring);
            }
            ring
        }
        (None, false) => vec![0u16; total],
    };
    let mut time_origin = 0.0;
    if needs.time && h.col[5].is_some() {
        let mut t = Vec::with_capacity(total);
        for c in &cols {
            t.extend_from_slice(&c.time);
        }
        time_origin = columns::time_origin(&t);
        cloud.time = Some(columns::time_to_f32(source, &t)?);
    }
    let header_end = bom + h.data_start;
    let head = &bytes[..header_end];
    let row_ends = if cols.iter().all(|c| c.ends) {
        let mut v = Vec::with_capacity(total);
        for c in &cols {
            v.extend(c.rows.iter().map(|r| r.end));
        }
        v
    } else {
        Vec::new()
    };
    Ok(Some(CsvRows {
        cloud,
        header: 0..header_end,
        pieces,
        row_ends,
        newline: if head.ends_with(b"\r\n") {
            b"\r\n"
        } else {
            b"\n"
        },
        columns: ncols,
        column_of: h.col,
        time_origin,
    }))
}

/// The `csv` crate path of [`parse_csv`], for files with quoted data cells.
fn parse_csv_quoted(
    bytes: &[u8],
    source: &Path,
    opts: &ReadOptions,
) -> Result<PointCloud, IoError> {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let declared = opts.declared_csv_columns();
    let h = parse_header(bytes, source, declared)?;
    let names = &h.names;
    let col = h.col;
    let req = [0, 1, 2, 3].map(|f| col[f].expect("checked by parse_header"));
    let mut rdr = reader(bytes, declared.is_none());
    let csv_err = csv_err(source);
    let parse_err =
        |line: u64, column: &str, reason: String| parse_err(source, line, column, reason);
    if declared.is_none() {
        rdr.byte_headers().map_err(&csv_err)?;
    }
    let lookup = match col[4] {
        Some(_) => None,
        None => Some(ring_lookup(source, opts)?),
    };
    let mut cloud = PointCloud::with_capacity(bytes.len() / 32);
    cloud.intensity_scale = opts.scale_for(PointFormat::Csv);
    let mut time = Vec::new();
    let mut rec = csv::ByteRecord::new();
    while rdr.read_byte_record(&mut rec).map_err(&csv_err)? {
        let line = rec.position().map_or(0, csv::Position::line);
        let i = cloud.len();
        let cell = |j: usize| -> Result<&str, IoError> {
            let c = rec.get(j).unwrap_or_default();
            let s = std::str::from_utf8(c)
                .map_err(|_| parse_err(line, &names[j], "cell is not UTF-8".into()))?;
            if s.is_empty() {
                return Err(parse_err(line, &names[j], "empty cell".into()));
            }
            Ok(s)
        };
        let mut v = [0f32; 4];
        for f in 0..4 {
            let j = req[f];
            let s = cell(j)?;
            v[f] = s
                .parse::<f32>()
                .map_err(|_| parse_err(line, &names[j], format!("{s:?} is not a number")))?;
            if !v[f].is_finite() {
                return Err(columns::non_finite(source, i, FIELDS[f], f64::from(v[f])));
            }
        }
        cloud.x.push(v[0]);
        cloud.y.push(v[1]);
        cloud.z.push(v[2]);
        cloud.intensity.push(v[3]);
        if let Some(j) = col[4] {
            let s = cell(j)?;
            let r = s
                .parse::<f64>()
                .map_err(|_| parse_err(line, &names[j], format!("{s:?} is not a number")))?;
            let r = columns::ring_id(r).map_err(|reason| IoError::BadValue {
                path: source.to_path_buf(),
                point: i,
                field: "ring",
                reason,
            })?;
            cloud.ring.push(r);
        }
        if let Some(j) = col[5] {
            let s = cell(j)?;
            let t = s
                .parse::<f64>()
                .map_err(|_| parse_err(line, &names[j], format!("{s:?} is not a number")))?;
            if !t.is_finite() {
                return Err(columns::non_finite(source, i, "time", t));
            }
            time.push(t);
        }
    }
    if let Some(lookup) = lookup {
        let mut ring = Vec::with_capacity(cloud.len());
        lookup.extend(&mut ring, &cloud.x, &cloud.y, &cloud.z);
        cloud.ring = ring;
    }
    if col[5].is_some() {
        cloud.time = Some(columns::time_to_f32(source, &time)?);
    }
    Ok(cloud)
}

/// Encodes `cloud` as `x,y,z,intensity,ring[,time]` CSV (shortest
/// round-trip decimals).
pub(crate) fn encode_csv(cloud: &PointCloud, path: &Path) -> Result<Vec<u8>, IoError> {
    let io = |e: csv::Error| IoError::Io {
        path: path.to_path_buf(),
        action: "encode CSV",
        source: e.into(),
    };
    let mut w = csv::Writer::from_writer(Vec::with_capacity(cloud.len() * 40));
    let ncol = if cloud.time.is_some() { 6 } else { 5 };
    w.write_record(&FIELDS[..ncol]).map_err(io)?;
    let mut cell = String::new();
    for i in 0..cloud.len() {
        for v in [cloud.x[i], cloud.y[i], cloud.z[i], cloud.intensity[i]] {
            cell.clear();
            let _ = write!(cell, "{v}");
            w.write_field(&cell).map_err(io)?;
        }
        cell.clear();
        let _ = write!(cell, "{}", cloud.ring[i]);
        w.write_field(&cell).map_err(io)?;
        if let Some(t) = &cloud.time {
            cell.clear();
            let _ = write!(cell, "{}", t[i]);
            w.write_field(&cell).map_err(io)?;
        }
        w.write_record(None::<&[u8]>).map_err(io)?;
    }
    w.into_inner().map_err(|e| IoError::Io {
        path: path.to_path_buf(),
        action: "encode CSV",
        source: e.into_error(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn xorshift(s: &mut u64) -> u64 {
        *s ^= *s << 13;
        *s ^= *s >> 7;
        *s ^= *s << 17;
        *s
    }

    fn std_f32(s: &str) -> Option<f32> {
        s.parse::<f32>().ok()
    }

    #[test]
    fn fast_f32_gives_std_parse_bits_or_declines() {
        let mut s = 0x9E37_79B9_7F4A_7C15u64;
        let mut cells: Vec<String> = Vec::new();
        for _ in 0..300_000 {
            let v = f32::from_bits(xorshift(&mut s) as u32);
            if v.is_finite() {
                cells.push(format!("{v}"));
            }
            let w = (xorshift(&mut s) as f64 / u64::MAX as f64 - 0.5) * 400.0;
            let w32 = w as f32;
            cells.push(format!("{w32}"));
            let prec = (xorshift(&mut s) % 12) as usize;
            cells.push(format!("{w:.prec$}"));
            // Random digit strings with a dot anywhere.
            let len = 1 + (xorshift(&mut s) % 18) as usize;
            let mut d: String = (0..len)
                .map(|_| char::from(b'0' + (xorshift(&mut s) % 10) as u8))
                .collect();
            let dot = (xorshift(&mut s) % (len as u64 + 1)) as usize;
            d.insert(dot, '.');
            cells.push(d.clone());
            cells.push(format!("-{d}"));
        }
        // Halfway between two f32s, integers past 2^24, odd syntax.
        for c in [
            "16777217",
            "16777217.0",
            "-16777217",
            "33554434",
            "33554435",
            "0",
            "-0",
            "+0.5",
            "0.",
            ".5",
            "-.5",
            ".",
            "-",
            "+",
            "",
            "1e5",
            "1E5",
            "inf",
            "-inf",
            "NaN",
            "1.2.3",
            " 1.5",
            "1.5 ",
            "1,5",
            "0x10",
            "9007199254740993",
            "9007199254740992",
            "0.0000000000000000000001",
            "123456789012345678",
            "3.4028236e38",
            "340282356779733661637539395458142568448",
            "1.00000005960464477539",
        ] {
            cells.push(c.to_string());
        }
        let mut fast = 0usize;
        for c in &cells {
            // Followed by the rest of a row, the cell takes the SWAR reader.
            let padded = format!("{c},7,8,9,10,11,12,13,14,15,16\n");
            let swar = fast_f32_prefix(padded.as_bytes())
                .filter(|&(_, len)| len == c.len())
                .map(|(v, _)| v.to_bits());
            assert_eq!(swar, fast_f32(c.as_bytes()).map(f32::to_bits), "{c:?}");
            if let Some(v) = fast_f32(c.as_bytes()) {
                fast += 1;
                let want = std_f32(c)
                    .unwrap_or_else(|| panic!("{c:?}: fast path accepted what std refuses"));
                assert_eq!(v.to_bits(), want.to_bits(), "{c:?}");
            }
        }
        assert!(
            fast * 10 > cells.len() * 8,
            "fast path took {fast} of {}",
            cells.len()
        );
        assert_eq!(fast_f32(b"16777217"), None, "halfway case must decline");
        assert_eq!(fast_f32(b"-0").map(f32::to_bits), Some((-0.0f32).to_bits()));
    }

    /// The fast and the `csv`-crate parsers agree: same cloud, or errors of
    /// the same kind at the same line / point / column.
    fn agree(text: &str) {
        let p = Path::new("t.csv");
        let opts = ReadOptions::default();
        let fast = match parse_csv_rows(text.as_bytes(), p, &opts, CsvNeeds::ALL) {
            Ok(Some(rows)) => Ok(rows.cloud),
            Ok(None) => panic!("{text:?}: fast path declined"),
            Err(e) => Err(e),
        };
        let slow = parse_csv_quoted(text.as_bytes(), p, &opts);
        match (fast, slow) {
            (Ok(a), Ok(b)) => assert_eq!(a, b, "{text:?}"),
            (Err(a), Err(b)) => {
                // The csv crate miscounts lines after blank lines (the fast
                // parser's numbers are the editor's; tested elsewhere).
                // Same after `\r\n` line breaks.
                let blank =
                    text.contains("\n\n") || text.contains("\n   \n") || text.contains('\r');
                let key = |e: &IoError| match e {
                    IoError::Parse { column, .. } if blank => format!("parse {column}"),
                    IoError::Parse { line, column, .. } => format!("parse {line} {column}"),
                    IoError::NonFinite { point, field, .. } => format!("nonfinite {point} {field}"),
                    IoError::BadValue { point, field, .. } => format!("bad {point} {field}"),
                    other => format!("{other}"),
                };
                assert_eq!(key(&a), key(&b), "{text:?}: fast {a} / csv crate {b}");
            }
            (a, b) => panic!("{text:?}: fast {a:?} / csv crate {b:?}"),
        }
    }

    /// [`agree`], then the fast parser's rows of `text`.
    fn agreed_rows(text: &str) -> CsvRows {
        agree(text);
        parse_csv_rows(
            text.as_bytes(),
            Path::new("t.csv"),
            &ReadOptions::default(),
            CsvNeeds::ALL,
        )
        .unwrap()
        .expect("no quoted cells")
    }

    #[test]
    fn fast_parser_agrees_with_the_csv_crate() {
        for text in [
            "x,y,z,intensity,ring\n1,2,3,4,5\n-1.5,2.25,0.125,17,0\n",
            "x,y,z,intensity,ring\n1,2,3,4,5",
            "x,y,z,intensity,ring\r\n1,2,3,4,5\r\n6,7,8,9,10\r\n",
            "x,y,z,intensity,ring\n\n1,2,3,4,5\n\n\n6,7,8,9,10\n\n",
            "x , y,z ,intensity, ring\n 1 , 2,3 ,4, 5\n",
            "\u{FEFF}x,y,z,intensity\n1,2,3,4\n",
            "a,x,b,y,z,intensity,time,ring\nfoo,1,bar,2,3,4,1700000000.5,3.0\nq,5,r,6,7,8,1700000001.25,4\n",
            "x,y,z,intensity,time\n1,2,3,4,0.5\n2,3,4,5,0.75\n",
            "Points_m_XYZ:0,Points_m_XYZ:1,Points_m_XYZ:2,intensity,laser_id\n1,2,3,4,14\n",
            "x,y,z,intensity\n1e3,2E-2,+3,.5\n",
            // Bad inputs.
            "x,y,z,intensity,ring\n1,2,3,4,5\n1,2,3,bright,5\n",
            "x,y,z,intensity\n1,2,3,4\n1,inf,3,4\n",
            "x,y,z,intensity\n1,2,3,4\n1,2,3\n",
            "x,y,z,intensity\n1,2,3,4\n1,2,3,4,5\n",
            "x,y,z,intensity\n1,,3,4\n",
            "x,y,z,intensity,laser_id\n1,2,3,4,-2\n",
            "x,y,z,intensity,ring\n1,2,3,4,2.5\n",
            "x,y,z,intensity,ring\n1,2,3,4,70000\n",
            "x,y,z,intensity,ring\n1,2,3,4,x\n",
            "x,y,z,intensity,time\n1,2,3,4,nan\n",
            "x,y,z,intensity,time\n1,2,3,4,\n",
            "x,y,z,intensity\n1,2,3,1e39\n",
            "x,y,z,intensity\n\n\n1,2,3,4\n\n1,2,nope,4\n",
            "x,y,z,intensity\n1,2,3,4\n   \n",
            "x,y,z,intensity\r\n1,2,3,4\r\n1,2,x,4\r\n",
        ] {
            agree(text);
        }
    }

    #[test]
    fn large_files_parse_in_pieces_like_the_csv_crate() {
        // ~1.5 MB: several pieces; an error far in the file names its line.
        let mut s = 7u64;
        let mut text = String::from("x,y,z,intensity,ring,extra\n");
        for i in 0..40_000 {
            let v = |s: &mut u64| (xorshift(s) % 200_000) as f32 / 1000.0 - 100.0;
            let (x, y, z) = (v(&mut s), v(&mut s), v(&mut s));
            text.push_str(&format!("{x},{y},{z},{},{},e{i}\n", i % 256, i % 16));
            if i % 9_999 == 0 {
                text.push('\n');
            }
        }
        let rows = agreed_rows(&text);
        assert!(rows.pieces.len() > 3, "{} pieces", rows.pieces.len());
        // Everything kept, nothing edited: the file comes back byte for byte
        // less its blank lines.
        let all = rows.encode_subset(text.as_bytes(), &vec![1; rows.cloud.len()], &[], None);
        let no_blank: String = text
            .lines()
            .filter(|l| !l.is_empty())
            .map(|l| format!("{l}\n"))
            .collect();
        assert_eq!(String::from_utf8(all).unwrap(), no_blank);
        let bad = text.replacen("e30000", "e30000,oops", 1);
        agree(&bad);
        let e = parse_csv(bad.as_bytes(), Path::new("t.csv"), &ReadOptions::default()).unwrap_err();
        // Header line 1, rows 0..=30000, blank lines after rows 0, 9999,
        // 19998 and 29997.
        assert!(matches!(e, IoError::Parse { line: 30_006, .. }), "{e}");
    }

    #[test]
    fn odd_rows_anywhere_in_a_multi_piece_file_parse_like_the_csv_crate() {
        // Pieces are read two at a time, row by row in lockstep, and each
        // falls back on its own at a row the fast path declines: odd rows
        // sprinkled over many pieces must still give the csv crate's cloud.
        let mut s = 11u64;
        let mut text = String::from("x,y,z,intensity,ring\n");
        for i in 0..60_000u64 {
            let v = |s: &mut u64| (xorshift(s) % 2_000_000) as f32 / 10_000.0 - 100.0;
            let (x, y, z) = (v(&mut s), v(&mut s), v(&mut s));
            let row = match xorshift(&mut s) % 400 {
                0 => format!("{x:e},{y},{z},{},{}\n", i % 256, i % 16),
                1 => format!(" {x} ,{y},{z},{},{}\n", i % 256, i % 16),
                2 => format!("+{},{y},{z},{},{}\r\n", x.abs(), i % 256, i % 16),
                3 => format!("{x},{y:.12},{z},{},{}\n", i % 256, i % 16),
                4 => format!("{x},{y},{z},{},{}\n\n", i % 256, i % 16),
                5 => format!("{x},{y},{z},{}.0000000000001,{}\n", i % 256, i % 16),
                _ => format!("{x},{y},{z},{},{}\n", i % 256, i % 16),
            };
            text.push_str(&row);
        }
        let rows = agreed_rows(&text);
        assert!(rows.pieces.len() >= 6, "{} pieces", rows.pieces.len());
        // Kept rows written from the recorded row ends equal those found by
        // scanning for line breaks (CRLF and blank lines included).
        let keep: Vec<u8> = (0..rows.cloud.len())
            .map(|_| u8::from(xorshift(&mut s).is_multiple_of(3)))
            .collect();
        let mut scanned = rows.clone();
        scanned.row_ends.clear();
        assert_eq!(
            rows.encode_subset(text.as_bytes(), &keep, &[], None),
            scanned.encode_subset(text.as_bytes(), &keep, &[], None)
        );
        // An error in the second piece of a pair and a later one in the
        // first piece of the next pair: the earlier one is reported.
        let cut = rows.pieces[1].bytes.start + 100;
        let nl = cut + text[cut..].find('\n').unwrap() + 1;
        let mut bad = text.clone();
        bad.insert_str(nl, "1,2,x,4,5\n");
        let later = rows.pieces[2].bytes.start + 5_000;
        let nl2 = later + bad[later..].find('\n').unwrap() + 1;
        bad.insert_str(nl2, "1,2,3\n");
        agree(&bad);
        let e = parse_csv(bad.as_bytes(), Path::new("t.csv"), &ReadOptions::default()).unwrap_err();
        assert!(
            matches!(e, IoError::Parse { ref column, .. } if column == "z"),
            "{e}"
        );
    }

    #[test]
    fn encode_subset_copies_kept_rows_and_rewrites_only_edited_cells() {
        let text = b"ring,x,y,z,intensity,time,note\r\n3,10,0,0,7,1700000000.5,a b\r\n4,20,0,0,9,1700000000.75,c\r\n5,30,0,0,11,1700000001,d";
        let rows = parse_csv_rows(
            text,
            Path::new("t.csv"),
            &ReadOptions::default(),
            CsvNeeds::ALL,
        )
        .unwrap()
        .unwrap();
        assert_eq!(rows.time_origin, 1_700_000_000.5);
        let mut edit = RowEdit {
            row: 2,
            values: [1.5, -0.25, 0.1, 3.0],
            fresh: false,
        };
        let mut added = PointCloud::default();
        added.push_timed(2.0, 0.0, 0.5, 4.0, 7, 0.25);
        let out = rows.encode_subset(text, &[1, 0, 1], &[edit], Some(&added));
        let want = "ring,x,y,z,intensity,time,note\r\n3,10,0,0,7,1700000000.5,a b\r\n5,1.5,-0.25,0.1,3,1700000001,d\r\n7,2,0,0.5,4,1700000000.75,\r\n";
        assert_eq!(String::from_utf8(out).unwrap(), want);
        // A fresh point on the row's ray keeps ring and time, not the note.
        edit.fresh = true;
        let out = rows.encode_subset(text, &[1, 0, 1], &[edit], None);
        let want = "ring,x,y,z,intensity,time,note\r\n3,10,0,0,7,1700000000.5,a b\r\n5,1.5,-0.25,0.1,3,1700000001,";
        assert_eq!(String::from_utf8(out).unwrap(), want);
    }

    /// Every keep pattern of a file with blank lines and no final line
    /// break: the written subset is exactly the kept rows, in order (runs of
    /// consecutive kept rows are written as one slice, which must neither
    /// drop a row nor carry a blank line along), and an added point after a
    /// kept last row gets its own line.
    #[test]
    fn write_subset_gives_exactly_the_kept_rows_for_every_pattern() {
        let text = b"x,y,z,intensity\n1,0,0,1\n2,0,0,2\n\n3,0,0,3\n4,0,0,4\n\n\n5,0,0,5";
        let rows = parse_csv_rows(
            text,
            Path::new("t.csv"),
            &ReadOptions::default(),
            CsvNeeds::default(),
        )
        .unwrap()
        .unwrap();
        assert_eq!(rows.row_ends.len(), 5, "row ends recorded");
        // The same rows found by scanning for line breaks (what happens when
        // a piece is too large for recorded ends) must give the same bytes.
        let mut scanned = rows.clone();
        scanned.row_ends.clear();
        let lines = ["1,0,0,1", "2,0,0,2", "3,0,0,3", "4,0,0,4", "5,0,0,5"];
        let mut added = PointCloud::default();
        added.push(6.0, 0.0, 0.0, 6.0, 0);
        for r in [&rows, &scanned] {
            let got: Vec<&[u8]> = r.rows(text, &r.pieces[0]).collect();
            let want: Vec<&[u8]> = vec![
                b"1,0,0,1\n",
                b"2,0,0,2\n",
                b"3,0,0,3\n",
                b"4,0,0,4\n",
                b"5,0,0,5",
            ];
            assert_eq!(got, want);
        }
        for (pattern, rows) in (0u32..32).flat_map(|p| [(p, &rows), (p, &scanned)]) {
            let keep: Vec<u8> = (0..5).map(|k| ((pattern >> k) & 1) as u8).collect();
            let kept: Vec<&str> = (0..5).filter(|&k| keep[k] == 1).map(|k| lines[k]).collect();
            let mut want = String::from("x,y,z,intensity\n");
            for (i, l) in kept.iter().enumerate() {
                want.push_str(l);
                // Only the file's last row has no line break.
                if i + 1 < kept.len() || keep[4] == 0 {
                    want.push('\n');
                }
            }
            let out = rows.encode_subset(text, &keep, &[], None);
            assert_eq!(String::from_utf8(out).unwrap(), want, "keep {keep:?}");
            let with_added = rows.encode_subset(text, &keep, &[], Some(&added));
            let mut want_added = want.clone();
            if !want_added.ends_with('\n') {
                want_added.push('\n');
            }
            want_added.push_str("6,0,0,6\n");
            assert_eq!(
                String::from_utf8(with_added).unwrap(),
                want_added,
                "keep {keep:?}"
            );
        }
    }

    #[test]
    fn quoted_data_and_lone_carriage_returns_go_to_the_csv_crate() {
        let p = Path::new("t.csv");
        let o = ReadOptions::default();
        let quoted = b"x,y,z,intensity\n\"1\",2,3,4\n";
        assert!(
            parse_csv_rows(quoted, p, &o, CsvNeeds::ALL)
                .unwrap()
                .is_none()
        );
        assert_eq!(parse_csv(quoted, p, &o).unwrap().x, vec![1.0]);
        let old_mac = b"x,y,z,intensity\r1,2,3,4\r5,6,7,8\r";
        assert!(
            parse_csv_rows(old_mac, p, &o, CsvNeeds::ALL)
                .unwrap()
                .is_none()
        );
        assert_eq!(parse_csv(old_mac, p, &o).unwrap().x, vec![1.0, 5.0]);
    }
}
