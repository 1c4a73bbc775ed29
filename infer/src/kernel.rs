//! The per-point hot loops: the vanishing mask (hard or soft edge), the
//! compaction of the surviving points, range noise and intensity attenuation.
//!
//! **Why the loops look like this.** Vanishing is one compare per point, so
//! the loops are written for memory speed: columns (SoA) are read in fixed
//! [`CHUNK`]s spread over rayon; the band of a point is selected without a
//! branch (a running `select` over the band edges, unrolled by a const
//! generic band count); the range is compared squared (no `sqrt`); per-band
//! counts are integer reductions in the same pass. Compaction writes each
//! kept point unconditionally at the write cursor and advances the cursor by
//! the mask bit, which avoids a mispredicted branch per point; it stops at
//! the chunk's last kept point so the cursor never passes the chunk's output.
//!
//! **Bands are decided in the input's own intensity scale.** The band edges
//! (calibrated VLP-16 reflectivity) are mapped once into the raw scale of
//! the cloud (`raw = (edge − offset) / gain`, compared with the sign of the
//! gain), instead of converting every intensity to calibrated and back. The
//! decision is the same; the kept intensities are never touched, so an
//! unchanged point is written back bit for bit.

use murk_types::{IntensityScale, PointCloud};
use rand::RngExt;
use rayon::prelude::*;

use crate::model::{BandRule, SoftEdge};
use crate::sampling::{CHUNK, Purpose, ScanSeed};

/// Most reflectivity bands a table may have.
pub(crate) const MAX_BANDS: usize = 16;

/// Per-chunk (then per-scan) counts of the vanishing pass.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Counts {
    /// Points seen.
    pub n: u64,
    /// Points kept.
    pub kept: u64,
    /// Points whose key is ≥ the lower edge of band k (k = 0: the lowest
    /// band's lower edge, so `n − ge[0]` lie below every band).
    pub ge: [u64; MAX_BANDS],
    /// The same, kept points only.
    pub ge_kept: [u64; MAX_BANDS],
    /// Points at or above the upper edge of the highest band.
    pub above: u64,
}

impl Default for Counts {
    fn default() -> Self {
        Counts {
            n: 0,
            kept: 0,
            ge: [0; MAX_BANDS],
            ge_kept: [0; MAX_BANDS],
            above: 0,
        }
    }
}

impl Counts {
    fn add(mut self, o: &Counts) -> Counts {
        self.n += o.n;
        self.kept += o.kept;
        for k in 0..MAX_BANDS {
            self.ge[k] += o.ge[k];
            self.ge_kept[k] += o.ge_kept[k];
        }
        self.above += o.above;
        self
    }

    /// Points per band (points below the lowest band are not in it: see
    /// [`Counts::below`]; points above the highest are in it), and kept
    /// points per band.
    pub(crate) fn per_band(&self, bands: usize) -> Vec<(u64, u64)> {
        (0..bands)
            .map(|k| {
                let (lo, lo_kept) = (self.ge[k], self.ge_kept[k]);
                let (hi, hi_kept) = if k + 1 < bands {
                    (self.ge[k + 1], self.ge_kept[k + 1])
                } else {
                    (0, 0)
                };
                (lo - hi, lo_kept - hi_kept)
            })
            .collect()
    }

    /// Points below the lowest band's lower edge.
    pub(crate) fn below(&self) -> u64 {
        self.n - self.ge[0]
    }

    /// Of the points below the lowest band, those that vanished.
    pub(crate) fn below_vanished(&self) -> u64 {
        self.below() - (self.kept - self.ge_kept[0])
    }
}

/// The band edges of a cloud's intensity scale, in "key" space: `key =
/// sign · raw`, increasing with calibrated reflectivity.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Edges {
    /// Number of bands.
    pub bands: usize,
    /// `sign` of the scale's gain.
    pub sign: f32,
    /// `lower[0]`: lowest band's lower edge; `lower[k]`: band k's lower edge
    /// (= band k−1's upper edge); padding `+∞`.
    pub lower: [f32; MAX_BANDS],
    /// Highest band's upper edge (`+∞` when unbounded).
    pub upper: f32,
}

