//! Sensor metadata of a campaign's LiDAR.

use serde::{Deserialize, Serialize};

use crate::{BinLayout, IntensityScale, PcapReturn, TypesError};

/// The LiDAR of a campaign (`[lidar]` in `campaign.toml`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LidarSpec {
    /// Free-text model name (`VLP16`, `OS1-64`, …).
    pub model: String,
    /// Sensor range-scale coefficient (1.0 for the VLP-16, 0.9 for the
    /// Ouster OS1 in the seed's library); multiplies vanishing distances.
    #[serde(default = "one")]
    pub range_scale: f64,
    /// Elevation of each ring, degrees, indexed by ring id.
    pub elevation_deg: Vec<f64>,
    /// Horizontal angular step between firings, degrees.
    #[serde(default = "default_az")]
    pub azimuth_resolution_deg: f64,
    /// Maximum range of the sensor, metres.
    #[serde(default = "default_max_range")]
    pub max_range_m: f64,
    /// Points nearer than this (metres from the sensor) are not returns of
    /// the scene: formats that keep every firing write the ones without a
    /// return as points at or near the origin (nuScenes, Ouster), and a
    /// roof-mounted sensor sees the vehicle itself. murk's fit and diagnosis
    /// leave them out and `murk apply` passes them through untouched.
    /// Absent means every point is a return (nuScenes' own tools drop
    /// points within 1 m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_range_m: Option<f64>,
    /// Scale of the `intensity` stored in this campaign's files; absent means
    /// the format's default (calibrated for PCD/CSV/Parquet, KITTI for `.bin`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub intensity_scale: Option<IntensityScale>,
    /// Record layout of this campaign's `.bin` files (`xyzi`, `xyzir`,
    /// `xyzit`); absent means murk reads `.bin` as KITTI `xyzi` where the
    /// file size leaves no doubt and refuses files it cannot tell apart.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bin_layout: Option<BinLayout>,
    /// Column names of header-less CSV files, in order (for example
    /// `["x", "y", "z", "intensity", "ring"]` for RADIATE); absent means
    /// CSV files start with a header line.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub csv_columns: Option<Vec<String>>,
    /// Which return of each firing to read from dual-return `.pcap`
    /// recordings (`strongest`, `last`); absent means as recorded, which fit
    /// and diagnose refuse for a dual-return capture ([`PcapReturn`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pcap_return: Option<PcapReturn>,
}

fn one() -> f64 {
    1.0
}
fn default_az() -> f64 {
    0.2
}
fn default_max_range() -> f64 {
    100.0
}

/// VLP-16 ring elevations by laser id (degrees), from the sensor manual.
pub const VLP16_ELEVATION_DEG: [f64; 16] = [
    -15.0, 1.0, -13.0, 3.0, -11.0, 5.0, -9.0, 7.0, -7.0, 9.0, -5.0, 11.0, -3.0, 13.0, -1.0, 15.0,
];

/// A point this near the sensor (metres) is no return of the scene — a
/// LiDAR's housing and minimum range keep real returns farther: it is a
/// firing without a return written as a point at the origin (nuScenes,
/// Ouster), or the vehicle's body. Where no [`LidarSpec::min_range_m`] is
/// declared, fit and apply warn when at least [`NEAR_POINT_SHARE`] of the
/// points they check lie this near.
pub const NEAR_POINT_M: f64 = 0.3;
/// Share of points within [`NEAR_POINT_M`] that fit and apply warn about.
pub const NEAR_POINT_SHARE: f64 = 0.005;

/// The share `near / checked` of points within [`NEAR_POINT_M`] when it is
/// worth a warning (at least [`NEAR_POINT_SHARE`], and some), else `None`:
/// the one rule fit and apply warn by.
pub fn near_point_share(near: u64, checked: u64) -> Option<f64> {
    let share = near as f64 / checked.max(1) as f64;
    (near > 0 && share >= NEAR_POINT_SHARE).then_some(share)
}

/// HDL-32E laser elevations by laser id (degrees): the even lasers from
/// −30.67° and the odd ones from −9.33° up by 4/3°, interleaved (the
/// sensor's own calibration).
pub const HDL32E_ELEVATION_DEG: [f64; 32] = [
    -30.67, -9.33, -29.33, -8.0, -28.0, -6.67, -26.67, -5.33, -25.33, -4.0, -24.0, -2.67, -22.67,
    -1.33, -21.33, 0.0, -20.0, 1.33, -18.67, 2.67, -17.33, 4.0, -16.0, 5.33, -14.67, 6.67, -13.33,
    8.0, -12.0, 9.33, -10.67, 10.67,
];

