//! Quantiles with linear interpolation between order statistics (Hyndman &
//! Fan type 7, the default of numpy and pandas), so that the seed's estimator
//! and a numpy re-implementation agree to rounding.

/// Type-7 quantile of `values` (sorted in place). `None` when empty.
pub fn quantile(values: &mut [f64], q: f64) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let h = (values.len() - 1) as f64 * q;
    let lo = h.floor() as usize;
    let hi = (lo + 1).min(values.len() - 1);
    Some(values[lo] + (h - lo as f64) * (values[hi] - values[lo]))
}

/// Type-7 quantile of the multiset in which `x[i]` occurs `w[i]` times.
///
/// `x` must be sorted ascending (ties allowed). Equal to [`quantile`] of the
/// expanded values, without expanding them. `None` when the total weight is 0.
pub fn weighted_quantile_sorted(x: &[f64], w: &[u64], q: f64) -> Option<f64> {
    let n: u64 = w.iter().sum();
    if n == 0 {
        return None;
    }
    let h = (n - 1) as f64 * q;
    let lo = h.floor() as u64;
    let frac = h - lo as f64;
    // Value at expanded (0-based) index k < n.
    let value_at = |k: u64| {
        let mut seen = 0u64;
        for (xi, &wi) in x.iter().zip(w) {
            seen += wi;
            if k < seen {
                return *xi;
            }
        }
        x[x.len() - 1]
    };
    let a = value_at(lo);
    let b = if lo + 1 < n { value_at(lo + 1) } else { a };
    Some(a + frac * (b - a))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn known_answers_match_numpy() {
        // numpy.quantile([1, 2, 3, 4], 0.99) = 3.97; ([5], q) = 5.
        assert!((quantile(&mut [4.0, 1.0, 3.0, 2.0], 0.99).unwrap() - 3.97).abs() < 1e-12);
        assert_eq!(quantile(&mut [5.0], 0.3), Some(5.0));
        assert_eq!(quantile(&mut [], 0.5), None);
        // numpy.quantile([1, 1, 1, 2, 5, 5], 0.5) = 1.5
        let x = [1.0, 2.0, 5.0];
        assert_eq!(weighted_quantile_sorted(&x, &[3, 1, 2], 0.5), Some(1.5));
        assert_eq!(weighted_quantile_sorted(&x, &[0, 0, 0], 0.5), None);
    }

    proptest! {
        #[test]
        fn weighted_equals_expanded(
            pairs in proptest::collection::vec((0.0f64..100.0, 0u64..5), 1..40),
            q in 0.0f64..1.0,
        ) {
            let mut pairs = pairs;
            pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
            let x: Vec<f64> = pairs.iter().map(|p| p.0).collect();
            let w: Vec<u64> = pairs.iter().map(|p| p.1).collect();
            let mut expanded: Vec<f64> = pairs
                .iter()
                .flat_map(|&(v, k)| std::iter::repeat_n(v, k as usize))
                .collect();
            let want = quantile(&mut expanded, q);
            let got = weighted_quantile_sorted(&x, &w, q);
            match (want, got) {
                (None, None) => {}
                (Some(a), Some(b)) => prop_assert!((a - b).abs() < 1e-9, "{a} vs {b}"),
                other => prop_assert!(false, "{other:?}"),
            }
        }

        #[test]
        fn quantiles_are_monotone_in_q(
            v in proptest::collection::vec(-50.0f64..50.0, 1..30),
            q1 in 0.0f64..1.0,
            q2 in 0.0f64..1.0,
        ) {
            let (lo, hi) = if q1 <= q2 { (q1, q2) } else { (q2, q1) };
            let a = quantile(&mut v.clone(), lo).unwrap();
            let b = quantile(&mut v.clone(), hi).unwrap();
            prop_assert!(a <= b + 1e-12);
        }
    }
}
