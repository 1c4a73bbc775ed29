//! The vanishing-distance law: the one definition of how far a return of a
//! reflectivity band reaches in weather of a given MOR, which `fit` fits,
//! `infer` applies and `murk diagnose` evaluates (beside [`crate::EdgeShape`],
//! the one owner of the edge's shape around that distance).
//!
//! ```text
//! linear (the seed's law):  D = s · MOR · ρ
//! power (a law that bends): D = a · MOR^b · ρ
//! with reflectivity:        D = a · MOR^b · ρ · (max(x, x₀) / x_ref)^k
//! k varying with MOR:       k = k₀ + g · ln(MOR / M_ref)
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
//! everywhere; a consumer that knows the return's calibrated reflectivity
//! `x` multiplies by [`VanishingLaw::reflectivity_factor`] (1 for a law
//! without a reflectivity term). Tables store it as
//! `{"kind": "power", "a": …, "b": …}`, with
//! `"reflectivity": {"exponent": k, "reference": x_ref, "floor": x₀}` when the
//! distance also grows with reflectivity inside the band (the lidar
//! equation in fog gives each return its own distance by its reflectivity:
//! the hard echo `∝ x·exp(−2αR)/R²` must outlast the fog's own echo), and
//! `"exponent_per_ln_mor": g, "mor_reference_m": M_ref` in it when that
//! exponent changes with MOR (the same equation gives
//! `k = 1/(2αR₅₀ + 2)`, which grows as `R₅₀/MOR` shrinks with MOR); a band
//! without a `law` field has the linear law of its `slope`.
//!
//! ```
//! use murk_types::{ReflectivityDependence, VanishingLaw};
//! let law = VanishingLaw::Power {
//!     a: 2.0,
//!     b: 0.5,
//!     reflectivity: Some(ReflectivityDependence {
//!         exponent: 0.5,
//!         reference: 16.0,
//!         floor: 1.0,
//!         edge_width: None,
//!         exponent_per_ln_mor: None,
//!         mor_reference_m: None,
//!     }),
//! };
//! // 2·100^0.5 = 20 m at the reference reflectivity; four times as
//! // reflective reaches twice as far.
//! assert!((law.distance_m(100.0, 1.0) - 20.0).abs() < 1e-12);
//! assert!((law.distance_m(100.0, 1.0) * law.reflectivity_factor(64.0, 100.0) - 40.0).abs() < 1e-12);
//! ```

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
        /// How the distance grows with reflectivity inside the band (`None`:
        /// one distance for the whole band).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        reflectivity: Option<ReflectivityDependence>,
    },
}

/// The factor `(max(x, floor) / reference)^k` by which a return of
/// calibrated reflectivity `x` reaches further than the band's distance at
/// its reference reflectivity; `k = exponent + exponent_per_ln_mor ·
/// ln(MOR / mor_reference_m)` when the exponent changes with MOR
/// ([`ReflectivityDependence::at_mor`] gives the term at one MOR).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ReflectivityDependence {
    /// Exponent `k` of reflectivity.
    pub exponent: f64,
    /// Reflectivity at which the factor is 1 (the band's returns'
    /// geometric mean, as fitted).
    pub reference: f64,
    /// Reflectivities below count as this one (a reflectivity of 0 would
    /// otherwise vanish at once).
    pub floor: f64,
    /// The relative edge width fitted with the term, which appliers use in
    /// place of the band's `edge_width`: the band's is the line's, which
    /// also holds the spread of the band's reflectivities that the term
    /// now places. `None`: the band's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edge_width: Option<f64>,
    /// How much `k` grows per unit of `ln MOR` (`g`); `None`: one `k` at
    /// every MOR.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exponent_per_ln_mor: Option<f64>,
    /// The MOR, metres, at which `k` is `exponent` (with
    /// `exponent_per_ln_mor`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mor_reference_m: Option<f64>,
}

impl ReflectivityDependence {
    /// The factor at calibrated reflectivity `x` (a NaN `x` counts as the
    /// floor) with the exponent `exponent`: the term's factor at
    /// `mor_reference_m` when the exponent changes with MOR; use
    /// [`ReflectivityDependence::at_mor`] first for another MOR.
    #[inline]
    pub fn factor(&self, x: f64) -> f64 {
        (x.max(self.floor) / self.reference).powf(self.exponent)
    }

    /// The exponent `k` at `mor_m`.
    #[inline]
    pub fn exponent_at(&self, mor_m: f64) -> f64 {
        match (self.exponent_per_ln_mor, self.mor_reference_m) {
            (Some(g), Some(m)) => self.exponent + g * (mor_m / m).ln(),
            _ => self.exponent,
        }
    }

