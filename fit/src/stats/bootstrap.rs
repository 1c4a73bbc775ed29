//! Bootstrap over recordings of a pooled rate `Σ kept / Σ total`.
//!
//! Recordings, not points, are resampled: points of one recording share its
//! weather and are not independent, so a point bootstrap would understate the
//! uncertainty.

use murk_types::seed::{Purpose, derive};
use rand::{RngExt, SeedableRng, rngs::ChaCha8Rng};

use crate::stats::quantile::quantile;

/// Summary of the bootstrap replicates of a rate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateUncertainty {
    /// Standard deviation of the replicates.
    pub std: f64,
    /// 2.5 % percentile.
    pub ci95_low: f64,
    /// 97.5 % percentile.
    pub ci95_high: f64,
    /// Replicates drawn.
    pub replicates: u32,
}

/// Bootstrap of the pooled rate of `rows` (`(kept, total)` per recording),
/// seeded by murk's one derivation of `(seed, key, Purpose::Bootstrap)`
/// (`key` names the rate, e.g. `"radar/fog"`). `None` with fewer than two
/// recordings, no replicate, or no trial at all.
pub fn bootstrap_rate(
    rows: &[(u64, u64)],
    replicates: u32,
    seed: u64,
    key: &str,
) -> Option<RateUncertainty> {
    let n = rows.len();
    if n < 2 || replicates == 0 || rows.iter().all(|r| r.1 == 0) {
        return None;
    }
    let mut rng = ChaCha8Rng::from_seed(derive(seed, key, Purpose::Bootstrap).bytes());
    let mut reps = Vec::with_capacity(replicates as usize);
    for _ in 0..replicates {
        let (mut k, mut t) = (0u64, 0u64);
        for _ in 0..n {
            let r = rows[rng.random_range(0..n)];
            k += r.0;
            t += r.1;
        }
        if t > 0 {
            reps.push(k as f64 / t as f64);
        }
    }
    if reps.len() < 2 {
        return None;
    }
    let m = reps.iter().sum::<f64>() / reps.len() as f64;
    let var = reps.iter().map(|r| (r - m).powi(2)).sum::<f64>() / (reps.len() - 1) as f64;
    Some(RateUncertainty {
        std: var.sqrt(),
        ci95_low: quantile(&mut reps, 0.025)?,
        ci95_high: quantile(&mut reps, 0.975)?,
        replicates: reps.len() as u32,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_matches_the_binomial_between_recording_spread() {
        // 50 recordings of 100 trials; rates alternate 0.3 / 0.5. The pooled
        // rate is 0.4 and the SE of a mean of 50 such recordings is
        // 0.1/√50 = 0.0141. 2000 replicates: the bootstrap std is within 15 %.
        let rows: Vec<(u64, u64)> = (0..50)
            .map(|i| (if i % 2 == 0 { 30 } else { 50 }, 100))
            .collect();
        let u = bootstrap_rate(&rows, 2000, 1, "a").unwrap();
        assert!((u.std / 0.01414 - 1.0).abs() < 0.15, "{u:?}");
        assert!(u.ci95_low < 0.4 && u.ci95_high > 0.4);
    }

    #[test]
    fn same_seed_same_answer_other_key_other_answer() {
        let rows: Vec<(u64, u64)> = (0..20).map(|i| (i, 30)).collect();
        let a = bootstrap_rate(&rows, 200, 9, "a").unwrap();
        let b = bootstrap_rate(&rows, 200, 9, "a").unwrap();
        let c = bootstrap_rate(&rows, 200, 9, "b").unwrap();
        assert_eq!(a, b);
        assert_ne!(a, c);
    }

    #[test]
    fn one_recording_has_no_uncertainty() {
        assert!(bootstrap_rate(&[(3, 4)], 100, 0, "a").is_none());
    }
}
