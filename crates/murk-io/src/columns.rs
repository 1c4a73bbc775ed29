//! Decoding fixed-size binary records into the cloud's columns.
//!
//! Every binary layout murk reads is "field `f` of point `i` is `size` bytes
//! at `start + i * stride`": interleaved records (PCD `binary`, KITTI,
//! nuScenes) have `stride` = record size and `start` = field offset; PCL's
//! `binary_compressed` keeps each field contiguous, so `stride` = field size.
//! [`decode`] walks the points in blocks that stay in cache and, per block,
//! runs one monomorphised loop per field (`chunks_exact` + `from_le_bytes`,
//! no per-point dispatch or allocation), then checks finiteness of the block
//! just written while it is still hot.

use std::path::Path;

use murk_types::{IntensityScale, PointCloud};

use crate::IoError;
use crate::ring::RingLookup;

/// Points per block: 4096 points of a 22-byte record stay in L2.
const BLOCK: usize = 4096;

/// A little-endian numeric type of a binary field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Scalar {
    U8,
    U16,
    U32,
    U64,
    I8,
    I16,
    I32,
    I64,
    F32,
    F64,
}

impl Scalar {
    /// The type of a PCD `TYPE`/`SIZE` pair.
    pub(crate) fn from_pcd(ty: &str, size: &str) -> Option<Scalar> {
        Some(match (ty, size) {
            ("U", "1") => Scalar::U8,
            ("U", "2") => Scalar::U16,
            ("U", "4") => Scalar::U32,
            ("U", "8") => Scalar::U64,
            ("I", "1") => Scalar::I8,
            ("I", "2") => Scalar::I16,
            ("I", "4") => Scalar::I32,
            ("I", "8") => Scalar::I64,
            ("F", "4") => Scalar::F32,
            ("F", "8") => Scalar::F64,
            _ => return None,
        })
    }

    /// Size in bytes.
    #[cfg(test)]
    pub(crate) fn size(self) -> usize {
        match self {
            Scalar::U8 | Scalar::I8 => 1,
            Scalar::U16 | Scalar::I16 => 2,
            Scalar::U32 | Scalar::I32 | Scalar::F32 => 4,
            Scalar::U64 | Scalar::I64 | Scalar::F64 => 8,
        }
    }
}

/// Where the values of one field live in a byte buffer.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Field<'a> {
    /// The bytes from the first value's record on: `n * stride` bytes.
    pub(crate) bytes: &'a [u8],
    /// Distance between two consecutive values, bytes.
    pub(crate) stride: usize,
    /// Offset of the value inside its `stride`-byte record.
    pub(crate) offset: usize,
    /// Its type.
    pub(crate) ty: Scalar,
}

impl<'a> Field<'a> {
    /// The records of points `lo..hi`.
    #[inline]
    fn block(&self, lo: usize, hi: usize) -> &'a [u8] {
        &self.bytes[lo * self.stride..hi * self.stride]
    }
}

/// The fields of a binary layout.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Layout<'a> {
    pub(crate) x: Field<'a>,
    pub(crate) y: Field<'a>,
    pub(crate) z: Field<'a>,
    pub(crate) intensity: Field<'a>,
    pub(crate) ring: Option<Field<'a>>,
    pub(crate) time: Option<Field<'a>>,
}

/// Appends `f(value)` for each `N`-byte value at `offset` of each record.
#[inline(always)]
fn extend_with<const N: usize, T>(
    out: &mut Vec<T>,
    recs: &[u8],
    stride: usize,
    offset: usize,
    f: impl Fn([u8; N]) -> T,
) {
    // Checked once here so the per-record slice below cannot fail.
    assert!(offset + N <= stride, "field overruns its record");
    out.extend(recs.chunks_exact(stride).map(|rec| {
        let mut b = [0u8; N];
        b.copy_from_slice(&rec[offset..offset + N]);
        f(b)
    }));
}

/// Appends the values of `field` for the records in `recs`, as `f32`.
fn extend_f32(out: &mut Vec<f32>, recs: &[u8], field: &Field) {
    let (s, o) = (field.stride, field.offset);
    match field.ty {
        Scalar::F32 => extend_with::<4, _>(out, recs, s, o, f32::from_le_bytes),
        Scalar::F64 => extend_with::<8, _>(out, recs, s, o, |b| f64::from_le_bytes(b) as f32),
        Scalar::U8 => extend_with::<1, _>(out, recs, s, o, |b| f32::from(b[0])),
        Scalar::I8 => extend_with::<1, _>(out, recs, s, o, |b| f32::from(b[0] as i8)),
        Scalar::U16 => extend_with::<2, _>(out, recs, s, o, |b| f32::from(u16::from_le_bytes(b))),
        Scalar::I16 => extend_with::<2, _>(out, recs, s, o, |b| f32::from(i16::from_le_bytes(b))),
        Scalar::U32 => extend_with::<4, _>(out, recs, s, o, |b| u32::from_le_bytes(b) as f32),
        Scalar::I32 => extend_with::<4, _>(out, recs, s, o, |b| i32::from_le_bytes(b) as f32),
        Scalar::U64 => extend_with::<8, _>(out, recs, s, o, |b| u64::from_le_bytes(b) as f32),
        Scalar::I64 => extend_with::<8, _>(out, recs, s, o, |b| i64::from_le_bytes(b) as f32),
    }
}

