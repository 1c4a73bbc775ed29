//! Standard CDFs and their tails (the survival edge's law lives in
//! `murk_types::EdgeShape`), on `libm` so that results do not depend on
//! the platform's C library.

use std::f64::consts::SQRT_2;

/// Standard normal CDF Φ(z).
#[inline]
pub fn normal_cdf(z: f64) -> f64 {
    0.5 * libm::erfc(-z / SQRT_2)
}

/// Standard normal survival 1 − Φ(z), accurate in the upper tail.
#[cfg(test)]
#[inline]
pub fn normal_sf(z: f64) -> f64 {
    0.5 * libm::erfc(z / SQRT_2)
}

/// The logistic function 1 / (1 + e^(−x)).
#[inline]
pub fn sigmoid(x: f64) -> f64 {
    if x >= 0.0 {
        1.0 / (1.0 + libm::exp(-x))
    } else {
        let e = libm::exp(x);
        e / (1.0 + e)
    }
}

/// ln(p / (1 − p)).
#[inline]
pub fn logit(p: f64) -> f64 {
    (p / (1.0 - p)).ln()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_known_values() {
        // Tables: Φ(1.959964) = 0.975, Φ(−1) = 0.1586553.
        assert!((normal_cdf(1.959_963_985) - 0.975).abs() < 1e-9);
        assert!((normal_cdf(-1.0) - 0.158_655_254).abs() < 1e-9);
        assert!((normal_sf(1.0) - 0.158_655_254).abs() < 1e-9);
        // Deep tail stays positive: 1 − Φ(10) = 7.6199e−24.
        assert!((normal_sf(10.0) / 7.619_853e-24 - 1.0).abs() < 1e-5);
    }

    #[test]
    fn logit_inverts_sigmoid() {
        assert!((sigmoid(logit(0.3)) - 0.3).abs() < 1e-15);
        assert!((sigmoid(0.0) - 0.5).abs() < 1e-15);
    }
}
