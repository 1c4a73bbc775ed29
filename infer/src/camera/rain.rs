//! The renderer: checked [`RainParams`] → [`RainRenderer`] → rainy image.
//!
//! Rendering follows seed 003 §3.1.6 in three steps, on linear RGB:
//!
//! 1. **Fog-like rain** (eq. 1–2): `I_att = I·L_ext + A_in`, with
//!    `L_ext = exp(−0.312 R^0.67 d)` (d in km, see [`super::physics`]) and
//!    airlight `A_in = 4π·β_HG(θ)·Ē_sun·(1 − L_ext)`. θ is the angle
//!    between the pixel's ray and the sun direction (default: straight up,
//!    the overcast sky of a shower). The factor 4π makes the phase
//!    function average 1 over the sphere, so that airlight saturates at the
//!    sky radiance for isotropic scattering (Koschmieder's limit); the seed
//!    does not state its normalisation.
//! 2. **Streaks** (eq. 4–5 / 11): each simulated drop that images on at
//!    least one pixel is drawn as a capsule from its projected start to end
//!    point, composited in the drops' (seeded) order:
//!    `I ← (1 − α)·I + α·m·(0.94·F̄ + 0.06·Ē)`, with
//!    `α = a(x)·(τ₁/T)·b`, where
//!    - `τ₁/T = min(1, w/ℓ)`: the share of the exposure the drop spends on
//!      one pixel (w its imaged diameter, ℓ the streak length, both pixels);
//!    - `a(x) ∈ [0, 1]` the anti-aliased capsule coverage of pixel x, the
//!      capsule's width `w_b = √(w² + c²)` widened by the circle of
//!      confusion `c = |d − f_p| f f_x / (d (f_p − f) N)` (seed footnote 4,
//!      converted to pixels), and `b` the energy kept at the peak after that
//!      defocus (`w/w_b` across, `(ℓ+w)/(ℓ+w_b)` along);
//!    - `m = 1 + A sin(2π f_osc T t + φ)`, t ∈ [0, 1] along the streak: a
//!      brightness ripple at the drop's Rayleigh oscillation frequency with
//!      a random phase per drop.
//!
//!    **The Garg–Nayar streak database is not available**: instead of
//!    warping a database streak with a homography (eq. 3) the streak is this
//!    parametric capsule (width from drop size and defocus, alpha from the
//!    exposure-time ratio τ₁/T, oscillation as the ripple). Equation 11's
//!    `S′·τ₁/τ₀` with `S′ ∝ τ₀/T` then reduces to `α·L` above. Streaks
//!    behind the scene (drop depth > pixel depth) are not drawn (the seed
//!    lists ignoring occlusion as a limitation); this can be turned off.
//! 3. **Global luminosity** (§3.1.6): each colour channel is scaled (in
//!    linear RGB) so that the **per-channel mean of the 8-bit output equals
//!    that of the input**, to within 0.05 of a level unless clipping at 255
//!    makes it unreachable (stated tolerance in the tests: 0.5 level).
//!
//! **Determinism.** Drops come from one ChaCha8 stream (seed), generated
//! sequentially; the image is then processed in bands of rows in parallel,
//! each band applying the streaks that touch it in drop order. Sums are
//! integer. Output bytes do not depend on the rayon thread count.

use image::RgbImage;
use rayon::prelude::*;

use super::calib::Intrinsics;
use super::depth::DepthMap;
use super::photometry::{self, Encoder, EnvMap};
use super::physics::{self, FieldSpec};
use crate::error::InferError;

