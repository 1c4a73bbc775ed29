//! Stagewise extension with held-out acceptance.
//!
//! One term is not enough when a campaign hides several effects, and a
//! significant finding is not yet a reason to extend the model: the
//! baseline's own misfit (a count law of the wrong shape, a survival edge a
//! little off) is consistent across recordings and so significant, but a
//! term along it may gain nothing on recordings it was not fitted on. So:
//!
//! 1. attribute the current model's held-out residuals (every observable ×
//!    covariate, [`crate::DiagnoseValidParams`]'s tests);
//! 2. take the significant candidates of the strongest observable (at most
//!    [`CANDIDATES_PER_STEP`]); fit each one's term per fold on the fit set
//!    *on top of the current model* and evaluate the fold's held-out
//!    recordings with it;
//!    every [`extend::shapes`] of the term is fitted and evaluated so; the
//!    shape kept is the one with the fewest parameters whose mean held-out
//!    loss is not significantly above the lowest (paired sign-flip test
//!    over held-out recordings, p ≥ α): a flexible shape must earn its
//!    parameters out of sample (the penalty for parameters);
//! 3. a candidate passes when a paired test over held-out recordings
//!    ([`crate::attribution::paired_gain_test`] on the per-recording loss
//!    before − after, [`recording_loss`]) gives p < α and its metric gains;
//!    of those that pass, the one with the largest gain is *accepted*, the
//!    others go back to the pool; a candidate that fails is *rejected* (and
//!    not tried again). When no candidate of this observable passes, the
//!    next observable's are tried;
//! 4. with a term accepted, the model changes: its residuals are tested
//!    again and the next term is added, until no significant candidate is
//!    left, none passes, or [`crate::MAX_STEPS`] terms are in.
//!
//! The report's findings are those of the baseline, annotated: a finding
//! whose term was accepted is significant (with its `step`); one that was
//! significant and is not any more after step *k* is `explained_by` step
//! *k*'s covariate (what a conditional test asks: does B add anything once A
//! is in the model?); one whose term was turned down is not significant and
//! says why (`rejected`).

use std::collections::BTreeMap;

use murk_types::seed::Purpose;
use murk_types::{CoefficientTable, ExtensionObservable};

use crate::attribution::paired_gain_test;
use crate::data::Loaded;
use crate::evaluate::{Metrics, P_FLOOR, RecEval, SimOptions, evaluate};
use crate::extend::Shape;
use crate::report::{Finding, Gain, Rejected, ShapeParameter, ShapeTried, Step};
use crate::{
    Baseline, DiagnoseError, DiagnoseValidParams, Folds, Test, extend, rank, relative_gain, seed_of,
};
use murk_fit::FitValidParams;
use rayon::prelude::*;

/// Candidates of one observable fitted and compared per step.
pub const CANDIDATES_PER_STEP: usize = 3;

/// The loss of one held-out recording on `obs` along `covariate`: mean log
/// loss per expected return (survival), mean square residual of kept
/// returns (range, intensity), |log count ratio| (count along a scan-level
/// covariate) or its weighted mean per laser or azimuth sector (count along
/// `ring`, `elevation` or `azimuth`, [`crate::evaluate::count_bin_loss`]).
/// `None` without data.
pub fn recording_loss_of(
    loaded: &Loaded,
    e: &RecEval,
    obs: ExtensionObservable,
    covariate: &str,
) -> Option<f64> {
    if obs == ExtensionObservable::Count && murk_types::COUNT_POINT_COVARIATES.contains(&covariate)
    {
        let rec = &loaded.recs[e.rec];
        return crate::evaluate::count_bin_loss(&e.count_bin_residuals(loaded, rec), covariate);
    }
    recording_loss(loaded, e, obs)
}

/// The loss of one held-out recording on `obs`: mean log loss per expected
/// return (survival), mean square residual of kept returns (range,
/// intensity), |log count ratio| (count). `None` without data.
pub fn recording_loss(loaded: &Loaded, e: &RecEval, obs: ExtensionObservable) -> Option<f64> {
    let rec = &loaded.recs[e.rec];
    let mean_sq = |v: &[crate::evaluate::KeptUnit]| {
        let n: f64 = v.iter().map(|u| u.n).sum();
        (n > 0.0).then(|| v.iter().map(|u| u.sum_sq).sum::<f64>() / n)
    };
    match obs {
        ExtensionObservable::Survival => {
            let (mut ll, mut n) = (0.0, 0.0);
            for (u, p) in rec.units.iter().zip(e.p(loaded)) {
                let p = p.clamp(P_FLOOR, 1.0 - P_FLOOR);
                let (k, t) = (u.kept as f64, u.trials as f64);
                ll -= k * p.ln() + (t - k) * (1.0 - p).ln();
                n += t;
            }
            (n > 0.0).then(|| ll / n)
        }
        ExtensionObservable::Range | ExtensionObservable::Intensity => {
            mean_sq(&e.kept_residuals(loaded, obs))
        }
        ExtensionObservable::Count => e.count_residual(rec).map(f64::abs),
    }
}

