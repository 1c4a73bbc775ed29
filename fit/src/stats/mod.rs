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