/// Appends the values of `field` for the records in `recs`, as `f64`.
fn extend_f64(out: &mut Vec<f64>, recs: &[u8], field: &Field) {
    let (s, o) = (field.stride, field.offset);
    match field.ty {
        Scalar::F32 => extend_with::<4, _>(out, recs, s, o, |b| f64::from(f32::from_le_bytes(b))),
        Scalar::F64 => extend_with::<8, _>(out, recs, s, o, f64::from_le_bytes),
        Scalar::U8 => extend_with::<1, _>(out, recs, s, o, |b| f64::from(b[0])),
        Scalar::I8 => extend_with::<1, _>(out, recs, s, o, |b| f64::from(b[0] as i8)),
        Scalar::U16 => extend_with::<2, _>(out, recs, s, o, |b| f64::from(u16::from_le_bytes(b))),
        Scalar::I16 => extend_with::<2, _>(out, recs, s, o, |b| f64::from(i16::from_le_bytes(b))),
        Scalar::U32 => extend_with::<4, _>(out, recs, s, o, |b| f64::from(u32::from_le_bytes(b))),
        Scalar::I32 => extend_with::<4, _>(out, recs, s, o, |b| f64::from(i32::from_le_bytes(b))),
        Scalar::U64 => extend_with::<8, _>(out, recs, s, o, |b| u64::from_le_bytes(b) as f64),
        Scalar::I64 => extend_with::<8, _>(out, recs, s, o, |b| i64::from_le_bytes(b) as f64),
    }
}

/// Index of the first non-finite value, if any (a vectorisable fold first,
/// the search only when it fails).
#[inline]
pub(crate) fn first_non_finite(v: &[f32]) -> Option<usize> {
    if v.iter().fold(true, |ok, x| ok & x.is_finite()) {
        None
    } else {
        v.iter().position(|x| !x.is_finite())
    }
}

/// The ring id a numeric value stands for, or why it stands for none.
pub(crate) fn ring_id(v: f64) -> Result<u16, String> {
    if !v.is_finite() {
        return Err(format!("{v} is not finite"));
    }
    if v.fract() != 0.0 || !(0.0..=f64::from(u16::MAX)).contains(&v) {
        return Err(format!("{v} is not a ring id (an integer in 0..=65535)"));
    }
    Ok(v as u16)
}

/// Converts a time column to the cloud's `f32` seconds.
///
/// A column whose first value is 10⁵ s or more is an absolute clock (epoch
/// seconds): `f32` would round it to whole minutes, so it is made relative to
/// the first point, which is what [`PointCloud::time`] holds. Smaller values
/// are already relative to the scan and are kept. A value that does not fit
/// in an `f32` is an error for `path` at that point.
pub(crate) fn time_to_f32(path: &Path, v: &[f64]) -> Result<Vec<f32>, IoError> {
    let t0 = match v.first() {
        Some(&t0) if t0.abs() >= 1e5 => t0,
        _ => 0.0,
    };
    let out: Vec<f32> = v.iter().map(|&t| (t - t0) as f32).collect();
    match first_non_finite(&out) {
        None => Ok(out),
        Some(i) => Err(non_finite(path, i, "time", v[i])),
    }
}

/// The error for a non-finite value.
pub(crate) fn non_finite(path: &Path, point: usize, field: &'static str, value: f64) -> IoError {
    IoError::NonFinite {
        path: path.to_path_buf(),
        point,
        field,
        value,
    }
}

/// Checks that the last `new` values of `col` are finite.
#[inline]
fn check_block(path: &Path, col: &[f32], lo: usize, field: &'static str) -> Result<(), IoError> {
    match first_non_finite(&col[lo..]) {
        None => Ok(()),
        Some(k) => Err(non_finite(path, lo + k, field, f64::from(col[lo + k]))),
    }
}