/// A candidate term fitted per fold and evaluated held-out.
struct Candidate {
    /// The model of each fold with the term.
    tables: Vec<CoefficientTable>,
    /// Held-out evaluations with the term, by recording.
    evals: Vec<RecEval>,
    /// Its held-out gain on its metric.
    gain: Option<Gain>,
    /// Paired test p-value.
    p_value: f64,
    /// Recordings in the paired test.
    recordings: usize,
    /// Bins of the term (of the last fold).
    bins: usize,
    /// The soft edge re-fitted with a survival term (last fold).
    edge: Option<extend::EdgeRefit>,
    /// The shape chosen on held-out recordings.
    shape: Shape,
    /// The term of the last fold (its parameters, for the words).
    last_term: Option<murk_types::ModelExtension>,
    /// Every shape tried, with its held-out loss.
    shapes: Vec<ShapeTried>,
}

/// What the stagewise extension returns.
pub(crate) struct Stagewise {
    /// Accepted steps.
    pub steps: Vec<Step>,
    /// Rejected candidates.
    pub rejected: Vec<Rejected>,
    /// The baseline's findings, annotated, in report order.
    pub findings: Vec<Finding>,
    /// Most tests run in one round.
    pub tests: usize,
    /// Held-out metrics of the final model (simulated), when a step was
    /// accepted.
    pub metrics: Option<Metrics>,
    /// The table fitted on every recording with every accepted term.
    pub table: CoefficientTable,
}

/// What the candidates of one round share (the model is the same for all
/// of them): the current model's held-out metrics, and the reference of a
/// survival candidate's paired test — each fold's model with a constant
/// factor on the vanishing distance and the edge re-fitted, evaluated held
/// out, with each recording's loss. Computed by the first candidate that
/// needs them.
#[derive(Default)]
struct RoundCache {
    /// `Metrics::of` the current evaluations.
    before: Option<Metrics>,
    /// The survival reference's held-out loss per recording (by
    /// recording).
    null: Option<Vec<Option<f64>>>,
}

type Key = (ExtensionObservable, String);

fn key(f: &Finding) -> Key {
    (f.observable, f.covariate.clone())
}

/// The term of a step in words.
pub(crate) fn term_text(
    obs: ExtensionObservable,
    covariate: &str,
    bins: usize,
    term: Option<&murk_types::ModelExtension>,
) -> String {
    use murk_types::ExtensionFunction as F;
    let shape = match term.map(|t| &t.function) {
        Some(F::Bins { edges, .. }) if edges.len() == 1 && bins > 2 => {
            format!("a step at {}", edges[0])
        }
        Some(F::Monotone { knots, .. }) => {
            format!("monotone (isotonic) through {} knots", knots.len())
        }
        Some(F::Attenuation { k }) => format!("exp(−k·{covariate}/MOR), k = {k:.3}"),
        Some(F::Linear { intercept, slope }) => format!("{intercept:.4} + {slope:.4}·{covariate}"),
        Some(F::Power { scale, exponent }) => format!("{scale:.4}·{covariate}^{exponent:.3}"),
        _ => format!("piecewise constant over {bins} bins"),
    };
    format!(
        "{} × f({covariate}) — {shape}, fitted per fold on the fit set",
        match obs {
            ExtensionObservable::Survival => "vanishing distance",
            ExtensionObservable::Count if covariate == "range" => {
                "density of ghost and ring returns along their own range"
            }
            ExtensionObservable::Count if murk_types::COUNT_RAY_COVARIATES.contains(&covariate) => {
                "density of ghost and ring returns on the rays"
            }
            ExtensionObservable::Count => "expected ghost and ring count",
            ExtensionObservable::Range => "range of kept returns +",
            ExtensionObservable::Intensity => "reflectivity of kept returns",
        }
    )
}