/// Rain rendering parameters (checked by [`RainParams::check`]).
///
/// | Name | Default | Purpose | Range |
/// |---|---|---|---|
/// | `rate_mm_h` | (required) | rainfall rate R, mm/h | 0 ≤ R ≤ 500 |
/// | `exposure_s` | 0.005 | exposure time T, s (KITTI 0.002) | (0, 1] |
/// | `ego_speed_m_s` | 0 | camera forward speed, m/s | [0, 100] |
/// | `intrinsics` | 0.8·W focal, centred | pinhole intrinsics, px | f > 0 |
/// | `lens_focal_m` | 0.006 | lens focal length f, m (circle of confusion) | (0, 1) |
/// | `f_number` | 2.0 | lens f-number N | > 0 |
/// | `focus_m` | 6.0 | focus distance f_p, m (seed: 6 m) | > lens focal |
/// | `drop_diameter_m` | [0.001, 0.006] | diameters simulated as streaks | 0 < min < max ≤ 0.01 |
/// | `min_drop_px` | 1.0 | smallest imaged drop drawn as a streak, px | > 0 |
/// | `near_m` | 0.2 | nearest drop, m | > 0 |
/// | `phase_g` | 0.1 | Henyey–Greenstein asymmetry g | (−1, 1) |
/// | `sun_direction` | (0, −1, 0) up | sun/sky direction, camera frame | non-zero |
/// | `oscillation` | 0.2 | streak brightness ripple amplitude A | [0, 1) |
/// | `occlusion` | true | hide streaks behind the scene depth | |
/// | `seed` | 0 | drop field seed | any |
#[derive(Debug, Clone, PartialEq)]
pub struct RainParams {
    rate_mm_h: f64,
    exposure_s: f64,
    ego_speed_m_s: f64,
    intrinsics: Option<Intrinsics>,
    lens_focal_m: f64,
    f_number: f64,
    focus_m: f64,
    drop_diameter_m: (f64, f64),
    min_drop_px: f64,
    near_m: f64,
    phase_g: f64,
    sun_direction: [f64; 3],
    oscillation: f64,
    occlusion: bool,
    seed: u64,
}

impl RainParams {
    /// Defaults (see the table) for a rain rate in mm/h.
    pub fn new(rate_mm_h: f64) -> Self {
        RainParams {
            rate_mm_h,
            exposure_s: 0.005,
            ego_speed_m_s: 0.0,
            intrinsics: None,
            lens_focal_m: 0.006,
            f_number: 2.0,
            focus_m: 6.0,
            drop_diameter_m: (1e-3, 6e-3),
            min_drop_px: 1.0,
            near_m: 0.2,
            phase_g: 0.1,
            sun_direction: [0.0, -1.0, 0.0],
            oscillation: 0.2,
            occlusion: true,
            seed: 0,
        }
    }

    /// The rain rate, mm/h.
    pub fn rate_mm_h(&self) -> f64 {
        self.rate_mm_h
    }

    /// Sets the exposure time, s.
    pub fn exposure_s(mut self, t: f64) -> Self {
        self.exposure_s = t;
        self
    }

    /// Sets the camera's forward speed, m/s.
    pub fn ego_speed_m_s(mut self, v: f64) -> Self {
        self.ego_speed_m_s = v;
        self
    }

    /// Sets the pinhole intrinsics (e.g. [`super::KittiCalib::intrinsics`]).
    pub fn intrinsics(mut self, k: Intrinsics) -> Self {
        self.intrinsics = Some(k);
        self
    }

    /// Sets the lens focal length (m) and f-number used for defocus.
    pub fn lens(mut self, focal_m: f64, f_number: f64) -> Self {
        self.lens_focal_m = focal_m;
        self.f_number = f_number;
        self
    }

    /// Sets the focus distance, m.
    pub fn focus_m(mut self, d: f64) -> Self {
        self.focus_m = d;
        self
    }

    /// Sets the range of drop diameters drawn as streaks, m.
    pub fn drop_diameter_m(mut self, min: f64, max: f64) -> Self {
        self.drop_diameter_m = (min, max);
        self
    }

    /// Sets the smallest imaged drop size drawn as a streak, px.
    pub fn min_drop_px(mut self, px: f64) -> Self {
        self.min_drop_px = px;
        self
    }

    /// Sets the nearest drop distance, m.
    pub fn near_m(mut self, d: f64) -> Self {
        self.near_m = d;
        self
    }

    /// Sets the Henyey–Greenstein asymmetry g.
    pub fn phase_g(mut self, g: f64) -> Self {
        self.phase_g = g;
        self
    }

    /// Sets the sun direction in the camera frame (x right, y down, z
    /// forward); it need not be normalised.
    pub fn sun_direction(mut self, d: [f64; 3]) -> Self {
        self.sun_direction = d;
        self
    }

    /// Sets the streak brightness ripple amplitude.
    pub fn oscillation(mut self, a: f64) -> Self {
        self.oscillation = a;
        self
    }

