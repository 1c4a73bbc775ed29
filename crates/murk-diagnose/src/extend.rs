//! Fitting an extension term along a finding's covariate, on the fit set
//! only.
//!
//! The term is piecewise constant over the bins (or categories) of the
//! covariate, each bin's value estimated from the fit-set recordings with
//! the baseline model's own predictions:
//!
//! - `survival`: the factor on the vanishing distance that maximises the
//!   Bernoulli likelihood of the bin's kept/lost returns (Brent's method
//!   on `ln f` in [ln 0.2, ln 5]);
//! - `range`: the mean range residual of the bin's kept returns;
//! - `intensity`: `exp` of the mean log ratio of measured to reference
//!   reflectivity;
//! - `count`: `Σ(N_obs + ½) / Σ(N_sim + ½)` over the bin's recordings; along
//!   `ring`, `elevation`, `azimuth` or the returns' own `range`,
//!   `(Σn_obs + ½)/(Σn_sim + ½)` over the bin's lasers, azimuth sectors or
//!   1 m range bins in every recording (a factor on the density of the
//!   near-range returns on those rays, or along range).
//!
//! Every term is fitted on top of the terms the table already has (the
//! stagewise loop adds one at a time): survival factors multiply theirs,
//! and the other observables' residuals already have theirs removed.
//!
//! Bins with too little data (fewer than [`MIN_TRIALS`] returns, or no
//! recording) take the pooled value, which is also the term's default.
//!
//! A survival term is fitted on at most about [`SURVIVAL_FIT_UNITS`] units:
//! a larger fit set is thinned to the same fraction of every recording's
//! units, by a hash of recording and cell, so the term's fit takes the same
//! time and memory at forty recordings as at a thousand.
//!
//! Beside the bins a numeric covariate's term can take other [`Shape`]s
//! ([`fit_shaped`]); `stagewise` fits each one per fold and keeps the one
//! the held-out recordings prefer:
//!
//! - `step`: two bins, the split the bins' values are best cut at
//!   (weighted squares of the per-bin estimates), re-fitted as above;
//! - `monotone`: isotonic regression (pool adjacent violators, increasing
//!   or decreasing, whichever fits the bins closer, weighted by their
//!   returns) through the bins' estimates, linear between the bins'
//!   weighted mean covariate values;
//! - `attenuation` (survival, intensity): `exp(−k·x/MOR)`, `k` by maximum
//!   likelihood (survival, Brent's method, the soft edge re-fitted
//!   with it) or least squares on the log ratio (intensity, closed form);
//! - `linear` (range): `a + b·x`, least squares;
//! - `power` (range, intensity; covariates > 0): `a·x^b`, least squares
//!   (intensity on the log ratio, closed form; range by Brent's method on
//!   `b` with `a` closed form).
//!
//! The closed-form parameters carry a 95 % interval from a bootstrap over
//! recordings (the returns of one recording share its MOR reading, so the
//! recording is the unit resampled); the others carry none.

use std::collections::BTreeMap;

use serde::Serialize;

use murk_types::{
    CoefficientTable, CovariateValue, ExtensionFunction, ExtensionObservable, ModelExtension,
};

use crate::DiagnoseError;
use crate::attribution::Binning;
use crate::data::Loaded;
use crate::evaluate::{KeptUnit, P_FLOOR, RecEval, applier, extension_value};

/// Fewest returns for a bin of its own.
pub const MIN_TRIALS: f64 = 50.0;

/// Most survival units a survival term is fitted on. Its likelihood is
/// summed over every unit some hundreds of times (one-dimensional searches
/// per bin, the soft edge re-fitted), so beyond this the fit set's units are
/// thinned to a fixed fraction of each recording (by a hash of recording and cell): a term's
/// few parameters are pinned long before half a million units, while the
/// time and memory of the fit would otherwise grow with the campaign (40
/// HDL-64-size recordings, 2.2 M units: 13 minutes).
pub const SURVIVAL_FIT_UNITS: usize = 1 << 19;

/// Whether the unit of reference cell `cell` in the recording at campaign
/// position `order` is among a `fraction` of the units: a hash of the two
/// (SplitMix64's finaliser) below `fraction · 2⁶⁴`. Not a random draw: the
/// same units on any seed, fold and thread count, and a unit kept at one
/// fraction is kept at every larger one.
fn keeps_unit(order: usize, cell: u32, fraction: f64) -> bool {
    if fraction >= 1.0 {
        return true;
    }
    let mut z = ((order as u64) << 32 | cell as u64).wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    (z as f64) < fraction * 2f64.powi(64)
}

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

/// The numeric value of `covariate` for a point of a recording (`None`:
/// categorical or unknown).
fn x_of(
    covariate: &str,
    point: &murk_types::PointCovariates,
    scan: &BTreeMap<String, CovariateValue>,
) -> Option<f64> {
    match point.get(covariate) {
        Some(x) => Some(x),
        None => match scan.get(covariate) {
            Some(CovariateValue::Number(x)) if x.is_finite() => Some(*x),
            _ => None,
        },
    }
}

/// Where `f` is least on `[a, b]`, to within about `1e−8·(b − a)`:
/// murk-fit's [`murk_fit::minimize_scalar`] (Brent's method), the midpoint
/// if the search cannot run. A survival term's likelihood is a sum over up
/// to [`SURVIVAL_FIT_UNITS`] units, so every evaluation is one pass over
/// them: the parabolic steps reach the tolerance in about a third of the
/// passes a fixed golden-section search needs.
fn minimize_1d(f: impl Fn(f64) -> f64, a: f64, b: f64) -> f64 {
    murk_fit::minimize_scalar(&f, a, b, 2e-8 * (b - a)).unwrap_or(0.5 * (a + b))
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
    /// 95 % intervals (bootstrap over recordings) of the function's
    /// [`ExtensionFunction::parameters`], in their order; empty when the
    /// shape has none or they were not computed.
    pub intervals: Vec<Option<[f64; 2]>>,
}

