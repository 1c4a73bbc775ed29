//! Does a residual depend on a covariate? Profiles, permutation tests over
//! recordings, and the strength of a dependence.
//!
//! Recordings, not points, are the independent evidence: the returns of one
//! scan share its weather, its MOR error and its sensor state. So:
//!
//! - **point-level covariates** (range, reflectivity, ring, elevation,
//!   azimuth): each recording contributes its residuals per covariate bin,
//!   *centred on the recording's own mean* (a scan-level offset is not a
//!   point-level dependence). The profile is the pooled centred mean per bin.
//!   Under "no dependence" each recording's centred contribution has mean 0,
//!   so the null distribution flips the sign of whole recordings
//!   ([`point_test`]);
//! - **scan-level covariates** (`mor`, every `weather.csv` column): one
//!   residual per recording; the profile is the mean residual per covariate
//!   bin or category, and the null shuffles the covariate across recordings
//!   ([`scan_test`]).
//!
//! The statistic is the weighted mean square of the profile. Its **strength**
//! is the root of what exceeds chance, `√max(0, T − mean T_null)`, in the
//! residual's unit, so a covariate with many bins does not look strong by
//! fitting noise. The p-value is the share of null statistics at least as
//! large (with the observed one counted).
//!
//! ```
//! use murk_diagnose::attribution::{Binning, point_test};
//!
//! // 12 recordings whose residual rises by 0.2 from covariate 0 to 1.
//! let mut units = Vec::new();
//! for rec in 0..12 {
//!     for i in 0..200 {
//!         let x = (i % 2) as f64;
//!         let noise = ((rec * 200 + i) as f64 * 0.7).sin() * 0.05;
//!         units.push((rec, x, 0.2 * x + noise, 1.0));
//!     }
//! }
//! let xs: Vec<f64> = units.iter().map(|u| u.1).collect();
//! let binning = Binning::numeric(&xs, 12);
//! let t = point_test(&units, 12, &binning, 999, 7);
//! assert!(t.p_value < 0.01);
//! assert!((t.strength - 0.1).abs() < 0.02); // the ±0.1 profile
//! ```

use murk_types::CovariateValue;
use rand::rngs::ChaCha8Rng;
use rand::seq::SliceRandom;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Distinct values up to which a numeric point-level covariate is binned by
/// value (scan-level covariates: see [`Binning::scan`]).
pub const MAX_DISTINCT_BINS: usize = 24;

/// Edges of up to `bins` equal-count bins of the sorted finite `v` (not
/// empty): the values at the `k·n/bins` positions, without repeats, and
/// none at the smallest value (it would leave bin 0 empty).
fn quantile_edges(v: &[f64], bins: usize) -> Vec<f64> {
    let n = v.len();
    let mut e: Vec<f64> = (1..bins).map(|k| v[(k * n / bins).min(n - 1)]).collect();
    e.dedup();
    e.retain(|x| *x > v[0]);
    e
}

/// How a covariate's values are grouped.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Binning {
    /// Numeric: bin `k` holds values with `k` edges at or below them.
    Numeric {
        /// Ascending edges.
        edges: Vec<f64>,
    },
    /// Categorical: one bin per category (sorted).
    Categories {
        /// The categories.
        names: Vec<String>,
    },
}

impl Binning {
    /// Bins for numeric values: one per distinct value when there are at
    /// most [`MAX_DISTINCT_BINS`], else up to `quantile_bins` equal-count
    /// bins.
    pub fn numeric(values: &[f64], quantile_bins: usize) -> Binning {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        v.sort_by(f64::total_cmp);
        let mut distinct = v.clone();
        distinct.dedup();
        let edges = if distinct.len() <= MAX_DISTINCT_BINS.max(quantile_bins) {
            distinct.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect()
        } else {
            quantile_edges(&v, quantile_bins)
        };
        Binning::Numeric { edges }
    }

