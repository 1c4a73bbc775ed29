//! Hand-built figure data shared by the `render_all` example and the tests:
//! a fog table with two bands (one `vanishing_slope_q99` null), a ghost law
//! and a ring law the data cannot pin down, and the counts behind them.
#![allow(dead_code)]

use murk_types::{Gaussian, MorBin, NoiseLaw, SlopeBand, SweepBand, WeatherCoefficients};

fn mor_bins(slope: f64, mors: &[f64]) -> Vec<MorBin> {
    mors.iter()
        .map(|&m| MorBin {
            mor_m: m,
            mor_lo_m: Some(m - 5.0),
            mor_hi_m: Some(m + 5.0),
            recordings: 2,
            q99_range_m: Some(slope * m * 1.02),
            points: 900,
            censored: m > 100.0,
            used: m <= 100.0,
            reason: (m > 100.0).then(|| "censored: the clear scene ends first".into()),
        })
        .collect()
}

fn band(min: f64, max: Option<f64>, slope: Option<f64>, bins: Vec<MorBin>) -> SlopeBand {
    SlopeBand {
        reflectivity_min: min,
        reflectivity_max: max,
        slope,
        points: 5000,
        reason: slope
            .is_none()
            .then(|| "no MOR bin with 50 no-change returns".into()),
        std_error: None,
        std_error_independent: None,
        ci95: None,
        edge_test: None,
        edge_width: None,
        edge_width_ci95: None,
        edge_width_corrected: None,
        edge_width_corrected_ci95: None,
        mor_bins: bins,
        law: None,
        survival_bins: vec![],
        lack_of_fit: None,
    }
}

fn gaussian(mean: f64, std: f64, lower: Option<f64>, upper: Option<f64>) -> Gaussian {
    Gaussian {
        mean,
        std,
        lower,
        upper,
        mean_std_error: Some(std * 0.03),
        std_std_error: Some(std * 0.02),
        reason: None,
    }
}

fn noise(distance: Gaussian, reflectivity: Gaussian) -> NoiseLaw {
    NoiseLaw {
        distance_m: distance,
        reflectivity,
        points_per_scan: 12.0,
        points_per_recording: None,
        points: 400,
        visible_fraction: None,
        count_law: None,
        count_law_reason: None,
        count_law_choice: None,
    }
}

/// MOR bin centres of the counts, metres.
pub const MORS: [f64; 8] = [45.0, 55.0, 65.0, 75.0, 85.0, 95.0, 105.0, 115.0];

/// Fog coefficients: ML slopes 0.30 / 0.34, q99 0.29 in the low band and
/// null in the high one; ghost law well inside its window; ring
/// reflectivity mean −985 below its floor of 0.
pub fn fog() -> WeatherCoefficients {
    WeatherCoefficients {
        recordings: 16,
        mor_min_m: Some(40.0),
        mor_max_m: Some(120.0),
        vanishing_slope: vec![
            band(0.0, Some(10.0), Some(0.30), vec![]),
            band(10.0, None, Some(0.34), vec![]),
        ],
        vanishing_slope_q99: vec![
            band(0.0, Some(10.0), Some(0.29), mor_bins(0.29, &MORS)),
            band(10.0, None, None, vec![]),
        ],
        quantile: 0.99,
        mor_bins: mor_bins(0.31, &MORS),
        survival: None,
        no_change_rate: Some(0.4),
        no_change_rate_uncertainty: None,
        no_change_rate_reason: None,
        ghost: Some(noise(
            gaussian(5.0, 1.7, Some(3.0), Some(10.0)),
            gaussian(2.0, 3.0, Some(0.0), None),
        )),
        ghost_reason: None,
        ghost_returns: None,
        ring: Some(noise(
            gaussian(1.2, 0.6, Some(0.0), Some(3.0)),
            gaussian(-985.0, 20.8, Some(0.0), None),
        )),
        ring_reason: None,
        ring_returns: None,
        mor_from_rain_rate: None,
        mor_from_rain_rate_reason: None,
        reflectivity_sweep: [0.0, 5.0, 10.0, 20.0, 40.0]
            .iter()
            .enumerate()
            .map(|(i, &lo)| SweepBand {
                reflectivity_min: lo,
                reflectivity_max: [Some(5.0), Some(10.0), Some(20.0), Some(40.0), None][i],
                slope: Some(0.30 + 0.01 * i as f64),
                slope_q99: (i != 3).then_some(0.28 + 0.01 * i as f64),
                points: 1000,
            })
            .collect(),
        extensions: vec![],
        law_choice: None,
        occlusion: None,
    }
}

/// Rain coefficients: like fog, lower slopes, no ring law (null with a
/// reason).
pub fn rain() -> WeatherCoefficients {
    let mut c = fog();
    for b in c
        .vanishing_slope
        .iter_mut()
        .chain(c.vanishing_slope_q99.iter_mut())
    {
        b.slope = b.slope.map(|s| s * 0.7);
    }
    for b in &mut c.reflectivity_sweep {
        b.slope = b.slope.map(|s| s * 0.7);
        b.slope_q99 = Some(0.2);
    }
    c.ring = None;
    c.ring_reason = Some("no ring returns found".into());
    c
}

/// `(kept, lost)` counts per MOR bin of [`MORS`] in 0.5 m range steps, for
/// a vanishing distance of `slope · MOR`.
pub fn counts(slope: f64) -> (Vec<Vec<u64>>, Vec<Vec<u64>>) {
    let steps = 70;
    let mut kept = Vec::new();
    let mut lost = Vec::new();
    for &m in &MORS {
        let vd = slope * m;
        kept.push(
            (0..steps)
                .map(|k| {
                    let r = k as f64 * 0.5;
                    if r < vd {
                        (200.0 * (1.0 - r / vd)) as u64 + 3
                    } else {
                        1
                    }
                })
                .collect(),
        );
        lost.push(
            (0..steps)
                .map(|k| if k as f64 * 0.5 > 0.8 * vd { 80 } else { 2 })
                .collect(),
        );
    }
    (kept, lost)
}

/// A ghost-like histogram: `(lo, step, counts)`.
pub fn histogram(lo: f64, step: f64, mean: f64, std: f64, n: usize) -> (f64, f64, Vec<u64>) {
    let counts = (0..n)
        .map(|k| {
            let x = lo + (k as f64 + 0.5) * step;
            (300.0 * (-0.5 * ((x - mean) / std).powi(2)).exp()) as u64
        })
        .collect();
    (lo, step, counts)
}

/// Rings of points around the sensor, every 5 m out to 35 m.
pub fn rings(max_r: f32) -> Vec<[f32; 3]> {
    (0..4000)
        .map(|i| {
            let a = i as f32 * 0.0157;
            let r = 5.0 + (i % 7) as f32 * 5.0;
            [r * a.cos(), r * a.sin(), 0.0]
        })
        .filter(|p| p[0].hypot(p[1]) <= max_r)
        .collect()
}
