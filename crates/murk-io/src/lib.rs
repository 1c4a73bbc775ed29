//! Point-cloud readers and writers of murk.
//!
//! One entry point per direction, the format chosen by extension (or forced
//! with [`ReadOptions::format`] / [`WriteOptions::format`]):
//!
//! - [`read_cloud`] reads a whole file into a [`PointCloud`] (a `.pcap`
//!   capture: all revolutions concatenated); [`read_frames`] keeps a
//!   capture's revolutions apart. [`read_cloud_noted`] and
//!   [`read_frames_noted`] also return [`ReadNotes`] (where the intensity
//!   scale came from, fields the cloud cannot carry, packets skipped, a
//!   capture cut short) and, for captures, which revolutions are partial.
//! - [`write_cloud`] / [`write_cloud_with`] write atomically (a temporary
//!   file in the target folder, then a rename), byte-identically for
//!   identical clouds.
//! - [`parse_pcd`], [`parse_kitti`], [`parse_nuscenes`], [`parse_csv`],
//!   `parse_parquet` parse bytes already in memory (fuzzing, benches).
//!
//! Parquet support (polars) is the default feature `parquet`; without it the
//! Parquet format is an error and the crate builds in a fraction of the time
//! (the fuzz targets use that).
//!
//! | format | read | write |
//! |---|---|---|
//! | PCD `.pcd` | `ascii`, `binary`, `binary_compressed`; any field order and numeric type | `x y z intensity ring [time]`, any of the three encodings ([`PcdData`]) |
//! | KITTI `.bin` | `f32 × 4`; ring from elevation; or a declared [`BinLayout`] (`xyzir`, `xyzit`) | `x y z intensity` (0–1) |
//! | nuScenes `.pcd.bin` | `f32 × 5` | `x y z intensity ring` |
//! | CSV `.csv` | `x,y,z,intensity[,ring][,time]` or VeloView export; header-less with declared columns | `x,y,z,intensity,ring[,time]` |
//! | Parquet `.parquet` | `x y z intensity [ring] [time]`, any numeric type | `f32` columns, `ring` `u32` |
//! | Velodyne `.pcap` | through `murk-velodyne` | — |
//!
//! **Layouts murk must be told.** A header-less CSV (RADIATE writes
//! `x,y,z,intensity,ring` rows) needs [`ReadOptions::csv_columns`]; without
//! it a first line of numbers is an [`IoError::NoHeader`] that says so. A
//! `.bin` is KITTI `xyzi` unless [`ReadOptions::bin_layout`] says `xyzir`
//! (Seeing Through Fog) or `xyzit`; a `.bin` whose size fits several
//! layouts is refused ([`IoError::AmbiguousLayout`]) unless the bytes rule
//! the five-float layouts out (see [`parse_kitti`]). Both also come from
//! `csv_columns` / `bin_layout` of the sensor description
//! ([`ReadOptions::lidar`], `[lidar]` in `campaign.toml`).
//!
//! **Intensity is never converted by a reader.** The returned cloud's
//! [`PointCloud::intensity_scale`] says what its `intensity` means: the
//! declared scale ([`ReadOptions::intensity_scale`], else the sensor
//! description's), else what the file records, else the format's (or
//! layout's) default; [`ReadNotes::scale_source`] says which. Callers call
//! [`PointCloud::to_calibrated`]. Writers store intensity as it is in the
//! cloud; a **PCD records a scale other than calibrated** in a header
//! comment, `# murk: intensity_scale kitti` (or `… gain G offset O`),
//! which other PCD readers skip and [`parse_pcd`] reads back. The other
//! formats have no place for it: write them in [`portable_scale`] (their
//! default) so that a plain read gives the same reflectivities, as `murk
//! convert` and `murk apply` do. A read warns when the values contradict
//! their scale (KITTI-scaled values above 1, calibrated values all in 0–1).
//!
//! **Rings.** Formats or files without a ring get it from each point's
//! elevation: the ring of [`ReadOptions::lidar`] (default: the VLP-16) whose
//! elevation is nearest, as [`murk_types::LidarSpec::nearest_ring`] decides.
//!
//! **Time.** `PointCloud::time` is seconds relative to the scan. A time
//! column that holds absolute clock values (first value ≥ 10⁵ s, e.g. epoch
//! seconds in an `F8` PCD field) is made relative to its first point, since
//! `f32` cannot hold it; smaller values are kept as they are.
//!
//! **Captures** are decoded with packets that are not the sensor's (ARP,
//! GPS) skipped and counted, and a file cut inside its last packet keeps
//! the revolutions before the cut; both are reported in the notes, and the
//! first and last revolutions are flagged partial when they do not cover
//! 360° ([`Frames::partial`]).
//!
//! **Fields a cloud cannot carry** (a PCD's `rgb`, normals or `label`, a
//! CSV's extra columns) are listed in [`ReadNotes::dropped_fields`]; the
//! row-preserving CSV path ([`parse_csv_rows`]) keeps extra columns.
//!
//! **Bad input is an error, never a skip**: empty files, truncated data,
//! sizes that disagree with a header, non-finite coordinates or intensities,
//! ring ids outside 0..=65535 (checked by every CSV path, whether the ring
//! is decoded or not), unusable field types; each [`IoError`] names the
//! file and the line, point or column.
//!
//! ```
//! use murk_io::{read_cloud, write_cloud_with, PcdData, ReadOptions, WriteOptions};
//! use murk_types::{PointCloud, PointFormat};
//!
//! let dir = tempfile::tempdir()?;
//! let path = dir.path().join("scan.pcd");
//! let mut cloud = PointCloud::with_capacity(2);
//! cloud.push(12.5, -3.0, 0.25, 40.0, 7);
//! cloud.push(0.5, 0.5, -0.125, 3.0, 0);
//!
//! let opts = WriteOptions { format: PointFormat::Pcd, pcd_data: PcdData::BinaryCompressed };
//! write_cloud_with(&path, &cloud, &opts)?;
//! let back = read_cloud(&path, &ReadOptions::default())?;
//! assert_eq!(back, cloud);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![deny(missing_docs)]