impl Edges {
    pub(crate) fn new(bands: &[BandRule], scale: IntensityScale) -> Edges {
        let (gain, _) = match scale {
            IntensityScale::Calibrated => (1.0f32, 0.0f32),
            IntensityScale::Linear { gain, offset } => (gain, offset),
        };
        let sign = if gain < 0.0 { -1.0 } else { 1.0 };
        let key = |calibrated: f64| sign * scale.from_calibrated(calibrated as f32);
        let mut lower = [f32::INFINITY; MAX_BANDS];
        for (k, b) in bands.iter().enumerate() {
            lower[k] = key(b.reflectivity_min);
        }
        let upper = bands
            .last()
            .and_then(|b| b.reflectivity_max)
            .map_or(f32::INFINITY, key);
        Edges {
            bands: bands.len(),
            sign,
            lower,
            upper,
        }
    }

    /// The band index of a raw intensity (clamped into the first / last band).
    #[inline]
    pub(crate) fn band_of(&self, raw: f32) -> usize {
        let key = self.sign * raw;
        let mut b = 0;
        for k in 1..self.bands {
            if key >= self.lower[k] {
                b = k;
            }
        }
        b
    }
}

/// The hard-threshold kernel: squared vanishing distances per band.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Hard {
    pub edges: Edges,
    /// `(slope_k · MOR · range_scale)²`, padding repeats the last band.
    pub thr2: [f32; MAX_BANDS],
}

impl Hard {
    pub(crate) fn new(bands: &[BandRule], scale: IntensityScale) -> Hard {
        let edges = Edges::new(bands, scale);
        let mut thr2 = [0f32; MAX_BANDS];
        for k in 0..MAX_BANDS {
            let d = bands[k.min(bands.len() - 1)].vanishing_distance_m;
            thr2[k] = (d * d) as f32;
        }
        Hard { edges, thr2 }
    }
}

/// One chunk of the hard kernel with `N` (padded) bands.
#[inline(always)]
fn hard_chunk<const N: usize>(
    h: &Hard,
    x: &[f32],
    y: &[f32],
    z: &[f32],
    intensity: &[f32],
    mask: &mut [u8],
) -> Counts {
    let sign = h.edges.sign;
    let upper = h.edges.upper;
    let lower: [f32; N] = std::array::from_fn(|k| h.edges.lower[k]);
    let thr2: [f32; N] = std::array::from_fn(|k| h.thr2[k]);
    let mut kept = 0u32;
    let mut ge = [0u32; N];
    let mut ge_kept = [0u32; N];
    let mut above = 0u32;
    let n = mask.len();
    let (x, y, z, intensity) = (&x[..n], &y[..n], &z[..n], &intensity[..n]);
    for i in 0..n {
        let key = sign * intensity[i];
        let d2 = x[i] * x[i] + y[i] * y[i] + z[i] * z[i];
        let mut t = thr2[0];
        for k in 1..N {
            t = if key >= lower[k] { thr2[k] } else { t };
        }
        let keep = d2 <= t;
        mask[i] = keep as u8;
        kept += keep as u32;
        for k in 0..N {
            let g = key >= lower[k];
            ge[k] += g as u32;
            ge_kept[k] += (g & keep) as u32;
        }
        above += (key >= upper) as u32;
    }
    let mut c = Counts {
        n: n as u64,
        kept: kept as u64,
        above: above as u64,
        ..Counts::default()
    };
    for k in 0..N {
        c.ge[k] = ge[k] as u64;
        c.ge_kept[k] = ge_kept[k] as u64;
    }
    c
}

/// Hard-threshold mask of a whole cloud; returns the counts of every chunk.
pub(crate) fn hard_mask(h: &Hard, cloud: &PointCloud, mask: &mut Vec<u8>) -> Vec<Counts> {
    mask.clear();
    mask.resize(cloud.len(), 0);
    let run = |c: usize, m: &mut [u8]| {
        let s = c * CHUNK;
        let e = s + m.len();
        let (x, y, z, it) = (
            &cloud.x[s..e],
            &cloud.y[s..e],
            &cloud.z[s..e],
            &cloud.intensity[s..e],
        );
        match h.edges.bands {
            1 => hard_chunk::<1>(h, x, y, z, it, m),
            2 => hard_chunk::<2>(h, x, y, z, it, m),
            3 => hard_chunk::<3>(h, x, y, z, it, m),
            4 => hard_chunk::<4>(h, x, y, z, it, m),
            5..=8 => hard_chunk::<8>(h, x, y, z, it, m),
            _ => hard_chunk::<MAX_BANDS>(h, x, y, z, it, m),
        }
    };
    mask.par_chunks_mut(CHUNK)
        .enumerate()
        .map(|(c, m)| run(c, m))
        .collect()
}

