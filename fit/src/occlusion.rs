//! Do a weather's near returns *replace* the returns it loses, or *hide*
//! returns whatever their fate?
//!
//! A degraded return in a cell's direction that pairs with nothing and
//! lies in the ghost or ring window hides the cell's clear return: the
//! fit cannot see whether that return would have survived, and by default
//! it leaves the survival trials (a first-return sensor: a ghost in front
//! hides whatever is behind it, survivor or not — murk's generator and the
//! seed's model). A strongest-return sensor behaves otherwise: it reports
//! the fog's own echo only where that echo beats the hard target's, that
//! is where the hard return is lost (the lidar equation in fog, Hahner et
//! al. 2021). There the hidden returns *are* the lost ones, and leaving
//! them out of the trials removes the losses beyond the edge: measured on
//! the physics fog on a real nuScenes scan, every band came out without a
//! slope; on the VLP-16 scene the 50 % ranges 5–30 % long.
//!
//! The data say which. Among the clear returns at or beyond the far end of
//! the noise windows (every near return of their ray lies in front of
//! them), the cells the weather mostly keeps (paired share ≥ 0.8, pooled
//! over its recordings at the cell's range over MOR and reflectivity
//! class) and those it mostly loses (≤ 0.2) are hidden alike when near
//! returns hide independently, and only the lost ones are when they
//! replace. Per recording (one MOR, one near-return density: the strata),
//! the Mantel–Haenszel odds ratio of being hidden, lost against kept, and
//! the Cochran–Mantel–Haenszel test of ratio 1 decide
//! ([`murk_types::OcclusionTest`]). Measured: murk's generator (hiding)
//! 0.95–1.22 for fog and rain; the physics fog with the fog's echo in
//! place of lost returns 1.2·10⁴ on the nuScenes scan and 38.9 on the
//! VLP-16 scene, without the echo 0.01 and 0.08 (the scenes' own near
//! returns, hidden where the fog keeps returns). `fit/tests/occlusion.rs`.
//!
//! ```text
//! // assemble::weather, before any survival estimator:
//! let occlusion = occlusion::test(acc, p.edge_test_alpha(), reach_m);
//! let acc = if occlusion.replaced { occlusion::with_hidden_as_lost(acc) } else { acc };
//! // one recording: 90 of 100 lost cells hidden, 2 of 100 kept ones
//! cmh(&[(90, 100, 2, 100)], 0.01)  // odds ratio 441, p < 1e-10
//! ```

use murk_types::OcclusionTest;

use crate::accumulate::WeatherAcc;

/// Paired share at or above which a histogram cell counts as kept.
pub(crate) const KEPT_SHARE: f64 = 0.8;
/// Paired share at or below which a histogram cell counts as lost.
pub(crate) const LOST_SHARE: f64 = 0.2;

/// The Mantel–Haenszel summary of `strata` of `(hidden lost, expected
/// lost, hidden kept, expected kept)`: the odds ratio, the continuity
/// corrected Cochran–Mantel–Haenszel p-value of ratio 1 (two-sided, one
/// degree of freedom) and the pooled shares, at level `alpha` (not yet
/// decided: `replaced` false). Strata without both kinds are skipped;
/// `recordings` counts the others.
pub(crate) fn cmh(strata: &[(u64, u64, u64, u64)], alpha: f64) -> OcclusionTest {
    let (mut r, mut s, mut dev, mut var) = (0.0, 0.0, 0.0, 0.0);
    let (mut hl, mut nl, mut hk, mut nk) = (0u64, 0u64, 0u64, 0u64);
    let mut used = 0u32;
    for &(a, n1, c, n0) in strata {
        if n1 == 0 || n0 == 0 {
            continue;
        }
        used += 1;
        (hl, nl, hk, nk) = (hl + a, nl + n1, hk + c, nk + n0);
        let (a, n1, c, n0) = (a as f64, n1 as f64, c as f64, n0 as f64);
        let n = n1 + n0;
        r += a * (n0 - c) / n;
        s += c * (n1 - a) / n;
        let m1 = a + c;
        dev += a - n1 * m1 / n;
        if n > 1.0 {
            var += n1 * n0 * m1 * (n - m1) / (n * n * (n - 1.0));
        }
    }
    let share = |h: u64, n: u64| (n > 0).then(|| h as f64 / n as f64);
    let p_value = (used > 0).then(|| {
        if var > 0.0 {
            let chi = ((dev.abs() - 0.5).max(0.0)).powi(2) / var;
            libm::erfc((chi / 2.0).sqrt())
        } else {
            1.0
        }
    });
    OcclusionTest {
        recordings: used,
        hidden_where_kept: share(hk, nk),
        hidden_where_lost: share(hl, nl),
        // Unbounded (no kept return hidden) or undefined (none hidden):
        // no number, which a JSON table could not hold anyway.
        odds_ratio: (used > 0 && s > 0.0).then(|| r / s),
        p_value,
        alpha,
        replaced: false,
        reason: None,
    }
}