mod bin_records;
mod columns;
mod decimal;
mod error;
mod options;
mod pcap;
mod pcd;
mod positioned;
mod ring;
#[cfg(feature = "parquet")]
mod table;
mod text;

use std::path::Path;

use murk_types::{LidarSpec, PointCloud, PointFormat};

pub use bin_records::{parse_kitti, parse_nuscenes};
pub use error::IoError;
pub use murk_types::BinLayout;
pub use options::{PcdData, ReadOptions, WriteOptions};
pub use pcd::parse_pcd;
pub use positioned::{read_exact_at, write_all_at};
#[cfg(feature = "parquet")]
pub use table::parse_parquet;
pub use text::{CsvNeeds, CsvRows, RowEdit, RowPiece, parse_csv, parse_csv_rows};

/// The ring lookup for a read: `opts.lidar`, else the VLP-16.
pub(crate) fn ring_lookup(source: &Path, opts: &ReadOptions) -> Result<ring::RingLookup, IoError> {
    match &opts.lidar {
        Some(spec) => {
            spec.validate().map_err(|e| IoError::Lidar {
                path: source.to_path_buf(),
                reason: e.to_string(),
            })?;
            Ok(ring::RingLookup::new(spec))
        }
        None => Ok(ring::RingLookup::new(&LidarSpec::vlp16())),
    }
}

/// Largest read buffer a thread keeps for its next file, bytes.
const KEEP_BUFFER: usize = 1 << 28;

