//! Decoding fixed-size binary records into the cloud's columns.
//!
//! Every binary layout murk reads is "field `f` of point `i` is `size` bytes
//! at `start + i * stride`": interleaved records (PCD `binary`, KITTI,
//! nuScenes) have `stride` = record size and `start` = field offset; PCL's
//! `binary_compressed` keeps each field contiguous, so `stride` = field size.
//!
//! [`decode`] allocates every column once at its final size and splits the
//! points into [`UNIT`]-point pieces decoded in parallel (rayon); a piece is
//! walked in [`BLOCK`]s that stay in cache, and per block runs one
//! monomorphised loop per field (`chunks_exact` + `from_le_bytes` straight
//! into the column slice: no per-point dispatch, push or allocation), then
//! the ring (from its field or [`RingLookup::fill`]). Validation is a
//! branch-free finiteness fold per block; only when a fold fails is the file
//! searched point by point (in file order) for the first bad value, so the
//! error names the same point whatever the thread count. Decoding is pure,
//! so the output never depends on the thread count either.
//!
//! ```text
//! let layout = Layout { x: Field { bytes, stride: 16, offset: 0, ty: Scalar::F32 }, … };
//! let cloud = decode(path, &layout, n, Some(&ring_lookup), scale)?;
//! ```

use std::path::Path;

use murk_types::{IntensityScale, PointCloud};
use rayon::prelude::*;

use crate::IoError;
use crate::ring::RingLookup;

/// Points per cache block: 4096 points of a 22-byte record stay in L2.
const BLOCK: usize = 4096;

/// Points per parallel piece (a multiple of [`BLOCK`]).
const UNIT: usize = 16 * BLOCK;

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

/// Writes `f(value)` of the `N`-byte value at `offset` of each record of
/// `recs` to the matching slot of `out` (as many as both have).
///
/// Common record sizes get a compile-time stride (KITTI 16, nuScenes 20,
/// murk's PCD 18 / 22, PCL's 24 / 32, contiguous 1–8): with a constant
/// stride the loop compiles to plain strided loads instead of a slice
/// split and bounds check per record.
#[inline(always)]
fn fill_with<const N: usize, T>(
    out: &mut [T],
    recs: &[u8],
    stride: usize,
    offset: usize,
    f: impl Fn([u8; N]) -> T,
) {
    // Checked once here so the per-record slice below cannot fail.
    assert!(offset + N <= stride, "field overruns its record");
    match stride {
        1 => fill_const::<1, N, T>(out, recs, offset, &f),
        2 => fill_const::<2, N, T>(out, recs, offset, &f),
        4 => fill_const::<4, N, T>(out, recs, offset, &f),
        8 => fill_const::<8, N, T>(out, recs, offset, &f),
        16 => fill_const::<16, N, T>(out, recs, offset, &f),
        18 => fill_const::<18, N, T>(out, recs, offset, &f),
        20 => fill_const::<20, N, T>(out, recs, offset, &f),
        22 => fill_const::<22, N, T>(out, recs, offset, &f),
        24 => fill_const::<24, N, T>(out, recs, offset, &f),
        32 => fill_const::<32, N, T>(out, recs, offset, &f),
        _ => {
            for (o, rec) in out.iter_mut().zip(recs.chunks_exact(stride)) {
                let mut b = [0u8; N];
                b.copy_from_slice(&rec[offset..offset + N]);
                *o = f(b);
            }
        }
    }
}

/// [`fill_with`] for a stride known at compile time.
#[inline(always)]
fn fill_const<const S: usize, const N: usize, T>(
    out: &mut [T],
    recs: &[u8],
    offset: usize,
    f: &impl Fn([u8; N]) -> T,
) {
    let (recs, _) = recs.as_chunks::<S>();
    for (o, rec) in out.iter_mut().zip(recs) {
        let mut b = [0u8; N];
        b.copy_from_slice(&rec[offset..offset + N]);
        *o = f(b);
    }
}

/// Writes the values of `field` for the records in `recs` to `out`, as `f32`.
fn fill_f32(out: &mut [f32], recs: &[u8], field: &Field) {
    let (s, o) = (field.stride, field.offset);
    match field.ty {
        Scalar::F32 => fill_with::<4, _>(out, recs, s, o, f32::from_le_bytes),
        Scalar::F64 => fill_with::<8, _>(out, recs, s, o, |b| f64::from_le_bytes(b) as f32),
        Scalar::U8 => fill_with::<1, _>(out, recs, s, o, |b| f32::from(b[0])),
        Scalar::I8 => fill_with::<1, _>(out, recs, s, o, |b| f32::from(b[0] as i8)),
        Scalar::U16 => fill_with::<2, _>(out, recs, s, o, |b| f32::from(u16::from_le_bytes(b))),
        Scalar::I16 => fill_with::<2, _>(out, recs, s, o, |b| f32::from(i16::from_le_bytes(b))),
        Scalar::U32 => fill_with::<4, _>(out, recs, s, o, |b| u32::from_le_bytes(b) as f32),
        Scalar::I32 => fill_with::<4, _>(out, recs, s, o, |b| i32::from_le_bytes(b) as f32),
        Scalar::U64 => fill_with::<8, _>(out, recs, s, o, |b| u64::from_le_bytes(b) as f32),
        Scalar::I64 => fill_with::<8, _>(out, recs, s, o, |b| i64::from_le_bytes(b) as f32),
    }
}

