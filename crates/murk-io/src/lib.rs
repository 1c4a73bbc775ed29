//! Point-cloud readers and writers of murk.
//!
//! One entry point per direction, the format chosen by extension (or forced
//! with [`ReadOptions::format`] / [`WriteOptions::format`]):
//!
//! - [`read_cloud`] reads a whole file into a [`PointCloud`] (a `.pcap`
//!   capture: all revolutions concatenated); [`read_frames`] keeps a
//!   capture's revolutions apart.
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
//! | KITTI `.bin` | `f32 × 4`; ring from elevation | `x y z intensity` |
//! | nuScenes `.pcd.bin` | `f32 × 5` | `x y z intensity ring` |
//! | CSV `.csv` | `x,y,z,intensity[,ring][,time]` or VeloView export | `x,y,z,intensity,ring[,time]` |
//! | Parquet `.parquet` | `x y z intensity [ring] [time]`, any numeric type | `f32` columns, `ring` `u32` |
//! | Velodyne `.pcap` | through `murk-velodyne` | — |
//!
//! **Intensity is never converted.** The returned cloud's
//! [`PointCloud::intensity_scale`] says what its `intensity` means (see
//! [`ReadOptions`]); callers call [`PointCloud::to_calibrated`]. Writers
//! store intensity as it is in the cloud.
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
//! **Bad input is an error, never a skip**: empty files, truncated data,
//! sizes that disagree with a header, non-finite coordinates or intensities,
//! unusable field types; each [`IoError`] names the file and the line, point
//! or column.
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
mod ring;
#[cfg(feature = "parquet")]
mod table;
mod text;

use std::path::Path;

use murk_types::{LidarSpec, PointCloud, PointFormat};

pub use bin_records::{parse_kitti, parse_nuscenes};
pub use error::IoError;
pub use options::{PcdData, ReadOptions, WriteOptions};
pub use pcd::parse_pcd;
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

/// Reads a whole point-cloud file (a `.pcap`: every revolution, concatenated).
pub fn read_cloud(path: &Path, opts: &ReadOptions) -> Result<PointCloud, IoError> {
    let format = opts.format_of(path)?;
    if format == PointFormat::Pcap {
        let frames = pcap::read_frames(path, opts)?;
        let mut all = PointCloud::default();
        if let Some(first) = frames.first() {
            all.intensity_scale = first.intensity_scale;
        }
        for f in &frames {
            all.extend_from(f).map_err(|e| IoError::Format {
                path: path.to_path_buf(),
                reason: format!("cannot join the capture's frames: {e}"),
            })?;
        }
        return Ok(all);
    }
    with_file_bytes(path, |bytes| parse_cloud(bytes, format, path, opts))?
}

/// Reads a file as a list of scans: one per revolution for a `.pcap`, the
/// whole file as one scan for every other format.
pub fn read_frames(path: &Path, opts: &ReadOptions) -> Result<Vec<PointCloud>, IoError> {
    match opts.format_of(path)? {
        PointFormat::Pcap => pcap::read_frames(path, opts),
        _ => Ok(vec![read_cloud(path, opts)?]),
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