    /// The term at one MOR: its exponent there, constant in MOR (what an
    /// applier at `mor_m` uses).
    pub fn at_mor(&self, mor_m: f64) -> ReflectivityDependence {
        ReflectivityDependence {
            exponent: self.exponent_at(mor_m),
            exponent_per_ln_mor: None,
            mor_reference_m: None,
            ..*self
        }
    }

    /// Why the term cannot be applied, if it cannot.
    pub fn check(&self) -> Result<(), String> {
        if !(self.exponent.is_finite()
            && self.reference.is_finite()
            && self.reference > 0.0
            && self.floor.is_finite()
            && self.floor > 0.0
            && self.edge_width.is_none_or(|w| w.is_finite() && w > 0.0))
        {
            return Err(format!(
                "reflectivity exponent {}, reference {}, floor {}, edge width {:?}: the exponent must be finite, the reference, floor and edge width finite and > 0",
                self.exponent, self.reference, self.floor, self.edge_width
            ));
        }
        match (self.exponent_per_ln_mor, self.mor_reference_m) {
            (None, None) => Ok(()),
            (Some(g), Some(m)) if g.is_finite() && m.is_finite() && m > 0.0 => Ok(()),
            (g, m) => Err(format!(
                "reflectivity exponent_per_ln_mor {g:?}, mor_reference_m {m:?}: both or neither, the first finite, the second finite and > 0"
            )),
        }
    }
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
            VanishingLaw::Power { a, b, .. } => a * mor_m.powf(b - 1.0),
        }
    }

    /// The reflectivity term, if the law has one.
    pub fn reflectivity(&self) -> Option<ReflectivityDependence> {
        match *self {
            VanishingLaw::Power { reflectivity, .. } => reflectivity,
            VanishingLaw::Linear { .. } => None,
        }
    }

    /// How much further than [`VanishingLaw::distance_m`] at `mor_m` a
    /// return of calibrated reflectivity `x` reaches (1 without a
    /// reflectivity term).
    #[inline]
    pub fn reflectivity_factor(&self, x: f64, mor_m: f64) -> f64 {
        self.reflectivity()
            .map_or(1.0, |r| r.at_mor(mor_m).factor(x))
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
            VanishingLaw::Power { a, b, .. } if !(a.is_finite() && a > 0.0 && b.is_finite()) => {
                Err(format!("a {a} must be finite and > 0, b {b} finite"))
            }
            VanishingLaw::Power {
                reflectivity: Some(r),
                ..
            } => r.check(),
            _ => Ok(()),
        }
    }

    /// Short text for summaries: `0.303·MOR` or `1.52·MOR^0.74`.
    pub fn describe(&self) -> String {
        match *self {
            VanishingLaw::Linear { slope } => format!("{slope:.4}·MOR"),
            VanishingLaw::Power {
                a,
                b,
                reflectivity: None,
            } => format!("{a:.4}·MOR^{b:.3}"),
            VanishingLaw::Power {
                a,
                b,
                reflectivity: Some(r),
            } => match (r.exponent_per_ln_mor, r.mor_reference_m) {
                (Some(g), Some(m)) => format!(
                    "{a:.4}·MOR^{b:.3}·(x/{:.3})^({:.3}{:+.3}·ln(MOR/{m:.1}))",
                    r.reference, r.exponent, g
                ),
                _ => format!("{a:.4}·MOR^{b:.3}·(x/{:.3})^{:.3}", r.reference, r.exponent),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn power_law_with_exponent_one_is_the_line() {
        let l = VanishingLaw::Linear { slope: 0.3 };
        let p = VanishingLaw::Power {
            a: 0.3,
            b: 1.0,
            reflectivity: None,
        };
        for m in [10.0, 60.0, 400.0] {
            assert!((l.distance_m(m, 1.1) - p.distance_m(m, 1.1)).abs() < 1e-12);
        }
    }

    #[test]
    fn known_answers() {
        // 2 · 100^0.5 = 20 m, range scale 1.5: 30 m; effective slope 0.2.
        let p = VanishingLaw::Power {
            a: 2.0,
            b: 0.5,
            reflectivity: None,
        };
        assert!((p.distance_m(100.0, 1.5) - 30.0).abs() < 1e-12);
        assert!((p.effective_slope(100.0) - 0.2).abs() < 1e-15);
        assert_eq!(p.exponent(), 0.5);
        assert!(p.check().is_ok());
        assert!(
            VanishingLaw::Power {
                a: -1.0,
                b: 1.0,
                reflectivity: None
            }
            .check()
            .is_err()
        );
        assert!(VanishingLaw::Linear { slope: f64::NAN }.check().is_err());
    }

    #[test]
    fn json_layout() {
        let p = VanishingLaw::Power {
            a: 1.5,
            b: 0.75,
            reflectivity: None,
        };
        let j = serde_json::to_string(&p).unwrap();
        assert_eq!(j, r#"{"kind":"power","a":1.5,"b":0.75}"#);
        assert_eq!(serde_json::from_str::<VanishingLaw>(&j).unwrap(), p);
        let l: VanishingLaw = serde_json::from_str(r#"{"kind":"linear","slope":0.3}"#).unwrap();
        assert_eq!(l, VanishingLaw::Linear { slope: 0.3 });
    }

    #[test]
    fn reflectivity_term_known_answers_and_layout() {
        let r = ReflectivityDependence {
            exponent: 0.25,
            reference: 20.0,
            floor: 2.0,
            edge_width: None,
            exponent_per_ln_mor: None,
            mor_reference_m: None,
        };
        let p = VanishingLaw::Power {
            a: 1.0,
            b: 1.0,
            reflectivity: Some(r),
        };
        // 16 times the reference: twice as far; at or below the floor the
        // floor's factor (2/20)^0.25; NaN counts as the floor.
        assert!((p.reflectivity_factor(320.0, 30.0) - 2.0).abs() < 1e-12);
        let f0 = 0.1f64.powf(0.25);
        assert!((p.reflectivity_factor(0.0, 30.0) - f0).abs() < 1e-12);
        assert!((p.reflectivity_factor(f64::NAN, 30.0) - f0).abs() < 1e-12);
        assert_eq!(p.reflectivity_factor(20.0, 30.0), 1.0);
        assert_eq!(
            VanishingLaw::Linear { slope: 0.3 }.reflectivity_factor(5.0, 30.0),
            1.0
        );
        assert!(p.check().is_ok());
        let bad = VanishingLaw::Power {
            a: 1.0,
            b: 1.0,
            reflectivity: Some(ReflectivityDependence { floor: 0.0, ..r }),
        };
        assert!(bad.check().is_err());
        let j = serde_json::to_string(&p).unwrap();
        assert_eq!(
            j,
            r#"{"kind":"power","a":1.0,"b":1.0,"reflectivity":{"exponent":0.25,"reference":20.0,"floor":2.0}}"#
        );
        assert_eq!(serde_json::from_str::<VanishingLaw>(&j).unwrap(), p);
        assert!(
            p.describe().contains("(x/20.000)^0.250"),
            "{}",
            p.describe()
        );
    }

    #[test]
    fn an_exponent_that_changes_with_mor_known_answers_and_layout() {
        let r = ReflectivityDependence {
            exponent: 0.15,
            reference: 10.0,
            floor: 1.0,
            edge_width: None,
            exponent_per_ln_mor: Some(0.05),
            mor_reference_m: Some(20.0),
        };
        // k = 0.15 at 20 m, 0.15 + 0.05·ln 4 at 80 m.
        assert_eq!(r.exponent_at(20.0), 0.15);
        let k80 = 0.15 + 0.05 * 4f64.ln();
        assert!((r.exponent_at(80.0) - k80).abs() < 1e-15);
        let at = r.at_mor(80.0);
        assert_eq!((at.exponent_per_ln_mor, at.mor_reference_m), (None, None));
        assert!((at.factor(40.0) - 4f64.powf(k80)).abs() < 1e-12);
        let p = VanishingLaw::Power {
            a: 1.0,
            b: 1.0,
            reflectivity: Some(r),
        };
        assert!((p.reflectivity_factor(40.0, 80.0) - 4f64.powf(k80)).abs() < 1e-12);
        assert!((p.reflectivity_factor(40.0, 20.0) - 4f64.powf(0.15)).abs() < 1e-12);
        assert!(p.check().is_ok());
        assert!(p.describe().contains("ln(MOR/20.0)"), "{}", p.describe());
        let j = serde_json::to_string(&p).unwrap();
        assert!(
            j.contains(r#""exponent_per_ln_mor":0.05,"mor_reference_m":20.0"#),
            "{j}"
        );
        assert_eq!(serde_json::from_str::<VanishingLaw>(&j).unwrap(), p);
        // Both or neither, and a reference MOR above 0.
        for (g, m) in [
            (Some(0.05), None),
            (None, Some(20.0)),
            (Some(0.05), Some(0.0)),
        ] {
            let bad = ReflectivityDependence {
                exponent_per_ln_mor: g,
                mor_reference_m: m,
                ..r
            };
            assert!(bad.check().is_err(), "{g:?} {m:?}");
        }
    }
}
