//! Intensity scales: how a sensor's raw intensity maps onto calibrated
//! VLP-16 reflectivity.
//!
//! Every reflectivity band in murk (the seed report's "reflectivity < 10"
//! rule, the bands of a coefficient table) is expressed in **calibrated
//! VLP-16 reflectivity**: 0–100 for diffuse targets (percent of a white
//! Lambertian reflector), 101–255 for retro-reflectors. Sensors and datasets
//! store intensity differently, so each cloud carries its scale and readers
//! set it from the format (or from `campaign.toml` / a CLI flag, which win):
//!
//! | name | raw range | to calibrated | typical source |
//! |---|---|---|---|
//! | `calibrated`, `vlp16` | 0–255 | identity | VLP-16 pcap, campaign PCD/CSV/Parquet |
//! | `nuscenes`, `byte` | 0–255 | identity | nuScenes `.pcd.bin` (HDL-32E, same 8-bit convention) |
//! | `kitti`, `unit` | 0–1 | × 255 | KITTI `.bin` (the 8-bit value divided by 255) |
//! | `six-bit` | 0–63 | × 255/63 | older HDL-32E recordings that report 6 bits |
//! | `{ gain = G, offset = O }` | any | G·raw + O | anything else, stated by the user |
//!
//! The map is affine and invertible (gain ≠ 0), so a degraded scan can be
//! written back in its source's own convention.

use serde::{Deserialize, Serialize};

use crate::TypesError;

/// How raw intensity maps onto calibrated VLP-16 reflectivity:
/// `calibrated = gain · raw + offset`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum IntensityScale {
    /// Already calibrated VLP-16 reflectivity (0–255).
    #[default]
    Calibrated,
    /// An affine map to calibrated reflectivity.
    Linear {
        /// Multiplier applied to the raw value (non-zero).
        gain: f32,
        /// Added after the multiplication.
        offset: f32,
    },
}

impl IntensityScale {
    /// KITTI's 0–1 convention (raw × 255).
    pub const KITTI: IntensityScale = IntensityScale::Linear {
        gain: 255.0,
        offset: 0.0,
    };
    /// A 6-bit 0–63 convention (raw × 255/63).
    pub const SIX_BIT: IntensityScale = IntensityScale::Linear {
        gain: 255.0 / 63.0,
        offset: 0.0,
    };

    /// Parses a preset name (see the module table).
    pub fn from_name(name: &str) -> Result<Self, TypesError> {
        match name.trim().to_ascii_lowercase().as_str() {
            "calibrated" | "vlp16" | "nuscenes" | "byte" => Ok(IntensityScale::Calibrated),
            "kitti" | "unit" => Ok(Self::KITTI),
            "six-bit" | "6bit" | "six_bit" => Ok(Self::SIX_BIT),
            other => Err(TypesError::UnknownIntensityScale(other.to_string())),
        }
    }

    /// Builds an affine scale, rejecting a zero or non-finite gain.
    pub fn linear(gain: f32, offset: f32) -> Result<Self, TypesError> {
        if !gain.is_finite() || gain == 0.0 || !offset.is_finite() {
            return Err(TypesError::UnknownIntensityScale(format!(
                "{{ gain = {gain}, offset = {offset} }} (gain must be finite and non-zero)"
            )));
        }
        if gain == 1.0 && offset == 0.0 {
            return Ok(IntensityScale::Calibrated);
        }
        Ok(IntensityScale::Linear { gain, offset })
    }

    /// Raw value → calibrated reflectivity.
    #[inline]
    pub fn to_calibrated(self, raw: f32) -> f32 {
        match self {
            IntensityScale::Calibrated => raw,
            IntensityScale::Linear { gain, offset } => gain * raw + offset,
        }
    }

    /// Calibrated reflectivity → raw value in this scale.
    #[inline]
    pub fn from_calibrated(self, calibrated: f32) -> f32 {
        match self {
            IntensityScale::Calibrated => calibrated,
            IntensityScale::Linear { gain, offset } => (calibrated - offset) / gain,
        }
    }

    /// A short human-readable name.
    pub fn describe(self) -> String {
        match self {
            IntensityScale::Calibrated => "calibrated".to_string(),
            s if s == Self::KITTI => "kitti".to_string(),
            s if s == Self::SIX_BIT => "six-bit".to_string(),
            IntensityScale::Linear { gain, offset } => {
                format!("{{ gain = {gain}, offset = {offset} }}")
            }
        }
    }
}

impl std::str::FromStr for IntensityScale {
    type Err = TypesError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::from_name(s)
    }
}

impl std::fmt::Display for IntensityScale {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.describe())
    }
}

#[derive(Serialize, Deserialize)]
#[serde(untagged)]
enum Repr {
    Name(String),
    Linear {
        gain: f32,
        #[serde(default)]
        offset: f32,
    },
}

impl Serialize for IntensityScale {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match *self {
            IntensityScale::Calibrated => Repr::Name("calibrated".into()).serialize(s),
            IntensityScale::Linear { gain, offset } => Repr::Linear { gain, offset }.serialize(s),
        }
    }
}

impl<'de> Deserialize<'de> for IntensityScale {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        match Repr::deserialize(d)? {
            Repr::Name(n) => IntensityScale::from_name(&n).map_err(serde::de::Error::custom),
            Repr::Linear { gain, offset } => {
                IntensityScale::linear(gain, offset).map_err(serde::de::Error::custom)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_map_full_scale_to_255() {
        assert_eq!(IntensityScale::KITTI.to_calibrated(1.0), 255.0);
        assert!((IntensityScale::SIX_BIT.to_calibrated(63.0) - 255.0).abs() < 1e-4);
        assert_eq!(
            IntensityScale::from_name("nuScenes").unwrap(),
            IntensityScale::Calibrated
        );
    }

    #[test]
    fn a_band_means_the_same_on_every_sensor() {
        // A diffuse target at calibrated reflectivity 8 (below the seed's
        // "< 10" band edge) as KITTI and as a 6-bit sensor would store it.
        for s in [
            IntensityScale::KITTI,
            IntensityScale::SIX_BIT,
            IntensityScale::Calibrated,
        ] {
            let raw = s.from_calibrated(8.0);
            assert!((s.to_calibrated(raw) - 8.0).abs() < 1e-4);
        }
    }

    #[test]
    fn unknown_name_is_an_error() {
        let e = IntensityScale::from_name("furlongs")
            .unwrap_err()
            .to_string();
        assert!(e.contains("furlongs"), "{e}");
        assert!(IntensityScale::linear(0.0, 1.0).is_err());
    }

    #[test]
    fn serde_accepts_names_and_tables() {
        #[derive(Deserialize, Serialize)]
        struct T {
            s: IntensityScale,
        }
        let t: T = serde_json::from_str(r#"{"s":"kitti"}"#).unwrap();
        assert_eq!(t.s, IntensityScale::KITTI);
        let t: T = serde_json::from_str(r#"{"s":{"gain":2.0,"offset":1.0}}"#).unwrap();
        assert_eq!(t.s.to_calibrated(3.0), 7.0);
        let back = serde_json::to_string(&t).unwrap();
        assert_eq!(back, r#"{"s":{"gain":2.0,"offset":1.0}}"#);
        assert!(serde_json::from_str::<T>(r#"{"s":"bogus"}"#).is_err());
    }
}
