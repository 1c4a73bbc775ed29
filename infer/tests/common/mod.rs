//! Hand-built coefficient tables and clouds shared by the integration tests.
#![allow(dead_code)]

use std::collections::BTreeMap;

use murk_types::*;

/// The seed's Table 4 slopes.
pub const FOG_LOW: f64 = 0.302_865_36;
pub const FOG_HIGH: f64 = 0.346_343_64;
pub const RAIN_LOW: f64 = 0.156_886_75;
pub const RAIN_HIGH: f64 = 0.225_304_45;
pub const SNOW: f64 = 0.326_850_39;

/// Deserialises a table piece from JSON: fields the format gains later
/// (with their defaults) do not break the tests.
fn from<T: serde::de::DeserializeOwned>(v: serde_json::Value) -> T {
    serde_json::from_value(v).unwrap()
}

pub fn band(min: f64, max: Option<f64>, slope: Option<f64>) -> SlopeBand {
    from(serde_json::json!({
        "reflectivity_min": min, "reflectivity_max": max, "slope": slope, "points": 100,
        "reason": if slope.is_none() { Some("too few points") } else { None },
        "edge_width": 0.1,
    }))
}

/// A ghost/ring law of the seed's Table 5 form.
pub fn law(dist: (f64, f64, f64, f64), refl: (f64, f64), per_scan: f64) -> NoiseLaw {
    from(serde_json::json!({
        "distance_m": {"mean": dist.0, "std": dist.1, "lower": dist.2, "upper": dist.3},
        "reflectivity": {"mean": refl.0, "std": refl.1, "lower": 0.0},
        "points_per_scan": per_scan, "points": 1000,
        "count_law": null, "count_law_reason": "hand-built",
    }))
}

pub fn weather(low: f64, high: f64) -> WeatherCoefficients {
    let mut w: WeatherCoefficients = from(serde_json::json!({
        "recordings": 10, "mor_min_m": 50.0, "mor_max_m": 200.0,
        "vanishing_slope": [], "quantile": 0.99,
        "survival": {"edge": "probit", "dropout": 0.1, "residual": 0.05,
                     "neg_log_likelihood": 1.0, "trials": 1000},
        "no_change_rate": 0.4, "ghost": null, "ring": null,
    }));
    w.vanishing_slope = vec![
        band(0.0, Some(10.0), Some(low)),
        band(10.0, None, Some(high)),
    ];
    w.vanishing_slope_q99 = vec![
        band(0.0, Some(10.0), Some(low * 0.9)),
        band(10.0, None, Some(high * 0.9)),
    ];
    w.ghost = Some(law((5.011, 1.753, 3.0, 10.0), (4.113, 11.533), 41.0));
    w.ring = Some(law((1.308, 0.172, 0.5, 3.0), (1.461, 3.055), 12.0));
    w
}

/// The seed's fog, rain and snow (Tables 4 and 5), rain with the REHEARSE
/// conversion fitted on 1–100 mm/h.
pub fn seed_table() -> CoefficientTable {
    let mut rain = weather(RAIN_LOW, RAIN_HIGH);
    rain.mor_from_rain_rate = Some(from(serde_json::json!({
        "slope": -0.8308, "intercept": 159.16, "points": 42,
        "rain_rate_min": 1.0, "rain_rate_max": 100.0, "zero_mor_rain_rate": 159.16 / 0.8308,
    })));
    let mut snow = weather(SNOW, SNOW);
    snow.vanishing_slope = vec![band(0.0, None, Some(SNOW))];
    // Built from JSON so that fields the table format gains later (with
    // their defaults) do not break the tests.
    let mut t = CoefficientTable::from_json(
        r#"{"format": "weather-noise-coefficients/1", "campaign": "seed",
            "lidar": {"model": "VLP16", "range_scale": 1.0}, "weathers": {},
            "provenance": {"tool": "hand", "inputs_sha256": "", "parameters": null}}"#,
    )
    .unwrap();
    t.weathers = BTreeMap::from([
        (WeatherClass::Fog, weather(FOG_LOW, FOG_HIGH)),
        (WeatherClass::Rain, rain),
        (WeatherClass::Snow, snow),
    ]);
    t
}

/// A deterministic pseudo-random VLP-16-like scan of `n` points: ranges
/// 0.5–120 m, reflectivity 0–255, rings 0–15, with a time column.
pub fn synthetic_scan(n: usize, salt: u64) -> PointCloud {
    let mut c = PointCloud::with_capacity(n);
    let mut s = salt.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut next = || {
        // xorshift64*: test data only.
        s ^= s >> 12;
        s ^= s << 25;
        s ^= s >> 27;
        (s.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    };
    for i in 0..n {
        let r = 0.5 + 119.5 * next();
        let az = next() * std::f64::consts::TAU;
        let ring = (i % 16) as u16;
        let el = murk_types::LidarSpec::vlp16().elevation_deg[ring as usize].to_radians();
        let refl = (next() * 256.0).floor().min(255.0);
        c.push_timed(
            (r * el.cos() * az.cos()) as f32,
            (r * el.cos() * az.sin()) as f32,
            (r * el.sin()) as f32,
            refl as f32,
            ring,
            i as f32 * 1e-5,
        );
    }
    c
}