    /// [`Binning::numeric`] of a multiset given as `(value, count)` pairs:
    /// the same edges, bit for bit, as `numeric` on the values each
    /// repeated `count` times, without holding them. The diagnosis bins a
    /// point covariate of millions of returns this way, from the counts of
    /// its reference cells.
    pub fn numeric_counted(values: &[(f64, u64)], quantile_bins: usize) -> Binning {
        let mut v: Vec<(f64, u64)> = values
            .iter()
            .copied()
            .filter(|(x, c)| x.is_finite() && *c > 0)
            .collect();
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        // Runs of bit-identical values (what the sorted multiset holds).
        let mut runs: Vec<(f64, u64)> = Vec::with_capacity(v.len());
        for (x, c) in v {
            match runs.last_mut() {
                Some(r) if r.0.total_cmp(&x).is_eq() => r.1 += c,
                _ => runs.push((x, c)),
            }
        }
        // `dedup` of the sorted values: equal by `==` (−0 and 0 too), the
        // first kept.
        let mut distinct: Vec<f64> = Vec::with_capacity(runs.len());
        for &(x, _) in &runs {
            if distinct.last() != Some(&x) {
                distinct.push(x);
            }
        }
        let edges = if distinct.len() <= MAX_DISTINCT_BINS.max(quantile_bins) {
            distinct.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect()
        } else {
            let n: u64 = runs.iter().map(|r| r.1).sum();
            // The value at position `i` of the sorted multiset.
            let mut ends = Vec::with_capacity(runs.len());
            let mut end = 0u64;
            for r in &runs {
                end += r.1;
                ends.push(end);
            }
            let at = |i: u64| runs[ends.partition_point(|&e| e <= i)].0;
            let q = quantile_bins as u64;
            let mut e: Vec<f64> = (1..q).map(|k| at((k * n / q).min(n - 1))).collect();
            e.dedup();
            let first = runs[0].0;
            e.retain(|x| *x > first);
            e
        };
        Binning::Numeric { edges }
    }

    /// One bin per category.
    pub fn categories<'a>(values: impl IntoIterator<Item = &'a str>) -> Binning {
        let mut names: Vec<String> = values.into_iter().map(str::to_string).collect();
        names.sort();
        names.dedup();
        Binning::Categories { names }
    }

    /// Bins for scan-level values (one per recording): categories for text,
    /// one bin per distinct value when there are at most `bins`, else
    /// `bins` equal-count (quantile) bins — ties can merge some, so fewer
    /// is possible, never more.
    pub fn scan(values: &[&CovariateValue], bins: usize) -> Binning {
        if values.iter().any(|v| matches!(v, CovariateValue::Text(_))) {
            return Binning::categories(values.iter().map(|v| match v {
                CovariateValue::Text(t) => t.as_str(),
                CovariateValue::Number(_) => "(number)",
            }));
        }
        let nums: Vec<f64> = values
            .iter()
            .filter_map(|v| match v {
                CovariateValue::Number(x) => Some(*x),
                CovariateValue::Text(_) => None,
            })
            .collect();
        let mut sorted: Vec<f64> = nums.into_iter().filter(|x| x.is_finite()).collect();
        sorted.sort_by(f64::total_cmp);
        let mut distinct = sorted.clone();
        distinct.dedup();
        let edges = if distinct.len() <= bins {
            distinct.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect()
        } else {
            // Never by value past `bins` (unlike a point covariate, whose
            // values each hold many returns): a continuous weather reading
            // has one value per recording, so on a campaign of up to
            // `MAX_DISTINCT_BINS` recordings each would sit in a bin of its
            // own, which no shuffle changes — the test could never tell.
            quantile_edges(&sorted, bins)
        };
        Binning::Numeric { edges }
    }

    /// Number of bins.
    pub fn len(&self) -> usize {
        match self {
            Binning::Numeric { edges } => edges.len() + 1,
            Binning::Categories { names } => names.len(),
        }
    }

    /// True when there is no bin.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The bin of a numeric value.
    pub fn of_number(&self, x: f64) -> Option<usize> {
        match self {
            Binning::Numeric { edges } if x.is_finite() => Some(edges.partition_point(|e| *e <= x)),
            _ => None,
        }
    }

    /// The bin of a covariate value.
    pub fn of(&self, v: &CovariateValue) -> Option<usize> {
        match (self, v) {
            (Binning::Numeric { .. }, CovariateValue::Number(x)) => self.of_number(*x),
            (Binning::Categories { names }, CovariateValue::Text(t)) => names.binary_search(t).ok(),
            _ => None,
        }
    }

    /// A label per bin (`[lo, hi)` ranges or the category).
    pub fn labels(&self) -> Vec<String> {
        match self {
            Binning::Categories { names } => names.clone(),
            Binning::Numeric { edges } => (0..=edges.len())
                .map(|k| {
                    let lo = if k == 0 {
                        "−∞".to_string()
                    } else {
                        fmt(edges[k - 1])
                    };
                    let hi = if k == edges.len() {
                        "∞".to_string()
                    } else {
                        fmt(edges[k])
                    };
                    format!("[{lo}, {hi})")
                })
                .collect(),
        }
    }
}

