//! KITTI `.bin` and nuScenes `.pcd.bin`: headerless little-endian `f32`
//! records (`x y z intensity`, and `ring_index` for nuScenes).

use std::path::Path;

use murk_types::{PointCloud, PointFormat};

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

/// Parses a KITTI `.bin` file held in memory (`x y z intensity` as
/// little-endian `f32`; the ring comes from each point's elevation, with
/// `opts.lidar` or the VLP-16).
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
    let n = whole_records(bytes, KITTI_RECORD, source)?;
    let lookup = ring_lookup(source, opts)?;
    let layout = Layout {
        x: f32_field(bytes, KITTI_RECORD, 0),
        y: f32_field(bytes, KITTI_RECORD, 1),
        z: f32_field(bytes, KITTI_RECORD, 2),
        intensity: f32_field(bytes, KITTI_RECORD, 3),
        ring: None,
        time: None,
    };
    columns::decode(
        source,
        &layout,
        n,
        Some(&lookup),
        opts.scale_for(PointFormat::KittiBin),
    )
}

/// Parses a nuScenes `.pcd.bin` file held in memory (`x y z intensity
/// ring_index` as little-endian `f32`; `ring_index` must be a whole number).
pub fn parse_nuscenes(
    bytes: &[u8],
    source: &Path,
    opts: &ReadOptions,
) -> Result<PointCloud, IoError> {
    let n = whole_records(bytes, NUSCENES_RECORD, source)?;
    let layout = Layout {
        x: f32_field(bytes, NUSCENES_RECORD, 0),
        y: f32_field(bytes, NUSCENES_RECORD, 1),
        z: f32_field(bytes, NUSCENES_RECORD, 2),
        intensity: f32_field(bytes, NUSCENES_RECORD, 3),
        ring: Some(f32_field(bytes, NUSCENES_RECORD, 4)),
        time: None,
    };
    columns::decode(
        source,
        &layout,
        n,
        None,
        opts.scale_for(PointFormat::NuscenesBin),
    )
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