impl DiagnoseValidParams {
    /// The stagewise loop (module docs). `full` is the baseline fitted on
    /// every recording (or the table given); `evals` are the baseline's
    /// evaluations (taken from `baseline`, not copied: they are the largest
    /// thing a diagnosis holds).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn stagewise(
        &self,
        loaded: &Loaded,
        folds: &Folds,
        baseline: &Baseline,
        evals: Vec<RecEval>,
        sim: &SimOptions,
        fit_params: &FitValidParams,
        mut full: CoefficientTable,
    ) -> Result<Stagewise, DiagnoseError> {
        let p = &self.0;
        let aliases = crate::aliases::of_loaded(loaded);
        let mut tables = baseline.tables.clone();
        let mut evals = evals;
        let mut steps: Vec<Step> = Vec::new();
        let mut accepted: Vec<(usize, Key)> = Vec::new();
        let mut rejected: Vec<Rejected> = Vec::new();
        let mut rejected_keys: BTreeMap<Key, String> = BTreeMap::new();
        let mut rounds: Vec<Vec<Finding>> = Vec::new();
        let mut max_tests = 0;
        loop {
            let round = rounds.len();
            let (tests, findings) = self.attribute(loaded, &evals, &aliases);
            max_tests = max_tests.max(tests.len());
            rounds.push(findings.clone());
            if steps.len() >= crate::MAX_STEPS {
                break;
            }
            // Significant candidates, grouped by observable in report order.
            let mut groups: Vec<(ExtensionObservable, Vec<usize>)> = Vec::new();
            for i in rank(&findings) {
                let f = &findings[i];
                if !f.significant
                    || rejected_keys.contains_key(&key(f))
                    || accepted.iter().any(|(_, k)| *k == key(f))
                {
                    continue;
                }
                match groups.iter_mut().find(|g| g.0 == f.observable) {
                    Some(g) => g.1.push(i),
                    None => groups.push((f.observable, vec![i])),
                }
            }
            let mut took: Option<(usize, Candidate)> = None;
            let mut cache = RoundCache::default();
            for (_, group) in &groups {
                for &i in group.iter().take(CANDIDATES_PER_STEP) {
                    let t = &tests[i];
                    let c = self.candidate(
                        loaded, folds, &tables, &evals, t, sim, fit_params, round, &mut cache,
                    )?;
                    let rel = c.gain.as_ref().map(|g| g.relative);
                    let passes = c.p_value < p.alpha && rel.is_some_and(|g| g > 0.0);
                    if passes {
                        let better = took.as_ref().is_none_or(|(_, b)| {
                            rel.unwrap_or(f64::NEG_INFINITY)
                                > b.gain.as_ref().map_or(f64::NEG_INFINITY, |g| g.relative)
                        });
                        if better {
                            took = Some((i, c));
                        }
                    } else {
                        let reason = match &c.gain {
                            Some(g) => format!(
                                "no significant held-out gain: {} {:.5} → {:.5} ({:+.2} %), paired p = {:.4} over {} recordings (needs p < {})",
                                g.metric,
                                g.before,
                                g.after,
                                100.0 * g.relative,
                                c.p_value,
                                c.recordings,
                                p.alpha
                            ),
                            None => {
                                "its metric could not be measured on held-out recordings".into()
                            }
                        };
                        rejected.push(Rejected {
                            observable: t.observable,
                            covariate: t.covariate.clone(),
                            step: steps.len() + 1,
                            gain: c.gain.clone(),
                            p_value: c.p_value,
                            reason: reason.clone(),
                        });
                        rejected_keys.insert((t.observable, t.covariate.clone()), reason);
                    }
                }
                if took.is_some() {
                    break;
                }
            }
            let Some((i, c)) = took else {
                break;
            };
            let t = &tests[i];
            let (table, fitted) =
                self.with_full_term(loaded, &full, t, c.shape, sim, fit_params)?;
            full = table;
            let parameters = fitted
                .term
                .function
                .parameters()
                .into_iter()
                .enumerate()
                .map(|(j, (name, value))| ShapeParameter {
                    name: name.to_string(),
                    value,
                    ci95: fitted.intervals.get(j).copied().flatten(),
                })
                .collect();
            steps.push(Step {
                observable: t.observable,
                covariate: t.covariate.clone(),
                term: match c.edge {
                    Some(e) => format!(
                        "{}; the soft edge re-fitted with it (width × {:.3}, dropout {:.4}, residual {:.4} in the last fold)",
                        term_text(t.observable, &t.covariate, c.bins, c.last_term.as_ref()),
                        e.width_factor,
                        e.dropout,
                        e.residual
                    ),
                    None => term_text(t.observable, &t.covariate, c.bins, c.last_term.as_ref()),
                },
                gain: c.gain.clone().expect("an accepted candidate has a gain"),
                p_value: c.p_value,
                recordings: c.recordings,
                shape: c.shape.name().to_string(),
                parameters,
                shapes: c.shapes.clone(),
            });
            accepted.push((round, (t.observable, t.covariate.clone())));
            tables = c.tables;
            evals = c.evals;
        }
        // The final model, simulated, for the combined metrics.
        let metrics = if steps.is_empty() {
            None
        } else {
            let mut fin = Vec::with_capacity(evals.len());
            for (f, table) in tables.iter().enumerate() {
                fin.extend(evaluate(
                    loaded,
                    table,
                    &baseline.held[f],
                    Some(sim),
                    fit_params,
                )?);
            }
            fin.sort_by_key(|e| e.rec);
            Some(Metrics::of(loaded, &fin))
        };
        let findings = annotate(&rounds, &accepted, &rejected_keys, &steps, p.weather);
        Ok(Stagewise {
            steps,
            rejected,
            findings,
            tests: max_tests,
            metrics,
            table: full,
        })
    }

    /// Fits `t`'s term per fold on the fit set on top of `tables` and
    /// measures it on the held-out recordings against `evals`.
    #[allow(clippy::too_many_arguments)]
    fn candidate(
        &self,
        loaded: &Loaded,
        folds: &Folds,
        tables: &[CoefficientTable],
        evals: &[RecEval],
        t: &Test,
        sim: &SimOptions,
        fit_params: &FitValidParams,
        round: usize,
        cache: &mut RoundCache,
    ) -> Result<Candidate, DiagnoseError> {
        let p = &self.0;
        // Counts need simulated near-range returns; the other observables
        // are read from the keep probabilities and kept returns, and keep
        // the current simulations.
        let count = t.observable == ExtensionObservable::Count;
        let with_sim = count.then_some(sim);
        // Per shape: the fold's tables, held-out evaluations, whether
        // every fold could fit it, and its last term.
        struct Tried {
            shape: Shape,
            tables: Vec<CoefficientTable>,
            evals: Vec<RecEval>,
            ok: bool,
            term: Option<extend::FittedTerm>,
            parameters: usize,
        }
        let first_binning = self.extension_binning(loaded, &folds.fit_set(0), t);
        let mut tried: Vec<Tried> = extend::shapes(t.observable, &first_binning)
            .into_iter()
            .map(|shape| Tried {
                shape,
                tables: Vec::with_capacity(folds.k),
                evals: Vec::with_capacity(evals.len()),
                ok: true,
                term: None,
                parameters: 0,
            })
            .collect();
        let mut bins = 0;
        // A survival term re-fits the soft edge with it; the covariate must
        // add something beyond that re-fit: its paired test is against the
        // same fit with one bin (a constant factor and the re-fitted edge).
        let survival = t.observable == ExtensionObservable::Survival;
        // The round's survival reference, when no candidate has made it yet
        // (from the same in-sample evaluations as the shapes: a survival
        // candidate evaluates without simulations).
        let make_null = survival && cache.null.is_none();
        let mut null_evals = Vec::new();
        for (f, table) in tables.iter().enumerate().take(folds.k) {
            let fit_set = folds.fit_set(f);
            let in_sample = evaluate(loaded, table, &fit_set, with_sim, fit_params)?;
            let binning = self.extension_binning(loaded, &fit_set, t);
            bins = binning.len();
            let mut shapes = extend::ShapeCache::default();
            for tr in tried.iter_mut().filter(|tr| tr.ok) {
                let Some(term) = extend::fit_shaped(
                    loaded,
                    table,
                    &in_sample,
                    t.observable,
                    &t.covariate,
                    &binning,
                    tr.shape,
                    true,
                    0,
                    0,
                    &mut shapes,
                )?
                else {
                    tr.ok = false;
                    continue;
                };
                let mut ext = table.clone();
                term.apply_to(&mut ext, p.weather);
                let mut held = evaluate(loaded, &ext, &folds.held_out(f), with_sim, fit_params)?;
                if !count {
                    for e in held.iter_mut() {
                        if let Some(old) = evals.iter().find(|o| o.rec == e.rec) {
                            e.near_sim = old.near_sim;
                            e.near_bins_sim = old.near_bins_sim.clone();
                            e.scene = old.scene;
                        }
                    }
                }
                tr.parameters = tr.parameters.max(term.term.function.parameter_count());
                tr.evals.extend(held);
                tr.tables.push(ext);
                tr.term = Some(term);
            }
            if make_null {
                // One bin along the recording's MOR, which every recording
                // has: a constant factor.
                let one = extend::fit_term_with_edge(
                    loaded,
                    table,
                    &in_sample,
                    t.observable,
                    "mor",
                    &crate::attribution::Binning::Numeric { edges: vec![] },
                    true,
                )?;
                let mut null = table.clone();
                one.apply_to(&mut null, p.weather);
                null_evals.extend(evaluate(
                    loaded,
                    &null,
                    &folds.held_out(f),
                    None,
                    fit_params,
                )?);
            }
        }
        if make_null {
            null_evals.sort_by_key(|e| e.rec);
            let losses = null_evals
                .par_iter()
                .map(|e| recording_loss(loaded, e, ExtensionObservable::Survival))
                .collect();
            cache.null = Some(losses);
        }
        let obs = t.observable;
        tried.retain(|tr| tr.ok);
        for tr in tried.iter_mut() {
            tr.evals.sort_by_key(|e| e.rec);
        }
        // The shape: the simplest (fewest parameters) whose held-out loss
        // is not significantly above the lowest one's (paired test over
        // held-out recordings): a more flexible shape must earn its
        // parameters on recordings it was not fitted on.
        let losses: Vec<Vec<Option<f64>>> = tried
            .iter()
            .map(|tr| {
                tr.evals
                    .par_iter()
                    .map(|e| recording_loss_of(loaded, e, obs, &t.covariate))
                    .collect()
            })
            .collect();
        let mean_loss = |l: &[Option<f64>]| -> f64 {
            let v: Vec<f64> = l.iter().flatten().copied().collect();
            if v.is_empty() {
                f64::INFINITY
            } else {
                v.iter().sum::<f64>() / v.len() as f64
            }
        };
        let means: Vec<f64> = losses.iter().map(|l| mean_loss(l)).collect();
        let best = (0..tried.len())
            .min_by(|&a, &b| means[a].total_cmp(&means[b]))
            .expect("bins always fit");
        let p_worse: Vec<f64> = (0..tried.len())
            .map(|s| {
                if s == best {
                    return 1.0;
                }
                let d: Vec<f64> = losses[s]
                    .iter()
                    .zip(&losses[best])
                    .filter_map(|(a, b)| Some((*a)? - (*b)?))
                    .collect();
                let seed = seed_of(
                    p.seed,
                    Purpose::DiagnoseTest,
                    &[
                        "shape",
                        obs.name(),
                        &t.covariate,
                        &round.to_string(),
                        tried[s].shape.name(),
                    ],
                );
                paired_gain_test(&d, p.permutations, seed)
            })
            .collect();
        let chosen = (0..tried.len())
            .filter(|&s| s == best || p_worse[s] >= p.alpha)
            .min_by_key(|&s| (tried[s].parameters, tried[s].shape))
            .expect("the best shape qualifies");
        let shapes_tried: Vec<ShapeTried> = tried
            .iter()
            .enumerate()
            .map(|(s, tr)| ShapeTried {
                shape: tr.shape.name().to_string(),
                parameters: tr.parameters,
                held_out_loss: means[s],
                p_worse_than_best: (s != best).then_some(p_worse[s]),
                chosen: s == chosen,
            })
            .collect();
        let Tried {
            shape,
            tables: new_tables,
            evals: new_evals,
            term: last,
            ..
        } = tried.swap_remove(chosen);
        let edge = last.as_ref().and_then(|t| t.edge);
        // Per recording: the reference's loss less the chosen shape's.
        let after = &losses[chosen];
        let own: Vec<Option<f64>>;
        let before: &[Option<f64>] = match &cache.null {
            Some(losses) if survival => losses,
            _ => {
                own = evals
                    .par_iter()
                    .map(|e| recording_loss_of(loaded, e, obs, &t.covariate))
                    .collect();
                &own
            }
        };
        let d: Vec<f64> = before
            .iter()
            .zip(after)
            .filter_map(|(a, b)| Some((*a)? - (*b)?))
            .collect();
        let seed = seed_of(
            p.seed,
            Purpose::DiagnoseTest,
            &["paired", obs.name(), &t.covariate, &round.to_string()],
        );
        let p_value = paired_gain_test(&d, p.permutations, seed);
        let (metric, before) = cache
            .before
            .get_or_insert_with(|| Metrics::of(loaded, evals))
            .of_test(obs, &t.covariate);
        let (_, after) = Metrics::of(loaded, &new_evals).of_test(obs, &t.covariate);
        Ok(Candidate {
            tables: new_tables,
            evals: new_evals,
            gain: relative_gain(metric, before, after),
            p_value,
            recordings: d.len(),
            bins,
            edge,
            shape,
            last_term: last.map(|t| t.term),
            shapes: shapes_tried,
        })
    }

    /// `full` with `t`'s term of `shape` fitted on every recording on top
    /// of it, and the term (with its parameters' bootstrap intervals over
    /// recordings).
    fn with_full_term(
        &self,
        loaded: &Loaded,
        full: &CoefficientTable,
        t: &Test,
        shape: Shape,
        sim: &SimOptions,
        fit_params: &FitValidParams,
    ) -> Result<(CoefficientTable, extend::FittedTerm), DiagnoseError> {
        let all: Vec<usize> = (0..loaded.recs.len()).collect();
        let with_sim = (t.observable == ExtensionObservable::Count).then_some(sim);
        let in_sample = evaluate(loaded, full, &all, with_sim, fit_params)?;
        let binning = self.extension_binning(loaded, &all, t);
        let seed = seed_of(
            self.0.seed,
            Purpose::Bootstrap,
            &["shape", t.observable.name(), &t.covariate],
        );
        let mut cache = extend::ShapeCache::default();
        let mut fit = |shape| {
            extend::fit_shaped(
                loaded,
                full,
                &in_sample,
                t.observable,
                &t.covariate,
                &binning,
                shape,
                true,
                extend::BOOTSTRAP,
                seed,
                &mut cache,
            )
        };
        // The shape fitted in every fold fits on all of them; bins always do.
        let term = match fit(shape)? {
            Some(term) => term,
            None => fit(Shape::Bins)?.expect("bins always fit"),
        };
        let mut table = full.clone();
        term.apply_to(&mut table, self.0.weather);
        Ok((table, term))
    }
}