fn fmt(x: f64) -> String {
    let s = format!("{x:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    s.to_string()
}

/// One bin of a profile.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProfileBin {
    /// The bin (range or category).
    pub label: String,
    /// Mean of the covariate in the bin (numeric covariates).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub center: Option<f64>,
    /// Mean residual in the bin (centred per recording for point-level
    /// covariates, relative to the overall mean for scan-level ones).
    pub mean_residual: f64,
    /// Weight in the bin (trials or returns; recordings for scan-level).
    pub weight: f64,
    /// Recordings contributing.
    pub recordings: usize,
}

/// The outcome of one test.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TestOutcome {
    /// Root of the profile's mean square beyond chance, residual units.
    pub strength: f64,
    /// Root of the observed mean square (chance included).
    pub amplitude: f64,
    /// Permutation p-value.
    pub p_value: f64,
    /// Recordings with data.
    pub recordings: usize,
    /// The profile.
    pub profile: Vec<ProfileBin>,
}

fn finish(t: f64, null: &[f64], recordings: usize, profile: Vec<ProfileBin>) -> TestOutcome {
    let ge = null.iter().filter(|&&x| x >= t * (1.0 - 1e-12)).count();
    let mean_null = if null.is_empty() {
        0.0
    } else {
        null.iter().sum::<f64>() / null.len() as f64
    };
    TestOutcome {
        strength: (t - mean_null).max(0.0).sqrt(),
        amplitude: t.max(0.0).sqrt(),
        p_value: (1 + ge) as f64 / (1 + null.len()) as f64,
        recordings,
        profile,
    }
}

/// Tests a point-level covariate. `units` are `(recording, covariate value,
/// residual, weight)` with recordings numbered `0..recordings`; `seed`
/// drives the `permutations` sign flips.
pub fn point_test(
    units: &[(usize, f64, f64, f64)],
    recordings: usize,
    binning: &Binning,
    permutations: usize,
    seed: u64,
) -> TestOutcome {
    point_test_stream(
        units.iter().copied(),
        recordings,
        binning,
        permutations,
        seed,
    )
}

/// What a point-level test reads of its units: per recording and bin the
/// sums Σw·e and Σw, and per bin Σw·x (for the profile's centres).
///
/// The sums are all a test keeps, so one pass over an observable's units
/// can fill the sums of every covariate's test at once (a [`PointRow`]
/// per recording, in parallel), instead of a pass per test: a pass computes
/// every unit's residual (a keep probability per reference cell), which is
/// what a diagnosis spends its attribution time on. Σw·x is summed per
/// recording and the recordings' sums added in recording order, so a
/// streamed and a batched accumulation give the same bits.
#[derive(Debug, Clone, PartialEq)]
pub struct PointSums {
    /// Bins (at least 1).
    nb: usize,
    /// Σw·e per recording and bin (`r · nb + bin`).
    s: Vec<f64>,
    /// Σw per recording and bin.
    w: Vec<f64>,
    /// Σw·x per bin.
    xs: Vec<f64>,
}

/// One recording's part of a [`PointSums`].
#[derive(Debug, Clone, PartialEq)]
pub struct PointRow {
    /// Σw·e per bin.
    s: Vec<f64>,
    /// Σw per bin.
    w: Vec<f64>,
    /// Σw·x per bin.
    xs: Vec<f64>,
}

impl PointRow {
    /// An empty row for `binning`.
    pub fn new(binning: &Binning) -> PointRow {
        let nb = binning.len().max(1);
        PointRow {
            s: vec![0.0; nb],
            w: vec![0.0; nb],
            xs: vec![0.0; nb],
        }
    }