/// Decodes `n` points of `layout` into a cloud.
///
/// `rings` gives the ring of each point when the layout has no ring field.
/// Every field must hold `n * stride` bytes (callers check the sizes against
/// the file and report mismatches before calling).
pub(crate) fn decode(
    path: &Path,
    layout: &Layout,
    n: usize,
    rings: Option<&RingLookup>,
    scale: IntensityScale,
) -> Result<PointCloud, IoError> {
    let mut cloud = PointCloud::with_capacity(n);
    cloud.intensity_scale = scale;
    let mut time64: Vec<f64> = Vec::new();
    let mut time32: Vec<f32> = Vec::new();
    let mut ring64: Vec<f64> = Vec::new();
    if let Some(t) = &layout.time {
        if t.ty == Scalar::F32 {
            time32.reserve_exact(n);
        } else {
            time64.reserve_exact(n);
        }
    }
    let mut lo = 0;
    while lo < n {
        let hi = (lo + BLOCK).min(n);
        let cols: [(&mut Vec<f32>, &Field, &'static str); 4] = [
            (&mut cloud.x, &layout.x, "x"),
            (&mut cloud.y, &layout.y, "y"),
            (&mut cloud.z, &layout.z, "z"),
            (&mut cloud.intensity, &layout.intensity, "intensity"),
        ];
        for (col, field, name) in cols {
            extend_f32(col, field.block(lo, hi), field);
            check_block(path, col, lo, name)?;
        }
        match (&layout.ring, rings) {
            (Some(f), _) => {
                let recs = f.block(lo, hi);
                match f.ty {
                    Scalar::U16 => extend_with::<2, _>(
                        &mut cloud.ring,
                        recs,
                        f.stride,
                        f.offset,
                        u16::from_le_bytes,
                    ),
                    Scalar::U8 => {
                        extend_with::<1, _>(&mut cloud.ring, recs, f.stride, f.offset, |b| {
                            u16::from(b[0])
                        })
                    }
                    _ => {
                        ring64.clear();
                        extend_f64(&mut ring64, recs, f);
                        for (k, &v) in ring64.iter().enumerate() {
                            let id = ring_id(v).map_err(|reason| IoError::BadValue {
                                path: path.to_path_buf(),
                                point: lo + k,
                                field: "ring",
                                reason,
                            })?;
                            cloud.ring.push(id);
                        }
                    }
                }
            }
            (None, Some(lookup)) => lookup.extend(
                &mut cloud.ring,
                &cloud.x[lo..hi],
                &cloud.y[lo..hi],
                &cloud.z[lo..hi],
            ),
            (None, None) => unreachable!("decode needs a ring field or a ring lookup"),
        }
        if let Some(f) = &layout.time {
            if f.ty == Scalar::F32 {
                extend_f32(&mut time32, f.block(lo, hi), f);
                check_block(path, &time32, lo, "time")?;
            } else {
                let start = time64.len();
                extend_f64(&mut time64, f.block(lo, hi), f);
                if let Some(k) = time64[start..].iter().position(|t| !t.is_finite()) {
                    return Err(non_finite(path, start + k, "time", time64[start + k]));
                }
            }
        }
        lo = hi;
    }
    if let Some(f) = &layout.time {
        cloud.time = Some(if f.ty == Scalar::F32 {
            time32
        } else {
            time_to_f32(path, &time64)?
        });
    }
    Ok(cloud)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ring_ids_must_be_small_non_negative_integers() {
        assert_eq!(ring_id(15.0), Ok(15));
        assert!(ring_id(-1.0).is_err());
        assert!(ring_id(2.5).is_err());
        assert!(ring_id(70_000.0).is_err());
        assert!(ring_id(f64::NAN).is_err());
    }

    #[test]
    fn absolute_times_are_made_relative_and_small_ones_kept() {
        let abs = [1_700_000_000.25, 1_700_000_000.5];
        let p = Path::new("t");
        assert_eq!(time_to_f32(p, &abs).unwrap(), vec![0.0, 0.25]);
        assert_eq!(time_to_f32(p, &[0.5, 0.75]).unwrap(), vec![0.5, 0.75]);
        // Relative to a first value of 1e5 s, 1e300 s does not fit an f32.
        let e = time_to_f32(p, &[1e5, 1e300]).unwrap_err();
        assert!(matches!(e, IoError::NonFinite { point: 1, .. }), "{e}");
    }

    #[test]
    fn every_scalar_type_decodes_little_endian() {
        // One record per type, each holding 7 (or -7 where signed) at stride 8.
        let cases: [(Scalar, Vec<u8>, f32); 10] = [
            (Scalar::U8, vec![7], 7.0),
            (Scalar::I8, vec![(-7i8) as u8], -7.0),
            (Scalar::U16, 7u16.to_le_bytes().to_vec(), 7.0),
            (Scalar::I16, (-7i16).to_le_bytes().to_vec(), -7.0),
            (Scalar::U32, 7u32.to_le_bytes().to_vec(), 7.0),
            (Scalar::I32, (-7i32).to_le_bytes().to_vec(), -7.0),
            (Scalar::U64, 7u64.to_le_bytes().to_vec(), 7.0),
            (Scalar::I64, (-7i64).to_le_bytes().to_vec(), -7.0),
            (Scalar::F32, 7.5f32.to_le_bytes().to_vec(), 7.5),
            (Scalar::F64, (-7.5f64).to_le_bytes().to_vec(), -7.5),
        ];
        for (ty, bytes, want) in cases {
            assert_eq!(ty.size(), bytes.len());
            let mut rec = bytes.clone();
            rec.resize(8, 0xAA);
            let field = Field {
                bytes: &rec,
                stride: 8,
                offset: 0,
                ty,
            };
            let mut out = Vec::new();
            extend_f32(&mut out, &rec, &field);
            assert_eq!(out, vec![want], "{ty:?}");
            let mut out = Vec::new();
            extend_f64(&mut out, &rec, &field);
            assert_eq!(out, vec![f64::from(want)], "{ty:?}");
        }
    }
}
