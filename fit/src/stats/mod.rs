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