/// A mask decided point by point: `keep(state, band, range, raw)` for each
/// point, `state` made per chunk by `chunk_state(chunk)` (the soft edge's
/// random stream), chunks in parallel, counts per chunk.
fn point_mask<S, F, K>(
    bands: &[BandRule],
    cloud: &PointCloud,
    mask: &mut Vec<u8>,
    chunk_state: F,
    keep: K,
) -> Vec<Counts>
where
    F: Fn(usize) -> S + Sync,
    K: Fn(&mut S, usize, f64, f32) -> bool + Sync,
{
    let edges = Edges::new(bands, cloud.intensity_scale);
    mask.clear();
    mask.resize(cloud.len(), 0);
    mask.par_chunks_mut(CHUNK)
        .enumerate()
        .map(|(c, m)| {
            let mut state = chunk_state(c);
            let s = c * CHUNK;
            let mut counts = Counts {
                n: m.len() as u64,
                ..Counts::default()
            };
            for (j, slot) in m.iter_mut().enumerate() {
                let i = s + j;
                let raw = cloud.intensity[i];
                let b = edges.band_of(raw);
                let r = (cloud.x[i] as f64)
                    .hypot(cloud.y[i] as f64)
                    .hypot(cloud.z[i] as f64);
                let k = keep(&mut state, b, r, raw);
                *slot = k as u8;
                counts.add_point(&edges, raw, k);
            }
            counts
        })
        .collect()
}

/// Hard-threshold mask when a band's law has a reflectivity term: each
/// point's distance is its band's times the term's factor at its own
/// calibrated reflectivity ([`BandRule::distance_at`]), so the per-band
/// squared thresholds of [`hard_mask`] do not apply. Same counts, same
/// chunks.
pub(crate) fn hard_mask_by_reflectivity(
    bands: &[BandRule],
    cloud: &PointCloud,
    mask: &mut Vec<u8>,
) -> Vec<Counts> {
    let scale = cloud.intensity_scale;
    point_mask(
        bands,
        cloud,
        mask,
        |_| (),
        |_, b, r, raw| r <= bands[b].distance_at(scale.to_calibrated(raw) as f64),
    )
}

/// Soft-edge mask: each point survives with the fitted probability, drawn
/// from the chunk's own stream.
pub(crate) fn soft_mask(
    bands: &[BandRule],
    soft: &SoftEdge,
    mor_scaled: f64,
    cloud: &PointCloud,
    seed: ScanSeed,
    mask: &mut Vec<u8>,
) -> Vec<Counts> {
    let scale = cloud.intensity_scale;
    let centre: Vec<f64> = bands.iter().map(|b| b.slope * mor_scaled).collect();
    let width: Vec<f64> = bands
        .iter()
        .map(|b| b.edge_width.unwrap_or(f64::NAN) * b.slope * mor_scaled)
        .collect();
    point_mask(
        bands,
        cloud,
        mask,
        |c| seed.rng(Purpose::SoftEdge, c as u64),
        |rng, b, r, raw| {
            // The edge's centre and width both scale with a reflectivity
            // term's factor (the width is relative).
            let f = bands[b]
                .reflectivity
                .map_or(1.0, |t| t.factor(scale.to_calibrated(raw) as f64));
            let zc = (r - centre[b] * f) / (width[b] * f);
            let p = soft.keep_probability_given_clear(zc);
            let u: f64 = rng.random();
            u < p
        },
    )
}

impl Counts {
    /// Counts one point of raw intensity `raw`, kept or not.
    #[inline]
    fn add_point(&mut self, edges: &Edges, raw: f32, keep: bool) {
        self.kept += keep as u64;
        let key = edges.sign * raw;
        for k in 0..edges.bands {
            let g = key >= edges.lower[k];
            self.ge[k] += g as u64;
            self.ge_kept[k] += (g & keep) as u64;
        }
        self.above += (key >= edges.upper) as u64;
    }
}

/// Sums chunk counts.
pub(crate) fn total(chunks: &[Counts]) -> Counts {
    chunks.iter().fold(Counts::default(), |a, c| a.add(c))
}