/// VLP-32C laser elevations by laser id (degrees), from its default
/// calibration: 32 lasers from −25° to +15°, densest (1/3° apart) around
/// the horizon, in the order the packet holds them.
pub const VLP32C_ELEVATION_DEG: [f64; 32] = [
    -25.0, -1.0, -1.667, -15.639, -11.31, 0.0, -0.667, -8.843, -7.254, 0.333, -0.333, -6.148,
    -5.333, 1.333, 0.667, -4.0, -4.667, 1.667, 1.0, -3.667, -3.333, 3.333, 2.333, -2.667, -3.0,
    7.0, 4.667, -2.333, -2.0, 15.0, 10.333, -1.333,
];

/// Puck Hi-Res (VLP-16 Hi-Res) laser elevations by laser id (degrees): the
/// VLP-16's lasers spread over ±10° instead of ±15°, 4/3° apart.
pub const PUCK_HI_RES_ELEVATION_DEG: [f64; 16] = [
    -10.0, 0.667, -8.667, 2.0, -7.333, 3.333, -6.0, 4.667, -4.667, 6.0, -3.333, 7.333, -2.0, 8.667,
    -0.667, 10.0,
];

impl LidarSpec {
    /// The Velodyne VLP-32C at 10 Hz (a firing every 0.2°: 55.296 µs a
    /// firing sequence). Its lasers also sit at horizontal offsets of
    /// ±1.4° and ±4.2° from the firing azimuth; a decoder puts each return
    /// at its laser's own azimuth, and fit measures each ring's phase.
    pub fn vlp32c() -> Self {
        LidarSpec {
            model: "VLP32C".into(),
            elevation_deg: VLP32C_ELEVATION_DEG.to_vec(),
            max_range_m: 200.0,
            ..LidarSpec::vlp16()
        }
    }

    /// The Velodyne HDL-32E at 10 Hz (a firing every 0.166°: 2,170 a
    /// turn).
    pub fn hdl32e() -> Self {
        LidarSpec {
            model: "HDL32E".into(),
            elevation_deg: HDL32E_ELEVATION_DEG.to_vec(),
            azimuth_resolution_deg: 0.166,
            ..LidarSpec::vlp16()
        }
    }

    /// The Velodyne VLP-16 as the PDD site used it.
    pub fn vlp16() -> Self {
        LidarSpec {
            model: "VLP16".into(),
            range_scale: 1.0,
            elevation_deg: VLP16_ELEVATION_DEG.to_vec(),
            azimuth_resolution_deg: 0.2,
            max_range_m: 100.0,
            min_range_m: None,
            intensity_scale: None,
            bin_layout: None,
            csv_columns: None,
            pcap_return: None,
        }
    }

    /// Checks the values a model depends on.
    pub fn validate(&self) -> Result<(), TypesError> {
        let bad = |m: String| Err(TypesError::InvalidLidar(m));
        if self.elevation_deg.is_empty() {
            return bad("elevation_deg is empty".into());
        }
        if self.elevation_deg.len() > u16::MAX as usize {
            return bad(format!(
                "{} rings is more than murk supports",
                self.elevation_deg.len()
            ));
        }
        if let Some(e) = self
            .elevation_deg
            .iter()
            .find(|e| !e.is_finite() || e.abs() > 90.0)
        {
            return bad(format!(
                "elevation {e} is not an angle in [-90, 90] degrees"
            ));
        }
        if !(self.range_scale.is_finite() && self.range_scale > 0.0) {
            return bad(format!("range_scale {} must be > 0", self.range_scale));
        }
        if !(self.azimuth_resolution_deg.is_finite() && self.azimuth_resolution_deg > 0.0) {
            return bad(format!(
                "azimuth_resolution_deg {} must be > 0",
                self.azimuth_resolution_deg
            ));
        }
        if !(self.max_range_m.is_finite() && self.max_range_m > 0.0) {
            return bad(format!("max_range_m {} must be > 0", self.max_range_m));
        }
        if let Some(m) = self.min_range_m
            && !(m.is_finite() && m >= 0.0 && m < self.max_range_m)
        {
            return bad(format!(
                "min_range_m {m} must be ≥ 0 and below max_range_m {}",
                self.max_range_m
            ));
        }
        Ok(())
    }