    /// Adds a unit of covariate value `x`, residual `e`, weight `wt`
    /// (nothing when `binning` places no bin at `x`).
    #[inline]
    pub fn add(&mut self, binning: &Binning, x: f64, e: f64, wt: f64) {
        if let Some(b) = binning.of_number(x) {
            self.add_at(b, x, e, wt);
        }
    }

    /// Adds a unit to bin `b` (which must be one of the row's).
    #[inline]
    pub fn add_at(&mut self, b: usize, x: f64, e: f64, wt: f64) {
        self.s[b] += wt * e;
        self.w[b] += wt;
        self.xs[b] += wt * x;
    }
}

impl PointSums {
    /// Sums of `recordings` recordings from their rows (in recording
    /// order; a recording without units may be given an empty row).
    pub fn from_rows(rows: impl IntoIterator<Item = PointRow>, binning: &Binning) -> PointSums {
        let nb = binning.len().max(1);
        let mut out = PointSums {
            nb,
            s: Vec::new(),
            w: Vec::new(),
            xs: vec![0.0; nb],
        };
        for row in rows {
            out.s.extend_from_slice(&row.s);
            out.w.extend_from_slice(&row.w);
            for (a, b) in out.xs.iter_mut().zip(&row.xs) {
                *a += b;
            }
        }
        out
    }

    /// Sums of units streamed recording by recording (`(recording, x, e,
    /// w)`, recordings ascending in `0..recordings`).
    pub fn of_units(
        units: impl IntoIterator<Item = (usize, f64, f64, f64)>,
        recordings: usize,
        binning: &Binning,
    ) -> PointSums {
        let mut rows: Vec<PointRow> = (0..recordings).map(|_| PointRow::new(binning)).collect();
        for (r, x, e, wt) in units {
            rows[r].add(binning, x, e, wt);
        }
        PointSums::from_rows(rows, binning)
    }

    /// Bins (at least 1).
    pub fn bins(&self) -> usize {
        self.nb
    }

    /// Recordings summed.
    pub fn recordings(&self) -> usize {
        self.s.len() / self.nb
    }

    /// `(Σw·e, Σw)` per recording and bin, and Σw·x per bin.
    pub fn parts(&self) -> (&[f64], &[f64], &[f64]) {
        (&self.s, &self.w, &self.xs)
    }
}

/// [`point_test`] on units produced one at a time (in the same order, the
/// same outcome bit for bit): the test holds per recording and bin two
/// sums, never the units.
pub fn point_test_stream(
    units: impl IntoIterator<Item = (usize, f64, f64, f64)>,
    recordings: usize,
    binning: &Binning,
    permutations: usize,
    seed: u64,
) -> TestOutcome {
    point_test_sums(
        &PointSums::of_units(units, recordings, binning),
        binning,
        permutations,
        seed,
    )
}

/// [`point_test`] on the units' sums.
pub fn point_test_sums(
    sums: &PointSums,
    binning: &Binning,
    permutations: usize,
    seed: u64,
) -> TestOutcome {
    let nb = sums.nb;
    debug_assert_eq!(nb, binning.len().max(1), "sums of another binning");
    let recordings = sums.recordings();
    let (s, w, xs) = sums.parts();
    // Centre each recording on its own mean.
    let mut d = vec![0.0; recordings * nb];
    let mut used = 0;
    for r in 0..recordings {
        let (sr, wr): (f64, f64) = (0..nb).fold((0.0, 0.0), |(a, b), k| {
            (a + s[r * nb + k], b + w[r * nb + k])
        });
        if wr <= 0.0 {
            continue;
        }
        let occupied = (0..nb).filter(|&k| w[r * nb + k] > 0.0).count();
        if occupied >= 2 {
            used += 1;
        }
        let m = sr / wr;
        for k in 0..nb {
            d[r * nb + k] = s[r * nb + k] - w[r * nb + k] * m;
        }
    }
    let wb: Vec<f64> = (0..nb)
        .map(|k| (0..recordings).map(|r| w[r * nb + k]).sum())
        .collect();
    let wt: f64 = wb.iter().sum();
    let stat = |signs: &[f64]| -> f64 {
        if wt <= 0.0 {
            return 0.0;
        }
        let mut t = 0.0;
        for k in 0..nb {
            if wb[k] <= 0.0 {
                continue;
            }
            let pk: f64 = (0..recordings)
                .map(|r| signs[r] * d[r * nb + k])
                .sum::<f64>()
                / wb[k];
            t += wb[k] * pk * pk;
        }
        t / wt
    };
    let ones = vec![1.0; recordings];
    let t = stat(&ones);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut signs = vec![1.0; recordings];
    let null: Vec<f64> = (0..permutations)
        .map(|_| {
            for x in signs.iter_mut() {
                *x = if rng.random::<bool>() { 1.0 } else { -1.0 };
            }
            stat(&signs)
        })
        .collect();
    let labels = binning.labels();
    let profile = (0..nb)
        .filter(|&k| wb[k] > 0.0)
        .map(|k| ProfileBin {
            label: labels.get(k).cloned().unwrap_or_default(),
            center: Some(xs[k] / wb[k]),
            mean_residual: (0..recordings).map(|r| d[r * nb + k]).sum::<f64>() / wb[k],
            weight: wb[k],
            recordings: (0..recordings).filter(|&r| w[r * nb + k] > 0.0).count(),
        })
        .collect();
    finish(t, &null, used, profile)
}

