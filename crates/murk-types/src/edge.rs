//! The soft survival edge: the one definition of the edge law that `fit`
//! fits, `infer` applies and `murk diagnose` evaluates.
//!
//! A clear return at range `r`, in weather whose vanishing distance for the
//! return's band is `D`, is kept with probability
//!
//! ```text
//! P(kept) = π + (1 − ε − π) · S(z),   z = (r − D) / (w · D)
//! ```
//!
//! with `S = 1 − F` the survival function of a **unit-variance** CDF `F`
//! ([`EdgeShape`]), `w` the relative edge width, `ε` the dropout well inside
//! `D` and `π` the residual survival far beyond it. Both shapes have unit
//! standard deviation, so `w` means the same thing (the edge's standard
//! deviation relative to `D`) whichever is chosen, and `D` is the 50 %
//! point of `S`:
//!
//! - probit: `S(z) = 1 − Φ(z)`;
//! - logistic: `S(z) = 1 / (1 + exp(z·π/√3))` (the standard logistic has
//!   variance π²/3; the factor π/√3 brings it to one).
//!
//! Tables store the shape as its lower-case name (`"probit"`,
//! `"logistic"`), as they always have.

use std::f64::consts::{PI, SQRT_2};
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// `π/√3`: the scale that gives the logistic distribution unit variance.
pub const LOGISTIC_UNIT: f64 = PI / 1.732_050_807_568_877_2;

/// Shape of the soft survival edge (see the module docs of `murk_types::edge`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum EdgeShape {
    /// Standard normal CDF.
    #[serde(alias = "normal")]
    Probit,
    /// Logistic CDF with unit variance, `1 / (1 + exp(−z·π/√3))`.
    #[serde(alias = "logit")]
    Logistic,
}

impl EdgeShape {
    /// Lower-case name as written in the table.
    pub fn name(self) -> &'static str {
        match self {
            EdgeShape::Probit => "probit",
            EdgeShape::Logistic => "logistic",
        }
    }

    /// The unit-variance CDF `F(z)`, accurate in its lower tail.
    #[inline]
    pub fn cdf(self, z: f64) -> f64 {
        self.sf(-z)
    }

    /// The survival function `S(z) = 1 − F(z)`, accurate in its upper tail.
    #[inline]
    pub fn sf(self, z: f64) -> f64 {
        match self {
            EdgeShape::Probit => 0.5 * libm::erfc(z / SQRT_2),
            EdgeShape::Logistic => {
                let t = z * LOGISTIC_UNIT;
                if t >= 0.0 {
                    let e = libm::exp(-t);
                    e / (1.0 + e)
                } else {
                    1.0 / (1.0 + libm::exp(t))
                }
            }
        }
    }

    /// `(S(z), F(z))`, each accurate in its own tail: the same bits as
    /// `(self.sf(z), self.cdf(z))`, from one `erfc` where that gives them.
    ///
    /// Why not two calls: the survival fit evaluates both tails at every
    /// histogram bin of every likelihood evaluation, and `erfc` (two `exp`
    /// beyond `|x| ≥ 0.84375`) was most of a fit's time. In that range
    /// libm's `erfc` computes one value `e` from `|x|` and returns `e` for
    /// `x > 0`, `2 − e` for `x < 0`; so the other tail
    /// `0.5·(2 − e)` equals `1 − 0.5·e` bit for bit (halving is exact, and
    /// `2 − e` and `1 − e/2` round alike, one binade apart). Inside that
    /// range, where `erfc` is a rational function without `exp`, both are
    /// evaluated. A test checks the bits against the two calls.
    #[inline]
    pub fn tails(self, z: f64) -> (f64, f64) {
        match self {
            EdgeShape::Probit => {
                let x = z / SQRT_2;
                if x.abs() >= 0.84375 {
                    let near = 0.5 * libm::erfc(x.abs());
                    let far = 1.0 - near;
                    if x > 0.0 { (near, far) } else { (far, near) }
                } else {
                    (self.sf(z), self.cdf(z))
                }
            }
            EdgeShape::Logistic => (self.sf(z), self.cdf(z)),
        }
    }

    /// The standardised distance `z = (r − D)/(w·D)` of range `range_m` from
    /// the vanishing distance `distance_m` with relative width `width`.
    #[inline]
    pub fn z(range_m: f64, distance_m: f64, width: f64) -> f64 {
        (range_m - distance_m) / (width * distance_m)
    }

    /// `P(kept) = π + (1 − ε − π)·S(z)` at standardised distance `z`, with
    /// dropout `ε` and residual survival `π`.
    #[inline]
    pub fn keep_probability(self, z: f64, dropout: f64, residual: f64) -> f64 {
        residual + (1.0 - dropout - residual) * self.sf(z)
    }
}

impl std::fmt::Display for EdgeShape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for EdgeShape {
    type Err = String;
    /// Parses `probit` (or `normal`) and `logistic` (or `logit`), any case.
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "probit" | "normal" => Ok(EdgeShape::Probit),
            "logistic" | "logit" => Ok(EdgeShape::Logistic),
            _ => Err(format!("edge {s:?} is not probit or logistic")),
        }
    }
}