    /// True when a point at `range_m` from the sensor is a return of the
    /// scene: not nearer than [`LidarSpec::min_range_m`].
    pub fn is_return(&self, range_m: f32) -> bool {
        self.min_range_m.is_none_or(|m| f64::from(range_m) >= m)
    }

    /// Number of rings.
    pub fn rings(&self) -> usize {
        self.elevation_deg.len()
    }

    /// The ring whose elevation is nearest to `elevation_rad`.
    pub fn nearest_ring(&self, elevation_rad: f32) -> u16 {
        let e = elevation_rad.to_degrees() as f64;
        let mut best = 0usize;
        let mut best_d = f64::INFINITY;
        for (i, &r) in self.elevation_deg.iter().enumerate() {
            let d = (r - e).abs();
            if d < best_d {
                best_d = d;
                best = i;
            }
        }
        best as u16
    }

    /// The ring of a point at `elevation_rad`, or `None` when the point lies
    /// more than half the smallest ring spacing (at least 0.5°) from every ring.
    pub fn ring_from_elevation(&self, elevation_rad: f32) -> Option<u16> {
        let ring = self.nearest_ring(elevation_rad);
        let e = elevation_rad.to_degrees() as f64;
        let d = (self.elevation_deg.get(ring as usize)? - e).abs();
        (d <= self.ring_tolerance_deg()).then_some(ring)
    }

    /// Half the smallest gap between two ring elevations, at least 0.5°.
    pub fn ring_tolerance_deg(&self) -> f64 {
        let mut s = self.elevation_deg.clone();
        s.sort_by(f64::total_cmp);
        let gap = s
            .windows(2)
            .map(|w| w[1] - w[0])
            .filter(|g| *g > 0.0)
            .fold(f64::INFINITY, f64::min);
        if gap.is_finite() {
            (gap / 2.0).max(0.5)
        } else {
            0.5
        }
    }

    /// Number of azimuth bins of one revolution.
    pub fn azimuth_bins(&self) -> usize {
        (360.0 / self.azimuth_resolution_deg).round().max(1.0) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vlp16_rings_round_trip() {
        let s = LidarSpec::vlp16();
        s.validate().unwrap();
        for (i, e) in VLP16_ELEVATION_DEG.iter().enumerate() {
            let r = (*e as f32 + 0.3).to_radians();
            assert_eq!(s.ring_from_elevation(r), Some(i as u16));
        }
        assert_eq!(s.ring_from_elevation(40f32.to_radians()), None);
        assert_eq!(s.nearest_ring(40f32.to_radians()), 15);
        assert_eq!(s.azimuth_bins(), 1800);
    }

    #[test]
    fn invalid_spec_is_named() {
        let mut s = LidarSpec::vlp16();
        s.range_scale = 0.0;
        assert!(
            s.validate()
                .unwrap_err()
                .to_string()
                .contains("range_scale")
        );
    }

    #[test]
    fn min_range_sets_which_points_are_returns() {
        let mut s = LidarSpec::vlp16();
        assert!(s.is_return(0.0));
        s.min_range_m = Some(1.0);
        s.validate().unwrap();
        assert!(!s.is_return(0.99) && s.is_return(1.0) && s.is_return(50.0));
        for bad in [-0.5, f64::NAN, 100.0, 250.0] {
            s.min_range_m = Some(bad);
            let e = s.validate().unwrap_err().to_string();
            assert!(
                e.contains("min_range_m") && e.contains("max_range_m"),
                "{e}"
            );
        }
    }

    #[test]
    fn serde_form_of_campaign_format() {
        let s: LidarSpec = serde_json::from_str(
            r#"{"model":"VLP16","range_scale":1.0,"elevation_deg":[-15.0,1.0],
                "azimuth_resolution_deg":0.2,"max_range_m":100.0,"intensity_scale":"kitti"}"#,
        )
        .unwrap();
        assert_eq!(s.rings(), 2);
        assert_eq!(s.intensity_scale, Some(IntensityScale::KITTI));
        let e = serde_json::from_str::<LidarSpec>(
            r#"{"model":"X","elevation_deg":[0.0],"rnage_scale":1}"#,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("rnage_scale"), "{e}");
    }
}