/// Tests a scan-level covariate: one `(value, residual)` per recording
/// (recordings without a value left out before).
pub fn scan_test(
    values: &[(&CovariateValue, f64)],
    binning: &Binning,
    permutations: usize,
    seed: u64,
) -> TestOutcome {
    let nb = binning.len().max(1);
    let mut bins: Vec<usize> = Vec::with_capacity(values.len());
    let mut es: Vec<f64> = Vec::with_capacity(values.len());
    let mut xs: Vec<Option<f64>> = Vec::with_capacity(values.len());
    for (v, e) in values {
        if let Some(b) = binning.of(v) {
            bins.push(b);
            es.push(*e);
            xs.push(match v {
                CovariateValue::Number(x) => Some(*x),
                CovariateValue::Text(_) => None,
            });
        }
    }
    let n = es.len();
    let mean = es.iter().sum::<f64>() / n.max(1) as f64;
    let stat = |order: &[usize]| -> f64 {
        // order[i]: which residual goes with bin of recording i.
        let mut s = vec![0.0; nb];
        let mut c = vec![0.0; nb];
        for (i, &b) in bins.iter().enumerate() {
            s[b] += es[order[i]] - mean;
            c[b] += 1.0;
        }
        (0..nb)
            .filter(|&k| c[k] > 0.0)
            .map(|k| s[k] * s[k] / c[k])
            .sum::<f64>()
            / n.max(1) as f64
    };
    let identity: Vec<usize> = (0..n).collect();
    let t = stat(&identity);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut order = identity.clone();
    let null: Vec<f64> = (0..permutations)
        .map(|_| {
            order.shuffle(&mut rng);
            stat(&order)
        })
        .collect();
    let labels = binning.labels();
    let mut per: BTreeMap<usize, (f64, f64, f64, usize)> = BTreeMap::new();
    for i in 0..n {
        let e = per.entry(bins[i]).or_default();
        e.0 += es[i] - mean;
        e.1 += 1.0;
        e.2 += xs[i].unwrap_or(f64::NAN);
        e.3 += 1;
    }
    let profile = per
        .into_iter()
        .map(|(k, (s, c, x, m))| ProfileBin {
            label: labels.get(k).cloned().unwrap_or_default(),
            center: (x / c).is_finite().then_some(x / c),
            mean_residual: s / c,
            weight: c,
            recordings: m,
        })
        .collect();
    finish(t, &null, n, profile)
}

/// One-sided paired test that `d` (per-recording loss before − after, one
/// per held-out recording) is positive on average: the null flips the sign
/// of each recording's difference (`permutations` draws from `seed`).
/// Returns the p-value (the observed mean counted among the null draws);
/// 1 when there is no difference to test.
///
/// ```
/// use murk_diagnose::attribution::paired_gain_test;
/// let d: Vec<f64> = (0..20).map(|i| 0.01 + 0.002 * ((i * 7 % 5) as f64 - 2.0)).collect();
/// assert!(paired_gain_test(&d, 999, 1) < 0.01);
/// let mixed: Vec<f64> = (0..20).map(|i| if i % 2 == 0 { 0.01 } else { -0.01 }).collect();
/// assert!(paired_gain_test(&mixed, 999, 1) > 0.3);
/// ```
pub fn paired_gain_test(d: &[f64], permutations: usize, seed: u64) -> f64 {
    let d: Vec<f64> = d.iter().copied().filter(|x| x.is_finite()).collect();
    if d.is_empty() || d.iter().all(|x| *x == 0.0) {
        return 1.0;
    }
    let t: f64 = d.iter().sum();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let ge = (0..permutations)
        .filter(|_| {
            let s: f64 = d
                .iter()
                .map(|x| if rng.random::<bool>() { *x } else { -*x })
                .sum();
            s >= t * (1.0 - 1e-12)
        })
        .count();
    (1 + ge) as f64 / (1 + permutations) as f64
}

