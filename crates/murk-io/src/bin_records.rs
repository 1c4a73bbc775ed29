//! KITTI `.bin` and nuScenes `.pcd.bin`: headerless little-endian `f32`
//! records (`x y z intensity`, and `ring_index` for nuScenes), or any
//! [`BinLayout`] the caller declares (Seeing Through Fog's `xyzir` `.bin`).

use std::path::Path;

use murk_types::{BinLayout, PointCloud};

use crate::columns::{self, Field, Layout, Scalar};
use crate::{IoError, ReadOptions, ring_lookup};

/// Bytes per KITTI record.
const KITTI_RECORD: usize = 16;
/// Bytes per nuScenes record.
const NUSCENES_RECORD: usize = 20;

/// Splits `bytes` into whole records or reports the trailing bytes.
fn whole_records(bytes: &[u8], record: usize, source: &Path) -> Result<usize, IoError> {
    if bytes.is_empty() {
        return Err(IoError::Empty {
            path: source.to_path_buf(),
        });
    }
    let trailing = bytes.len() % record;
    if trailing != 0 {
        return Err(IoError::TrailingBytes {
            path: source.to_path_buf(),
            size: bytes.len() as u64,
            record,
            trailing,
            points: (bytes.len() / record) as u64,
        });
    }
    Ok(bytes.len() / record)
}

fn f32_field(bytes: &[u8], stride: usize, k: usize) -> Field<'_> {
    Field {
        bytes,
        stride,
        offset: 4 * k,
        ty: Scalar::F32,
    }
}

/// Parses a `.bin` file held in memory: KITTI's `x y z intensity` as
/// little-endian `f32` (the ring from each point's elevation, with
/// `opts.lidar` or the VLP-16), or the layout the caller declares
/// ([`ReadOptions::bin_layout`], else `bin_layout` of `opts.lidar`).
///
/// **Undeclared layouts.** A `.bin` is taken as KITTI `xyzi` without being
/// told only when nothing else fits:
///
/// - size a multiple of 16 and not of 20: `xyzi` (every KITTI scan whose
///   point count is not a multiple of 4, such as the real 000008);
/// - a multiple of 20 and not of 16: a five-float layout, which one the
///   bytes cannot say (ring or time fifth): refused, naming both;
/// - a multiple of 80 (16 and 20): `xyzi` only when the five-float reading
///   is implausible for both five-float layouts: its fifth float is *not* a
///   whole number in 0..=255 for every point (what a ring id always is) and
///   does *not* stay within one second (what one revolution's point times
///   do). Read as 20-byte records, a genuine KITTI scan puts its successive
///   points' x, y, z and intensity into that fifth float: coordinates with
///   fractional metres spread over tens of metres fail both checks on any
///   real scene, so the KITTI default survives for KITTI data, while a
///   Seeing Through Fog `xyzir` file (whole ring ids) is refused instead of
///   read as garbage. Otherwise: refused, naming the layouts.
///
/// The intensity scale is the declared one, else the layout's
/// ([`BinLayout::default_intensity_scale`]: KITTI 0–1 for `xyzi`).
///
/// ```
/// use std::path::Path;
/// use murk_io::{parse_kitti, ReadOptions};
/// use murk_types::IntensityScale;
///
/// let bytes: Vec<u8> = [10.0f32, 0.0, 0.0, 0.5].iter().flat_map(|v| v.to_le_bytes()).collect();
/// let cloud = parse_kitti(&bytes, Path::new("000000.bin"), &ReadOptions::default())?;
/// assert_eq!(cloud.len(), 1);
/// assert_eq!(cloud.intensity_scale, IntensityScale::KITTI);
/// assert_eq!(cloud.ring, vec![1]); // 0° elevation: the VLP-16's +1° ring (id 1)
/// # Ok::<(), murk_io::IoError>(())
/// ```
pub fn parse_kitti(bytes: &[u8], source: &Path, opts: &ReadOptions) -> Result<PointCloud, IoError> {
    let layout = match opts.declared_bin_layout() {
        Some(l) => l,
        None => undeclared_layout(bytes, source)?,
    };
    parse_records(bytes, source, opts, layout)
}

