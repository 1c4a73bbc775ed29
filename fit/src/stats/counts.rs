//! Counts per scan as a function of MOR: Poisson maximum likelihood of the
//! power law `N(MOR) = n_ref · (mor_ref / MOR)^k`.
//!
//! The power law is linear in log space (`ln λ = ln n_ref + k·ln(mor_ref/MOR)`),
//! so this is a Poisson GLM with a log link: its likelihood is concave and the
//! optimum unique. Counts of zero are data, not gaps.

use crate::stats::optim::{INVALID, minimize};

/// A fitted power law.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PowerLaw {
    /// Expected count at `mor_ref`.
    pub n_ref: f64,
    /// Reference MOR, metres.
    pub mor_ref: f64,
    /// Exponent `k`.
    pub exponent: f64,
    /// Standard error of `n_ref` (inverse Fisher information).
    pub n_ref_std_error: f64,
    /// Standard error of `exponent`.
    pub exponent_std_error: f64,
}

impl PowerLaw {
    /// Expected count at `mor`.
    #[cfg(test)]
    pub fn expected(&self, mor: f64) -> f64 {
        self.n_ref * (self.mor_ref / mor).powf(self.exponent)
    }
}

/// Why a count law could not be fitted.
#[derive(Debug, Clone, PartialEq)]
pub enum CountLawFailure {
    /// No recording, or no count at all.
    NoCounts,
    /// Every recording has the same MOR: the exponent is not identified.
    SingleMor,
}

/// Poisson ML of the power law on `(mor, count)` pairs.
#[cfg(test)]
pub fn fit_power_law(data: &[(f64, u64)], mor_ref: f64) -> Result<PowerLaw, CountLawFailure> {
    let exposed: Vec<(f64, u64, f64)> = data.iter().map(|&(m, c)| (m, c, 1.0)).collect();
    fit_power_law_exposed(&exposed, mor_ref)
}