thread_local! {
    /// The buffer [`with_file_bytes`] reads into, kept per thread between
    /// files: a fresh file-sized `Vec` costs a page fault per 4 KiB page on
    /// its first touch (zeroing included), which measured as much time as
    /// decoding a binary PCD. Reusing one makes the read a plain copy from
    /// the page cache.
    static READ_BUFFER: std::cell::RefCell<Vec<u8>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Reads the whole file at `path` and calls `f` on its bytes (for callers
/// that parse and then copy parts of the file, as `murk apply` does with
/// CSV rows).
///
/// The bytes live in this thread's reusable buffer. A nested call on the same
/// thread (rayon may run another file's read inside `f` while it waits for
/// its own parallel decode) finds the buffer in use and reads into a fresh
/// one instead.
pub fn with_file_bytes<R>(path: &Path, f: impl FnOnce(&[u8]) -> R) -> Result<R, IoError> {
    let io = |source| IoError::Io {
        path: path.to_path_buf(),
        action: "read",
        source,
    };
    let read_into = |buf: &mut Vec<u8>| -> Result<(), IoError> {
        use std::io::Read as _;
        let mut file = std::fs::File::open(path).map_err(io)?;
        let size = file.metadata().map(|m| m.len() as usize).unwrap_or(0);
        buf.clear();
        buf.reserve(size);
        file.read_to_end(buf).map_err(io)?;
        if buf.is_empty() {
            return Err(IoError::Empty {
                path: path.to_path_buf(),
            });
        }
        Ok(())
    };
    READ_BUFFER.with(|cell| match cell.try_borrow_mut() {
        Ok(mut buf) => {
            let result = read_into(&mut buf).map(|()| f(&buf));
            if buf.capacity() > KEEP_BUFFER {
                *buf = Vec::new();
            }
            result
        }
        Err(_) => {
            let mut buf = Vec::new();
            read_into(&mut buf)?;
            Ok(f(&buf))
        }
    })
}

/// Parses bytes already in memory as `format` (every format but `Pcap`).
///
/// `source` only names the data in errors.
pub fn parse_cloud(
    bytes: &[u8],
    format: PointFormat,
    source: &Path,
    opts: &ReadOptions,
) -> Result<PointCloud, IoError> {
    match format {
        PointFormat::Pcd => parse_pcd(bytes, source, opts),
        PointFormat::KittiBin => parse_kitti(bytes, source, opts),
        PointFormat::NuscenesBin => parse_nuscenes(bytes, source, opts),
        PointFormat::Csv => parse_csv(bytes, source, opts),
        #[cfg(feature = "parquet")]
        PointFormat::Parquet => parse_parquet(bytes, source, opts),
        other => Err(IoError::Format {
            path: source.to_path_buf(),
            reason: format!("{other:?} cannot be parsed from memory; use read_frames"),
        }),
    }
}

/// Where the intensity scale of a cloud that was read came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub enum ScaleSource {
    /// The caller declared it ([`ReadOptions::intensity_scale`], or the
    /// `intensity_scale` of [`ReadOptions::lidar`]).
    Declared,
    /// The file records it (a murk PCD's `# murk: intensity_scale` comment).
    File,
    /// Nothing said: the format's or the layout's default was assumed.
    #[default]
    Default,
}

impl ScaleSource {
    /// A few words for summaries: `declared`, `recorded in the file`,
    /// `assumed (format default)`.
    pub fn describe(self) -> &'static str {
        match self {
            ScaleSource::Declared => "declared",
            ScaleSource::File => "recorded in the file",
            ScaleSource::Default => "assumed (format default)",
        }
    }
}

/// What a read did besides giving points: what the caller should tell the
/// user (see [`read_cloud_noted`]).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
#[non_exhaustive]
pub struct ReadNotes {
    /// Where the cloud's intensity scale came from.
    pub scale_source: ScaleSource,
    /// Fields (PCD) or columns (CSV) of the file that a [`PointCloud`]
    /// cannot carry (`rgb`, normals, labels, …): a file written from the
    /// cloud does not have them.
    pub dropped_fields: Vec<String>,
    /// Packets of a capture that were not the sensor's, skipped.
    pub foreign_packets: u64,
    /// Anything else worth a warning: skipped packets by kind, a capture
    /// cut short, intensities outside the range of their scale.
    pub warnings: Vec<String>,
    /// A dual-return capture read as recorded: both returns of a firing
    /// (where they differ) are points, at the same ring and azimuth.
    pub both_returns: bool,
}

/// The scans of a file, each flagged partial or not, and the read's notes
/// ([`read_frames_noted`]).
#[derive(Debug, Clone, Default, PartialEq)]
#[non_exhaustive]
pub struct Frames {
    /// One cloud per revolution for a `.pcap`, the whole file otherwise.
    pub clouds: Vec<PointCloud>,
    /// Per cloud: true for a capture's first or last revolution that does
    /// not cover 360° (always false for other formats).
    pub partial: Vec<bool>,
    /// What the read skipped, assumed or cut.
    pub notes: ReadNotes,
}

