//! The vanishing-distance law: the one definition of how far a return of a
//! reflectivity band reaches in weather of a given MOR, which `fit` fits,
//! `infer` applies and `murk diagnose` evaluates (beside [`crate::EdgeShape`],
//! the one owner of the edge's shape around that distance).
//!
//! ```text
//! linear (the seed's law):  D = s · MOR · ρ
//! power (a law that bends): D = a · MOR^b · ρ
//! ```
//!
//! with `ρ` the sensor's range scale. `b = 1` is the linear law with
//! `s = a`. A power law with `b < 1` reaches relatively further in dense
//! fog than in light fog, as the lidar equation in fog predicts (the hard
//! echo fades as `exp(−2αR)/R²` while the fog's own echo grows with β).
//!
//! Every consumer goes through [`VanishingLaw::distance_m`] or
//! [`VanishingLaw::effective_slope`] (the slope of the line through the
//! origin that gives the same distance at that MOR, which is what an applier
//! built for the linear law needs), so a table's law is applied the same way
//! everywhere. Tables store it as `{"kind": "power", "a": …, "b": …}`; a band
//! without a `law` field has the linear law of its `slope`.

use serde::{Deserialize, Serialize};

/// How the vanishing distance of a band depends on MOR.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum VanishingLaw {
    /// `D = slope · MOR · range_scale` (the seed's law).
    Linear {
        /// Vanishing slope (dimensionless).
        slope: f64,
    },
    /// `D = a · MOR^b · range_scale` (MOR in metres, so `a` has the unit
    /// m^(1−b)).
    Power {
        /// Coefficient `a`.
        a: f64,
        /// Exponent `b` (1 is the linear law).
        b: f64,
    },
}

impl VanishingLaw {
    /// The vanishing distance in metres at `mor_m` for a sensor of range
    /// scale `range_scale`.
    #[inline]
    pub fn distance_m(&self, mor_m: f64, range_scale: f64) -> f64 {
        self.effective_slope(mor_m) * mor_m * range_scale
    }

    /// The slope `D / (MOR · range_scale)` at `mor_m`: the slope itself for
    /// the linear law, `a · MOR^(b−1)` for the power law.
    #[inline]
    pub fn effective_slope(&self, mor_m: f64) -> f64 {
        match *self {
            VanishingLaw::Linear { slope } => slope,
            VanishingLaw::Power { a, b } => a * mor_m.powf(b - 1.0),
        }
    }

    /// The exponent of MOR (1 for the linear law).
    pub fn exponent(&self) -> f64 {
        match *self {
            VanishingLaw::Linear { .. } => 1.0,
            VanishingLaw::Power { b, .. } => b,
        }
    }

    /// Why the law cannot be applied, if it cannot: its numbers must be
    /// finite, the slope or `a` positive.
    pub fn check(&self) -> Result<(), String> {
        match *self {
            VanishingLaw::Linear { slope } if !(slope.is_finite() && slope > 0.0) => {
                Err(format!("slope {slope} must be finite and > 0"))
            }
            VanishingLaw::Power { a, b } if !(a.is_finite() && a > 0.0 && b.is_finite()) => {
                Err(format!("a {a} must be finite and > 0, b {b} finite"))
            }
            _ => Ok(()),
        }
    }

    /// Short text for summaries: `0.303·MOR` or `1.52·MOR^0.74`.
    pub fn describe(&self) -> String {
        match *self {
            VanishingLaw::Linear { slope } => format!("{slope:.4}·MOR"),
            VanishingLaw::Power { a, b } => format!("{a:.4}·MOR^{b:.3}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn power_law_with_exponent_one_is_the_line() {
        let l = VanishingLaw::Linear { slope: 0.3 };
        let p = VanishingLaw::Power { a: 0.3, b: 1.0 };
        for m in [10.0, 60.0, 400.0] {
            assert!((l.distance_m(m, 1.1) - p.distance_m(m, 1.1)).abs() < 1e-12);
        }
    }

    #[test]
    fn known_answers() {
        // 2 · 100^0.5 = 20 m, range scale 1.5: 30 m; effective slope 0.2.
        let p = VanishingLaw::Power { a: 2.0, b: 0.5 };
        assert!((p.distance_m(100.0, 1.5) - 30.0).abs() < 1e-12);
        assert!((p.effective_slope(100.0) - 0.2).abs() < 1e-15);
        assert_eq!(p.exponent(), 0.5);
        assert!(p.check().is_ok());
        assert!(VanishingLaw::Power { a: -1.0, b: 1.0 }.check().is_err());
        assert!(VanishingLaw::Linear { slope: f64::NAN }.check().is_err());
    }

    #[test]
    fn json_layout() {
        let p = VanishingLaw::Power { a: 1.5, b: 0.75 };
        let j = serde_json::to_string(&p).unwrap();
        assert_eq!(j, r#"{"kind":"power","a":1.5,"b":0.75}"#);
        assert_eq!(serde_json::from_str::<VanishingLaw>(&j).unwrap(), p);
        let l: VanishingLaw = serde_json::from_str(r#"{"kind":"linear","slope":0.3}"#).unwrap();
        assert_eq!(l, VanishingLaw::Linear { slope: 0.3 });
    }
}