/// The layout of an undeclared `.bin` (see [`parse_kitti`]).
fn undeclared_layout(bytes: &[u8], source: &Path) -> Result<BinLayout, IoError> {
    if bytes.is_empty() {
        return Err(IoError::Empty {
            path: source.to_path_buf(),
        });
    }
    let size = bytes.len();
    let ambiguous = |fits: &str, why: String| IoError::AmbiguousLayout {
        path: source.to_path_buf(),
        size: size as u64,
        fits: fits.to_string(),
        why,
    };
    match (
        size.is_multiple_of(KITTI_RECORD),
        size.is_multiple_of(NUSCENES_RECORD),
    ) {
        (true, false) => Ok(BinLayout::Xyzi),
        (false, false) => Err(IoError::TrailingBytes {
            path: source.to_path_buf(),
            size: size as u64,
            record: KITTI_RECORD,
            trailing: size % KITTI_RECORD,
            points: (size / KITTI_RECORD) as u64,
        }),
        (false, true) => Err(ambiguous(
            "20-byte records (xyzir or xyzit), not KITTI's 16",
            "the bytes do not say whether the fifth float is a ring or a time".into(),
        )),
        (true, true) => {
            let fifth = || {
                bytes
                    .chunks_exact(NUSCENES_RECORD)
                    .map(|r| f32::from_le_bytes([r[16], r[17], r[18], r[19]]))
            };
            let ring_like = fifth().all(|v| v.fract() == 0.0 && (0.0..=255.0).contains(&v));
            let (lo, hi) = fifth().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            });
            let time_like = lo.is_finite() && hi.is_finite() && hi - lo <= MAX_SCAN_SECONDS;
            if ring_like {
                Err(ambiguous(
                    "16-byte (xyzi, KITTI) and 20-byte records (xyzir, xyzit)",
                    "read as 20-byte records every fifth float is a whole number in 0..=255, as a ring id is".into(),
                ))
            } else if time_like {
                Err(ambiguous(
                    "16-byte (xyzi, KITTI) and 20-byte records (xyzir, xyzit)",
                    format!(
                        "read as 20-byte records the fifth floats span {:.3} s, as one scan's point times do",
                        hi - lo
                    ),
                ))
            } else {
                Ok(BinLayout::Xyzi)
            }
        }
    }
}

/// The widest span of point times (seconds) taken for one scan in
/// [`undeclared_layout`]'s plausibility check: a revolution lasts 0.05–0.2 s
/// on spinning LiDARs (5–20 Hz); one second leaves room for slow sensors.
const MAX_SCAN_SECONDS: f32 = 1.0;

/// Parses a nuScenes `.pcd.bin` file held in memory (`x y z intensity
/// ring_index` as little-endian `f32`; `ring_index` must be a whole number),
/// or the layout the caller declares.
pub fn parse_nuscenes(
    bytes: &[u8],
    source: &Path,
    opts: &ReadOptions,
) -> Result<PointCloud, IoError> {
    let layout = opts.declared_bin_layout().unwrap_or(BinLayout::Xyzir);
    parse_records(bytes, source, opts, layout)
}

/// Parses headerless `f32` records of `layout`.
fn parse_records(
    bytes: &[u8],
    source: &Path,
    opts: &ReadOptions,
    layout: BinLayout,
) -> Result<PointCloud, IoError> {
    let record = layout.record_len();
    let n = whole_records(bytes, record, source)?;
    let fifth = (record > KITTI_RECORD).then(|| f32_field(bytes, record, 4));
    let (ring, time) = match layout {
        BinLayout::Xyzi => (None, None),
        BinLayout::Xyzir => (fifth, None),
        BinLayout::Xyzit => (None, fifth),
    };
    let lookup = match ring {
        None => Some(ring_lookup(source, opts)?),
        Some(_) => None,
    };
    let fields = Layout {
        x: f32_field(bytes, record, 0),
        y: f32_field(bytes, record, 1),
        z: f32_field(bytes, record, 2),
        intensity: f32_field(bytes, record, 3),
        ring,
        time,
    };
    let scale = opts
        .declared_scale()
        .unwrap_or_else(|| layout.default_intensity_scale());
    columns::decode(source, &fields, n, lookup.as_ref(), scale)
}

/// Encodes `cloud` as KITTI records (ring and time are not stored).
pub(crate) fn encode_kitti(cloud: &PointCloud) -> Vec<u8> {
    let mut out = Vec::with_capacity(cloud.len() * KITTI_RECORD);
    for i in 0..cloud.len() {
        for v in [cloud.x[i], cloud.y[i], cloud.z[i], cloud.intensity[i]] {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}

/// Encodes `cloud` as nuScenes records (time is not stored).
pub(crate) fn encode_nuscenes(cloud: &PointCloud) -> Vec<u8> {
    let mut out = Vec::with_capacity(cloud.len() * NUSCENES_RECORD);
    for i in 0..cloud.len() {
        let ring = f32::from(cloud.ring[i]);
        for v in [cloud.x[i], cloud.y[i], cloud.z[i], cloud.intensity[i], ring] {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}