/// The occlusion test of one weather at level `alpha` (see the module
/// docs); `reach_m` is the far end of the noise windows, for the reason.
pub(crate) fn test(acc: &WeatherAcc, alpha: f64, reach_m: f64) -> OcclusionTest {
    // Paired share of each histogram cell, pooled over the recordings:
    // kept over expected (trials plus the hidden returns).
    let n = acc.survival.cells();
    let (mut kept, mut expected) = (vec![0u64; n], vec![0u64; n]);
    for row in &acc.rows {
        for &(i, k, t) in &row.survival {
            kept[i as usize] += k as u64;
            expected[i as usize] += t as u64;
        }
        for &(i, h, _) in &row.hidden {
            expected[i as usize] += h as u64;
        }
    }
    let kind = |i: usize| -> Option<bool> {
        let e = expected[i];
        if e == 0 {
            return None;
        }
        let share = kept[i] as f64 / e as f64;
        if share >= KEPT_SHARE {
            Some(false)
        } else if share <= LOST_SHARE {
            Some(true)
        } else {
            None
        }
    };
    let strata: Vec<(u64, u64, u64, u64)> = acc
        .rows
        .iter()
        .map(|row| {
            let mut s = (0u64, 0u64, 0u64, 0u64);
            for &(i, h, e) in &row.beyond_windows {
                match kind(i as usize) {
                    Some(true) => (s.0, s.1) = (s.0 + h as u64, s.1 + e as u64),
                    Some(false) => (s.2, s.3) = (s.2 + h as u64, s.3 + e as u64),
                    None => {}
                }
            }
            s
        })
        .collect();
    let mut t = cmh(&strata, alpha);
    if t.recordings == 0 {
        t.reason = Some(format!(
            "no recording has both returns the weather keeps and returns it loses at {reach_m} m or beyond (the noise windows' far end): the scene is too small for its MOR range, so hidden returns leave the survival trials (a first-return reading)"
        ));
    }
    let large = match t.odds_ratio {
        Some(r) => r >= OcclusionTest::MIN_ODDS_RATIO,
        // No kept return hidden: as large as a ratio gets, if any lost one is.
        None => t.hidden_where_lost.is_some_and(|h| h > 0.0),
    };
    t.replaced = t.p_value.is_some_and(|p| p <= alpha) && large;
    t
}

/// `acc` with every hidden return counted as lost: added to its cell's
/// trials in each recording's share and in the pooled histogram (with its
/// clear-weighted trials), so every estimator that reads the survival
/// trials sees the replacement reading.
pub(crate) fn with_hidden_as_lost(acc: &WeatherAcc) -> WeatherAcc {
    let mut out = acc.clone();
    for row in &mut out.rows {
        if row.hidden.is_empty() {
            continue;
        }
        let mut merged: Vec<(u32, u32, u32, f64)> = row
            .survival
            .iter()
            .zip(&row.survival_clear)
            .map(|(&(i, k, t), &c)| (i, k, t, c))
            .collect();
        merged.extend(row.hidden.iter().map(|&(i, h, c)| (i, 0, h, c)));
        out.survival.add_cells(
            &row.hidden
                .iter()
                .map(|&(i, h, _)| (i, 0, h))
                .collect::<Vec<_>>(),
            1,
        );
        (row.survival, row.survival_clear) = crate::accumulate::merge_cells(merged);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hiding_alike_gives_ratio_one_and_replacing_a_large_one() {
        // Two recordings hiding 5 % of kept and lost cells alike.
        let t = cmh(&[(5, 100, 50, 1000), (10, 200, 20, 400)], 0.01);
        assert!((t.odds_ratio.unwrap() - 1.0).abs() < 1e-9);
        assert!(t.p_value.unwrap() > 0.5);
        assert_eq!(t.recordings, 2);
        // Replacing: lost cells hidden 80 %, kept 1 %.
        let t = cmh(&[(80, 100, 10, 1000), (150, 200, 4, 400)], 0.01);
        assert!(t.odds_ratio.unwrap() > 100.0, "{t:?}");
        assert!(t.p_value.unwrap() < 1e-12);
        assert!((t.hidden_where_lost.unwrap() - 230.0 / 300.0).abs() < 1e-12);
        // A stratum with one kind only takes no part.
        let t = cmh(&[(80, 100, 0, 0)], 0.01);
        assert_eq!((t.recordings, t.odds_ratio, t.p_value), (0, None, None));
        // No kept return hidden: the ratio is unbounded, not a number.
        let t = cmh(&[(80, 100, 0, 1000)], 0.01);
        assert_eq!(t.odds_ratio, None);
        assert!(t.p_value.unwrap() < 1e-12 && t.hidden_where_kept == Some(0.0));
    }

    #[test]
    fn the_cmh_statistic_matches_a_hand_computation() {
        // One 2×2 table: a = 30 of n1 = 50, c = 10 of n0 = 50.
        // E[a] = 50·40/100 = 20; Var = 50·50·40·60/(100²·99) = 6.0606;
        // χ² = (|30 − 20| − 0.5)²/6.0606 = 14.891; p = erfc(√(χ²/2)).
        let t = cmh(&[(30, 50, 10, 50)], 0.01);
        let chi: f64 = 9.5f64.powi(2) / (50.0 * 50.0 * 40.0 * 60.0 / (1e4 * 99.0));
        assert!((t.p_value.unwrap() - libm::erfc((chi / 2.0).sqrt())).abs() < 1e-15);
        // OR = (30·40)/(10·20) = 6.
        assert!((t.odds_ratio.unwrap() - 6.0).abs() < 1e-12);
    }
}
