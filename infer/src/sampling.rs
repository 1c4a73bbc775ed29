//! Seeds and the few random laws the applier draws from.
//!
//! **Reproducibility.** Every random draw of a scan comes from a ChaCha8
//! generator keyed by [`murk_types::seed::derive`]`(seed, key,
//! Purpose::ApplyScan)` (SHA-256 of `"murk-infer/1" ‖ seed ‖ len(key) ‖ key`),
//! where `key` is the scan's name (its path relative to the batch input). A
//! scan is processed in fixed chunks of [`CHUNK`] points, and each chunk of
//! each randomised step reads its own ChaCha stream
//! (`purpose << 48 | chunk index`). No draw therefore depends on the order in
//! which rayon schedules chunks or files, and the output is byte-identical
//! whatever the thread count.

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};

/// Points per chunk of the parallel passes. Part of the determinism
/// contract: randomised steps draw one stream per chunk, so changing it
/// changes seeded outputs.
pub(crate) const CHUNK: usize = 16_384;

/// What a random stream is used for (the high bits of the stream id).
#[derive(Debug, Clone, Copy)]
#[repr(u64)]
pub(crate) enum Purpose {
    /// Soft-edge survival draws, one per point.
    SoftEdge = 1,
    /// Gaussian range noise, one per kept point.
    RangeNoise = 2,
    /// Near-range returns: counts, laws and rays.
    NearRange = 3,
    /// Survival draws of the extension path, one per point.
    Extension = 4,
}

/// The per-scan seed: SHA-256 over the master seed and the scan key.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct ScanSeed([u8; 32]);

impl ScanSeed {
    /// Derives the seed of scan `key` under master `seed` (murk's one
    /// derivation, [`murk_types::seed::derive`]).
    pub(crate) fn new(seed: u64, key: &str) -> Self {
        use murk_types::seed::{Purpose, derive};
        ScanSeed(derive(seed, key, Purpose::ApplyScan).bytes())
    }

    /// The generator of `purpose` for chunk `chunk`.
    pub(crate) fn rng(self, purpose: Purpose, chunk: u64) -> ChaCha8Rng {
        let mut rng = ChaCha8Rng::from_seed(self.0);
        rng.set_stream(((purpose as u64) << 48) | (chunk & ((1 << 48) - 1)));
        rng
    }
}

/// Standard normal CDF Φ(x).
pub(crate) fn norm_cdf(x: f64) -> f64 {
    0.5 * libm::erfc(-x / std::f64::consts::SQRT_2)
}