impl FittedTerm {
    /// `table` with the term added (and the edge widths scaled) for
    /// `weather`.
    pub fn apply_to(&self, table: &mut CoefficientTable, weather: murk_types::WeatherClass) {
        if let Some(w) = table.weathers.get_mut(&weather) {
            w.extensions.push(self.term.clone());
            if let Some(r) = self.edge {
                let noise = w.survival.as_ref().and_then(|s| s.mor_reading_noise);
                for b in w.vanishing_slope.iter_mut() {
                    b.scale_edge_width(r.width_factor, noise);
                }
                if let Some(s) = w.survival.as_mut() {
                    s.dropout = r.dropout;
                    // The interval was the baseline's dropout's.
                    s.dropout_ci95 = None;
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
    let fit = fit_bins(
        loaded, table, evals, observable, covariate, binning, refit_edge,
    )?;
    bins_term(&fit, observable, covariate, binning, evals.len())
}

/// The piecewise-constant term of a bins fit.
fn bins_term(
    fit: &BinsFit,
    observable: ExtensionObservable,
    covariate: &str,
    binning: &Binning,
    recordings: usize,
) -> Result<FittedTerm, DiagnoseError> {
    let values: Vec<f64> = fit
        .values
        .iter()
        .map(|v| v.unwrap_or(fit.default))
        .collect();
    let function = match binning {
        Binning::Numeric { edges } => ExtensionFunction::Bins {
            edges: edges.clone(),
            values,
        },
        Binning::Categories { names } => ExtensionFunction::Categories {
            values: names.iter().cloned().zip(values).collect(),
        },
    };
    finish(
        observable,
        covariate,
        recordings,
        function,
        fit.default,
        fit.edge,
    )
}

/// The bins fit of one fold, shared by the shapes built on it (bins, the
/// step's split, monotone): [`fit_shaped`] fills it on first use.
#[derive(Default)]
pub struct ShapeCache {
    bins: Option<BinsFit>,
}

/// The term with its description, checked.
fn finish(
    observable: ExtensionObservable,
    covariate: &str,
    recordings: usize,
    function: ExtensionFunction,
    default: f64,
    edge: Option<EdgeRefit>,
) -> Result<FittedTerm, DiagnoseError> {
    let term = ModelExtension {
        observable,
        covariate: covariate.to_string(),
        function,
        default,
        description: format!(
            "{} along {covariate:?}, fitted by murk diagnose on {recordings} recordings",
            observable.name(),
        ),
    };
    term.check()
        .map_err(|r| DiagnoseError::Table(format!("fitted term is invalid: {r}")))?;
    Ok(FittedTerm {
        term,
        edge,
        intervals: Vec::new(),
    })
}

/// Per-bin estimates of a term.
struct BinsFit {
    /// Per bin (`None`: too little data).
    values: Vec<Option<f64>>,
    /// The pooled value (the default).
    default: f64,
    /// Per bin: returns (survival trials, kept returns) or simulated
    /// counts (count).
    weights: Vec<f64>,
    /// Per bin: the weighted mean of the covariate (NaN for categories).
    means: Vec<f64>,
    /// The soft edge re-fitted with a survival term.
    edge: Option<EdgeRefit>,
}

fn fit_bins(
    loaded: &Loaded,
    table: &CoefficientTable,
    evals: &[RecEval],
    observable: ExtensionObservable,
    covariate: &str,
    binning: &Binning,
    refit_edge: bool,
) -> Result<BinsFit, DiagnoseError> {
    let nb = binning.len();
    let cell = |c: u32| loaded.cells[c as usize].expect("reference cell");
    let mut weights = vec![0.0f64; nb];
    let mut xsum = vec![0.0f64; nb];
    let mut edge = None;
    let (values, default): (Vec<Option<f64>>, f64) = match observable {
        ExtensionObservable::Survival => {
            let data = SurvivalData::new(
                loaded,
                table,
                evals,
                covariate,
                Some(binning),
                SURVIVAL_FIT_UNITS,
            )?;
            for it in &data.items {
                let n = it.trials as f64;
                weights[data.bin(it)] += n;
                xsum[data.bin(it)] += n * data.x(it);
            }
            let (v, pooled, e) = data.fit_bins(nb, refit_edge);
            edge = e;
            (v, pooled)
        }
        ExtensionObservable::Range | ExtensionObservable::Intensity => {
            let mut s = vec![(0.0f64, 0.0f64); nb];
            for e in evals {
                let rec = &loaded.recs[e.rec];
                for u in e.kept_residuals(loaded, observable) {
                    let cov = &cell(u.cell).cov;
                    if let Some(b) = bin_of(binning, covariate, cov, &rec.scan) {
                        s[b].0 += u.sum;
                        s[b].1 += u.n;
                        xsum[b] += u.n * x_of(covariate, cov, &rec.scan).unwrap_or(f64::NAN);
                    }
                }
            }
            for (w, x) in weights.iter_mut().zip(&s) {
                *w = x.1;
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
        ExtensionObservable::Count if murk_types::COUNT_POINT_COVARIATES.contains(&covariate) => {
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
                    if let CovariateValue::Number(x) = v {
                        xsum[b] += (sim + 0.5) * x;
                    }
                }
            }
            for (w, x) in weights.iter_mut().zip(&s) {
                *w = x.1;
            }
            let tot = s.iter().fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
            let pooled = if tot.1 > 0.0 { tot.0 / tot.1 } else { 1.0 };
            let v = s.iter().map(|&(o, x)| (x > 0.0).then(|| o / x)).collect();
            (v, pooled)
        }
    };
    let means = match binning {
        Binning::Numeric { .. } => xsum
            .iter()
            .zip(&weights)
            .map(|(x, w)| if *w > 0.0 { x / w } else { f64::NAN })
            .collect(),
        Binning::Categories { .. } => vec![f64::NAN; nb],
    };
    Ok(BinsFit {
        values,
        default,
        weights,
        means,
        edge,
    })
}

/// One survival unit: a reference cell of one recording (40 bytes; a fit
/// set holds at most about [`SURVIVAL_FIT_UNITS`]). The cell's range and
/// reflectivity are copied in, because every likelihood evaluation reads
/// them: looked up from the reference cells (72 bytes each, a grid of
/// hundreds of thousands at HDL-64 size, visited sparsely once thinned)
/// they were a cache miss per unit, the largest single cost of a term fit
/// (measured: 84 % of the likelihood's own time). The MOR comes from its
/// recording's applier, the covariate's value and bin from [`ByUnit`]
/// tables.
#[derive(Debug, Clone, Copy)]
struct Item {
    /// Index of its recording's applier.
    applier: u32,
    /// Reference cell.
    cell: u32,
    /// Kept returns.
    kept: u32,
    /// Trials.
    trials: u32,
    /// Factor of the terms the table already has.
    base: f64,
    /// The reference cell's range, metres.
    range: f64,
    /// The reference cell's reflectivity.
    reflectivity: f64,
}

/// A value of a survival unit that depends on its cell alone (a point
/// covariate's) or on its recording alone (a scan covariate's), held once
/// per cell or per recording instead of once per unit.
#[derive(Debug, Clone)]
enum ByUnit<T> {
    /// Indexed by reference cell (grid index).
    Cell(Vec<T>),
    /// Indexed by the unit's applier (its recording).
    Recording(Vec<T>),
}

impl<T: Copy> ByUnit<T> {
    fn of(&self, it: &Item) -> T {
        match self {
            ByUnit::Cell(v) => v[it.cell as usize],
            ByUnit::Recording(v) => v[it.applier as usize],
        }
    }

    /// Sets the value of `it`'s cell or recording.
    fn set(&mut self, it: &Item, value: T) {
        match self {
            ByUnit::Cell(v) => v[it.cell as usize] = value,
            ByUnit::Recording(v) => v[it.applier as usize] = value,
        }
    }
}

/// The fit set's survival units under a table (thinned to about
/// [`SURVIVAL_FIT_UNITS`]), for likelihood fits of a factor on the
/// vanishing distance.
struct SurvivalData {
    appliers: Vec<murk_infer::Applier>,
    /// The MOR of each applier's recording.
    mors: Vec<f64>,
    items: Vec<Item>,
    /// The covariate's numeric value (NaN when it has none) per unit.
    x: ByUnit<f64>,
    /// The unit's bin (0 without a binning).
    bin: ByUnit<u32>,
    soft: bool,
    eps0: f64,
    pi0: f64,
}

impl SurvivalData {
    /// Units of `evals` (those the binning places, when one is given),
    /// thinned to about `cap` when there are more ([`keeps_unit`]).
    fn new(
        loaded: &Loaded,
        table: &CoefficientTable,
        evals: &[RecEval],
        covariate: &str,
        binning: Option<&Binning>,
        cap: usize,
    ) -> Result<SurvivalData, DiagnoseError> {
        let cell = |c: u32| loaded.cells[c as usize].expect("reference cell");
        let mut appliers = Vec::with_capacity(evals.len());
        let mut mors = Vec::with_capacity(evals.len());
        let mut items: Vec<Item> = Vec::new();
        // A point covariate's value is its cell's, a scan covariate's its
        // recording's (the covariate's kind, whatever its name).
        let by_cell = loaded
            .cells
            .iter()
            .flatten()
            .next()
            .is_some_and(|c| c.cov.get(covariate).is_some());
        let (mut xs, mut bins) = if by_cell {
            let n = loaded.cells.len();
            (ByUnit::Cell(vec![f64::NAN; n]), ByUnit::Cell(vec![0; n]))
        } else {
            let n = evals.len();
            (
                ByUnit::Recording(vec![f64::NAN; n]),
                ByUnit::Recording(vec![0; n]),
            )
        };
        let total: usize = evals.iter().map(|e| loaded.recs[e.rec].units.len()).sum();
        let fraction = cap as f64 / total.max(1) as f64;
        for e in evals {
            let rec = &loaded.recs[e.rec];
            appliers.push(applier(table, loaded, rec, false, 0)?);
            mors.push(rec.mor);
            let a = (appliers.len() - 1) as u32;
            for u in rec.units.iter() {
                if !keeps_unit(rec.order, u.cell, fraction) {
                    continue;
                }
                let c = cell(u.cell);
                let bin = match binning {
                    Some(b) => match bin_of(b, covariate, &c.cov, &rec.scan) {
                        Some(k) => k,
                        None => continue,
                    },
                    None => 0,
                };
                let x = x_of(covariate, &c.cov, &rec.scan).unwrap_or(f64::NAN);
                if binning.is_none() && !x.is_finite() {
                    continue;
                }
                let base = extension_value(
                    table,
                    loaded,
                    ExtensionObservable::Survival,
                    &c.cov,
                    &rec.scan,
                    rec.mor,
                );
                let it = Item {
                    applier: a,
                    cell: u.cell,
                    kept: u.kept,
                    trials: u.trials,
                    base,
                    range: c.cov.range,
                    reflectivity: c.cov.reflectivity,
                };
                xs.set(&it, x);
                bins.set(&it, bin as u32);
                items.push(it);
            }
        }
        let soft = crate::evaluate::has_soft_edge(table, loaded);
        let (eps0, pi0) = table
            .weathers
            .get(&loaded.weather)
            .and_then(|w| w.survival.as_ref())
            .map_or((0.0, 0.0), |s| (s.dropout, s.residual));
        Ok(SurvivalData {
            appliers,
            mors,
            items,
            x: xs,
            bin: bins,
            soft,
            eps0,
            pi0,
        })
    }

    /// Keep probability with distance factor f and the edge `e`: the width
    /// factor m through the applier's z at r' = fD + (r − fD)/m, then the
    /// edge's dropout and residual swapped for e's.
    fn prob(&self, it: &Item, f: f64, e: &EdgeRefit) -> f64 {
        let ap = &self.appliers[it.applier as usize];
        let (ir, rho) = (it.range, it.reflectivity);
        let f = it.base * f;
        let m = e.width_factor;
        let r = if m == 1.0 {
            ir
        } else {
            let d = ap.vanishing_distance_m(rho) * f;
            d + (ir - d) / m
        };
        let p = ap.survival_probability(r, rho, f, false);
        let p = if self.soft && (e.dropout != self.eps0 || e.residual != self.pi0) {
            let sf = (p - self.pi0) / (1.0 - self.eps0 - self.pi0);
            e.residual + (1.0 - e.dropout - e.residual) * sf
        } else {
            p
        };
        p.clamp(P_FLOOR, 1.0 - P_FLOOR)
    }

    fn nll_item(&self, it: &Item, f: f64, e: &EdgeRefit) -> f64 {
        let p = self.prob(it, f, e);
        let (k, n) = (it.kept as f64, it.trials as f64);
        -(k * p.ln() + (n - k) * (1.0 - p).ln())
    }

    /// The recording's MOR of an item.
    fn mor(&self, it: &Item) -> f64 {
        self.mors[it.applier as usize]
    }

    /// The covariate's value of an item (NaN when it has none).
    fn x(&self, it: &Item) -> f64 {
        self.x.of(it)
    }

    /// The bin of an item.
    fn bin(&self, it: &Item) -> usize {
        self.bin.of(it) as usize
    }

    /// Σ over the items (`None`: all of them; else those at the indices
    /// given, in that order) in fixed chunks (the same sum on any thread
    /// count).
    fn sum(&self, its: Option<&[u32]>, g: &(dyn Fn(&Item) -> f64 + Sync)) -> f64 {
        use rayon::prelude::*;
        let chunks: Vec<f64> = match its {
            None => self
                .items
                .par_chunks(8192)
                .map(|c| c.iter().map(g).sum::<f64>())
                .collect(),
            Some(ix) => ix
                .par_chunks(8192)
                .map(|c| c.iter().map(|&i| g(&self.items[i as usize])).sum::<f64>())
                .collect(),
        };
        chunks.iter().sum()
    }

    /// The edge as the table has it.
    fn edge0(&self) -> EdgeRefit {
        EdgeRefit {
            width_factor: 1.0,
            dropout: self.eps0,
            residual: self.pi0,
        }
    }

    /// Re-fits the edge's width factor, residual and dropout with the
    /// factor `fs` per item.
    fn refit_edge(&self, e: EdgeRefit, fs: &(dyn Fn(&Item) -> f64 + Sync)) -> EdgeRefit {
        let mut e = e;
        let total = |e: &EdgeRefit| self.sum(None, &|it| self.nll_item(it, fs(it), e));
        e.width_factor = minimize_1d(
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
        e.residual = minimize_1d(|x| total(&EdgeRefit { residual: x, ..e }), 0.0, 0.5);
        e.dropout = minimize_1d(|x| total(&EdgeRefit { dropout: x, ..e }), 0.0, 0.5);
        e
    }

    /// Per-bin factors (`None`: too few returns), the pooled factor, and
    /// the soft edge re-fitted with them when `refit_edge` (and the table
    /// has a soft edge).
    fn fit_bins(&self, nb: usize, refit_edge: bool) -> SurvivalFit {
        // Indices of each bin's items, in item order.
        let mut by_bin: Vec<Vec<u32>> = vec![Vec::new(); nb];
        for (i, it) in self.items.iter().enumerate() {
            by_bin[self.bin(it)].push(i as u32);
        }
        let factors = |e: &EdgeRefit| -> (Vec<Option<f64>>, f64) {
            let ml = |its: Option<&[u32]>| -> f64 {
                minimize_1d(
                    |lf| self.sum(its, &|it| self.nll_item(it, lf.exp(), e)),
                    0.2f64.ln(),
                    5f64.ln(),
                )
                .exp()
            };
            let pooled = ml(None);
            let v = by_bin
                .iter()
                .map(|its| {
                    let n: f64 = its
                        .iter()
                        .map(|&i| self.items[i as usize].trials as f64)
                        .sum();
                    (n >= MIN_TRIALS).then(|| ml(Some(its)))
                })
                .collect();
            (v, pooled)
        };
        let mut e = self.edge0();
        let (mut v, mut pooled) = factors(&e);
        if !refit_edge || !self.soft {
            return (v, pooled, None);
        }
        for _ in 0..2 {
            let fs: Vec<f64> = v.iter().map(|x| x.unwrap_or(pooled)).collect();
            e = self.refit_edge(e, &|it| fs[self.bin(it)]);
            (v, pooled) = factors(&e);
        }
        (v, pooled, Some(e))
    }

    /// `k` of the factor `exp(−k·x/MOR)` by maximum likelihood, and the
    /// soft edge re-fitted with it when `refit_edge`.
    fn fit_attenuation(&self, refit_edge: bool) -> (f64, Option<EdgeRefit>) {
        let ml = |e: &EdgeRefit| {
            minimize_1d(
                |k| {
                    self.sum(None, &|it| {
                        self.nll_item(it, (-k * self.x(it) / self.mor(it)).exp(), e)
                    })
                },
                -ATTENUATION_K_MAX,
                ATTENUATION_K_MAX,
            )
        };
        let mut e = self.edge0();
        let mut k = ml(&e);
        if !refit_edge || !self.soft {
            return (k, None);
        }
        for _ in 0..2 {
            e = self.refit_edge(e, &|it| (-k * self.x(it) / self.mor(it)).exp());
            k = ml(&e);
        }
        (k, Some(e))
    }
}

/// Per-bin survival factors (`None`: too few returns), the pooled factor,
/// and the soft edge re-fitted with them.
type SurvivalFit = (Vec<Option<f64>>, f64, Option<EdgeRefit>);

/// The bracket of `k` in `exp(−k·x/MOR)`, both signs.
pub const ATTENUATION_K_MAX: f64 = 30.0;

/// A shape a term can take (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Shape {
    /// Piecewise constant over the bins (or categories).
    Bins,
    /// Two values split at one of the bins' edges.
    Step,
    /// Isotonic, linear between the bins' centres.
    Monotone,
    /// `exp(−k·x/MOR)`.
    Attenuation,
    /// `a + b·x`.
    Linear,
    /// `a·x^b`.
    Power,
}

impl Shape {
    /// Its name in reports (`bins`, `step`, …).
    pub fn name(self) -> &'static str {
        match self {
            Shape::Bins => "bins",
            Shape::Step => "step",
            Shape::Monotone => "monotone",
            Shape::Attenuation => "attenuation",
            Shape::Linear => "linear",
            Shape::Power => "power",
        }
    }
}

/// The shapes tried for a term on `observable` binned as `binning`: bins
/// always; for a numeric covariate with at least three bins step and
/// monotone; the parametric forms that are defined for the observable
/// (attenuation for factors that can be fitted by likelihood or on the log
/// ratio: survival, intensity; linear for the range bias; power for range
/// and intensity). Count keeps bins: its held-out error needs simulations,
/// which each further shape would multiply.
pub fn shapes(observable: ExtensionObservable, binning: &Binning) -> Vec<Shape> {
    let Binning::Numeric { edges } = binning else {
        return vec![Shape::Bins];
    };
    if observable == ExtensionObservable::Count {
        return vec![Shape::Bins];
    }
    let mut v = vec![Shape::Bins];
    if edges.len() >= 2 {
        v.extend([Shape::Step, Shape::Monotone]);
    }
    v.extend(match observable {
        ExtensionObservable::Survival => &[Shape::Attenuation][..],
        ExtensionObservable::Intensity => &[Shape::Attenuation, Shape::Power][..],
        ExtensionObservable::Range => &[Shape::Linear, Shape::Power][..],
        ExtensionObservable::Count => &[][..],
    });
    v
}

/// Fits the term of `shape` on `observable` along `covariate` (`binning`
/// for the piecewise shapes) from the fit-set evaluations `evals` under
/// `table`, re-fitting the soft edge with a survival term when
/// `refit_edge`. The parametric forms' intervals come from `bootstrap`
/// resamples of the recordings seeded by `seed` (none when 0). The shapes
/// of one fold share `cache` (pass one per fold and covariate). `None`
/// when the shape cannot be fitted on these data (a power law without
/// positive covariate values, no split with data on both sides).
#[allow(clippy::too_many_arguments)]
pub fn fit_shaped(
    loaded: &Loaded,
    table: &CoefficientTable,
    evals: &[RecEval],
    observable: ExtensionObservable,
    covariate: &str,
    binning: &Binning,
    shape: Shape,
    refit_edge: bool,
    bootstrap: usize,
    seed: u64,
    cache: &mut ShapeCache,
) -> Result<Option<FittedTerm>, DiagnoseError> {
    let n = evals.len();
    if matches!(shape, Shape::Bins | Shape::Step | Shape::Monotone) && cache.bins.is_none() {
        cache.bins = Some(fit_bins(
            loaded, table, evals, observable, covariate, binning, refit_edge,
        )?);
    }
    match shape {
        Shape::Bins => {
            let fit = cache.bins.as_ref().expect("filled above");
            bins_term(fit, observable, covariate, binning, n).map(Some)
        }
        Shape::Step | Shape::Monotone => {
            let Binning::Numeric { edges } = binning else {
                return Ok(None);
            };
            let fit = cache.bins.as_ref().expect("filled above");
            let tf = |v: f64| {
                if observable.multiplicative() {
                    v.max(1e-9).ln()
                } else {
                    v
                }
            };
            // Bins with data: (value on the fitting scale, weight, mean x).
            let pts: Vec<(usize, f64, f64, f64)> = fit
                .values
                .iter()
                .enumerate()
                .filter_map(|(b, v)| {
                    v.map(|v| (b, tf(v), fit.weights[b], fit.means[b]))
                        .filter(|p| p.2 > 0.0 && p.3.is_finite())
                })
                .collect();
            if shape == Shape::Step {
                let Some(cut) = best_split(&pts) else {
                    return Ok(None);
                };
                let one = Binning::Numeric {
                    edges: vec![edges[cut - 1]],
                };
                let mut t = fit_term_with_edge(
                    loaded, table, evals, observable, covariate, &one, refit_edge,
                )?;
                t.term.description =
                    format!("{} (a step at {})", t.term.description, edges[cut - 1]);
                return Ok(Some(t));
            }
            // Knots strictly ascending (bins are disjoint, so their means
            // are; equal means are merged into the first).
            let mut pts = pts;
            pts.dedup_by(|b, a| !(b.3 > a.3));
            if pts.len() < 2 {
                return Ok(None);
            }
            let y: Vec<f64> = pts.iter().map(|p| p.1).collect();
            let w: Vec<f64> = pts.iter().map(|p| p.2).collect();
            let up = isotonic(&y, &w, true);
            let down = isotonic(&y, &w, false);
            let sse = |z: &[f64]| -> f64 {
                z.iter()
                    .zip(&y)
                    .zip(&w)
                    .map(|((a, b), w)| w * (a - b).powi(2))
                    .sum()
            };
            let best = if sse(&up) <= sse(&down) { up } else { down };
            let back = |v: f64| {
                if observable.multiplicative() {
                    v.exp()
                } else {
                    v
                }
            };
            let function = ExtensionFunction::Monotone {
                knots: pts.iter().map(|p| p.3).collect(),
                values: best.into_iter().map(back).collect(),
            };
            finish(observable, covariate, n, function, fit.default, fit.edge).map(Some)
        }
        Shape::Attenuation | Shape::Linear | Shape::Power => fit_parametric(
            loaded, table, evals, observable, covariate, shape, refit_edge, bootstrap, seed,
        ),
    }
}

/// The cut (index into the points, 1..len) of the weighted points'
/// values into two groups with the least weighted squares.
fn best_split(pts: &[(usize, f64, f64, f64)]) -> Option<usize> {
    let ss = |g: &[(usize, f64, f64, f64)]| -> f64 {
        let w: f64 = g.iter().map(|p| p.2).sum();
        let m = g.iter().map(|p| p.2 * p.1).sum::<f64>() / w;
        g.iter().map(|p| p.2 * (p.1 - m).powi(2)).sum()
    };
    (1..pts.len())
        .map(|i| (i, ss(&pts[..i]) + ss(&pts[i..])))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| pts[i].0)
        .filter(|&b| b >= 1)
}

/// Weighted isotonic regression (pool adjacent violators), non-decreasing
/// when `increasing`, else non-increasing.
pub fn isotonic(y: &[f64], w: &[f64], increasing: bool) -> Vec<f64> {
    let s = if increasing { 1.0 } else { -1.0 };
    // Blocks: (weighted mean × s, weight, points).
    let mut blocks: Vec<(f64, f64, usize)> = Vec::with_capacity(y.len());
    for (&v, &wt) in y.iter().zip(w) {
        blocks.push((s * v, wt, 1));
        while blocks.len() >= 2 {
            let (b, a) = (blocks[blocks.len() - 1], blocks[blocks.len() - 2]);
            if a.0 <= b.0 {
                break;
            }
            let wt = a.1 + b.1;
            let m = (a.0 * a.1 + b.0 * b.1) / wt;
            blocks.pop();
            *blocks.last_mut().expect("two blocks") = (m, wt, a.2 + b.2);
        }
    }
    blocks
        .iter()
        .flat_map(|&(m, _, k)| std::iter::repeat_n(s * m, k))
        .collect()
}

/// Sums of one recording for a least-squares line `r = a + b·u` (or
/// through the origin): `[n, Σu, Σu², Σr, Σur]`.
type LineSums = [f64; 5];

/// `(a, b)` of the least-squares line (`a` = 0 when `origin`).
fn line_of(s: &LineSums, origin: bool) -> Option<(f64, f64)> {
    let [n, su, suu, sr, sur] = *s;
    if origin {
        return (suu > 0.0).then(|| (0.0, sur / suu));
    }
    let det = n * suu - su * su;
    (n > 1.0 && det > 1e-12 * n * suu.max(1e-300)).then(|| {
        let b = (n * sur - su * sr) / det;
        ((sr - b * su) / n, b)
    })
}

/// Percentile 95 % intervals of `fit` over `b` resamples of the
/// recordings' sums (with replacement, seeded by `seed`).
fn bootstrap_lines(
    per_rec: &[LineSums],
    origin: bool,
    b: usize,
    seed: u64,
) -> Option<[[f64; 2]; 2]> {
    use rand::{RngExt, SeedableRng};
    if b == 0 || per_rec.len() < 2 {
        return None;
    }
    let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
    let mut a_s = Vec::with_capacity(b);
    let mut b_s = Vec::with_capacity(b);
    for _ in 0..b {
        let mut s = [0.0; 5];
        for _ in 0..per_rec.len() {
            let r = &per_rec[rng.random_range(0..per_rec.len())];
            for (x, y) in s.iter_mut().zip(r) {
                *x += y;
            }
        }
        if let Some((a, bb)) = line_of(&s, origin) {
            a_s.push(a);
            b_s.push(bb);
        }
    }
    if a_s.len() < b / 2 {
        return None;
    }
    let pct = |mut v: Vec<f64>| -> [f64; 2] {
        v.sort_by(f64::total_cmp);
        let at = |q: f64| v[((q * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)];
        [at(0.025), at(0.975)]
    };
    Some([pct(a_s), pct(b_s)])
}

/// Bootstrap resamples for the parametric forms' intervals.
pub const BOOTSTRAP: usize = 200;

/// The parametric shapes (module docs).
#[allow(clippy::too_many_arguments)]
fn fit_parametric(
    loaded: &Loaded,
    table: &CoefficientTable,
    evals: &[RecEval],
    observable: ExtensionObservable,
    covariate: &str,
    shape: Shape,
    refit_edge: bool,
    bootstrap: usize,
    seed: u64,
) -> Result<Option<FittedTerm>, DiagnoseError> {
    let n = evals.len();
    let pooled_fit = |default: f64, function: ExtensionFunction, edge, intervals| {
        finish(observable, covariate, n, function, default, edge).map(|mut t| {
            t.intervals = intervals;
            Some(t)
        })
    };
    if observable == ExtensionObservable::Survival {
        if shape != Shape::Attenuation {
            return Ok(None);
        }
        let data = SurvivalData::new(loaded, table, evals, covariate, None, SURVIVAL_FIT_UNITS)?;
        if data.items.is_empty() {
            return Ok(None);
        }
        let (k, edge) = data.fit_attenuation(refit_edge);
        return pooled_fit(1.0, ExtensionFunction::Attenuation { k }, edge, vec![None]);
    }
    if !matches!(
        observable,
        ExtensionObservable::Range | ExtensionObservable::Intensity
    ) {
        return Ok(None);
    }
    // (recording, x, MOR, unit) of every kept unit with a numeric x (a unit
    // is a return, or a cell's returns summed: every fit below is a sum).
    let cell = |c: u32| loaded.cells[c as usize].expect("reference cell");
    let mut pts: Vec<(usize, f64, f64, KeptUnit)> = Vec::new();
    for (ri, e) in evals.iter().enumerate() {
        let rec = &loaded.recs[e.rec];
        for u in e.kept_residuals(loaded, observable) {
            if let Some(x) = x_of(covariate, &cell(u.cell).cov, &rec.scan) {
                pts.push((ri, x, rec.mor, u));
            }
        }
    }
    if pts.is_empty() {
        return Ok(None);
    }
    let mean_r = pts.iter().map(|p| p.3.sum).sum::<f64>() / pts.iter().map(|p| p.3.n).sum::<f64>();
    let intensity = observable == ExtensionObservable::Intensity;
    let default = if intensity { mean_r.exp() } else { mean_r };
    // Least squares on a regressor u per point.
    let lines = |u: &dyn Fn(f64, f64) -> Option<f64>| -> Vec<LineSums> {
        let mut per = vec![[0.0; 5]; n];
        for &(ri, x, mor, k) in &pts {
            if let Some(u) = u(x, mor).filter(|u| u.is_finite()) {
                let s = &mut per[ri];
                s[0] += k.n;
                s[1] += k.n * u;
                s[2] += k.n * u * u;
                s[3] += k.sum;
                s[4] += u * k.sum;
            }
        }
        per
    };
    let total = |per: &[LineSums]| -> LineSums {
        let mut s = [0.0; 5];
        for r in per {
            for (x, y) in s.iter_mut().zip(r) {
                *x += y;
            }
        }
        s
    };
    match (shape, intensity) {
        (Shape::Attenuation, true) => {
            // ln f = −k·x/MOR.
            let per = lines(&|x, mor| Some(-x / mor));
            let Some((_, k)) = line_of(&total(&per), true) else {
                return Ok(None);
            };
            let iv = bootstrap_lines(&per, true, bootstrap, seed).map(|v| v[1]);
            pooled_fit(
                default,
                ExtensionFunction::Attenuation { k },
                None,
                vec![iv],
            )
        }
        (Shape::Power, true) => {
            // ln f = ln a + b·ln x.
            let per = lines(&|x, _| (x > 0.0).then(|| x.ln()));
            let Some((la, b)) = line_of(&total(&per), false) else {
                return Ok(None);
            };
            let iv = bootstrap_lines(&per, false, bootstrap, seed);
            pooled_fit(
                default,
                ExtensionFunction::Power {
                    scale: la.exp(),
                    exponent: b,
                },
                None,
                vec![iv.map(|v| [v[0][0].exp(), v[0][1].exp()]), iv.map(|v| v[1])],
            )
        }
        (Shape::Linear, false) => {
            let per = lines(&|x, _| Some(x));
            let Some((a, b)) = line_of(&total(&per), false) else {
                return Ok(None);
            };
            let iv = bootstrap_lines(&per, false, bootstrap, seed);
            pooled_fit(
                default,
                ExtensionFunction::Linear {
                    intercept: a,
                    slope: b,
                },
                None,
                vec![iv.map(|v| v[0]), iv.map(|v| v[1])],
            )
        }
        (Shape::Power, false) => {
            // r = a·x^b: `a` in closed form for each `b`, `b` by
            // golden-section search on the squares.
            let pos: Vec<(f64, KeptUnit)> = pts
                .iter()
                .filter(|p| p.1 > 0.0)
                .map(|p| (p.1.ln(), p.3))
                .collect();
            if pos.iter().map(|p| p.1.n).sum::<f64>() < 2.0 {
                return Ok(None);
            }
            let a_of = |b: f64| -> (f64, f64) {
                let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
                for &(l, k) in &pos {
                    let z = (b * l).exp();
                    sxy += z * k.sum;
                    sxx += k.n * z * z;
                    syy += k.sum_sq;
                }
                if sxx > 0.0 {
                    (sxy / sxx, syy - sxy * sxy / sxx)
                } else {
                    (0.0, syy)
                }
            };
            let b = minimize_1d(|b| a_of(b).1, -POWER_EXPONENT_MAX, POWER_EXPONENT_MAX);
            let (a, _) = a_of(b);
            pooled_fit(
                default,
                ExtensionFunction::Power {
                    scale: a,
                    exponent: b,
                },
                None,
                vec![None, None],
            )
        }
        _ => Ok(None),
    }
}

/// The bracket of a power law's exponent (range bias).
pub const POWER_EXPONENT_MAX: f64 = 3.0;

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
    fn the_unit_hash_keeps_its_fraction_on_every_ring_and_nests() {
        // An HDL-64-like grid (64 rings × 4,000 azimuths, ring-major and
        // azimuth-major cell numbering both) over 30 recordings.
        for fraction in [0.05, 0.25, 0.6] {
            for ring_major in [true, false] {
                let mut per_ring = vec![(0u64, 0u64); 64];
                for order in 0..30 {
                    for ring in 0..64u32 {
                        for az in 0..4000u32 {
                            let cell = if ring_major {
                                ring * 4000 + az
                            } else {
                                az * 64 + ring
                            };
                            let k = keeps_unit(order, cell, fraction);
                            per_ring[ring as usize].0 += k as u64;
                            per_ring[ring as usize].1 += 1;
                            if k {
                                assert!(keeps_unit(order, cell, fraction + 0.1));
                            }
                        }
                    }
                }
                for (ring, &(k, n)) in per_ring.iter().enumerate() {
                    let f = k as f64 / n as f64;
                    // 120,000 units per ring: binomial sd ≤ 0.0015.
                    assert!(
                        (f - fraction).abs() < 0.01,
                        "ring {ring}: {f} kept for {fraction} ({ring_major})"
                    );
                }
            }
        }
        assert!((0..1000).all(|c| keeps_unit(3, c, 1.0)));
    }

    /// A generated fog campaign whose lower beams see less far (a factor
    /// 0.8 on the vanishing distance below −10° elevation, against 1 above).
    fn hidden_survival_campaign(seed: u64) -> (tempfile::TempDir, Loaded) {
        crate::test_support::fog_campaign(24, seed, true)
    }

    #[test]
    fn a_thinned_survival_fit_finds_the_factors_of_the_full_one() {
        let params = murk_fit::FitParams::default().check().unwrap();
        for seed in [3, 4] {
            let (_dir, loaded) = hidden_survival_campaign(seed);
            let table = params.fit_inputs(&loaded.inputs).unwrap().table().clone();
            let all: Vec<usize> = (0..loaded.recs.len()).collect();
            let evals = crate::evaluate::evaluate(&loaded, &table, &all, None, &params).unwrap();
            let binning = Binning::Numeric { edges: vec![-10.0] };
            let fit = |cap: usize| {
                let d =
                    SurvivalData::new(&loaded, &table, &evals, "elevation", Some(&binning), cap)
                        .unwrap();
                let n = d.items.len();
                let (v, _, _) = d.fit_bins(binning.len(), false);
                (n, v[0].unwrap() / v[1].unwrap())
            };
            let (n_full, full) = fit(usize::MAX);
            let (n_thin, thin) = fit(n_full / 5);
            // The thinned set is a fifth of the full one (hash sampling).
            let share = n_thin as f64 / n_full as f64;
            assert!(
                (share - 0.2).abs() < 0.02,
                "seed {seed}: {n_thin} of {n_full}"
            );
            // Lower over upper beams' factor: the hidden 0.8 by both.
            assert!((full - 0.8).abs() < 0.05, "seed {seed}: full fit {full}");
            assert!(
                (thin - full).abs() < 0.03,
                "seed {seed}: thinned {thin} vs full {full}"
            );
        }
    }

    #[test]
    fn isotonic_pools_violators() {
        let y = [1.0, 3.0, 2.0, 4.0];
        let w = [1.0, 1.0, 1.0, 1.0];
        assert_eq!(isotonic(&y, &w, true), vec![1.0, 2.5, 2.5, 4.0]);
        let d = isotonic(&y, &w, false);
        assert!(d.windows(2).all(|p| p[0] >= p[1]), "{d:?}");
        // The weighted mean is kept.
        assert!((d.iter().sum::<f64>() - 10.0).abs() < 1e-12);
        assert_eq!(isotonic(&[2.0, 1.0], &[3.0, 1.0], true), vec![1.75, 1.75]);
    }

    #[test]
    fn lines_and_their_bootstrap() {
        // r = 0.5 − 2u exactly, over three recordings.
        let per: Vec<LineSums> = (0..3)
            .map(|k| {
                let mut s = [0.0; 5];
                for i in 0..10 {
                    let u = (k * 10 + i) as f64 * 0.1;
                    let r = 0.5 - 2.0 * u;
                    s = [s[0] + 1.0, s[1] + u, s[2] + u * u, s[3] + r, s[4] + u * r];
                }
                s
            })
            .collect();
        let mut t = [0.0; 5];
        for s in &per {
            for (a, b) in t.iter_mut().zip(s) {
                *a += b;
            }
        }
        let (a, b) = line_of(&t, false).unwrap();
        assert!((a - 0.5).abs() < 1e-9 && (b + 2.0).abs() < 1e-9, "{a} {b}");
        let iv = bootstrap_lines(&per, false, 50, 7).unwrap();
        assert!(iv[1][0] <= -2.0 + 1e-9 && iv[1][1] >= -2.0 - 1e-9, "{iv:?}");
        assert!(bootstrap_lines(&per[..1], false, 50, 7).is_none());
    }
}