/// Intensities no scale's range explains: a KITTI-scaled cloud above 1, or
/// a calibrated cloud whose intensities all lie in 0..=1 (a 0–1 file read
/// without its scale). A warning for `path`, or `None`.
fn scale_warning(path: &Path, cloud: &PointCloud) -> Option<String> {
    if cloud.is_empty() {
        return None;
    }
    let (lo, hi) = cloud
        .intensity
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let scale = cloud.intensity_scale;
    if scale == murk_types::IntensityScale::KITTI && hi > 1.0 {
        Some(format!(
            "{}: intensities reach {hi}, beyond the 0–1 of the kitti scale they are read in: state the scale with --intensity-scale (or intensity_scale in campaign.toml)",
            path.display()
        ))
    } else if scale == murk_types::IntensityScale::Calibrated
        && lo >= 0.0
        && hi <= 1.0
        && hi > 0.0
        && cloud.len() >= 100
    {
        Some(format!(
            "{}: every intensity lies in 0–1 but is read as calibrated 0–255 reflectivity: if the file uses a 0–1 scale, say --intensity-scale kitti",
            path.display()
        ))
    } else {
        None
    }
}

/// [`parse_cloud`] with the read's notes.
pub fn parse_cloud_noted(
    bytes: &[u8],
    format: PointFormat,
    source: &Path,
    opts: &ReadOptions,
) -> Result<(PointCloud, ReadNotes), IoError> {
    let (cloud, mut notes) = match format {
        PointFormat::Pcd => pcd::parse_pcd_noted(bytes, source, opts)?,
        _ => {
            let cloud = parse_cloud(bytes, format, source, opts)?;
            let notes = ReadNotes {
                scale_source: if opts.declared_scale().is_some() {
                    ScaleSource::Declared
                } else {
                    ScaleSource::Default
                },
                dropped_fields: if format == PointFormat::Csv {
                    text::extra_columns(bytes, source, opts)
                } else {
                    Vec::new()
                },
                ..ReadNotes::default()
            };
            (cloud, notes)
        }
    };
    notes.warnings.extend(scale_warning(source, &cloud));
    Ok((cloud, notes))
}

/// Reads a whole point-cloud file (a `.pcap`: every revolution, concatenated).
pub fn read_cloud(path: &Path, opts: &ReadOptions) -> Result<PointCloud, IoError> {
    read_cloud_noted(path, opts).map(|(c, _)| c)
}

/// [`read_cloud`] with the read's notes (where the intensity scale came
/// from, fields the cloud cannot carry, packets skipped).
pub fn read_cloud_noted(
    path: &Path,
    opts: &ReadOptions,
) -> Result<(PointCloud, ReadNotes), IoError> {
    let format = opts.format_of(path)?;
    if format == PointFormat::Pcap {
        let frames = pcap::read_frames(path, opts)?;
        let mut all = PointCloud::default();
        if let Some(first) = frames.clouds.first() {
            all.intensity_scale = first.intensity_scale;
        }
        for f in &frames.clouds {
            all.extend_from(f).map_err(|e| IoError::Format {
                path: path.to_path_buf(),
                reason: format!("cannot join the capture's frames: {e}"),
            })?;
        }
        return Ok((all, frames.notes));
    }
    with_file_bytes(path, |bytes| parse_cloud_noted(bytes, format, path, opts))?
}

/// Reads a file as a list of scans: one per revolution for a `.pcap`
/// (partial first and last revolutions included), the whole file as one
/// scan for every other format.
pub fn read_frames(path: &Path, opts: &ReadOptions) -> Result<Vec<PointCloud>, IoError> {
    read_frames_noted(path, opts).map(|f| f.clouds)
}

/// [`read_frames`] with each scan flagged partial or not and the read's
/// notes.
pub fn read_frames_noted(path: &Path, opts: &ReadOptions) -> Result<Frames, IoError> {
    match opts.format_of(path)? {
        PointFormat::Pcap => pcap::read_frames(path, opts),
        _ => {
            let (cloud, notes) = read_cloud_noted(path, opts)?;
            Ok(Frames {
                clouds: vec![cloud],
                partial: vec![false],
                notes,
            })
        }
    }
}