/// Writes the values of `field` for the records in `recs` to `out`, as `f64`.
fn fill_f64(out: &mut [f64], recs: &[u8], field: &Field) {
    let (s, o) = (field.stride, field.offset);
    match field.ty {
        Scalar::F32 => fill_with::<4, _>(out, recs, s, o, |b| f64::from(f32::from_le_bytes(b))),
        Scalar::F64 => fill_with::<8, _>(out, recs, s, o, f64::from_le_bytes),
        Scalar::U8 => fill_with::<1, _>(out, recs, s, o, |b| f64::from(b[0])),
        Scalar::I8 => fill_with::<1, _>(out, recs, s, o, |b| f64::from(b[0] as i8)),
        Scalar::U16 => fill_with::<2, _>(out, recs, s, o, |b| f64::from(u16::from_le_bytes(b))),
        Scalar::I16 => fill_with::<2, _>(out, recs, s, o, |b| f64::from(i16::from_le_bytes(b))),
        Scalar::U32 => fill_with::<4, _>(out, recs, s, o, |b| f64::from(u32::from_le_bytes(b))),
        Scalar::I32 => fill_with::<4, _>(out, recs, s, o, |b| f64::from(i32::from_le_bytes(b))),
        Scalar::U64 => fill_with::<8, _>(out, recs, s, o, |b| u64::from_le_bytes(b) as f64),
        Scalar::I64 => fill_with::<8, _>(out, recs, s, o, |b| i64::from_le_bytes(b) as f64),
    }
}

/// True when every value is finite (a branch-free, vectorisable fold).
#[inline]
fn all_finite<T: Copy>(v: &[T], finite: impl Fn(T) -> bool) -> bool {
    v.iter().fold(true, |ok, &x| ok & finite(x))
}

