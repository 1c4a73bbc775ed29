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
//! - `count`: `Σ(N_obs + ½) / Σ(N_sim + ½)` over the bin's recordings; along
//!   `ring`, `elevation` or `azimuth`, `(Σn_obs + ½)/(Σn_sim + ½)` over the
//!   bin's lasers or azimuth sectors in every recording (a factor on the density of the near-range
//!   returns on those rays).
//!
//! Every term is fitted on top of the terms the table already has (the
//! stagewise loop adds one at a time): survival factors multiply theirs,
//! and the other observables' residuals already have theirs removed.
//!
//! Bins with too little data (fewer than [`MIN_TRIALS`] returns, or no
//! recording) take the pooled value, which is also the term's default.

use std::collections::BTreeMap;

use serde::Serialize;

use murk_types::{
    CoefficientTable, CovariateValue, ExtensionFunction, ExtensionObservable, ModelExtension,
};

use crate::DiagnoseError;
use crate::attribution::Binning;
use crate::data::Loaded;
use crate::evaluate::{P_FLOOR, RecEval, applier, extension_value};

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

/// Golden-section steps: the bracket shrinks by 0.618 per step (to 1e−7 of
/// its width).
const GOLDEN_STEPS: usize = 34;

fn golden(mut f: impl FnMut(f64) -> f64, mut a: f64, mut b: f64) -> f64 {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let mut c = b - g * (b - a);
    let mut d = a + g * (b - a);
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..GOLDEN_STEPS {
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
    fit_term_with_edge(loaded, table, evals, observable, covariate, binning, false).map(|t| t.term)
}

/// A fitted term, and for survival the factor on the soft edge's widths
/// re-fitted with it.
#[derive(Debug, Clone, PartialEq)]
pub struct FittedTerm {
    /// The term.
    pub term: ModelExtension,
    /// The soft edge re-fitted with a survival term (when asked and the
    /// table has one): the baseline's edge was fitted on recordings that
    /// hold the effect the term now models, which distorts its width,
    /// dropout and residual; re-fitting them with the term removes that
    /// echo (a survival misfit along range, and azimuth on a static site).
    pub edge: Option<EdgeRefit>,
}

impl FittedTerm {
    /// `table` with the term added (and the edge widths scaled) for
    /// `weather`.
    pub fn apply_to(&self, table: &mut CoefficientTable, weather: murk_types::WeatherClass) {
        if let Some(w) = table.weathers.get_mut(&weather) {
            w.extensions.push(self.term.clone());
            if let Some(r) = self.edge {
                for b in w.vanishing_slope.iter_mut() {
                    if let Some(e) = b.edge_width.as_mut() {
                        *e *= r.width_factor;
                    }
                }
                if let Some(s) = w.survival.as_mut() {
                    s.dropout = r.dropout;
                    s.residual = r.residual;
                }
            }
        }
    }
}

/// [`fit_term`], re-fitting the soft edge's width with a survival term when
/// `refit_edge` is true (coordinate descent: the bins' factors, then one
/// width factor over every return, twice).
pub fn fit_term_with_edge(
    loaded: &Loaded,
    table: &CoefficientTable,
    evals: &[RecEval],
    observable: ExtensionObservable,
    covariate: &str,
    binning: &Binning,
    refit_edge: bool,
) -> Result<FittedTerm, DiagnoseError> {
    let nb = binning.len();
    let cell = |c: u32| loaded.cells[c as usize].expect("reference cell");
    let mut edge = None;
    let (values, default): (Vec<Option<f64>>, f64) = match observable {
        ExtensionObservable::Survival => {
            let (v, pooled, e) =
                fit_survival(loaded, table, evals, covariate, binning, refit_edge)?;
            edge = e;
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
        ExtensionObservable::Count if murk_types::COUNT_RAY_COVARIATES.contains(&covariate) => {
            // Per bin of lasers (or azimuth sectors): (Σn_obs + ½)/(Σn_sim + ½)
            // over the fit set's recordings and the bin's units (a pseudo
            // count per unit would pull sparse bins to 1), the factor
            // on the density of the returns on those rays
            // (`murk_types::RayDensity`, which `murk apply` places by).
            let mut s = vec![(0.0f64, 0.0f64); nb];
            for e in evals {
                let rec = &loaded.recs[e.rec];
                for u in e.count_bin_residuals(loaded, rec) {
                    let Some(b) = u.cov.get(covariate).and_then(|x| binning.of_number(x)) else {
                        continue;
                    };
                    s[b].0 += u.observed;
                    s[b].1 += u.simulated;
                }
            }
            let tot = s.iter().fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
            let pooled = (tot.0 + 0.5) / (tot.1 + 0.5);
            let v = s
                .iter()
                .map(|&(o, x)| (x > 0.0).then(|| (o + 0.5) / (x + 0.5)))
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
    Ok(FittedTerm { term, edge })
}

/// Per-bin survival factors (`None`: too few returns), the pooled factor,
/// and the soft edge re-fitted with them.
type SurvivalFit = (Vec<Option<f64>>, f64, Option<EdgeRefit>);

/// Per-bin survival factors (`None`: too few returns), the pooled factor,
/// and the soft edge re-fitted with them when `refit_edge` (and the table
/// has a soft edge).
fn fit_survival(
    loaded: &Loaded,
    table: &CoefficientTable,
    evals: &[RecEval],
    covariate: &str,
    binning: &Binning,
    refit_edge: bool,
) -> Result<SurvivalFit, DiagnoseError> {
    let nb = binning.len();
    let cell = |c: u32| loaded.cells[c as usize].expect("reference cell");
    // (bin, applier index, r, ρ, kept, trials, factor of the terms the table
    // already has), in recording order.
    type Item = (usize, usize, f64, f64, f64, f64, f64);
    let mut appliers = Vec::with_capacity(evals.len());
    let mut items: Vec<Item> = Vec::new();
    for e in evals {
        let rec = &loaded.recs[e.rec];
        appliers.push(applier(table, loaded, rec, false, 0)?);
        let a = appliers.len() - 1;
        for u in &rec.units {
            let c = cell(u.cell);
            if let Some(b) = bin_of(binning, covariate, &c.cov, &rec.scan) {
                let base = extension_value(
                    table,
                    loaded,
                    ExtensionObservable::Survival,
                    &c.cov,
                    &rec.scan,
                    rec.mor,
                );
                items.push((
                    b,
                    a,
                    c.cov.range,
                    c.cov.reflectivity,
                    u.kept as f64,
                    u.trials as f64,
                    base,
                ));
            }
        }
    }
    let soft = crate::evaluate::has_soft_edge(table, loaded);
    let (eps0, pi0) = table
        .weathers
        .get(&loaded.weather)
        .and_then(|w| w.survival.as_ref())
        .map_or((0.0, 0.0), |s| (s.dropout, s.residual));
    // Keep probability with distance factor f and the edge `e`: the width
    // factor m through the applier's z at r' = fD + (r − fD)/m, then the
    // edge's dropout and residual swapped for e's.
    let prob = |it: &Item, f: f64, e: &EdgeRefit| -> f64 {
        let &(_, a, r, rho, _, _, base) = it;
        let ap = &appliers[a];
        let f = base * f;
        let m = e.width_factor;
        let r = if m == 1.0 {
            r
        } else {
            let d = ap.vanishing_distance_m(rho) * f;
            d + (r - d) / m
        };
        let p = ap.survival_probability(r, rho, f, false);
        let p = if soft && (e.dropout != eps0 || e.residual != pi0) {
            let sf = (p - pi0) / (1.0 - eps0 - pi0);
            e.residual + (1.0 - e.dropout - e.residual) * sf
        } else {
            p
        };
        p.clamp(P_FLOOR, 1.0 - P_FLOOR)
    };
    let nll_item = |it: &Item, f: f64, e: &EdgeRefit| -> f64 {
        let p = prob(it, f, e);
        -(it.4 * p.ln() + (it.5 - it.4) * (1.0 - p).ln())
    };
    // Σ over `its` in fixed chunks (the same sum on any thread count).
    let sum = |its: &[Item], g: &(dyn Fn(&Item) -> f64 + Sync)| -> f64 {
        use rayon::prelude::*;
        its.par_chunks(8192)
            .map(|c| c.iter().map(g).sum::<f64>())
            .collect::<Vec<f64>>()
            .iter()
            .sum()
    };
    let mut by_bin: Vec<Vec<Item>> = vec![Vec::new(); nb];
    for it in &items {
        by_bin[it.0].push(*it);
    }
    let factors = |e: &EdgeRefit| -> (Vec<Option<f64>>, f64) {
        let ml = |its: &[Item]| -> f64 {
            golden(
                |lf| sum(its, &|it| nll_item(it, lf.exp(), e)),
                0.2f64.ln(),
                5f64.ln(),
            )
            .exp()
        };
        let pooled = ml(&items);
        let v = by_bin
            .iter()
            .map(|its| {
                let n: f64 = its.iter().map(|i| i.5).sum();
                (n >= MIN_TRIALS).then(|| ml(its))
            })
            .collect();
        (v, pooled)
    };
    let mut e = EdgeRefit {
        width_factor: 1.0,
        dropout: eps0,
        residual: pi0,
    };
    let (mut v, mut pooled) = factors(&e);
    if !refit_edge || !soft {
        return Ok((v, pooled, None));
    }
    for _ in 0..2 {
        let fs: Vec<f64> = v.iter().map(|x| x.unwrap_or(pooled)).collect();
        let total = |e: &EdgeRefit| sum(&items, &|it| nll_item(it, fs[it.0], e));
        e.width_factor = golden(
            |lm| {
                total(&EdgeRefit {
                    width_factor: lm.exp(),
                    ..e
                })
            },
            0.25f64.ln(),
            4f64.ln(),
        )
        .exp();
        e.residual = golden(|x| total(&EdgeRefit { residual: x, ..e }), 0.0, 0.5);
        e.dropout = golden(|x| total(&EdgeRefit { dropout: x, ..e }), 0.0, 0.5);
        (v, pooled) = factors(&e);
    }
    Ok((v, pooled, Some(e)))
}

/// The soft edge re-fitted with a survival term.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct EdgeRefit {
    /// Factor on every band's `edge_width`.
    pub width_factor: f64,
    /// The edge's dropout `ε`.
    pub dropout: f64,
    /// The edge's residual survival `π`.
    pub residual: f64,
}
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn golden_finds_a_minimum() {
        // 34 steps shrink the bracket of width 5 to 4e−7.
        let x = golden(|x| (x - 0.7).powi(2), -2.0, 3.0);
        assert!((x - 0.7).abs() < 1e-6, "{x}");
    }
}
