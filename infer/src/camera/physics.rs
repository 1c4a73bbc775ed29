//! Rain physics: extinction, drop sizes, fall speeds, oscillation, and the
//! seeded drop field in front of the camera.
//!
//! - **Extinction** (seed 003 eq. 2): `β = 0.312 R^0.67` per **kilometre**
//!   (R in mm/h). The seed prints `exp(-0.312 R^0.67 d)` without units; with
//!   `d` in metres 100 mm/h would make a wall 1 m away invisible, so `d` is
//!   in km here: at 100 mm/h `β ≈ 6.8 km⁻¹`, a meteorological visibility of
//!   `3/β ≈ 440 m`, which is what heavy rain does.
//! - **Drop sizes**: Marshall–Palmer, `N(D) = N₀ e^{−ΛD}` with
//!   `N₀ = 8000 m⁻³ mm⁻¹`, `Λ = 4.1 R^{−0.21} mm⁻¹`.
//! - **Terminal velocity**: Atlas, Srivastava & Sekhon (1973),
//!   `v(D) = 9.65 − 10.3 e^{−0.6 D}` m/s, D in mm (valid 0.1–6 mm).
//! - **Oscillation**: Rayleigh's fundamental (n = 2) mode of a water drop,
//!   `f = (1/2π) √(8σ / (ρ r³))`, σ = 0.0728 N/m, ρ = 1000 kg/m³.
//!
//! The drop field replaces the particle simulator of the seed's ref. 11:
//! drops of diameter ≥ the minimum (1 mm) that image on at least
//! `min_drop_px` pixels (i.e. closer than `f_x·D/min_drop_px`) are placed
//! uniformly in the camera frustum, Poisson in number, from one ChaCha8
//! stream (`sample_drops`, crate-internal).

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Poisson};

/// Marshall–Palmer intercept N₀, drops per m³ per mm of diameter.
pub const MP_N0: f64 = 8000.0;

/// Rain extinction coefficient `0.312 R^0.67`, per kilometre.
pub fn extinction_per_km(rate_mm_h: f64) -> f64 {
    0.312 * rate_mm_h.powf(0.67)
}

/// Fog-like rain transmittance `L_ext = exp(−0.312 R^0.67 d)` over `depth_m`
/// metres (d converted to km, see the module docs).
pub fn transmittance(rate_mm_h: f64, depth_m: f64) -> f64 {
    (-extinction_per_km(rate_mm_h) * depth_m / 1000.0).exp()
}

/// Marshall–Palmer slope Λ = 4.1 R^−0.21, per mm.
pub fn mp_lambda_per_mm(rate_mm_h: f64) -> f64 {
    4.1 * rate_mm_h.powf(-0.21)
}

/// Marshall–Palmer number density of drops of diameter `d_mm`, per m³ per mm.
pub fn mp_density(rate_mm_h: f64, d_mm: f64) -> f64 {
    MP_N0 * (-mp_lambda_per_mm(rate_mm_h) * d_mm).exp()
}

/// Terminal fall speed of a drop of diameter `d_mm` (Atlas et al. 1973), m/s,
/// floored at 0.
pub fn terminal_velocity_m_s(d_mm: f64) -> f64 {
    (9.65 - 10.3 * (-0.6 * d_mm).exp()).max(0.0)
}

/// Rayleigh n = 2 oscillation frequency of a drop of diameter `d_m`, Hz.
pub fn oscillation_hz(d_m: f64) -> f64 {
    let r = d_m / 2.0;
    (8.0 * 0.0728 / (1000.0 * r * r * r)).sqrt() / std::f64::consts::TAU
}

/// The camera and rain settings the drop field depends on.
#[derive(Debug, Clone, Copy)]
pub(crate) struct FieldSpec {
    pub rate_mm_h: f64,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub width: f64,
    pub height: f64,
    pub exposure_s: f64,
    pub ego_speed_m_s: f64,
    pub d_min_m: f64,
    pub d_max_m: f64,
    pub min_drop_px: f64,
    pub near_m: f64,
    pub far_m: f64,
    pub seed: u64,
}