/// Standard normal quantile Φ⁻¹(p) for p in (0, 1).
///
/// Hand-written because neither rand_distr nor libm provides the inverse
/// normal CDF: Acklam's rational approximation (relative error < 1.2e-9)
/// refined by one Halley step on `erfc`, which brings it to f64 precision.
pub(crate) fn norm_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    if p <= 0.0 {
        return f64::NEG_INFINITY;
    }
    if p >= 1.0 {
        return f64::INFINITY;
    }
    const P_LOW: f64 = 0.024_25;
    let x = if p < P_LOW {
        let q = (-2.0 * p.ln()).sqrt();
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    } else if p <= 1.0 - P_LOW {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    } else {
        let q = (-2.0 * (1.0 - p).ln()).sqrt();
        -(((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    // One Halley step.
    let e = norm_cdf(x) - p;
    let u = e * (2.0 * std::f64::consts::PI).sqrt() * (x * x / 2.0).exp();
    x - u / (1.0 + x * u / 2.0)
}

/// A normal law `N(mean, std²)` truncated to `[lower, upper]`, sampled by
/// inverting the CDF (one uniform per draw, whatever the truncation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct TruncNormal {
    mean: f64,
    std: f64,
    /// Standardised bounds, flipped so that the interval leans to the lower
    /// tail, where Φ keeps its relative precision.
    a: f64,
    b: f64,
    flip: bool,
    pa: f64,
    pb: f64,
}

impl TruncNormal {
    /// The law; `lower < upper` and `std > 0` are checked by the caller.
    pub(crate) fn new(mean: f64, std: f64, lower: f64, upper: f64) -> Self {
        let (mut a, mut b) = ((lower - mean) / std, (upper - mean) / std);
        let flip = a + b > 0.0;
        if flip {
            (a, b) = (-b, -a);
        }
        TruncNormal {
            mean,
            std,
            a,
            b,
            flip,
            pa: norm_cdf(a),
            pb: norm_cdf(b),
        }
    }

    /// Lower bound of the support.
    pub(crate) fn lower(&self) -> f64 {
        self.mean + self.std * if self.flip { -self.b } else { self.a }
    }

    /// Upper bound of the support.
    pub(crate) fn upper(&self) -> f64 {
        self.mean + self.std * if self.flip { -self.a } else { self.b }
    }

    /// One draw.
    pub(crate) fn sample(&self, rng: &mut ChaCha8Rng) -> f64 {
        let u: f64 = rng.random();
        self.at(u)
    }

    /// The value at probability fraction `t` in `[0, 1]` of the truncated
    /// mass (the quantile; [`TruncNormal::sample`] at a uniform `t`).
    pub(crate) fn at(&self, t: f64) -> f64 {
        let z = if self.pb > self.pa {
            norm_quantile(self.pa + t * (self.pb - self.pa)).clamp(self.a, self.b)
        } else {
            // Both bounds so deep in the tail that Φ underflows: the law is
            // concentrated at the bound nearest to the mean.
            self.b
        };
        let z = if self.flip { -z } else { z };
        (self.mean + self.std * z).clamp(self.lower(), self.upper())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantile_inverts_cdf_to_1e12() {
        for &p in &[
            1e-300,
            1e-12,
            1e-6,
            0.01,
            0.02425,
            0.3,
            0.5,
            0.7,
            0.99,
            1.0 - 1e-9,
        ] {
            let x = norm_quantile(p);
            let back = norm_cdf(x);
            assert!(((back - p) / p).abs() < 1e-10, "p {p} x {x} back {back}");
        }
        assert!((norm_quantile(0.975) - 1.959_963_984_540_054).abs() < 1e-12);
    }

    #[test]
    fn truncated_normal_stays_inside_and_has_the_known_mean() {
        // N(4.113, 11.533²) truncated to [0, 255] (the seed's fog ghost
        // reflectivity): mean = μ + σ·φ(α)/(1 − Φ(α)) with α = −μ/σ
        // (upper bound negligible).
        let law = TruncNormal::new(4.113, 11.533, 0.0, 255.0);
        let seed = ScanSeed::new(1, "t");
        let mut rng = seed.rng(Purpose::NearRange, 0);
        let n = 200_000;
        let mut sum = 0.0;
        for _ in 0..n {
            let x = law.sample(&mut rng);
            assert!((0.0..=255.0).contains(&x));
            sum += x;
        }
        let alpha: f64 = -4.113 / 11.533;
        let phi = (-alpha * alpha / 2.0).exp() / (2.0 * std::f64::consts::PI).sqrt();
        let expected = 4.113 + 11.533 * phi / (1.0 - norm_cdf(alpha));
        // Standard error ≈ 8/sqrt(2e5) ≈ 0.02; allow 5 of them.
        assert!(
            (sum / n as f64 - expected).abs() < 0.1,
            "{} vs {expected}",
            sum / n as f64
        );
    }

    #[test]
    fn far_tail_truncation_does_not_hang_or_escape() {
        let law = TruncNormal::new(0.0, 1.0, 40.0, 41.0);
        let mut rng = ScanSeed::new(1, "t").rng(Purpose::NearRange, 0);
        for _ in 0..100 {
            let x = law.sample(&mut rng);
            assert!((40.0..=41.0).contains(&x), "{x}");
        }
    }

    #[test]
    fn streams_differ_by_purpose_chunk_and_key() {
        let s = ScanSeed::new(7, "a.bin");
        let draw = |mut r: ChaCha8Rng| r.random::<u64>();
        let base = draw(s.rng(Purpose::RangeNoise, 0));
        assert_eq!(base, draw(s.rng(Purpose::RangeNoise, 0)));
        assert_ne!(base, draw(s.rng(Purpose::RangeNoise, 1)));
        assert_ne!(base, draw(s.rng(Purpose::SoftEdge, 0)));
        assert_ne!(
            base,
            draw(ScanSeed::new(7, "b.bin").rng(Purpose::RangeNoise, 0))
        );
        assert_ne!(
            base,
            draw(ScanSeed::new(8, "a.bin").rng(Purpose::RangeNoise, 0))
        );
    }
}
