//! Light: sRGB ↔ linear conversion, the sky/sun irradiance and environment
//! map estimated from the image, the Henyey–Greenstein phase function, and
//! a drop's field-of-view radiance (seed 003 §3.1.1, §3.1.4, appendix A).
//!
//! All radiometry is done on **linear** RGB (the 8-bit input decoded with
//! the sRGB transfer curve), since blending and attenuation are linear in
//! radiance; the result is encoded back to sRGB.
//!
//! - **Sun/sky irradiance `Ē_sun`**: the mean linear colour of the brightest
//!   10 % of the pixels (by luminance) in the top quarter of the image rows.
//!   In a road scene the top rows hold the sky when there is any; the bright
//!   decile keeps façades and trees out of it.
//! - **Environment map `E`** (our stand-in for the seed's ref. 10): an
//!   equirectangular map of 64 × 32 cells around the camera. Directions
//!   inside the camera's field of view take the (block-averaged) image;
//!   other directions take the mean of the image row at the same elevation
//!   (clamped to the top or bottom row): a cylindrical extension that puts
//!   the sky above and the road below all around the camera.
//! - **Drop field of view** (appendix A): a drop refracts light from a cone
//!   of 165° about its viewing direction; `F̄` is the solid-angle-weighted
//!   mean of the map cells inside that cone (the seed fills the polygon of
//!   the cone's 20 contour points on the sphere; summing cells inside the
//!   cone is the same region without the polygon step). The drop is taken
//!   at the camera centre, as the seed does (drops are within a few metres
//!   while the sphere radius is 10 m).

use image::RgbImage;

/// sRGB electro-optical transfer: 8-bit code → linear [0, 1].
pub(crate) fn decode_lut() -> [f32; 256] {
    let mut lut = [0f32; 256];
    for (i, v) in lut.iter_mut().enumerate() {
        let c = i as f64 / 255.0;
        *v = if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        } as f32;
    }
    lut
}

/// Resolution of the linear → sRGB table.
const ENC_N: usize = 16384;

/// Linear [0, 1] → 8-bit sRGB by table lookup (a precomputed table is ~20×
/// faster than `powf` per sample and exact to the 8-bit output).
pub(crate) struct Encoder {
    lut: Vec<u8>,
}

impl Encoder {
    pub(crate) fn new() -> Self {
        let lut = (0..=ENC_N)
            .map(|i| {
                let l = i as f64 / ENC_N as f64;
                let c = if l <= 0.003_130_8 {
                    12.92 * l
                } else {
                    1.055 * l.powf(1.0 / 2.4) - 0.055
                };
                (c * 255.0).round().clamp(0.0, 255.0) as u8
            })
            .collect();
        Encoder { lut }
    }

    #[inline]
    pub(crate) fn encode(&self, l: f32) -> u8 {
        let i = (l * ENC_N as f32 + 0.5).clamp(0.0, ENC_N as f32) as usize;
        self.lut[i]
    }
}

/// Henyey–Greenstein phase function (per steradian) for asymmetry `g` and
/// scattering-angle cosine `cos_theta`.
pub fn henyey_greenstein(g: f64, cos_theta: f64) -> f64 {
    let d = 1.0 + g * g - 2.0 * g * cos_theta;
    (1.0 - g * g) / (4.0 * std::f64::consts::PI * d * d.sqrt())
}

/// Linear luminance (Rec. 709 weights).
#[inline]
pub(crate) fn luminance(c: [f32; 3]) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

/// Mean linear colour of the brightest decile of the top quarter rows.
pub(crate) fn sun_irradiance(lin: &[f32], w: usize, h: usize) -> [f32; 3] {
    let rows = (h / 4).max(1);
    let px = &lin[..rows * w * 3];
    let mut lum: Vec<f32> = px
        .chunks_exact(3)
        .map(|c| luminance([c[0], c[1], c[2]]))
        .collect();
    let n = lum.len();
    let k = (n * 9 / 10).min(n - 1);
    let (_, thr, _) = lum.select_nth_unstable_by(k, f32::total_cmp);
    let thr = *thr;
    let mut sum = [0f64; 3];
    let mut cnt = 0usize;
    for c in px.chunks_exact(3) {
        if luminance([c[0], c[1], c[2]]) >= thr {
            for j in 0..3 {
                sum[j] += f64::from(c[j]);
            }
            cnt += 1;
        }
    }
    let cnt = cnt.max(1) as f64;
    [
        (sum[0] / cnt) as f32,
        (sum[1] / cnt) as f32,
        (sum[2] / cnt) as f32,
    ]
}

