//! Fitting an extension term along a finding's covariate, on the fit set
//! only.
//!
//! The term is piecewise constant over the bins (or categories) of the
//! covariate, each bin's value estimated from the fit-set recordings with
//! the baseline model's own predictions:
//!
//! - `survival`: the factor on the vanishing distance that maximises the
//!   Bernoulli likelihood of the bin's kept/lost returns (golden-section
//!   search on `ln f` in [ln 0.2, ln 5]);
//! - `range`: the mean range residual of the bin's kept returns;
//! - `intensity`: `exp` of the mean log ratio of measured to reference
//!   reflectivity;
//! - `count`: `Σ(N_obs + ½) / Σ(N_sim + ½)` over the bin's recordings.
//!
//! Bins with too little data (fewer than [`MIN_TRIALS`] returns, or no
//! recording) take the pooled value, which is also the term's default.

use std::collections::BTreeMap;

use murk_types::{
    CoefficientTable, CovariateValue, ExtensionFunction, ExtensionObservable, ModelExtension,
};

use crate::DiagnoseError;
use crate::attribution::Binning;
use crate::data::Loaded;
use crate::evaluate::{P_FLOOR, RecEval, applier};

/// Fewest returns for a bin of its own.
pub const MIN_TRIALS: f64 = 50.0;

/// A covariate value for a survival/range/intensity item.
fn bin_of(
    binning: &Binning,
    covariate: &str,
    point: &murk_types::PointCovariates,
    scan: &BTreeMap<String, CovariateValue>,
) -> Option<usize> {
    match point.get(covariate) {
        Some(x) => binning.of_number(x),
        None => scan.get(covariate).and_then(|v| binning.of(v)),
    }
}

fn golden(mut f: impl FnMut(f64) -> f64, mut a: f64, mut b: f64) -> f64 {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let mut c = b - g * (b - a);
    let mut d = a + g * (b - a);
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..60 {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = f(d);
        }
    }
    0.5 * (a + b)
}

/// Fits the term on `observable` along `covariate` (bins `binning`) from the
/// fit-set evaluations `evals` under `table`.
pub fn fit_term(
    loaded: &Loaded,
    table: &CoefficientTable,
    evals: &[RecEval],
    observable: ExtensionObservable,
    covariate: &str,
    binning: &Binning,
) -> Result<ModelExtension, DiagnoseError> {
    let nb = binning.len();
    let cell = |c: u32| loaded.cells[c as usize].expect("reference cell");
    let (values, default): (Vec<Option<f64>>, f64) = match observable {
        ExtensionObservable::Survival => {
            // (applier index, r, ρ, kept, trials) per bin.
            type Item = (usize, f64, f64, f64, f64);
            let mut appliers = Vec::with_capacity(evals.len());
            let mut items: Vec<Vec<Item>> = vec![Vec::new(); nb];
            for e in evals {
                let rec = &loaded.recs[e.rec];
                appliers.push(applier(table, loaded, rec, false, 0)?);
                let a = appliers.len() - 1;
                for u in &rec.units {
                    let c = cell(u.cell);
                    if let Some(b) = bin_of(binning, covariate, &c.cov, &rec.scan) {
                        items[b].push((
                            a,
                            c.cov.range,
                            c.cov.reflectivity,
                            u.kept as f64,
                            u.trials as f64,
                        ));
                    }
                }
            }
            let ml = |its: &[&Item]| -> f64 {
                let nll = |lf: f64| -> f64 {
                    let f = lf.exp();
                    its.iter()
                        .map(|&&(a, r, rho, k, n)| {
                            let p = appliers[a]
                                .survival_probability(r, rho, f, false)
                                .clamp(P_FLOOR, 1.0 - P_FLOOR);
                            -(k * p.ln() + (n - k) * (1.0 - p).ln())
                        })
                        .sum()
                };
                golden(nll, 0.2f64.ln(), 5f64.ln()).exp()
            };
            let all: Vec<&Item> = items.iter().flatten().collect();
            let pooled = ml(&all);
            let v = items
                .iter()
                .map(|its| {
                    let n: f64 = its.iter().map(|i| i.4).sum();
                    (n >= MIN_TRIALS).then(|| ml(&its.iter().collect::<Vec<_>>()))
                })
                .collect();
            (v, pooled)
        }
        ExtensionObservable::Range | ExtensionObservable::Intensity => {
            let mut s = vec![(0.0f64, 0.0f64); nb];
            for e in evals {
                let rec = &loaded.recs[e.rec];
                let res = if observable == ExtensionObservable::Range {
                    &e.range_residual
                } else {
                    &e.intensity_residual
                };
                for (k, r) in rec.kept.iter().zip(res) {
                    if let Some(b) = bin_of(binning, covariate, &cell(k.cell).cov, &rec.scan) {
                        s[b].0 += r;
                        s[b].1 += 1.0;
                    }
                }
            }
            let tot = s.iter().fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
            let tf = |m: f64| {
                if observable == ExtensionObservable::Range {
                    m
                } else {
                    m.exp()
                }
            };
            let pooled = tf(tot.0 / tot.1.max(1.0));
            let v = s
                .iter()
                .map(|&(a, n)| (n >= MIN_TRIALS).then(|| tf(a / n)))
                .collect();
            (v, pooled)
        }
        ExtensionObservable::Count => {
            let mut s = vec![(0.0f64, 0.0f64); nb];
            for e in evals {
                let rec = &loaded.recs[e.rec];
                let (Some(sim), Some(v)) = (e.near_sim, rec.scan.get(covariate)) else {
                    continue;
                };
                if let Some(b) = binning.of(v) {
                    s[b].0 += rec.near as f64 + 0.5;
                    s[b].1 += sim + 0.5;
                }
            }
            let tot = s.iter().fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
            let pooled = if tot.1 > 0.0 { tot.0 / tot.1 } else { 1.0 };
            let v = s.iter().map(|&(o, x)| (x > 0.0).then(|| o / x)).collect();
            (v, pooled)
        }
    };
    let values: Vec<f64> = values.into_iter().map(|v| v.unwrap_or(default)).collect();
    let function = match binning {
        Binning::Numeric { edges } => ExtensionFunction::Bins {
            edges: edges.clone(),
            values,
        },
        Binning::Categories { names } => ExtensionFunction::Categories {
            values: names.iter().cloned().zip(values).collect(),
        },
    };
    let term = ModelExtension {
        observable,
        covariate: covariate.to_string(),
        function,
        default,
        description: format!(
            "{} along {covariate:?}, fitted by murk diagnose on {} recordings",
            observable.name(),
            evals.len()
        ),
    };
    term.check()
        .map_err(|r| DiagnoseError::Table(format!("fitted term is invalid: {r}")))?;
    Ok(term)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn golden_finds_a_minimum() {
        let x = golden(|x| (x - 0.7).powi(2), -2.0, 3.0);
        assert!((x - 0.7).abs() < 1e-9);
    }
}