    /// Hides (true) or draws (false) streaks behind the scene.
    pub fn occlusion(mut self, on: bool) -> Self {
        self.occlusion = on;
        self
    }

    /// Sets the seed of the drop field.
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// Checks every parameter against its range (first failure is
    /// reported by name) and returns the renderer.
    pub fn check(&self) -> Result<RainRenderer, InferError> {
        fn bad(name: &'static str, value: impl std::fmt::Debug, reason: &str) -> InferError {
            InferError::InvalidParam {
                name,
                value: format!("{value:?}"),
                reason: reason.to_string(),
            }
        }
        let p = self;
        if !(p.rate_mm_h.is_finite() && (0.0..=500.0).contains(&p.rate_mm_h)) {
            return Err(bad("rate_mm_h", p.rate_mm_h, "must be in [0, 500] mm/h"));
        }
        if !(p.exposure_s > 0.0 && p.exposure_s <= 1.0) {
            return Err(bad("exposure_s", p.exposure_s, "must be in (0, 1] s"));
        }
        if !(p.ego_speed_m_s.is_finite() && (0.0..=100.0).contains(&p.ego_speed_m_s)) {
            return Err(bad(
                "ego_speed_m_s",
                p.ego_speed_m_s,
                "must be in [0, 100] m/s",
            ));
        }
        if let Some(k) = p.intrinsics
            && !(k.fx > 0.0
                && k.fy > 0.0
                && k.fx.is_finite()
                && k.fy.is_finite()
                && k.cx.is_finite()
                && k.cy.is_finite())
        {
            return Err(bad(
                "intrinsics",
                k,
                "focal lengths must be positive and all values finite",
            ));
        }
        if !(p.lens_focal_m > 0.0 && p.lens_focal_m < 1.0) {
            return Err(bad("lens_focal_m", p.lens_focal_m, "must be in (0, 1) m"));
        }
        if !(p.f_number > 0.0 && p.f_number.is_finite()) {
            return Err(bad("f_number", p.f_number, "must be positive"));
        }
        if !(p.focus_m > p.lens_focal_m && p.focus_m.is_finite()) {
            return Err(bad(
                "focus_m",
                p.focus_m,
                "must be finite and beyond the lens focal length",
            ));
        }
        let (d0, d1) = p.drop_diameter_m;
        if !(d0 > 0.0 && d0 < d1 && d1 <= 0.01) {
            return Err(bad(
                "drop_diameter_m",
                p.drop_diameter_m,
                "need 0 < min < max ≤ 0.01 m",
            ));
        }
        if !(p.min_drop_px > 0.0 && p.min_drop_px.is_finite()) {
            return Err(bad("min_drop_px", p.min_drop_px, "must be positive"));
        }
        if !(p.near_m > 0.0 && p.near_m.is_finite()) {
            return Err(bad("near_m", p.near_m, "must be positive"));
        }
        if !(p.phase_g > -1.0 && p.phase_g < 1.0) {
            return Err(bad("phase_g", p.phase_g, "must be in (-1, 1)"));
        }
        let n = p.sun_direction.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !(n > 0.0 && n.is_finite()) {
            return Err(bad(
                "sun_direction",
                p.sun_direction,
                "must be a finite non-zero vector",
            ));
        }
        if !(0.0..1.0).contains(&p.oscillation) {
            return Err(bad("oscillation", p.oscillation, "must be in [0, 1)"));
        }
        Ok(RainRenderer {
            params: self.clone(),
            sun: p.sun_direction.map(|v| v / n),
        })
    }
}

/// What a render did.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct RainStats {
    /// Drops simulated (in the spawn volume around the frustum).
    pub drops: usize,
    /// Streaks whose footprint touches the image.
    pub streaks: usize,
    /// Pixels where some streak's alpha is at least 1/255.
    pub covered_pixels: u64,
    /// `covered_pixels` over the pixel count.
    pub covered_share: f64,
    /// Estimated sun/sky irradiance `Ē_sun`, linear RGB.
    pub sun: [f32; 3],
    /// Environment-map mean `Ē`, linear RGB.
    pub env_mean: [f32; 3],
    /// Per-channel gain applied to restore the mean luminosity.
    pub gain: [f64; 3],
}

/// A checked rain renderer.
#[derive(Debug, Clone, PartialEq)]
pub struct RainRenderer {
    params: RainParams,
    sun: [f64; 3],
}