/// The baseline's findings annotated with what the steps did to them (module
/// docs), in report order.
fn annotate(
    rounds: &[Vec<Finding>],
    accepted: &[(usize, Key)],
    rejected: &BTreeMap<Key, String>,
    steps: &[Step],
    weather: murk_types::WeatherClass,
) -> Vec<Finding> {
    let mut out: Vec<Finding> = rounds[0].clone();
    let last = rounds.len() - 1;
    let find = |r: usize, k: &Key| rounds[r].iter().find(|f| &key(f) == k);
    for f in out.iter_mut() {
        let k = key(f);
        if let Some(s) = accepted.iter().position(|(_, a)| *a == k) {
            let round = accepted[s].0;
            if let Some(g) = find(round, &k) {
                *f = g.clone();
            }
            f.significant = true;
            f.explained_by = None;
            f.step = Some(s + 1);
            f.cause = crate::report::cause(f, weather);
            continue;
        }
        if let Some(why) = rejected.get(&k) {
            f.significant = false;
            f.rejected = Some(why.clone());
            f.cause = crate::report::cause(f, weather);
            continue;
        }
        // The last round in which it was significant.
        let Some(r) = (0..=last)
            .rev()
            .find(|&r| find(r, &k).is_some_and(|g| g.significant))
        else {
            continue;
        };
        if r == last {
            // Still significant: the step cap stopped the loop first (every
            // tested covariate has a term: counts are tested only along the
            // near-range returns' own covariates, `COUNT_POINT_COVARIATES`).
            if !f.significant
                && let Some(g) = find(r, &k)
            {
                *f = g.clone();
            }
            f.cause = format!(
                "{} (not extended: the {} steps allowed were used first)",
                f.cause,
                crate::MAX_STEPS
            );
            continue;
        }
        // Significant in round r, not after the step accepted then.
        if let Some(s) = accepted.iter().position(|(ar, _)| *ar == r) {
            f.significant = false;
            f.explained_by = Some(steps[s].covariate.clone());
            f.cause = format!(
                "{} follows {:?} only as far as {} along {:?} does: nothing is left once that term (step {}) is in the model",
                f.observable,
                f.covariate,
                steps[s].observable,
                steps[s].covariate,
                s + 1
            );
        }
    }
    let order = rank(&out);
    order.into_iter().map(|i| out[i].clone()).collect()
}