/// Poisson ML of the power law on `(mor, count, exposure)` triples: recording
/// i's count has mean `exposure_i · N(mor_i)` (a GLM offset). The exposure is
/// the share of the law's returns the recording could show (those not hidden
/// behind nearer returns of their ray), so `N` is the generating rate.
pub fn fit_power_law_exposed(
    data: &[(f64, u64, f64)],
    mor_ref: f64,
) -> Result<PowerLaw, CountLawFailure> {
    let data: Vec<(f64, u64, f64)> = data.iter().copied().filter(|d| d.2 > 0.0).collect();
    let total: u64 = data.iter().map(|d| d.1).sum();
    if data.is_empty() || total == 0 {
        return Err(CountLawFailure::NoCounts);
    }
    let first = data[0].0;
    if data.iter().all(|d| d.0 == first) {
        return Err(CountLawFailure::SingleMor);
    }
    // Centre on the geometric mean MOR so that the two parameters are nearly
    // uncorrelated, then move the reference to `mor_ref`.
    let lm: f64 = data.iter().map(|d| d.0.ln()).sum::<f64>() / data.len() as f64;
    let xs: Vec<(f64, f64, f64)> = data
        .iter()
        .map(|&(m, c, e)| (lm - m.ln(), c as f64, e.ln()))
        .collect();
    let nll = |p: &[f64]| {
        let (a, k) = (p[0], p[1]);
        let mut s = 0.0;
        for &(x, c, off) in &xs {
            let eta = off + a + k * x;
            if eta > 700.0 {
                return INVALID;
            }
            s += eta.exp() - c * eta;
        }
        s
    };
    let exposure: f64 = data.iter().map(|d| d.2).sum();
    let a0 = (total as f64 / exposure).ln();
    let m = minimize(&nll, &[a0, 0.0], &[0.2, 0.5]);
    let (a, k) = (m.x[0], m.x[1]);
    let z = lm - mor_ref.ln();
    let n_ref = (a + k * z).exp();
    // Fisher information of the log-link Poisson GLM: Σ λᵢ [1 xᵢ; xᵢ xᵢ²].
    let (mut i00, mut i01, mut i11) = (0.0, 0.0, 0.0);
    for &(x, _, off) in &xs {
        let l = (off + a + k * x).exp();
        i00 += l;
        i01 += l * x;
        i11 += l * x * x;
    }
    let det = i00 * i11 - i01 * i01;
    let (v00, v01, v11) = if det > 0.0 {
        (i11 / det, -i01 / det, i00 / det)
    } else {
        (f64::INFINITY, 0.0, f64::INFINITY)
    };
    // ln n_ref = a + k·z: its variance by the delta method.
    let var_ln_n = v00 + 2.0 * z * v01 + z * z * v11;
    Ok(PowerLaw {
        n_ref,
        mor_ref,
        exponent: k,
        n_ref_std_error: n_ref * var_ln_n.max(0.0).sqrt(),
        exponent_std_error: v11.max(0.0).sqrt(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{SeedableRng, rngs::ChaCha8Rng};
    use rand_distr::{Distribution, Poisson};

    #[test]
    fn recovers_a_power_law_from_poisson_counts() {
        // 400 scans, MOR 40–400 m, N = 30·(100/MOR)^1.5. With ~20 counts per
        // scan the standard errors are ≈ 1 % on n_ref and ≈ 0.02 on k.
        let truth = PowerLaw {
            n_ref: 30.0,
            mor_ref: 100.0,
            exponent: 1.5,
            n_ref_std_error: 0.0,
            exponent_std_error: 0.0,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let data: Vec<(f64, u64)> = (0..400)
            .map(|i| {
                let mor = 40.0 + 360.0 * (i as f64 / 399.0);
                let c: f64 = Poisson::new(truth.expected(mor)).unwrap().sample(&mut rng);
                (mor, c as u64)
            })
            .collect();
        let f = fit_power_law(&data, 100.0).unwrap();
        assert!((f.n_ref / 30.0 - 1.0).abs() < 0.05, "{f:?}");
        assert!((f.exponent - 1.5).abs() < 0.08, "{f:?}");
    }

    #[test]
    fn degenerate_inputs_are_named() {
        assert_eq!(
            fit_power_law(&[(50.0, 0), (80.0, 0)], 100.0),
            Err(CountLawFailure::NoCounts)
        );
        assert_eq!(
            fit_power_law(&[(50.0, 3), (50.0, 4)], 100.0),
            Err(CountLawFailure::SingleMor)
        );
    }

    #[test]
    fn exposure_restores_counts_hidden_in_dense_weather() {
        // N = 30·(100/MOR)^1.5, but only a share 1 − N/200 of each scan's
        // returns can be seen (crowding grows as MOR falls): the plain fit
        // flattens the exponent, the exposed one does not.
        let truth = PowerLaw {
            n_ref: 30.0,
            mor_ref: 100.0,
            exponent: 1.5,
            n_ref_std_error: 0.0,
            exponent_std_error: 0.0,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut plain = Vec::new();
        let mut exposed = Vec::new();
        for i in 0..400 {
            let mor = 40.0 + 360.0 * (i as f64 / 399.0);
            let n = truth.expected(mor);
            let e = 1.0 - n / 200.0;
            let c = Poisson::new(n * e).unwrap().sample(&mut rng) as u64;
            plain.push((mor, c));
            exposed.push((mor, c, e));
        }
        let p = fit_power_law(&plain, 100.0).unwrap();
        let f = fit_power_law_exposed(&exposed, 100.0).unwrap();
        assert!(p.exponent < 1.4, "plain fit should flatten: {}", p.exponent);
        assert!((f.exponent - 1.5).abs() < 0.05, "{}", f.exponent);
        assert!((f.n_ref / 30.0 - 1.0).abs() < 0.03, "{}", f.n_ref);
    }
}