/// One streak ready to draw.
#[derive(Debug, Clone, Copy)]
struct Streak {
    p0: [f32; 2],
    d: [f32; 2],
    inv_len2: f32,
    radius: f32,
    alpha: f32,
    colour: [f32; 3],
    z0: f32,
    dz: f32,
    cycles: f32,
    phase: f32,
    amp: f32,
    x0: usize,
    x1: usize,
    y0: usize,
    y1: usize,
}

/// Rows per parallel band (part of nothing random: results do not depend
/// on it).
const BAND: usize = 16;

impl RainRenderer {
    /// The checked parameters.
    pub fn params(&self) -> &RainParams {
        &self.params
    }

    /// The same renderer with another seed (e.g. one per image of a batch).
    pub fn with_seed(&self, seed: u64) -> Self {
        let mut r = self.clone();
        r.params.seed = seed;
        r
    }

    /// Renders rain on `image` whose per-pixel depth is `depth`.
    pub fn render(&self, image: &RgbImage, depth: &DepthMap) -> Result<RgbImage, InferError> {
        self.render_with_stats(image, depth).map(|(img, _)| img)
    }

    /// Renders rain and reports what was drawn. A rate of 0 returns the
    /// input unchanged.
    pub fn render_with_stats(
        &self,
        image: &RgbImage,
        depth: &DepthMap,
    ) -> Result<(RgbImage, RainStats), InferError> {
        let (w, h) = image.dimensions();
        if (w, h) != (depth.width(), depth.height()) {
            return Err(InferError::SizeMismatch {
                image_w: w,
                image_h: h,
                depth_w: depth.width(),
                depth_h: depth.height(),
            });
        }
        let p = &self.params;
        if p.rate_mm_h == 0.0 {
            return Ok((
                image.clone(),
                RainStats {
                    drops: 0,
                    streaks: 0,
                    covered_pixels: 0,
                    covered_share: 0.0,
                    sun: [0.0; 3],
                    env_mean: [0.0; 3],
                    gain: [1.0; 3],
                },
            ));
        }
        let (wu, hu) = (w as usize, h as usize);
        let k = p
            .intrinsics
            .unwrap_or_else(|| Intrinsics::default_for(w, h));
        let lut = photometry::decode_lut();
        let mut lin = photometry::to_linear(image, &lut);
        let sun = photometry::sun_irradiance(&lin, wu, hu);
        let mut env = EnvMap::estimate(&lin, wu, hu, k.fx, k.fy, k.cx, k.cy);
        let env_mean = env.mean();

        let field = FieldSpec {
            rate_mm_h: p.rate_mm_h,
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            width: f64::from(w),
            height: f64::from(h),
            exposure_s: p.exposure_s,
            ego_speed_m_s: p.ego_speed_m_s,
            d_min_m: p.drop_diameter_m.0,
            d_max_m: p.drop_diameter_m.1,
            min_drop_px: p.min_drop_px,
            near_m: p.near_m,
            far_m: 1e4,
            seed: p.seed,
        };
        let drops = physics::sample_drops(&field);
        let streaks = self.streaks(&drops, &k, wu, hu, &mut env, env_mean);

        // Streaks touching each band, in drop order.
        let bands = hu.div_ceil(BAND);
        let mut per_band: Vec<Vec<u32>> = vec![Vec::new(); bands];
        for (i, s) in streaks.iter().enumerate() {
            for list in &mut per_band[s.y0 / BAND..=(s.y1 - 1) / BAND] {
                list.push(i as u32);
            }
        }

        let beta_km = physics::extinction_per_km(p.rate_mm_h) as f32;
        let g = p.phase_g;
        let sd = self.sun;
        let dm = depth.as_slice();
        let occlusion = p.occlusion;
        let covered: u64 = lin
            .par_chunks_mut(BAND * wu * 3)
            .zip(per_band.par_iter())
            .enumerate()
            .map(|(b, (rows, list))| {
                let y_base = b * BAND;
                let nrows = rows.len() / (wu * 3);
                // 1. Fog-like rain.
                for r in 0..nrows {
                    let y = y_base + r;
                    let ry = (y as f64 + 0.5 - k.cy) / k.fy;
                    for x in 0..wu {
                        let rx = (x as f64 + 0.5 - k.cx) / k.fx;
                        let inv = 1.0 / (rx * rx + ry * ry + 1.0).sqrt();
                        let cos_t = (rx * sd[0] + ry * sd[1] + sd[2]) * inv;
                        let phase =
                            (4.0 * std::f64::consts::PI * photometry::henyey_greenstein(g, cos_t))
                                as f32;
                        let d = dm[y * wu + x];
                        let l_ext = (-beta_km * d / 1000.0).exp();
                        let air = phase * (1.0 - l_ext);
                        let px = &mut rows[(r * wu + x) * 3..(r * wu + x) * 3 + 3];
                        for j in 0..3 {
                            px[j] = px[j] * l_ext + air * sun[j];
                        }
                    }
                }
                // 2. Streaks, in drop order.
                let mut cover = vec![false; nrows * wu];
                for &i in list {
                    let s = &streaks[i as usize];
                    let ya = s.y0.max(y_base);
                    let yb = s.y1.min(y_base + nrows);
                    for y in ya..yb {
                        let r = y - y_base;
                        let py = y as f32 + 0.5 - s.p0[1];
                        for x in s.x0..s.x1 {
                            let px_ = x as f32 + 0.5 - s.p0[0];
                            let t = ((px_ * s.d[0] + py * s.d[1]) * s.inv_len2).clamp(0.0, 1.0);
                            let ex = px_ - t * s.d[0];
                            let ey = py - t * s.d[1];
                            let dist = (ex * ex + ey * ey).sqrt();
                            let a = (s.radius + 0.5 - dist).clamp(0.0, 1.0);
                            if a <= 0.0 {
                                continue;
                            }
                            if occlusion && dm[y * wu + x] < s.z0 + t * s.dz {
                                continue;
                            }
                            let alpha = s.alpha * a;
                            let m = 1.0
                                + s.amp * (std::f32::consts::TAU * s.cycles * t + s.phase).sin();
                            let o = (r * wu + x) * 3;
                            for j in 0..3 {
                                rows[o + j] = (1.0 - alpha) * rows[o + j] + alpha * m * s.colour[j];
                            }
                            if alpha >= 1.0 / 255.0 {
                                cover[r * wu + x] = true;
                            }
                        }
                    }
                }
                cover.iter().filter(|&&c| c).count() as u64
            })
            .sum();

        // 3. Restore the per-channel mean of the 8-bit image.
        let enc = Encoder::new();
        let n = (wu * hu) as f64;
        let target = channel_sums(image.as_raw()).map(|s| s as f64 / n);
        let mut gain = [1f64; 3];
        // First guess: ratio of linear means.
        let lin_sum = {
            let mut s = [0f64; 3];
            for (i, v) in lin.iter().enumerate() {
                s[i % 3] += f64::from(*v);
            }
            s
        };
        let in_lin = {
            let mut s = [0f64; 3];
            for (i, v) in image.as_raw().iter().enumerate() {
                s[i % 3] += f64::from(lut[*v as usize]);
            }
            s
        };
        for j in 0..3 {
            gain[j] = if lin_sum[j] > 0.0 {
                in_lin[j] / lin_sum[j]
            } else {
                1.0
            };
        }
        for _ in 0..8 {
            let got = encoded_sums(&lin, gain, &enc).map(|s| s as f64 / n);
            let mut done = true;
            for j in 0..3 {
                if (got[j] - target[j]).abs() > 0.05 && got[j] > 0.0 {
                    done = false;
                    gain[j] *= srgb_decode(target[j] / 255.0) / srgb_decode(got[j] / 255.0);
                }
            }
            if done {
                break;
            }
        }
        let gf = gain.map(|v| v as f32);
        let mut out = vec![0u8; lin.len()];
        out.par_chunks_mut(wu * 3)
            .zip(lin.par_chunks(wu * 3))
            .for_each(|(o, l)| {
                for (i, (ov, lv)) in o.iter_mut().zip(l).enumerate() {
                    *ov = enc.encode(lv * gf[i % 3]);
                }
            });
        let img = RgbImage::from_raw(w, h, out).expect("buffer has the image's size");
        Ok((
            img,
            RainStats {
                drops: drops.len(),
                streaks: streaks.len(),
                covered_pixels: covered,
                covered_share: covered as f64 / n,
                sun,
                env_mean,
                gain,
            },
        ))
    }

