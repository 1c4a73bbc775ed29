//! The firing step of a spinning LiDAR, measured from its returns: the one
//! estimator murk-fit's sensor geometry (clear recordings) and murk-infer's
//! near-range rays (each scan it applies to) both call.
//!
//! A ring fires every `step` degrees; the azimuth differences between its
//! consecutive returns are one step, or a multiple where firings returned
//! nothing, plus the jitter of both ends. The step is the mode of the
//! differences on a logarithmic histogram (1 % bins, smoothed over ±2),
//! refined as the median of those within ±5 % of it, and then as `Σd / Σm`
//! over every difference of `m` ≤ 50 steps, which telescopes the jitter
//! away (the number of firings in a turn needs the step to better than one
//! part in twice that number).
//!
//! ```
//! use murk_types::firing::mode_step;
//!
//! // Every 0.4°, with a firing in five returning nothing.
//! let diffs: Vec<f32> = (0..500)
//!     .map(|k| if k % 5 == 4 { 0.8 } else { 0.4 })
//!     .collect();
//! let (step, share) = mode_step(&diffs).unwrap();
//! assert!((step - 0.4).abs() < 1e-6);
//! assert!((share - 0.8).abs() < 1e-9);
//! // Too few differences: no step.
//! assert_eq!(mode_step(&diffs[..10]), None);
//! ```

/// Differences a step needs.
pub const MIN_DIFFS: usize = 20;
/// Smallest difference considered a step, degrees (below: duplicate or
/// second return of the same firing).
pub const MIN_STEP_DEG: f64 = 1e-3;
/// Largest step considered, degrees.
pub const MAX_STEP_DEG: f64 = 90.0;
/// Relative width of the histogram bins of the mode search.
const LOG_BIN: f64 = 0.01;
/// Relative half-width of the window the mode is refined in.
const REFINE: f64 = 0.05;
/// Share of the differences the mode must hold to be trusted.
const MIN_MODE_SHARE: f64 = 0.2;

/// Azimuth of `(x, y)`, degrees in `[0, 360)`.
#[inline]
pub fn azimuth_deg(x: f32, y: f32) -> f64 {
    let a = (y as f64).atan2(x as f64).to_degrees();
    if a < 0.0 { a + 360.0 } else { a }
}

/// `|a − b|` on the circle, degrees in `[0, 180]`.
#[inline]
pub fn circ_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).abs() % 360.0;
    if d > 180.0 { 360.0 - d } else { d }
}

/// The step of `diffs` (azimuth differences between consecutive returns of
/// a ring, degrees) and the share of differences within ±5 % of it, or
/// `None` with fewer than [`MIN_DIFFS`] or no clear mode (under a fifth of
/// the differences at it).
pub fn mode_step(diffs: &[f32]) -> Option<(f64, f64)> {
    if diffs.len() < MIN_DIFFS {
        return None;
    }
    let lo = MIN_STEP_DEG.ln();
    let n_bins = ((MAX_STEP_DEG.ln() - lo) / LOG_BIN).ceil() as usize + 1;
    let mut hist = vec![0u32; n_bins];
    for &d in diffs {
        let d = d as f64;
        if !(MIN_STEP_DEG..=MAX_STEP_DEG).contains(&d) {
            continue;
        }
        let k = ((d.ln() - lo) / LOG_BIN) as usize;
        hist[k.min(n_bins - 1)] += 1;
    }
    // Smoothed over ±2 bins (jitter spreads a step over a few percent);
    // ties go to the smaller step (a gap is a multiple, never a fraction).
    let smooth = |k: usize| -> u32 { hist[k.saturating_sub(2)..(k + 3).min(n_bins)].iter().sum() };
    let mut best = (0u32, 0usize);
    for k in 0..n_bins {
        let v = smooth(k);
        if v > best.0 {
            best = (v, k);
        }
    }
    if best.0 == 0 {
        return None;
    }
    // The median within ±5 % of the histogram's bin, then re-centred on
    // the estimate three times (the bin is 1 % wide).
    let mut step = (lo + (best.1 as f64 + 0.5) * LOG_BIN).exp();
    for _ in 0..4 {
        let near: Vec<f32> = diffs
            .iter()
            .copied()
            .filter(|&d| (d as f64 - step).abs() <= REFINE * step)
            .collect();
        if near.is_empty() {
            return None;
        }
        step = median(&near);
    }
    // The cell count needs the step to better than 1 / (2 · cells): a
    // difference is `m` steps plus the jitter of its two ends, so over all
    // differences of up to 50 steps Σd / Σm telescopes the jitter away.
    for _ in 0..2 {
        let (mut sd, mut sm) = (0.0f64, 0.0f64);
        for &d in diffs {
            let m = (d as f64 / step).round();
            if (1.0..=50.0).contains(&m) && (d as f64 - m * step).abs() <= 0.3 * step {
                sd += d as f64;
                sm += m;
            }
        }
        if sm > 0.0 {
            step = sd / sm;
        }
    }
    let share = diffs
        .iter()
        .filter(|&&d| (d as f64 - step).abs() <= REFINE * step)
        .count() as f64
        / diffs.len() as f64;
    (share >= MIN_MODE_SHARE).then_some((step, share))
}

/// The median of `v` (mean of the middle two for an even count; NaN for
/// none).
pub fn median(v: &[f32]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut w = v.to_vec();
    w.sort_by(f32::total_cmp);
    let n = w.len();
    if n % 2 == 1 {
        w[n / 2] as f64
    } else {
        0.5 * (w[n / 2 - 1] as f64 + w[n / 2] as f64)
    }
}

/// The number of firings in a turn at `step` degrees and the step that
/// divides the turn into them (`360 / round(360 / step)`).
pub fn firings_per_turn(step: f64) -> (u64, f64) {
    let n = (360.0 / step).round().max(1.0);
    (n as u64, 360.0 / n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jittered_differences_telescope_to_the_step() {
        // Firing k at k·step + jitter; differences of consecutive returns
        // with a return missing now and then.
        let step = 360.0 / 905.0;
        let mut az = Vec::new();
        let mut x: u64 = 3;
        for k in 0..900u32 {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let u = (x >> 11) as f64 / (1u64 << 53) as f64;
            if k % 7 != 3 {
                az.push(k as f64 * step + 0.02 * (u - 0.5));
            }
        }
        let diffs: Vec<f32> = az.windows(2).map(|w| (w[1] - w[0]) as f32).collect();
        let (s, _) = mode_step(&diffs).unwrap();
        assert_eq!(firings_per_turn(s).0, 905, "{s}");
        assert!((s - step).abs() < 1e-4, "{s}");
    }

    #[test]
    fn no_clear_mode_is_no_step() {
        // Differences spread evenly over a decade: no fifth at any step.
        let diffs: Vec<f32> = (0..200)
            .map(|k| 0.1 * 10f32.powf(k as f32 / 200.0))
            .collect();
        assert_eq!(mode_step(&diffs), None);
        assert!(median(&[]).is_nan());
        assert_eq!(median(&[3.0, 1.0, 2.0, 10.0]), 2.5);
        assert!((circ_diff(359.5, 0.5) - 1.0).abs() < 1e-12);
        assert!((azimuth_deg(0.0, -1.0) - 270.0).abs() < 1e-9);
    }
}