/// One simulated drop: its diameter, its camera-frame position at shutter
/// opening and closing (x right, y down, z forward, metres), and a random
/// oscillation phase.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drop {
    /// Diameter, metres.
    pub diameter_m: f64,
    /// Position when the shutter opens.
    pub start: [f64; 3],
    /// Position when the shutter closes.
    pub end: [f64; 3],
    /// Oscillation phase, radians.
    pub phase: f64,
}

/// Diameter grid bins of the sampling table.
const BINS: usize = 512;

impl FieldSpec {
    /// Farthest depth at which a drop of diameter `d_m` still images on
    /// `min_drop_px` pixels (capped at `far_m`).
    fn z_hi(&self, d_m: f64) -> f64 {
        (self.fx * d_m / self.min_drop_px).min(self.far_m)
    }

    /// Image-space margin (pixels) around the image inside which drops are
    /// spawned, so that streaks entering the picture during the exposure are
    /// drawn: the displacement of the fastest drop at the nearest depth,
    /// capped at half the larger image side.
    fn margin_px(&self) -> f64 {
        let v = terminal_velocity_m_s(self.d_max_m * 1000.0) + self.ego_speed_m_s;
        let m = self.fx.max(self.fy) * v * self.exposure_s / self.near_m;
        m.min(0.5 * self.width.max(self.height)).max(2.0)
    }
}