/// Holm's step-down adjustment of p-values (family-wise error).
pub fn holm(p: &[f64]) -> Vec<f64> {
    let m = p.len();
    let mut idx: Vec<usize> = (0..m).collect();
    idx.sort_by(|&a, &b| p[a].total_cmp(&p[b]));
    let mut out = vec![1.0; m];
    let mut running: f64 = 0.0;
    for (rank, &i) in idx.iter().enumerate() {
        let adj = ((m - rank) as f64 * p[i]).min(1.0);
        running = running.max(adj);
        out[i] = running;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(seed: &mut u64) -> f64 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    }

    #[test]
    fn point_test_ignores_recording_offsets_and_finds_dependence() {
        let mut g = 1;
        // Null: big per-recording offsets, no dependence on x.
        let mut null_units = Vec::new();
        let mut dep_units = Vec::new();
        for r in 0..20 {
            let offset = lcg(&mut g) * 2.0;
            for i in 0..300 {
                let x = (i % 10) as f64;
                let noise = lcg(&mut g) * 0.5;
                null_units.push((r, x, offset + noise, 1.0));
                dep_units.push((r, x, offset + noise + 0.01 * x, 1.0));
            }
        }
        let xs: Vec<f64> = null_units.iter().map(|u| u.1).collect();
        let b = Binning::numeric(&xs, 12);
        assert_eq!(b.len(), 10);
        let n = point_test(&null_units, 20, &b, 999, 3);
        assert!(n.p_value > 0.01, "{n:?}");
        assert!(n.strength < 0.01, "{}", n.strength);
        let d = point_test(&dep_units, 20, &b, 999, 3);
        assert!(d.p_value < 0.005, "{}", d.p_value);
        // Profile of 0.01·x centred: RMS over x = 0..9 is 0.01·√8.25.
        assert!(
            (d.strength - 0.01 * 8.25f64.sqrt()).abs() < 0.006,
            "{}",
            d.strength
        );
        let slope = d.profile[9].mean_residual - d.profile[0].mean_residual;
        assert!((slope - 0.09).abs() < 0.02, "{slope}");
    }

    #[test]
    fn scan_test_finds_categories_and_not_noise() {
        let mut g = 9;
        let wet = CovariateValue::Text("wet".into());
        let dry = CovariateValue::Text("dry".into());
        let vals: Vec<(&CovariateValue, f64)> = (0..30)
            .map(|i| {
                let v = if i % 3 == 0 { &wet } else { &dry };
                let e = lcg(&mut g) * 0.1 + if i % 3 == 0 { 0.2 } else { 0.0 };
                (v, e)
            })
            .collect();
        let vs: Vec<&CovariateValue> = vals.iter().map(|v| v.0).collect();
        let b = Binning::scan(&vs, 5);
        assert_eq!(b.len(), 2);
        let t = scan_test(&vals, &b, 999, 1);
        assert!(t.p_value < 0.01);
        // Shuffled residuals: no dependence.
        let mut shuffled = vals.clone();
        for (i, v) in shuffled.iter_mut().enumerate() {
            v.1 = lcg(&mut g) * 0.1 + (i as f64 * 0.0);
        }
        let t = scan_test(&shuffled, &b, 999, 1);
        assert!(t.p_value > 0.01, "{}", t.p_value);
    }

    #[test]
    fn scan_bins_continuous_readings_by_quantile_on_small_campaigns() {
        // 16 recordings, one continuous reading each (all distinct, as a
        // temperature column is): 4 equal-count bins, never one per
        // recording, so the shuffle test can see a trend along it.
        let mut g = 21;
        let temps: Vec<CovariateValue> = (0..16)
            .map(|i| CovariateValue::Number(-5.0 + i as f64 * 0.37 + lcg(&mut g) * 0.01))
            .collect();
        let vals: Vec<(&CovariateValue, f64)> = temps
            .iter()
            .enumerate()
            .map(|(i, v)| (v, 0.02 * i as f64 + lcg(&mut g) * 0.02))
            .collect();
        let vs: Vec<&CovariateValue> = vals.iter().map(|v| v.0).collect();
        let b = Binning::scan(&vs, 4);
        assert_eq!(b.len(), 4, "{b:?}");
        let mut counts = [0; 4];
        for v in &vs {
            counts[b.of(v).unwrap()] += 1;
        }
        assert_eq!(counts, [4; 4]);
        let t = scan_test(&vals, &b, 999, 3);
        assert!(t.p_value < 0.01, "{}", t.p_value);
        // Few distinct values: still one bin per value.
        let few: Vec<CovariateValue> = (0..16)
            .map(|i| CovariateValue::Number((i % 3) as f64))
            .collect();
        let vs: Vec<&CovariateValue> = few.iter().collect();
        assert_eq!(Binning::scan(&vs, 4).len(), 3);
        // Ties at a quantile merge bins instead of leaving one empty.
        let tied: Vec<CovariateValue> = (0..16)
            .map(|i| CovariateValue::Number(if i < 10 { 1.0 } else { i as f64 }))
            .collect();
        let vs: Vec<&CovariateValue> = tied.iter().collect();
        let b = Binning::scan(&vs, 4);
        let mut counts = vec![0; b.len()];
        for v in &vs {
            counts[b.of(v).unwrap()] += 1;
        }
        assert!(counts.iter().all(|&c| c > 0), "{counts:?}");
        assert!(b.len() >= 2 && b.len() <= 4, "{b:?}");
    }

    #[test]
    fn holm_is_monotone_and_bounded() {
        let p = [0.01, 0.04, 0.03, 0.5];
        let a = holm(&p);
        assert_eq!(a, vec![0.04, 0.09, 0.09, 0.5]);
    }

    #[test]
    fn counted_binning_equals_binning_the_repeated_values() {
        let mut g = 5;
        for case in 0..40 {
            // Few distinct values (by value), many (quantiles), ties, zeros
            // of both signs, non-finite values.
            let distinct = [3, 20, 30, 200][case % 4];
            let mut counted: Vec<(f64, u64)> = (0..distinct)
                .map(|i| {
                    let x = ((lcg(&mut g) + 0.5) * 40.0).round() / 4.0 - 2.0;
                    let x = if i % 17 == 0 {
                        -0.0
                    } else if i % 13 == 0 {
                        0.0
                    } else {
                        x
                    };
                    (x, ((lcg(&mut g) + 0.5) * 9.0) as u64)
                })
                .collect();
            counted.push((f64::NAN, 3));
            counted.push((f64::INFINITY, 2));
            let repeated: Vec<f64> = counted
                .iter()
                .flat_map(|&(x, c)| std::iter::repeat_n(x, c as usize))
                .collect();
            for q in [2, 4, 12] {
                let a = Binning::numeric(&repeated, q);
                let b = Binning::numeric_counted(&counted, q);
                let bits = |b: &Binning| match b {
                    Binning::Numeric { edges } => {
                        edges.iter().map(|e| e.to_bits()).collect::<Vec<_>>()
                    }
                    Binning::Categories { .. } => unreachable!(),
                };
                assert_eq!(bits(&a), bits(&b), "case {case}, {q} bins");
            }
        }
    }

    #[test]
    fn binning_by_value_and_quantile() {
        let b = Binning::numeric(&[1.0, 2.0, 2.0, 3.0], 12);
        assert_eq!(
            b,
            Binning::Numeric {
                edges: vec![1.5, 2.5]
            }
        );
        let many: Vec<f64> = (0..1000).map(|i| i as f64).collect();
        let b = Binning::numeric(&many, 10);
        assert_eq!(b.len(), 10);
        assert_eq!(b.of_number(0.0), Some(0));
        assert_eq!(b.of_number(999.0), Some(9));
    }
}