/// Splits `s` into consecutive pieces of the given lengths.
fn split_by<'a, T>(mut s: &'a mut [T], lens: &[usize]) -> Vec<&'a mut [T]> {
    let mut out = Vec::with_capacity(lens.len());
    for &l in lens {
        let (a, b) = std::mem::take(&mut s).split_at_mut(l);
        out.push(a);
        s = b;
    }
    out
}

/// Copies `src[i]` for every `mask[i] == 1` into `dst` (exactly the kept
/// count long), branch-free up to the last kept point.
#[inline]
fn compact_chunk<T: Copy>(src: &[T], mask: &[u8], dst: &mut [T]) {
    let Some(last) = mask.iter().rposition(|&m| m != 0) else {
        return;
    };
    let mut w = 0usize;
    for (s, &m) in src[..=last].iter().zip(&mask[..=last]) {
        dst[w] = *s;
        w += m as usize;
    }
    debug_assert_eq!(w, dst.len());
}

/// Compacts one column in parallel.
fn compact_column<T: Copy + Default + Send + Sync>(
    src: &[T],
    mask: &[u8],
    kept: &[usize],
    total: usize,
) -> Vec<T> {
    let mut out = vec![T::default(); total];
    let pieces = split_by(&mut out, kept);
    pieces
        .into_par_iter()
        .zip(src.par_chunks(CHUNK).zip(mask.par_chunks(CHUNK)))
        .for_each(|(dst, (s, m))| compact_chunk(s, m, dst));
    out
}

/// The kept points of `cloud`, in order.
pub(crate) fn compact(cloud: &PointCloud, mask: &[u8], chunks: &[Counts]) -> PointCloud {
    let kept: Vec<usize> = chunks.iter().map(|c| c.kept as usize).collect();
    let total: usize = kept.iter().sum();
    if total == cloud.len() {
        return cloud.clone();
    }
    let col = |v: &Vec<f32>| compact_column(v, mask, &kept, total);
    PointCloud {
        x: col(&cloud.x),
        y: col(&cloud.y),
        z: col(&cloud.z),
        intensity: col(&cloud.intensity),
        ring: compact_column(&cloud.ring, mask, &kept, total),
        time: cloud.time.as_ref().map(col),
        intensity_scale: cloud.intensity_scale,
    }
}

/// Shortest range a noisy return is given (metres): noise never moves a
/// return through or behind the sensor.
pub(crate) const MIN_NOISY_RANGE_M: f64 = 1e-3;

/// Adds N(0, σ²) to the range of every point (direction kept) and/or
/// multiplies calibrated intensity by `exp(−2·α·r)`. One stream per chunk;
/// one normal draw per point whether or not it moves.
pub(crate) fn perturb(
    cloud: &mut PointCloud,
    sigma: Option<f64>,
    alpha: Option<f64>,
    seed: ScanSeed,
) {
    let scale = cloud.intensity_scale;
    let PointCloud {
        x, y, z, intensity, ..
    } = cloud;
    x.par_chunks_mut(CHUNK)
        .zip(y.par_chunks_mut(CHUNK))
        .zip(z.par_chunks_mut(CHUNK))
        .zip(intensity.par_chunks_mut(CHUNK))
        .enumerate()
        .for_each(|(c, (((x, y), z), it))| {
            let mut rng = sigma.map(|_| seed.rng(Purpose::RangeNoise, c as u64));
            for i in 0..x.len() {
                let (px, py, pz) = (x[i] as f64, y[i] as f64, z[i] as f64);
                let r = (px * px + py * py + pz * pz).sqrt();
                let mut r_new = r;
                if let (Some(s), Some(rng)) = (sigma, rng.as_mut()) {
                    let e: f64 = rng.sample(rand_distr::StandardNormal);
                    if r > 0.0 {
                        r_new = (r + s * e).max(MIN_NOISY_RANGE_M);
                        let f = r_new / r;
                        x[i] = (px * f) as f32;
                        y[i] = (py * f) as f32;
                        z[i] = (pz * f) as f32;
                    }
                }
                if let Some(a) = alpha {
                    let c = scale.to_calibrated(it[i]) as f64 * (-2.0 * a * r_new).exp();
                    it[i] = scale.from_calibrated(c as f32);
                }
            }
        });
}