/// Cells of the environment map, azimuth × elevation.
const ENV_W: usize = 64;
const ENV_H: usize = 32;

/// The environment map estimate and the drop field-of-view means.
pub(crate) struct EnvMap {
    /// Unit directions (camera frame: x right, y down, z forward).
    dirs: Vec<[f64; 3]>,
    /// Solid-angle weights.
    weight: Vec<f64>,
    /// Linear colours.
    colour: Vec<[f64; 3]>,
    /// Lazily computed F̄ per cell.
    fov_cache: Vec<Option<[f32; 3]>>,
    /// Ē, the weighted mean of the map.
    mean: [f32; 3],
}

/// Half-angle of a drop's field of view (165° / 2), as a cosine.
fn cos_half_fov() -> f64 {
    (165f64.to_radians() / 2.0).cos()
}

impl EnvMap {
    /// Builds the map from the linear image and its intrinsics.
    pub(crate) fn estimate(
        lin: &[f32],
        w: usize,
        h: usize,
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
    ) -> Self {
        // Block-averaged thumbnail, ~128 blocks across the longer side.
        let b = (w.max(h) / 128).max(1);
        let (tw, th) = (w.div_ceil(b), h.div_ceil(b));
        let mut thumb = vec![[0f64; 3]; tw * th];
        let mut cnt = vec![0u32; tw * th];
        for y in 0..h {
            let ty = y / b;
            for x in 0..w {
                let k = ty * tw + x / b;
                let p = &lin[(y * w + x) * 3..(y * w + x) * 3 + 3];
                for j in 0..3 {
                    thumb[k][j] += f64::from(p[j]);
                }
                cnt[k] += 1;
            }
        }
        for (t, &c) in thumb.iter_mut().zip(&cnt) {
            for v in t.iter_mut() {
                *v /= f64::from(c.max(1));
            }
        }
        let row_mean: Vec<[f64; 3]> = (0..th)
            .map(|ty| {
                let mut s = [0f64; 3];
                for tx in 0..tw {
                    for j in 0..3 {
                        s[j] += thumb[ty * tw + tx][j];
                    }
                }
                s.map(|v| v / tw as f64)
            })
            .collect();
        let mut dirs = Vec::with_capacity(ENV_W * ENV_H);
        let mut weight = Vec::with_capacity(ENV_W * ENV_H);
        let mut colour = Vec::with_capacity(ENV_W * ENV_H);
        for ei in 0..ENV_H {
            // Elevation from +90° (up) to −90°, cell centres.
            let el = std::f64::consts::FRAC_PI_2
                - (ei as f64 + 0.5) * std::f64::consts::PI / ENV_H as f64;
            for ai in 0..ENV_W {
                let az = -std::f64::consts::PI
                    + (ai as f64 + 0.5) * std::f64::consts::TAU / ENV_W as f64;
                let d = [el.cos() * az.sin(), -el.sin(), el.cos() * az.cos()];
                let mut c = None;
                if d[2] > 1e-6 {
                    let u = cx + fx * d[0] / d[2];
                    let v = cy + fy * d[1] / d[2];
                    if u >= 0.0 && v >= 0.0 && u < w as f64 && v < h as f64 {
                        c = Some(thumb[(v as usize / b) * tw + u as usize / b]);
                    }
                }
                let c = c.unwrap_or_else(|| {
                    // Row of the same elevation, clamped into the image.
                    let v = (cy - fy * el.tan()).clamp(0.0, h as f64 - 1.0);
                    row_mean[v as usize / b]
                });
                dirs.push(d);
                weight.push(el.cos());
                colour.push(c);
            }
        }
        let wsum: f64 = weight.iter().sum();
        let mut mean = [0f64; 3];
        for (c, wt) in colour.iter().zip(&weight) {
            for j in 0..3 {
                mean[j] += c[j] * wt / wsum;
            }
        }
        EnvMap {
            fov_cache: vec![None; dirs.len()],
            dirs,
            weight,
            colour,
            mean: mean.map(|v| v as f32),
        }
    }

