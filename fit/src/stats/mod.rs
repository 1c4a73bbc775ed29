//! Generic statistics on in-memory values: distributions, a minimiser,
//! quantiles, regressions, truncated-normal and Poisson likelihood fits, and
//! the bootstrap. Nothing here knows about LiDAR, campaigns or files.

pub mod bootstrap;
pub mod counts;
pub mod dist;
pub mod optim;
pub mod quantile;
pub mod regress;
pub mod truncnorm;

/// Folds over units interleaved in the order of `keys` (ties by index):
/// unit of rank `r` goes to fold `r % folds`, so every fold spans the range
/// of the key (the held-out comparisons over recordings use MOR, or a
/// function of it). Returns each unit's fold.
pub fn interleaved_folds(keys: &[f64], folds: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..keys.len()).collect();
    order.sort_by(|&a, &b| keys[a].total_cmp(&keys[b]).then(a.cmp(&b)));
    let mut fold_of = vec![0usize; keys.len()];
    for (rank, &g) in order.iter().enumerate() {
        fold_of[g] = rank % folds;
    }
    fold_of
}

/// The grouped-jackknife standard error and 95 % half-width of an estimate
/// from its values with each of `k ≥ 3` groups left out: variance
/// `(k − 1)/k · Σ (θ₋g − θ̄)²`, Student's t on `k − 1` degrees of freedom
/// (the delete-a-group jackknife). `None` with fewer than three groups or a
/// non-finite value.
pub fn jackknife(leave_out: &[f64]) -> Option<(f64, f64)> {
    let k = leave_out.len();
    if k < 3 || leave_out.iter().any(|x| !x.is_finite()) {
        return None;
    }
    let kf = k as f64;
    let mean = leave_out.iter().sum::<f64>() / kf;
    let var = (kf - 1.0) / kf * leave_out.iter().map(|c| (c - mean).powi(2)).sum::<f64>();
    let se = var.sqrt();
    Some((se, crate::survival::student_t_975(kf - 1.0) * se))
}

/// The leave-one-unit-out ("CR3") cluster-robust covariance of an
/// M-estimate: `(G−1)/G · Σ_g Δ_g Δ_gᵀ` with `Δ_g = (H − H_g)⁻¹ s_g`, one
/// Newton step of the fit without unit `g`. `info` is the whole fit's
/// information `H`, `inverse` its inverse; `units` yields each unit's score
/// `s_g` and information `H_g` at the optimum. A unit whose removal leaves
/// `H − H_g` singular (it alone pins a parameter) contributes the
/// sandwich's step `H⁻¹ s_g`; a step that is not finite either is left
/// out. Bell & McCaffrey (2002); MacKinnon, Nielsen & Webb (2023): for a
/// linear model this is exactly CR3, and unlike the sandwich `H⁻¹ B H⁻¹` it
/// does not run narrow with tens of units, because a unit that pulls the
/// optimum towards itself no longer looks close to it.
pub fn leave_one_out_covariance(
    info: &[Vec<f64>],
    inverse: &[Vec<f64>],
    units: impl IntoIterator<Item = (Vec<f64>, Vec<Vec<f64>>)>,
) -> Vec<Vec<f64>> {
    let p = info.len();
    let apply = |m: &[Vec<f64>], x: &[f64]| -> Vec<f64> {
        m.iter()
            .map(|row| row.iter().zip(x).map(|(a, b)| a * b).sum())
            .collect()
    };
    let finite = |d: &Vec<f64>| d.iter().all(|x| x.is_finite());
    let mut v = vec![vec![0.0; p]; p];
    let mut g_n = 0usize;
    for (score, own) in units {
        g_n += 1;
        let rest: Vec<Vec<f64>> = info
            .iter()
            .zip(&own)
            .map(|(r, o)| r.iter().zip(o).map(|(x, y)| x - y).collect())
            .collect();
        let step = optim::invert(&rest)
            .map(|r| apply(&r, &score))
            .filter(finite)
            .unwrap_or_else(|| apply(inverse, &score));
        if finite(&step) {
            for i in 0..p {
                for j in 0..p {
                    v[i][j] += step[i] * step[j];
                }
            }
        }
    }
    let scale = if g_n > 0 {
        (g_n as f64 - 1.0) / g_n as f64
    } else {
        0.0
    };
    for row in &mut v {
        for x in row.iter_mut() {
            *x *= scale;
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    /// For least squares (information `XᵀX`, a unit's `x xᵀ`, score
    /// `x·e`) the leave-one-out covariance is the jackknife's: the spread
    /// of the slopes refitted without each point, computed exactly here.
    #[test]
    fn leave_one_out_covariance_is_the_jackknife_for_least_squares() {
        let xs = [1.0, 2.0, 3.0, 4.0, 6.0, 9.0];
        let ys = [1.2, 1.9, 3.3, 3.8, 6.4, 8.7];
        let sxx: f64 = xs.iter().map(|x| x * x).sum();
        let sxy: f64 = xs.iter().zip(&ys).map(|(x, y)| x * y).sum();
        let b = sxy / sxx;
        let units = xs
            .iter()
            .zip(&ys)
            .map(|(x, y)| (vec![x * (y - b * x)], vec![vec![x * x]]));
        let v = leave_one_out_covariance(&[vec![sxx]], &[vec![1.0 / sxx]], units);
        // Slopes without point g, exactly; uncentred around the full fit.
        let n = xs.len() as f64;
        let jack: f64 = (0..xs.len())
            .map(|g| {
                let bg = (sxy - xs[g] * ys[g]) / (sxx - xs[g] * xs[g]);
                (bg - b).powi(2)
            })
            .sum::<f64>()
            * (n - 1.0)
            / n;
        assert!(
            (v[0][0] / jack - 1.0).abs() < 1e-12,
            "{} vs {jack}",
            v[0][0]
        );
    }
}