/// True when files of `format` record their intensity scale: PCD, in a
/// `# murk: intensity_scale NAME` header comment (written for every scale
/// but calibrated, read back by [`parse_pcd`]). The other formats have no
/// place for it.
pub fn records_intensity_scale(format: PointFormat) -> bool {
    format == PointFormat::Pcd
}

/// The scale to write a cloud whose intensity is in `scale` as `format`,
/// so that reading the file back with default options gives the same
/// reflectivities: `scale` itself where the format records it
/// ([`records_intensity_scale`]), else the format's default (KITTI `.bin`:
/// 0–1; CSV, Parquet, nuScenes: calibrated).
pub fn portable_scale(
    format: PointFormat,
    scale: murk_types::IntensityScale,
) -> murk_types::IntensityScale {
    if records_intensity_scale(format) {
        scale
    } else {
        format.default_intensity_scale()
    }
}

/// Checks that `cloud` can be written: equal column lengths, finite values.
fn check_writable(cloud: &PointCloud, path: &Path) -> Result<(), IoError> {
    let invalid = |point: usize, reason: String| IoError::InvalidCloud {
        path: path.to_path_buf(),
        point,
        reason,
    };
    cloud.check().map_err(|e| invalid(0, e.to_string()))?;
    let cols = [
        ("x", &cloud.x),
        ("y", &cloud.y),
        ("z", &cloud.z),
        ("intensity", &cloud.intensity),
    ];
    for (name, col) in cols
        .into_iter()
        .chain(cloud.time.as_ref().map(|t| ("time", t)))
    {
        if let Some(i) = columns::first_non_finite(col) {
            return Err(invalid(i, format!("{name} is {} (not finite)", col[i])));
        }
    }
    Ok(())
}

/// Encodes `cloud` in memory as `opts` says (what [`write_cloud_with`]
/// writes). `path` only names the destination in errors.
pub fn encode_cloud(
    cloud: &PointCloud,
    opts: &WriteOptions,
    path: &Path,
) -> Result<Vec<u8>, IoError> {
    check_writable(cloud, path)?;
    match opts.format {
        PointFormat::Pcd => pcd::encode_pcd(cloud, opts.pcd_data, path),
        PointFormat::KittiBin => Ok(bin_records::encode_kitti(cloud)),
        PointFormat::NuscenesBin => Ok(bin_records::encode_nuscenes(cloud)),
        PointFormat::Csv => text::encode_csv(cloud, path),
        #[cfg(feature = "parquet")]
        PointFormat::Parquet => table::encode_parquet(cloud, path),
        other => Err(IoError::Format {
            path: path.to_path_buf(),
            reason: format!("murk cannot write {other:?} files"),
        }),
    }
}

/// Writes `cloud` to `path` in `format` (PCD: `DATA binary`), atomically.
pub fn write_cloud(path: &Path, cloud: &PointCloud, format: PointFormat) -> Result<(), IoError> {
    write_cloud_with(path, cloud, &WriteOptions::new(format))
}

/// Writes `cloud` to `path` as `opts` says, atomically: the bytes go to a
/// temporary file in the same folder, which is then renamed over `path`, so
/// a reader never sees a half-written file.
pub fn write_cloud_with(
    path: &Path,
    cloud: &PointCloud,
    opts: &WriteOptions,
) -> Result<(), IoError> {
    stage_cloud_with(path, cloud, opts)?
        .commit()
        .map_err(atomic_error(path))
}

/// The first half of [`write_cloud_with`]: the encoded cloud in a temporary
/// file next to `path`, synced and renamed into place by
/// [`murk_types::StagedFile::commit`] (dropping it removes the temporary
/// file). For batches that commit on other threads while they go on
/// computing.
pub fn stage_cloud_with(
    path: &Path,
    cloud: &PointCloud,
    opts: &WriteOptions,
) -> Result<murk_types::StagedFile, IoError> {
    let bytes = encode_cloud(cloud, opts, path)?;
    murk_types::stage_atomic(path, &bytes).map_err(atomic_error(path))
}

/// The error of a failed atomic write of `path`.
fn atomic_error(path: &Path) -> impl Fn(murk_types::AtomicWriteError) -> IoError + '_ {
    move |e| IoError::Io {
        path: path.to_path_buf(),
        action: e.action,
        source: e.source,
    }
}