    /// Projects drops to streaks with their photometry; drops whose
    /// footprint misses the image are left out.
    fn streaks(
        &self,
        drops: &[physics::Drop],
        k: &Intrinsics,
        w: usize,
        h: usize,
        env: &mut EnvMap,
        env_mean: [f32; 3],
    ) -> Vec<Streak> {
        let p = &self.params;
        let (f, n_f, fp) = (p.lens_focal_m, p.f_number, p.focus_m);
        let mut out = Vec::new();
        for d in drops {
            let proj = |x: [f64; 3]| [k.cx + k.fx * x[0] / x[2], k.cy + k.fy * x[1] / x[2]];
            let a = proj(d.start);
            let b = proj(d.end);
            let zm = 0.5 * (d.start[2] + d.end[2]);
            let wpx = k.fx * d.diameter_m / zm;
            let coc = (zm - fp).abs() * f * k.fx / (zm * (fp - f) * n_f);
            let wb = (wpx * wpx + coc * coc).sqrt();
            let r = 0.5 * wb;
            let dv = [b[0] - a[0], b[1] - a[1]];
            let len = (dv[0] * dv[0] + dv[1] * dv[1]).sqrt();
            let tau_ratio = if len > 1e-9 {
                (wpx / len).min(1.0)
            } else {
                1.0
            };
            let keep = (wpx / wb) * ((len + wpx) / (len + wb));
            let alpha = tau_ratio * keep;
            let x0 = (a[0].min(b[0]) - r - 1.0).floor().max(0.0);
            let x1 = (a[0].max(b[0]) + r + 2.0).ceil().min(w as f64);
            let y0 = (a[1].min(b[1]) - r - 1.0).floor().max(0.0);
            let y1 = (a[1].max(b[1]) + r + 2.0).ceil().min(h as f64);
            if x0 >= x1 || y0 >= y1 {
                continue;
            }
            let mid = [
                0.5 * (d.start[0] + d.end[0]),
                0.5 * (d.start[1] + d.end[1]),
                zm,
            ];
            let nm = (mid[0] * mid[0] + mid[1] * mid[1] + mid[2] * mid[2]).sqrt();
            let fbar = env.fov_mean(mid.map(|v| v / nm));
            let colour = [0, 1, 2].map(|j| 0.94 * fbar[j] + 0.06 * env_mean[j]);
            out.push(Streak {
                p0: [a[0] as f32, a[1] as f32],
                d: [dv[0] as f32, dv[1] as f32],
                inv_len2: if len > 1e-9 {
                    (1.0 / (len * len)) as f32
                } else {
                    0.0
                },
                radius: r as f32,
                alpha: alpha as f32,
                colour,
                z0: d.start[2] as f32,
                dz: (d.end[2] - d.start[2]) as f32,
                cycles: (physics::oscillation_hz(d.diameter_m) * p.exposure_s) as f32,
                phase: d.phase as f32,
                amp: p.oscillation as f32,
                x0: x0 as usize,
                x1: x1 as usize,
                y0: y0 as usize,
                y1: y1 as usize,
            });
        }
        out
    }
}

/// Continuous sRGB decode of a [0, 1] value.
fn srgb_decode(c: f64) -> f64 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Per-channel sums of an interleaved 8-bit RGB buffer.
fn channel_sums(raw: &[u8]) -> [u64; 3] {
    let mut s = [0u64; 3];
    for px in raw.chunks_exact(3) {
        for j in 0..3 {
            s[j] += u64::from(px[j]);
        }
    }
    s
}

/// Per-channel sums of the encoded output for a gain (integer, so the
/// parallel reduction is exact).
fn encoded_sums(lin: &[f32], gain: [f64; 3], enc: &Encoder) -> [u64; 3] {
    let g = gain.map(|v| v as f32);
    lin.par_chunks(3 * 4096)
        .map(|chunk| {
            let mut s = [0u64; 3];
            for px in chunk.chunks_exact(3) {
                for j in 0..3 {
                    s[j] += u64::from(enc.encode(px[j] * g[j]));
                }
            }
            s
        })
        .reduce(|| [0; 3], |a, b| [a[0] + b[0], a[1] + b[1], a[2] + b[2]])
}