/// Samples the drops of one image. The expected number is
/// `∫ N(D) · A/(f_x f_y) · (z_hi(D)³ − near³)/3 dD` over `[d_min, d_max]`,
/// `A` the spawn area in pixels² (image plus margin); the count is Poisson,
/// diameters follow that integrand (tabulated on 512 bins, linear inside a
/// bin), depth has density ∝ z² on `[near, z_hi(D)]`, image position is
/// uniform. Drops fall straight down (+y) at terminal velocity while the
/// camera moves forward (+z) at the ego speed, with the camera's axis taken
/// horizontal. Drops that would reach the lens (z < 5 cm) are dropped.
/// Everything comes from one ChaCha8 stream seeded by `seed`, drawn in a
/// fixed order: the result does not depend on threads.
pub(crate) fn sample_drops(spec: &FieldSpec) -> Vec<Drop> {
    if spec.rate_mm_h <= 0.0 {
        return Vec::new();
    }
    let margin = spec.margin_px();
    let (u0, u1) = (-margin, spec.width + margin);
    let (v0, v1) = (-margin, spec.height + margin);
    let area = (u1 - u0) * (v1 - v0);
    let d0 = spec.d_min_m * 1000.0;
    let d1 = spec.d_max_m * 1000.0;
    let step = (d1 - d0) / BINS as f64;
    let near3 = spec.near_m.powi(3);
    // Per-bin expected counts (midpoint rule).
    let mut cdf = Vec::with_capacity(BINS + 1);
    cdf.push(0.0);
    let mut total = 0.0;
    for i in 0..BINS {
        let d_mm = d0 + (i as f64 + 0.5) * step;
        let zh = spec.z_hi(d_mm / 1000.0);
        let vol = if zh > spec.near_m {
            (zh.powi(3) - near3) / 3.0
        } else {
            0.0
        };
        total += mp_density(spec.rate_mm_h, d_mm) * step * vol * area / (spec.fx * spec.fy);
        cdf.push(total);
    }
    if total <= 0.0 {
        return Vec::new();
    }
    let mut rng = ChaCha8Rng::seed_from_u64(spec.seed);
    rng.set_stream(0x7261_696e); // "rain"
    let n = Poisson::new(total)
        .map(|p| p.sample(&mut rng))
        .unwrap_or(total.round()) as usize;
    let mut drops = Vec::with_capacity(n);
    for _ in 0..n {
        let target = rng.random::<f64>() * total;
        let bin = cdf.partition_point(|&c| c <= target).clamp(1, BINS) - 1;
        let within = ((target - cdf[bin]) / (cdf[bin + 1] - cdf[bin])).clamp(0.0, 1.0);
        let d_m = (d0 + (bin as f64 + within) * step) / 1000.0;
        let zh = spec.z_hi(d_m).max(spec.near_m);
        let z = (near3 + rng.random::<f64>() * (zh.powi(3) - near3)).cbrt();
        let u = u0 + rng.random::<f64>() * (u1 - u0);
        let v = v0 + rng.random::<f64>() * (v1 - v0);
        let phase = rng.random::<f64>() * std::f64::consts::TAU;
        let start = [(u - spec.cx) * z / spec.fx, (v - spec.cy) * z / spec.fy, z];
        let t = spec.exposure_s;
        let end = [
            start[0],
            start[1] + terminal_velocity_m_s(d_m * 1000.0) * t,
            start[2] - spec.ego_speed_m_s * t,
        ];
        if end[2] < 0.05 {
            continue;
        }
        drops.push(Drop {
            diameter_m: d_m,
            start,
            end,
            phase,
        });
    }
    drops
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_values() {
        // Atlas et al.: 2 mm → 9.65 − 10.3 e^−1.2 = 6.5478 m/s.
        assert!((terminal_velocity_m_s(2.0) - 6.547_8).abs() < 1e-3);
        // Λ(1 mm/h) = 4.1 /mm.
        assert!((mp_lambda_per_mm(1.0) - 4.1).abs() < 1e-12);
        // β(100) = 0.312 · 100^0.67 = 6.8258 /km.
        assert!((extinction_per_km(100.0) - 6.825_8).abs() < 1e-4);
        // A 2 mm drop (r = 1 mm): √(8·0.0728 / (1000·1e-9)) / 2π = 121.46 Hz.
        assert!((oscillation_hz(2e-3) - 121.46).abs() < 0.1);
    }

    fn spec(rate: f64, seed: u64) -> FieldSpec {
        FieldSpec {
            rate_mm_h: rate,
            fx: 1000.0,
            fy: 1000.0,
            cx: 400.0,
            cy: 300.0,
            width: 800.0,
            height: 600.0,
            exposure_s: 0.005,
            ego_speed_m_s: 0.0,
            d_min_m: 1e-3,
            d_max_m: 6e-3,
            min_drop_px: 1.0,
            near_m: 0.2,
            far_m: 100.0,
            seed,
        }
    }

    #[test]
    fn drops_obey_the_size_and_image_limits() {
        let drops = sample_drops(&spec(50.0, 3));
        assert!(drops.len() > 100, "{} drops", drops.len());
        for d in &drops {
            assert!((1e-3..=6e-3).contains(&d.diameter_m));
            // At least one pixel wide where it starts.
            assert!(1000.0 * d.diameter_m / d.start[2] >= 1.0 - 1e-9);
            assert!(d.start[2] >= 0.2 - 1e-12);
            // Falls downwards by v·T.
            let fall = d.end[1] - d.start[1];
            let v = terminal_velocity_m_s(d.diameter_m * 1000.0);
            assert!((fall - v * 0.005).abs() < 1e-12);
        }
    }

    #[test]
    fn mean_diameter_matches_the_law() {
        // Check the sampled mean diameter against a direct quadrature of the
        // sampling density N(D)·(z_hi(D)³ − near³) on [1, 6] mm; 3 σ tolerance.
        let s = spec(100.0, 11);
        let drops = sample_drops(&s);
        let n = drops.len() as f64;
        let (mut w, mut wd, mut wd2) = (0.0, 0.0, 0.0);
        for i in 0..10_000 {
            let d = 1.0 + (i as f64 + 0.5) * 5.0 / 10_000.0;
            let zh = (s.fx * d / 1000.0).min(s.far_m);
            let g = mp_density(100.0, d) * (zh.powi(3) - 0.2f64.powi(3)).max(0.0);
            w += g;
            wd += g * d;
            wd2 += g * d * d;
        }
        let mean = wd / w;
        let sd = (wd2 / w - mean * mean).sqrt();
        let got = drops.iter().map(|d| d.diameter_m * 1000.0).sum::<f64>() / n;
        assert!((got - mean).abs() < 3.0 * sd / n.sqrt(), "{got} vs {mean}");
    }
}