/// Index of the first non-finite value, if any (a vectorisable fold first,
/// the search only when it fails).
#[inline]
pub(crate) fn first_non_finite(v: &[f32]) -> Option<usize> {
    if all_finite(v, f32::is_finite) {
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
    let t0 = time_origin(v);
    let out: Vec<f32> = v.iter().map(|&t| (t - t0) as f32).collect();
    match first_non_finite(&out) {
        None => Ok(out),
        Some(i) => Err(non_finite(path, i, "time", v[i])),
    }
}

/// What [`time_to_f32`] subtracts from a time column: its first value when
/// that is an absolute clock (10⁵ s or more), else 0.
pub(crate) fn time_origin(v: &[f64]) -> f64 {
    match v.first() {
        Some(&t0) if t0.abs() >= 1e5 => t0,
        _ => 0.0,
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

/// The time column being decoded: `f32` as stored, anything else through
/// `f64` (made relative by [`time_to_f32`] afterwards).
enum TimeCol {
    None,
    F32(Vec<f32>),
    F64(Vec<f64>),
}

/// The column slices of one parallel piece.
struct Piece<'a> {
    /// Index of the piece's first point.
    start: usize,
    x: &'a mut [f32],
    y: &'a mut [f32],
    z: &'a mut [f32],
    intensity: &'a mut [f32],
    ring: &'a mut [u16],
    time32: Option<&'a mut [f32]>,
    time64: Option<&'a mut [f64]>,
}

/// Decodes one piece; false when some value is invalid (the caller then
/// finds and reports the first one).
fn decode_piece(layout: &Layout, rings: Option<&RingLookup>, mut p: Piece) -> bool {
    let mut ok = true;
    let mut ring64 = Vec::new();
    let n = p.x.len();
    for lo in (0..n).step_by(BLOCK) {
        let hi = (lo + BLOCK).min(n);
        let (a, b) = (p.start + lo, p.start + hi);
        let cols: [(&mut [f32], &Field); 4] = [
            (&mut p.x[lo..hi], &layout.x),
            (&mut p.y[lo..hi], &layout.y),
            (&mut p.z[lo..hi], &layout.z),
            (&mut p.intensity[lo..hi], &layout.intensity),
        ];
        for (col, field) in cols {
            fill_f32(col, field.block(a, b), field);
            ok &= all_finite(col, f32::is_finite);
        }
        let ring = &mut p.ring[lo..hi];
        match (&layout.ring, rings) {
            (Some(f), _) => {
                let recs = f.block(a, b);
                match f.ty {
                    Scalar::U16 => {
                        fill_with::<2, _>(ring, recs, f.stride, f.offset, u16::from_le_bytes)
                    }
                    Scalar::U8 => {
                        fill_with::<1, _>(ring, recs, f.stride, f.offset, |b| u16::from(b[0]))
                    }
                    _ => {
                        ring64.resize(hi - lo, 0.0);
                        fill_f64(&mut ring64, recs, f);
                        for (o, &v) in ring.iter_mut().zip(&ring64) {
                            ok &= v >= 0.0 && v <= f64::from(u16::MAX) && v.fract() == 0.0;
                            *o = v as u16;
                        }
                    }
                }
            }
            (None, Some(lookup)) => {
                lookup.fill(ring, &p.x[lo..hi], &p.y[lo..hi], &p.z[lo..hi]);
            }
            (None, None) => unreachable!("decode needs a ring field or a ring lookup"),
        }
        if let Some(f) = &layout.time {
            match (p.time32.as_deref_mut(), p.time64.as_deref_mut()) {
                (Some(t), _) => {
                    let t = &mut t[lo..hi];
                    fill_f32(t, f.block(a, b), f);
                    ok &= all_finite(t, f32::is_finite);
                }
                (None, Some(t)) => {
                    let t = &mut t[lo..hi];
                    fill_f64(t, f.block(a, b), f);
                    ok &= all_finite(t, f64::is_finite);
                }
                (None, None) => {}
            }
        }
    }
    ok
}

/// One value of `field` for point `i`, as `f64`.
fn value_f64(field: &Field, i: usize) -> f64 {
    let mut v = [0.0];
    fill_f64(&mut v, field.block(i, i + 1), field);
    v[0]
}

/// One value of `field` for point `i`, as the `f32` the column holds.
fn value_f32(field: &Field, i: usize) -> f32 {
    let mut v = [0.0];
    fill_f32(&mut v, field.block(i, i + 1), field);
    v[0]
}

/// The error of the first invalid value in file order (point by point, then
/// `x y z intensity ring time`), or `None` if every value is valid.
fn first_error(path: &Path, layout: &Layout, n: usize) -> Option<IoError> {
    let coords = [
        (&layout.x, "x"),
        (&layout.y, "y"),
        (&layout.z, "z"),
        (&layout.intensity, "intensity"),
    ];
    for i in 0..n {
        for (f, name) in coords {
            let v = value_f32(f, i);
            if !v.is_finite() {
                return Some(non_finite(path, i, name, f64::from(v)));
            }
        }
        if let Some(f) = &layout.ring
            && !matches!(f.ty, Scalar::U8 | Scalar::U16)
            && let Err(reason) = ring_id(value_f64(f, i))
        {
            return Some(IoError::BadValue {
                path: path.to_path_buf(),
                point: i,
                field: "ring",
                reason,
            });
        }
        if let Some(f) = &layout.time {
            let v = if f.ty == Scalar::F32 {
                f64::from(value_f32(f, i))
            } else {
                value_f64(f, i)
            };
            if !v.is_finite() {
                return Some(non_finite(path, i, "time", v));
            }
        }
    }
    None
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
    // Zeroed allocations of this size come straight from the OS as zero
    // pages: no fill pass, each page is touched first by the decoder.
    let mut x = vec![0f32; n];
    let mut y = vec![0f32; n];
    let mut z = vec![0f32; n];
    let mut intensity = vec![0f32; n];
    let mut ring = vec![0u16; n];
    let mut time = match &layout.time {
        None => TimeCol::None,
        Some(f) if f.ty == Scalar::F32 => TimeCol::F32(vec![0f32; n]),
        Some(_) => TimeCol::F64(vec![0f64; n]),
    };
    let (mut t32, mut t64) = match &mut time {
        TimeCol::None => (None, None),
        TimeCol::F32(v) => (Some(v.chunks_mut(UNIT)), None),
        TimeCol::F64(v) => (None, Some(v.chunks_mut(UNIT))),
    };
    let pieces: Vec<Piece> = x
        .chunks_mut(UNIT)
        .zip(y.chunks_mut(UNIT))
        .zip(z.chunks_mut(UNIT))
        .zip(intensity.chunks_mut(UNIT))
        .zip(ring.chunks_mut(UNIT))
        .enumerate()
        .map(|(k, ((((x, y), z), intensity), ring))| Piece {
            start: k * UNIT,
            x,
            y,
            z,
            intensity,
            ring,
            time32: t32.as_mut().and_then(Iterator::next),
            time64: t64.as_mut().and_then(Iterator::next),
        })
        .collect();
    let ok = if pieces.len() > 1 {
        pieces
            .into_par_iter()
            .map(|p| decode_piece(layout, rings, p))
            .reduce(|| true, |a, b| a & b)
    } else {
        pieces.into_iter().all(|p| decode_piece(layout, rings, p))
    };
    if !ok && let Some(e) = first_error(path, layout, n) {
        return Err(e);
    }
    let mut cloud = PointCloud {
        x,
        y,
        z,
        intensity,
        ring,
        time: None,
        intensity_scale: scale,
    };
    cloud.time = match time {
        TimeCol::None => None,
        TimeCol::F32(t) => Some(t),
        TimeCol::F64(t) => Some(time_to_f32(path, &t)?),
    };
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
            let mut out = [0f32];
            fill_f32(&mut out, &rec, &field);
            assert_eq!(out, [want], "{ty:?}");
            let mut out = [0f64];
            fill_f64(&mut out, &rec, &field);
            assert_eq!(out, [f64::from(want)], "{ty:?}");
        }
    }
}