    /// Ē, the mean of the map.
    pub(crate) fn mean(&self) -> [f32; 3] {
        self.mean
    }

    /// The cell whose centre direction is nearest to `d` (a unit vector).
    fn cell_of(d: [f64; 3]) -> usize {
        let el = (-d[1]).clamp(-1.0, 1.0).asin();
        let az = d[0].atan2(d[2]);
        let ei = ((std::f64::consts::FRAC_PI_2 - el) / std::f64::consts::PI * ENV_H as f64)
            .floor()
            .clamp(0.0, ENV_H as f64 - 1.0) as usize;
        let ai = ((az + std::f64::consts::PI) / std::f64::consts::TAU * ENV_W as f64)
            .floor()
            .clamp(0.0, ENV_W as f64 - 1.0) as usize;
        ei * ENV_W + ai
    }

    /// F̄ for a drop seen in direction `d` (unit vector, camera frame): the
    /// weighted mean of the cells within 82.5° of `d`'s cell.
    pub(crate) fn fov_mean(&mut self, d: [f64; 3]) -> [f32; 3] {
        let cell = Self::cell_of(d);
        if let Some(c) = self.fov_cache[cell] {
            return c;
        }
        let a = self.dirs[cell];
        let lim = cos_half_fov();
        let mut s = [0f64; 3];
        let mut ws = 0.0;
        for ((b, c), wt) in self.dirs.iter().zip(&self.colour).zip(&self.weight) {
            if a[0] * b[0] + a[1] * b[1] + a[2] * b[2] >= lim {
                for j in 0..3 {
                    s[j] += c[j] * wt;
                }
                ws += wt;
            }
        }
        let out = s.map(|v| (v / ws.max(1e-12)) as f32);
        self.fov_cache[cell] = Some(out);
        out
    }
}

/// Decodes an 8-bit image to interleaved linear RGB.
pub(crate) fn to_linear(img: &RgbImage, lut: &[f32; 256]) -> Vec<f32> {
    img.as_raw().iter().map(|&v| lut[v as usize]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trip_is_exact_for_every_code() {
        let lut = decode_lut();
        let enc = Encoder::new();
        for v in 0..=255u8 {
            assert_eq!(enc.encode(lut[v as usize]), v, "code {v}");
        }
    }

    #[test]
    fn hg_integrates_to_one_and_is_isotropic_at_zero() {
        // ∫ p dΩ = 2π ∫_{-1}^{1} p(μ) dμ = 1 (midpoint rule, 1e-4).
        for g in [0.0, 0.3, 0.8] {
            let n = 20_000;
            let s: f64 = (0..n)
                .map(|i| {
                    let mu = -1.0 + (i as f64 + 0.5) * 2.0 / n as f64;
                    henyey_greenstein(g, mu) * 2.0 / n as f64
                })
                .sum::<f64>()
                * std::f64::consts::TAU;
            assert!((s - 1.0).abs() < 1e-4, "g {g}: {s}");
        }
        let iso = 1.0 / (4.0 * std::f64::consts::PI);
        assert!((henyey_greenstein(0.0, 0.3) - iso).abs() < 1e-15);
    }

    #[test]
    fn uniform_image_gives_uniform_environment() {
        let lin = vec![0.25f32; 40 * 30 * 3];
        let mut env = EnvMap::estimate(&lin, 40, 30, 30.0, 30.0, 20.0, 15.0);
        for j in 0..3 {
            assert!((env.mean()[j] - 0.25).abs() < 1e-6);
            assert!((env.fov_mean([0.0, 0.0, 1.0])[j] - 0.25).abs() < 1e-6);
        }
        assert_eq!(sun_irradiance(&lin, 40, 30), [0.25; 3]);
    }
}