/// The relative edge width with a MOR reading variance `v` (in `ln MOR`)
/// taken out: `√(max(w² − v, 0))` — the one owner of this correction (the
/// fit writes `edge_width_corrected` with it, `murk diagnose` recomputes
/// it when a term rescales the width).
///
/// A fit sees returns at `r / MOR'` with `MOR' = MOR·e^e`, `e ~ N(0, v)`
/// per recording, so a probit edge of width `w` at the true MOR shows as
/// one of width `√(w² + v)` (to first order in `e`; for the logistic edge,
/// whose convolution with a normal is close to but not exactly logistic,
/// approximately).
///
/// ```
/// let (w, v) = (0.08f64, 0.0028);
/// let seen = (w * w + v).sqrt();
/// assert!((murk_types::deconvolve_edge_width(seen, v) - w).abs() < 1e-12);
/// assert_eq!(murk_types::deconvolve_edge_width(0.03, v), 0.0);
/// ```
pub fn deconvolve_edge_width(w: f64, v: f64) -> f64 {
    (w * w - v).max(0.0).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tails_are_the_same_bits_as_sf_and_cdf() {
        let mut zs: Vec<f64> = (-40_000..=40_000).map(|i| i as f64 * 1e-3).collect();
        // Around erfc's branch point |z/√2| = 0.84375, ulp by ulp.
        let b = 0.84375 * SQRT_2;
        for c in [b, -b] {
            let mut x = c;
            for _ in 0..64 {
                x = f64::from_bits(x.to_bits() - 1);
            }
            for _ in 0..128 {
                zs.push(x);
                x = f64::from_bits(x.to_bits() + 1);
            }
        }
        zs.extend([
            0.0,
            -0.0,
            1e-300,
            -1e-300,
            39.0,
            -39.0,
            1e6,
            -1e6,
            f64::MAX,
            f64::MIN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ]);
        let mut g = 0x2545_f491_4f6c_dd1d_u64;
        for _ in 0..100_000 {
            g ^= g << 13;
            g ^= g >> 7;
            g ^= g << 17;
            zs.push((g >> 11) as f64 / (1u64 << 53) as f64 * 80.0 - 40.0);
        }
        for e in [EdgeShape::Probit, EdgeShape::Logistic] {
            for &z in &zs {
                let (s, f) = e.tails(z);
                assert_eq!(
                    (s.to_bits(), f.to_bits()),
                    (e.sf(z).to_bits(), e.cdf(z).to_bits()),
                    "{e} at z = {z:e}"
                );
            }
            let (s, f) = e.tails(f64::NAN);
            assert!(s.is_nan() && f.is_nan());
        }
    }

    #[test]
    fn probit_known_values() {
        // Tables: Φ(1) = 0.8413447461, Φ(1.959964) = 0.975.
        assert!((EdgeShape::Probit.sf(1.0) - 0.158_655_253_9).abs() < 1e-10);
        assert!((EdgeShape::Probit.cdf(1.959_963_985) - 0.975).abs() < 1e-9);
        // Deep tail stays positive: 1 − Φ(10) = 7.6199e−24.
        assert!((EdgeShape::Probit.sf(10.0) / 7.619_853e-24 - 1.0).abs() < 1e-5);
    }

    #[test]
    fn logistic_known_values() {
        // π/√3 = 1.813799364234217850…; S(1) = 1/(1+e^1.8138) = 0.1401795649…
        assert!((LOGISTIC_UNIT - 1.813_799_364_234_217_9).abs() < 1e-15);
        let s1 = EdgeShape::Logistic.sf(1.0);
        assert!((s1 - 0.140_179_564_9).abs() < 1e-9, "{s1}");
        assert!((EdgeShape::Logistic.sf(0.0) - 0.5).abs() < 1e-15);
        assert!((EdgeShape::Logistic.cdf(1.0) - (1.0 - s1)).abs() < 1e-15);
        // Tails: S(30) = e^{−54.414} to relative precision.
        let s30 = EdgeShape::Logistic.sf(30.0);
        assert!((s30 / (-30.0 * LOGISTIC_UNIT).exp() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn logistic_has_unit_variance() {
        // ∫ z² f(z) dz by the trapezoid rule on the density −dS/dz.
        let (h, mut var) = (1e-3, 0.0);
        let mut z = -40.0;
        while z < 40.0 {
            let f = (EdgeShape::Logistic.sf(z) - EdgeShape::Logistic.sf(z + h)) / h;
            let m = z + 0.5 * h;
            var += m * m * f * h;
            z += h;
        }
        assert!((var - 1.0).abs() < 1e-4, "{var}");
    }

    #[test]
    fn keep_probability_known_answer() {
        // Logistic, w = 0.1, D = 100 m, r = 110 m: z = 1; ε = 0.02,
        // π = 0.01: 0.01 + 0.97 · 0.1401795649 = 0.1459741779.
        let z = EdgeShape::z(110.0, 100.0, 0.1);
        assert!((z - 1.0).abs() < 1e-12);
        let p = EdgeShape::Logistic.keep_probability(z, 0.02, 0.01);
        assert!((p - 0.145_974_177_9).abs() < 1e-9, "{p}");
        // At D the probability is halfway between π and 1 − ε.
        let p = EdgeShape::Probit.keep_probability(0.0, 0.02, 0.01);
        assert!((p - 0.495).abs() < 1e-15);
    }

    #[test]
    fn names_round_trip_and_old_strings_parse() {
        for e in [EdgeShape::Probit, EdgeShape::Logistic] {
            assert_eq!(e.name().parse::<EdgeShape>().unwrap(), e);
            let j = serde_json::to_string(&e).unwrap();
            assert_eq!(j, format!("\"{}\"", e.name()));
            assert_eq!(serde_json::from_str::<EdgeShape>(&j).unwrap(), e);
        }
        assert_eq!("Normal".parse::<EdgeShape>().unwrap(), EdgeShape::Probit);
        assert_eq!("logit".parse::<EdgeShape>().unwrap(), EdgeShape::Logistic);
        assert!("cauchy".parse::<EdgeShape>().is_err());
        assert!(serde_json::from_str::<EdgeShape>("\"cauchy\"").is_err());
    }
}
