//! A vanishing law that can bend, and the evidence for or against the line.
//!
//! The survival fit ([`crate::survival`]) places each band's edge at
//! `D = s·MOR·ρ`. Physics says otherwise in fog (the lidar equation gives a
//! 50 %-survival range that grows sublinearly with MOR), so this module
//!
//! - fits the power law `D = a·MOR^c·ρ` of each band (its own coefficient,
//!   exponent, edge width, ε and π) by maximum likelihood: for a fixed `c`,
//!   `r/(ρ·MOR^c) = u·MOR^(1−c)` with `u = r/(MOR·ρ)`, so every recording's
//!   trials move along `ln u` by `(1 − c)·ln MOR` and the survival fit runs
//!   unchanged on them; `c` is profiled (Brent's method, argmin's);
//! - chooses between the line and the power law on held-out recordings
//!   (folds over recordings, per-recording log-likelihood gains, one-sided
//!   sign-flip test), so the line stays unless the bend predicts recordings
//!   it has not seen significantly better;
//! - when asked (`reflectivity_law_edges`), fits a reflectivity term
//!   inside each band, `D·(x/x_ref)^k` ([`fit_reflectivity`]), on the
//!   band's reflectivity classes moved by `−k·(ln x − ln x_ref)` in `ln u`
//!   the same way, and compares it with the preferred law on the same
//!   folds ([`compare_reflectivity`]);
//! - measures, per MOR bin and band, the nonparametric 50 %-survival range
//!   (isotonic survival curve in range, pooled over the bin's recordings)
//!   with a bootstrap-over-recordings interval, and tests the fitted line
//!   against those ranges (χ² lack of fit on the log scale).
//!
//! No I/O; every random step is seeded by `murk_types::seed`.

use rand::{RngExt, SeedableRng, rngs::ChaCha8Rng};
use rayon::prelude::*;

use crate::hyperparams::EdgeShape;
use crate::survival::{
    Obs, RecordingTrials, SurvivalOptions, SurvivalResult, fit_survival, sign_flip_p,
};

/// Range of the exponent searched, and the precision of its profile.
const EXPONENT_RANGE: (f64, f64) = (0.2, 1.8);
const EXPONENT_TOL: f64 = 0.002;

/// Width of the range bins pooled for the nonparametric curve, in `ln r`.
pub const RANGE_STEP: f64 = 0.02;

/// The trials of `recs` per band with `u` moved to `u·MOR^(1−c)`, binned
/// at `step` in `ln u` (bins anchored as the survival histogram's, so
/// `c = 1` gives its observations back).
///
/// The binning is linear (as in linear-binned kernel estimates): a shifted
/// observation between two bin centres shares its trials and survivors
/// between them in proportion to its nearness, so the binned data, and the
/// profile likelihood over `c` computed on them, change continuously with
/// `c`. Flooring each observation into one bin (as before) made the profile
/// jump by tens of nats between exponents 0.005 apart whenever a
/// recording's observations crossed a bin edge, and a 1-D search then
/// returned a local optimum. Linear binning keeps each observation's mean
/// `ln u` and costs no more than flooring.
pub fn shifted_observations(
    recs: &[&RecordingTrials],
    n_bands: usize,
    c: f64,
    step: f64,
    anchor: f64,
) -> Vec<Vec<Obs>> {
    (0..n_bands)
        .map(|b| {
            linear_binned(
                recs.iter()
                    .map(|r| ((1.0 - c) * r.mor.ln(), r.bands[b].as_slice())),
                step,
                anchor,
            )
        })
        .collect()
}

/// The exponent of reflectivity of a term at a recording's MOR:
/// `k + g·(ln MOR − ln M_ref)` (`g = 0`: one `k` at every MOR).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TermExponent {
    /// `k` at the reference MOR.
    pub k: f64,
    /// Change of `k` per unit of `ln MOR`.
    pub g: f64,
    /// `ln` of the reference MOR (metres).
    pub ln_mor_ref: f64,
}

impl TermExponent {
    /// One `k` at every MOR.
    pub fn constant(k: f64) -> Self {
        TermExponent {
            k,
            g: 0.0,
            ln_mor_ref: 0.0,
        }
    }

    /// The exponent at `ln MOR` (exactly `k` when `g` is 0).
    #[inline]
    pub fn at(&self, ln_mor: f64) -> f64 {
        if self.g == 0.0 {
            self.k
        } else {
            self.k + self.g * (ln_mor - self.ln_mor_ref)
        }
    }
}

/// [`shifted_observations`] with a reflectivity term: each class of a
/// band's trials ([`RecordingTrials::classes`]) also moves by `−k·δ`, `δ`
/// its `ln x` less the band's reference and `k` the term's exponent at the
/// recording's MOR, so a fit on them places the edge at
/// `a·MOR^c·(x/x_ref)^k`. `k = g = 0` is [`shifted_observations`] exactly.
pub fn shifted_class_observations(
    recs: &[&RecordingTrials],
    n_bands: usize,
    c: f64,
    e: TermExponent,
    step: f64,
    anchor: f64,
) -> Vec<Vec<Obs>> {
    if e.k == 0.0 && e.g == 0.0 {
        return shifted_observations(recs, n_bands, c, step, anchor);
    }
    (0..n_bands)
        .map(|b| {
            linear_binned(
                recs.iter().flat_map(|r| {
                    let ln_mor = r.mor.ln();
                    let shift = (1.0 - c) * ln_mor;
                    let k = e.at(ln_mor);
                    r.classes
                        .get(b)
                        .into_iter()
                        .flatten()
                        .map(move |(delta, obs)| (shift - k * delta, obs.as_slice()))
                }),
                step,
                anchor,
            )
        })
        .collect()
}

/// Observations moved by their shift in `ln u`, linear-binned at `step`.
fn linear_binned<'a>(
    items: impl Iterator<Item = (f64, &'a [Obs])>,
    step: f64,
    anchor: f64,
) -> Vec<Obs> {
    // Positions this close to a bin centre (in bins) are on it: `c = 1`
    // gives the observations back exactly, not with a 1e-12 share moved.
    const ON_CENTRE: f64 = 1e-9;
    // Each observation's lower bin and its share of the next, then the
    // sums in a dense run of bins (a map per call was most of a profile
    // step's time once the reflectivity classes multiplied the
    // observations); the same additions in the same order, so the same bits.
    let mut placed: Vec<(i64, f64, f64, f64)> = Vec::new();
    let (mut lo, mut hi) = (i64::MAX, i64::MIN);
    for (shift, obs) in items {
        for o in obs {
            // Position in bin centres: bin k's centre is at k.
            let x = (o.u.ln() + shift - anchor) / step - 0.5;
            let nearest = x.round();
            let (k, w) = if (x - nearest).abs() < ON_CENTRE {
                (nearest as i64, 0.0)
            } else {
                let k = x.floor();
                (k as i64, x - k)
            };
            lo = lo.min(k);
            hi = hi.max(k + 1);
            placed.push((k, w, o.kept, o.total));
        }
    }
    if placed.is_empty() {
        return Vec::new();
    }
    let mut m = vec![(0.0f64, 0.0f64); (hi - lo + 1) as usize];
    for (k, w, kept, total) in placed {
        let e = &mut m[(k - lo) as usize];
        e.0 += (1.0 - w) * kept;
        e.1 += (1.0 - w) * total;
        if w > 0.0 {
            let e = &mut m[(k + 1 - lo) as usize];
            e.0 += w * kept;
            e.1 += w * total;
        }
    }
    m.into_iter()
        .enumerate()
        .filter(|(_, (_, n))| *n > 0.0)
        .map(|(j, (kept, total))| Obs {
            u: (anchor + ((j as i64 + lo) as f64 + 0.5) * step).exp(),
            kept,
            total,
        })
        .collect()
}

/// A power-law fit: the exponent and the survival fit at it (whose band
/// slopes are the coefficients `a`).
#[derive(Debug, Clone, PartialEq)]
pub struct PowerFit {
    /// The exponent `c` of MOR.
    pub exponent: f64,
    /// The survival fit on the shifted trials.
    pub fit: SurvivalResult,
}

/// Binning of the shifted trials: the survival histogram's step and anchor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Binning {
    /// Bin width in `ln u`.
    pub step: f64,
    /// `ln u` of the first bin's lower edge.
    pub anchor: f64,
}

/// Fits band `band` alone (its own edge width, ε and π) at exponent `c`;
/// `None` when it has no slope there.
pub fn fit_band_at(
    recs: &[&RecordingTrials],
    n_bands: usize,
    band: usize,
    c: f64,
    opts: &SurvivalOptions,
    bin: Binning,
) -> Option<SurvivalResult> {
    fit_band_at_k(
        recs,
        n_bands,
        band,
        c,
        TermExponent::constant(0.0),
        opts,
        bin,
    )
}

/// [`fit_band_at`] with the reflectivity exponent `e` too
/// ([`shifted_class_observations`]).
pub fn fit_band_at_k(
    recs: &[&RecordingTrials],
    n_bands: usize,
    band: usize,
    c: f64,
    e: TermExponent,
    opts: &SurvivalOptions,
    bin: Binning,
) -> Option<SurvivalResult> {
    let mut obs = shifted_class_observations(recs, n_bands, c, e, bin.step, bin.anchor);
    for (j, o) in obs.iter_mut().enumerate() {
        if j != band {
            o.clear();
        }
    }
    fit_survival(&obs, opts).filter(|r| r.bands[band].slope.is_ok())
}

/// Fits the power law of band `band` on `recs` (profile likelihood over
/// its exponent; the band's own edge width, ε and π).
///
/// The profile is smooth in the exponent because the shifted trials are
/// linear-binned ([`shifted_observations`]): scanned at steps of 0.005
/// around the estimate on the physics-fog campaigns of `fit/tests/bend.rs`
/// (3 seeds, 2 bands, the full fit and its folds), it rises on both sides
/// like a parabola, by 35–230 nats at ±0.05, and no neighbour 0.005 away
/// is more than 0.6 nats below the estimate (the search's tolerance is
/// 0.002). Flooring each trial into one bin, as before, made neighbours
/// differ by tens of nats and the search stop at local optima 0.01–0.02
/// from the maximum.
pub fn fit_power(
    recs: &[&RecordingTrials],
    n_bands: usize,
    band: usize,
    opts: &SurvivalOptions,
    bin: Binning,
) -> Option<PowerFit> {
    let eval = |c: f64| fit_band_at(recs, n_bands, band, c, opts, bin);
    let cost = |c: f64| eval(c).map_or(f64::INFINITY, |r| r.nll);
    let (lo, hi) = EXPONENT_RANGE;
    let c = crate::stats::optim::minimize_scalar(&cost, lo, hi, EXPONENT_TOL)?;
    let fit = eval(c)?;
    fit.nll.is_finite().then_some(PowerFit { exponent: c, fit })
}

/// The power law of every band whose line has a slope (`fitted[i]`).
pub fn fit_powers(
    recs: &[&RecordingTrials],
    fitted: &[bool],
    opts: &SurvivalOptions,
    bin: Binning,
) -> Vec<Option<PowerFit>> {
    // Bands in parallel (each its own profile search; order kept).
    (0..fitted.len())
        .into_par_iter()
        .map(|i| {
            fitted[i]
                .then(|| fit_power(recs, fitted.len(), i, opts, bin))
                .flatten()
        })
        .collect()
}

/// The held-out comparison of the power law with the line (see the module
/// docs).
#[derive(Debug, Clone, PartialEq)]
pub struct LawEvidence {
    /// Mean held-out gain of the power law, nats per recording.
    pub gain: f64,
    /// One-sided sign-flip p-value.
    pub p: f64,
    /// Recordings compared.
    pub recordings: usize,
    /// Recordings the power law predicted better.
    pub better: usize,
    /// `fold_exponents[f][b]`: band `b`'s exponent fitted without fold `f`
    /// (`None` for a band that takes no part).
    pub fold_exponents: Vec<Vec<Option<f64>>>,
}

/// Compares the power law with the line on held-out recordings: `folds`
/// folds interleaved in MOR order, each predicted by both laws fitted
/// without it, band by band with the same freedom (each band its own edge
/// width, ε and π), so the gain is the exponent's alone. `fitted[b]` says
/// which bands take part.
pub fn compare_laws(
    recs: &[RecordingTrials],
    fitted: &[bool],
    opts: &SurvivalOptions,
    bin: Binning,
    folds: usize,
    seed: [u8; 32],
) -> Result<LawEvidence, String> {
    let n_bands = fitted.len();
    let lp = |p: f64| p.clamp(1e-12, 1.0 - 1e-12);
    held_out(recs, folds, seed, |train, held| {
        // The line with the same per-band freedom (edge width, ε, π) as the
        // power law, so the comparison weighs the exponent alone.
        let lines: Vec<Option<SurvivalResult>> = (0..n_bands)
            .map(|b| {
                fitted[b]
                    .then(|| fit_band_at(train, n_bands, b, 1.0, opts, bin))
                    .flatten()
            })
            .collect();
        let powers = fit_powers(train, fitted, opts, bin);
        if powers.iter().zip(fitted).any(|(p, f)| *f && p.is_none()) {
            return Err(
                "the power law could not be fitted with a fold of recordings left out".into(),
            );
        }
        let exponents = powers
            .iter()
            .map(|p| p.as_ref().map(|p| p.exponent))
            .collect();
        let mut gains = Vec::new();
        for r in held {
            let mut d = 0.0;
            let mut any = false;
            for (b, power) in powers.iter().enumerate() {
                let (Some(power), Some(line)) = (power, &lines[b]) else {
                    continue;
                };
                let shift = (1.0 - power.exponent) * r.mor.ln();
                for o in &r.bands[b] {
                    let (Some(pl), Some(pp)) = (
                        line.keep_probability(opts, b, o.u),
                        power
                            .fit
                            .keep_probability(opts, b, (o.u.ln() + shift).exp()),
                    ) else {
                        continue;
                    };
                    let (pl, pp) = (lp(pl), lp(pp));
                    any = true;
                    d += o.kept * (pp / pl).ln()
                        + (o.total - o.kept) * ((1.0 - pp) / (1.0 - pl)).ln();
                }
            }
            if any {
                gains.push(d);
            }
        }
        Ok((exponents, gains))
    })
}

/// The held-out comparison's frame, shared by [`compare_laws`] and
/// [`compare_reflectivity`]: `folds` folds of `recs` interleaved in MOR
/// order; `fold(train, held)` fits on the training recordings and returns
/// its exponents and the gains of the held-out recordings it could score.
/// Folds run in parallel; the gains are put back in fold order, so the
/// result is the same on any thread count.
fn held_out<F>(
    recs: &[RecordingTrials],
    folds: usize,
    seed: [u8; 32],
    fold: F,
) -> Result<LawEvidence, String>
where
    F: Fn(&[&RecordingTrials], &[&RecordingTrials]) -> Result<(Vec<Option<f64>>, Vec<f64>), String>
        + Sync,
{
    let g_n = recs.len();
    if g_n < folds.max(3) {
        return Err(format!(
            "too few recordings ({g_n}) to compare the laws on held-out recordings"
        ));
    }
    let mors: Vec<f64> = recs.iter().map(|r| r.mor).collect();
    let fold_of = crate::stats::interleaved_folds(&mors, folds);
    type Fold = Result<(Vec<Option<f64>>, Vec<f64>), String>;
    let per_fold: Vec<Fold> = (0..folds)
        .into_par_iter()
        .map(|f| {
            let (held, train): (Vec<&RecordingTrials>, Vec<&RecordingTrials>) = (0..g_n)
                .map(|g| &recs[g])
                .zip(&fold_of)
                .fold((Vec::new(), Vec::new()), |(mut h, mut t), (r, &k)| {
                    if k == f {
                        h.push(r)
                    } else {
                        t.push(r)
                    }
                    (h, t)
                });
            fold(&train, &held)
        })
        .collect();
    let mut gains = Vec::new();
    let mut fold_exponents = Vec::with_capacity(folds);
    for f in per_fold {
        let (exponents, g) = f?;
        fold_exponents.push(exponents);
        gains.extend(g);
    }
    let n = gains.len();
    if n < 3 {
        return Err(format!(
            "too few recordings with fitted bands ({n}) to compare the laws"
        ));
    }
    Ok(LawEvidence {
        gain: gains.iter().sum::<f64>() / n as f64,
        p: sign_flip_p(&gains, seed),
        recordings: n,
        better: gains.iter().filter(|x| **x > 0.0).count(),
        fold_exponents,
    })
}

/// Range of the reflectivity exponent searched (the lidar equation in fog
/// gives about 0.1–0.25: see [`ReflectivityFit`]).
const REFLECTIVITY_EXPONENT_RANGE: (f64, f64) = (-1.0, 1.5);

/// Range of the change of the reflectivity exponent per unit of `ln MOR`
/// searched (the lidar equation in fog gives about 0.03–0.05 over MOR
/// 4–300 m: see [`ReflectivityFit`]).
const MOR_SLOPE_RANGE: (f64, f64) = (-0.5, 0.5);

/// A band's law with a reflectivity term: `a·MOR^c·(x/x_ref)^k`.
///
/// Why a power of reflectivity: in fog the hard echo of a return of
/// reflectivity `x` at range `R` is `∝ x·exp(−2αR)/R²` and it is lost where
/// it falls below the fog's own echo, so its 50 %-survival range solves
/// `ln x = 2αR + 2 ln R + const`: `d ln R / d ln x = 1/(2αR + 2)`, about
/// 0.13–0.2 at the ranges where returns vanish (`α = ln 20/MOR`,
/// `R ≈ 0.5–0.9·MOR`), nearly constant, so a power of `x` with one exponent
/// per band follows it within a few percent. Where the data pin it down
/// further, `k` may change with MOR (`k + g·ln(MOR/M_ref)`): `R₅₀/MOR`
/// shrinks as MOR grows (the law bends, `c < 1`), so `1/(2αR₅₀ + 2)` grows
/// — about 0.13 to 0.20 from MOR 4 to 30 m on the physics fixture's scene.
#[derive(Debug, Clone, PartialEq)]
pub struct ReflectivityFit {
    /// The exponent `c` of MOR (1 when the line was kept).
    pub exponent: f64,
    /// The exponent `k` of reflectivity (at `ln_mor_ref` when `per_ln_mor`
    /// is not 0).
    pub reflectivity_exponent: f64,
    /// The change of `k` per unit of `ln MOR` (0: one `k`).
    pub per_ln_mor: f64,
    /// `ln` of the MOR at which `k` is `reflectivity_exponent`.
    pub ln_mor_ref: f64,
    /// The survival fit on the shifted trials (its band slope is `a`).
    pub fit: SurvivalResult,
}

impl ReflectivityFit {
    /// The term's exponent of reflectivity.
    pub fn term(&self) -> TermExponent {
        TermExponent {
            k: self.reflectivity_exponent,
            g: self.per_ln_mor,
            ln_mor_ref: self.ln_mor_ref,
        }
    }

    /// Log-likelihood of recording `r`'s trials of band `b` under the fit.
    fn log_likelihood(&self, opts: &SurvivalOptions, b: usize, r: &RecordingTrials) -> Option<f64> {
        let ln_mor = r.mor.ln();
        let shift = (1.0 - self.exponent) * ln_mor;
        let k = self.term().at(ln_mor);
        r.classes
            .get(b)
            .into_iter()
            .flatten()
            .map(|(delta, obs)| log_likelihood(&self.fit, opts, b, obs, shift - k * delta))
            .sum()
    }
}

/// Fits band `band`'s law with a reflectivity term on `recs`: profile
/// likelihood over `k` at `c = bend_from` (1 when `None`, the line), and,
/// when the law bends or `k` changes with MOR (`vary`: `ln` of the
/// reference MOR), over `c` (bending), `k` and `g` (varying) by turns, each
/// turn followed by a search along its own move, until a turn moves none
/// (each search Brent's method). `None` when the band has no class spread
/// (every trial in one class) or no slope.
pub fn fit_reflectivity(
    recs: &[&RecordingTrials],
    n_bands: usize,
    band: usize,
    bend_from: Option<f64>,
    vary: Option<f64>,
    opts: &SurvivalOptions,
    bin: Binning,
) -> Option<ReflectivityFit> {
    let spread = recs
        .iter()
        .flat_map(|r| r.classes.get(band).into_iter().flatten())
        .filter(|(_, o)| !o.is_empty())
        .map(|(d, _)| *d)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), d| {
            (a.min(d), b.max(d))
        });
    if !(spread.1 - spread.0 > 0.0) {
        return None;
    }
    let ln_mor_ref = vary.unwrap_or(0.0);
    let term = |k: f64, g: f64| TermExponent { k, g, ln_mor_ref };
    let eval =
        |c: f64, k: f64, g: f64| fit_band_at_k(recs, n_bands, band, c, term(k, g), opts, bin);
    let cost = |c: f64, k: f64, g: f64| eval(c, k, g).map_or(f64::INFINITY, |r| r.nll);
    let (klo, khi) = REFLECTIVITY_EXPONENT_RANGE;
    let c0 = bend_from.unwrap_or(1.0);
    let k0 = crate::stats::optim::minimize_scalar(&|k| cost(c0, k, 0.0), klo, khi, EXPONENT_TOL)?;
    // The coordinates searched by turns, in order: c (bending), k, g
    // (varying), each with its range; the point is (c, k, g).
    let mut axes: Vec<(usize, (f64, f64))> = Vec::new();
    if bend_from.is_some() {
        axes.push((0, EXPONENT_RANGE));
    }
    if !axes.is_empty() || vary.is_some() {
        axes.push((1, REFLECTIVITY_EXPONENT_RANGE));
    }
    if vary.is_some() {
        axes.push((2, MOR_SLOPE_RANGE));
    }
    let at = |x: [f64; 3]| cost(x[0], x[1], x[2]);
    let mut x = [c0, k0, 0.0];
    if !axes.is_empty() {
        // By turns, each turn followed by a search along the turn's own
        // move: where the coordinates trade off (a ridge of the
        // likelihood: in a scene whose dim returns sit near, c and k both
        // move the band's edge alike) turns alone creep along the ridge
        // and stop short of its top, at a point that depends on where they
        // started. The cost at x as it stands (each a survival fit).
        let mut here = at(x);
        for _ in 0..8 {
            let before = here;
            let from = x;
            for &(j, (lo, hi)) in &axes {
                let line = |v: f64| {
                    let mut y = x;
                    y[j] = v;
                    at(y)
                };
                x[j] = crate::stats::optim::minimize_scalar(&line, lo, hi, EXPONENT_TOL)?;
            }
            let d: Vec<f64> = axes.iter().map(|&(j, _)| x[j] - from[j]).collect();
            here = at(x);
            let size = d.iter().fold(0f64, |m, v| m.max(v.abs()));
            if size < EXPONENT_TOL {
                break;
            }
            // How far along d the searched ranges allow, up to 8 moves.
            let room = |v: f64, dv: f64, (lo, hi): (f64, f64)| {
                if dv > 0.0 {
                    (hi - v) / dv
                } else if dv < 0.0 {
                    (lo - v) / dv
                } else {
                    f64::INFINITY
                }
            };
            let t_max = axes
                .iter()
                .zip(&d)
                .fold(8f64, |t, (&(j, r), &dv)| t.min(room(x[j], dv, r)));
            if t_max > EXPONENT_TOL / size {
                let moved = |t: f64| {
                    let mut y = x;
                    for (&(j, _), &dv) in axes.iter().zip(&d) {
                        y[j] = x[j] + t * dv;
                    }
                    y
                };
                let along = |t: f64| at(moved(t));
                let t =
                    crate::stats::optim::minimize_scalar(&along, 0.0, t_max, EXPONENT_TOL / size)?;
                let there = along(t);
                if there < here {
                    x = moved(t);
                    here = there;
                }
            }
            // A turn that gains less than a hundredth of a nat is done:
            // the searches' own precision moves the point by that much.
            if before - here < 0.01 {
                break;
            }
        }
    }
    let [c, k, g] = x;
    let fit = eval(c, k, g)?;
    fit.nll.is_finite().then_some(ReflectivityFit {
        exponent: c,
        reflectivity_exponent: k,
        per_ln_mor: g,
        ln_mor_ref,
        fit,
    })
}

/// [`fit_reflectivity`] of every band with a slope (`fitted[i]`), bands in
/// parallel; `bend_from[i]` is band `i`'s exponent of MOR to start from
/// when the law bends (`None`: the line); `vary`, the `ln` of the
/// reference MOR when `k` may change with MOR.
pub fn fit_reflectivities(
    recs: &[&RecordingTrials],
    fitted: &[bool],
    bend_from: &[Option<f64>],
    vary: Option<f64>,
    opts: &SurvivalOptions,
    bin: Binning,
) -> Vec<Option<ReflectivityFit>> {
    (0..fitted.len())
        .into_par_iter()
        .map(|i| {
            fitted[i]
                .then(|| fit_reflectivity(recs, fitted.len(), i, bend_from[i], vary, opts, bin))
                .flatten()
        })
        .collect()
}

/// Log-likelihood of `obs` moved by `shift` in `ln u` under band `b` of
/// `fit`; `None` when the fit has no slope there.
fn log_likelihood(
    fit: &SurvivalResult,
    opts: &SurvivalOptions,
    b: usize,
    obs: &[Obs],
    shift: f64,
) -> Option<f64> {
    let lp = |p: f64| p.clamp(1e-12, 1.0 - 1e-12);
    let mut l = 0.0;
    for o in obs {
        let p = lp(fit.keep_probability(opts, b, (o.u.ln() + shift).exp())?);
        l += o.kept * p.ln() + (o.total - o.kept) * (1.0 - p).ln();
    }
    Some(l)
}

/// What [`compare_reflectivity`] compares on held-out recordings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TermComparison {
    /// The term of one `k` against the law without it: the line (`bend`
    /// false) or the power law (`bend` true); `fold_exponents` holds the
    /// folds' `k`.
    Term {
        /// Whether the law bends.
        bend: bool,
    },
    /// The term whose `k` changes with MOR (`ln_mor_ref`: `ln` of the
    /// reference MOR) against the term of one `k`, both from the bend's
    /// exponent when `bend`; `fold_exponents` holds the folds' `g`.
    MorVarying {
        /// Whether the law bends.
        bend: bool,
        /// `ln` of the reference MOR (metres).
        ln_mor_ref: f64,
    },
}

/// The held-out comparison of a reflectivity term ([`TermComparison`]),
/// each law fitted per band with the same freedom, all fitted without the
/// fold, as [`compare_laws`].
pub fn compare_reflectivity(
    recs: &[RecordingTrials],
    fitted: &[bool],
    what: TermComparison,
    opts: &SurvivalOptions,
    bin: Binning,
    folds: usize,
    seed: [u8; 32],
) -> Result<LawEvidence, String> {
    let (bend, vary) = match what {
        TermComparison::Term { bend } => (bend, None),
        TermComparison::MorVarying { bend, ln_mor_ref } => (bend, Some(ln_mor_ref)),
    };
    let n_bands = fitted.len();
    held_out(recs, folds, seed, |train, held| {
        // The law without the term: (exponent, fit) per band.
        let base: Vec<Option<(f64, SurvivalResult)>> = (0..n_bands)
            .map(|b| {
                if !fitted[b] {
                    None
                } else if bend {
                    fit_power(train, n_bands, b, opts, bin).map(|p| (p.exponent, p.fit))
                } else {
                    fit_band_at(train, n_bands, b, 1.0, opts, bin).map(|r| (1.0, r))
                }
            })
            .collect();
        let from: Vec<Option<f64>> = base
            .iter()
            .map(|b| b.as_ref().map(|(c, _)| *c).filter(|_| bend))
            .collect();
        let alt = fit_reflectivities(train, fitted, &from, vary, opts, bin);
        // With `vary`, the term of one `k` is the base.
        let base_term = vary.map(|_| fit_reflectivities(train, fitted, &from, None, opts, bin));
        let missing = |fits: &[Option<ReflectivityFit>]| {
            fits.iter().zip(fitted).any(|(p, f)| *f && p.is_none())
        };
        if missing(&alt) || base_term.as_deref().is_some_and(missing) {
            return Err(
                "the reflectivity term could not be fitted with a fold of recordings left out"
                    .into(),
            );
        }
        let exponents = alt
            .iter()
            .map(|p| {
                p.as_ref().map(|p| {
                    if vary.is_some() {
                        p.per_ln_mor
                    } else {
                        p.reflectivity_exponent
                    }
                })
            })
            .collect();
        let mut gains = Vec::new();
        for r in held {
            let mut d = 0.0;
            let mut any = false;
            for (b, alt) in alt.iter().enumerate() {
                let (Some(alt), Some((c0, base))) = (alt, &base[b]) else {
                    continue;
                };
                let l0 = match &base_term {
                    Some(t) => t[b].as_ref().and_then(|t| t.log_likelihood(opts, b, r)),
                    None => log_likelihood(base, opts, b, &r.bands[b], (1.0 - c0) * r.mor.ln()),
                };
                let l1 = alt.log_likelihood(opts, b, r);
                if let (Some(l0), Some(l1)) = (l0, l1) {
                    any = true;
                    d += l1 - l0;
                }
            }
            if any {
                gains.push(d);
            }
        }
        Ok((exponents, gains))
    })
}

/// The grouped-jackknife 95 % interval of `g`, the change of the
/// reflectivity exponent per unit of `ln MOR` (as [`jackknife_interval`],
/// over its searched range).
pub fn mor_slope_jackknife_interval(
    estimate: f64,
    leave_out: &[Option<f64>],
) -> Result<[f64; 2], String> {
    jackknife_in(estimate, leave_out, MOR_SLOPE_RANGE)
}

/// The grouped-jackknife 95 % interval of the reflectivity exponent `k`
/// (as [`jackknife_interval`], over [`REFLECTIVITY_EXPONENT_RANGE`]).
pub fn reflectivity_jackknife_interval(
    estimate: f64,
    leave_out: &[Option<f64>],
) -> Result<[f64; 2], String> {
    jackknife_in(estimate, leave_out, REFLECTIVITY_EXPONENT_RANGE)
}

/// The 50 % crossing of a fitted law's survival over the clear returns of
/// band `band` in `recs` (one MOR bin), pooled by range as
/// [`half_survival`] pools the data: what the law predicts for that
/// number. `keep(r, delta, u)` is the law's keep probability of a trial at
/// `u` of a class `delta` from the band's reference in recording `r`.
pub fn predicted_half_crossing(
    recs: &[&RecordingTrials],
    band: usize,
    keep: impl Fn(&RecordingTrials, f64, f64) -> Option<f64>,
) -> Result<f64, String> {
    let mut m: std::collections::BTreeMap<i64, (f64, f64)> = Default::default();
    for r in recs {
        // The law's expected survivors in place of the kept ones.
        let predicted = r
            .classes
            .get(band)
            .into_iter()
            .flatten()
            .flat_map(|(delta, obs)| obs.iter().map(move |o| (*delta, o)))
            .map(|(delta, o)| {
                let p = keep(r, delta, o.u).ok_or("the law has no slope in this band")?;
                Ok(Obs {
                    kept: p * o.total,
                    ..*o
                })
            })
            .collect::<Result<Vec<Obs>, String>>()?;
        for (k, kept, total) in by_range(&predicted, r.ln_mor_scaled) {
            let e = m.entry(k).or_default();
            e.0 += kept;
            e.1 += total;
        }
    }
    let rows: Vec<(i64, f64, f64)> = m.into_iter().map(|(k, (a, b))| (k, a, b)).collect();
    half_crossing(&rows)
}

/// The grouped-jackknife 95 % interval of an exponent from its fits with
/// each of `k` folds of recordings left out (`k ≥ 3`): centre `estimate`,
/// variance `(k − 1)/k · Σ (θ₋f − θ̄)²`, Student's t on `k − 1` degrees of
/// freedom. A resampling interval over recordings, like every interval of
/// the table, reusing the held-out comparison's fits instead of new ones.
/// `Err` when a fold's exponent is missing or any fit sits within the
/// search's precision of the searched range's ends (the profile did not
/// find an interior optimum, so its spread says nothing).
pub fn jackknife_interval(estimate: f64, leave_out: &[Option<f64>]) -> Result<[f64; 2], String> {
    jackknife_in(estimate, leave_out, EXPONENT_RANGE)
}

fn jackknife_in(
    estimate: f64,
    leave_out: &[Option<f64>],
    (lo, hi): (f64, f64),
) -> Result<[f64; 2], String> {
    let k = leave_out.len();
    if k < 3 {
        return Err(format!("{k} folds are too few for a jackknife interval"));
    }
    let Some(th): Option<Vec<f64>> = leave_out.iter().copied().collect() else {
        return Err("the exponent could not be fitted with a fold left out".into());
    };
    let edge = |c: f64| c <= lo + 2.0 * EXPONENT_TOL || c >= hi - 2.0 * EXPONENT_TOL;
    if edge(estimate) || th.iter().any(|&c| edge(c)) {
        return Err(format!(
            "an exponent sits at the end of the searched range [{lo}, {hi}]"
        ));
    }
    let (_, half) = crate::stats::jackknife(&th).ok_or("a fold's exponent is not finite")?;
    Ok([estimate - half, estimate + half])
}

/// One recording's trials of one band by range: `(ln r bin, kept, total)`
/// at [`RANGE_STEP`].
fn by_range(obs: &[Obs], ln_mor_scaled: f64) -> Vec<(i64, f64, f64)> {
    let mut m: std::collections::BTreeMap<i64, (f64, f64)> = Default::default();
    for o in obs {
        let k = ((o.u.ln() + ln_mor_scaled) / RANGE_STEP).floor() as i64;
        let e = m.entry(k).or_default();
        e.0 += o.kept;
        e.1 += o.total;
    }
    m.into_iter().map(|(k, (a, b))| (k, a, b)).collect()
}

/// The 50 % crossing of the non-increasing (isotonic) fit to the kept
/// shares of pooled `(ln r bin, kept, total)` rows in bin order, metres.
pub fn half_crossing(rows: &[(i64, f64, f64)]) -> Result<f64, String> {
    // Pool-adjacent-violators for a non-increasing sequence: blocks of
    // (weighted ln r sum, kept, total).
    let mut blocks: Vec<(f64, f64, f64)> = Vec::new();
    for &(k, kept, total) in rows {
        if total <= 0.0 {
            continue;
        }
        let lr = (k as f64 + 0.5) * RANGE_STEP;
        blocks.push((lr * total, kept, total));
        while blocks.len() >= 2 {
            let n = blocks.len();
            let (a, b) = (blocks[n - 2], blocks[n - 1]);
            if a.1 / a.2 < b.1 / b.2 {
                blocks.pop();
                blocks[n - 2] = (a.0 + b.0, a.1 + b.1, a.2 + b.2);
            } else {
                break;
            }
        }
    }
    let Some(first) = blocks.first() else {
        return Err("no clear return".into());
    };
    if first.1 / first.2 < 0.5 {
        return Err("fewer than half the returns survive already at the nearest range".into());
    }
    for w in blocks.windows(2) {
        let (a, b) = (w[0], w[1]);
        let (pa, pb) = (a.1 / a.2, b.1 / b.2);
        if pb < 0.5 {
            let (xa, xb) = (a.0 / a.2, b.0 / b.2);
            let t = (pa - 0.5) / (pa - pb);
            return Ok((xa + t * (xb - xa)).exp());
        }
    }
    Err("censored: more than half the returns survive to the end of the clear scene".into())
}

/// The nonparametric 50 %-survival range of one band in one MOR bin, with
/// its bootstrap-over-recordings 95 % interval.
#[derive(Debug, Clone, PartialEq)]
pub struct HalfSurvival {
    /// The range, metres, or why there is none.
    pub range: Result<f64, String>,
    /// The 95 % interval, or why there is none.
    pub ci95: Result<[f64; 2], String>,
    /// Recordings with trials.
    pub recordings: usize,
    /// Trials.
    pub trials: u64,
}

/// The 50 %-survival range of band `band` over the recordings `recs` (one
/// MOR bin), with `replicates` bootstrap resamples of the recordings drawn
/// from `seed`.
pub fn half_survival(
    recs: &[&RecordingTrials],
    band: usize,
    replicates: u32,
    seed: [u8; 32],
) -> HalfSurvival {
    let rows: Vec<Vec<(i64, f64, f64)>> = recs
        .iter()
        .map(|r| by_range(&r.bands[band], r.ln_mor_scaled))
        .filter(|v| !v.is_empty())
        .collect();
    let trials: f64 = rows.iter().flatten().map(|x| x.2).sum();
    let (lo, hi) = rows
        .iter()
        .flatten()
        .fold((i64::MAX, i64::MIN), |(a, b), x| (a.min(x.0), b.max(x.0)));
    let pool = |pick: &mut dyn Iterator<Item = usize>| -> Vec<(i64, f64, f64)> {
        let len = (hi - lo + 1).max(0) as usize;
        let mut dense = vec![(0.0, 0.0); len];
        for i in pick {
            for &(k, a, b) in &rows[i] {
                let d = &mut dense[(k - lo) as usize];
                d.0 += a;
                d.1 += b;
            }
        }
        dense
            .into_iter()
            .enumerate()
            .filter(|(_, d)| d.1 > 0.0)
            .map(|(j, d)| (lo + j as i64, d.0, d.1))
            .collect()
    };
    let n = rows.len();
    let range = if n == 0 {
        Err("no clear return of this band in the bin".into())
    } else {
        half_crossing(&pool(&mut (0..n)))
    };
    let ci95 = if range.is_err() {
        Err("no range to bound".into())
    } else if n < 2 {
        Err("one recording: no interval over recordings".into())
    } else if replicates == 0 {
        Err("no bootstrap replicates asked".into())
    } else {
        let mut rng = ChaCha8Rng::from_seed(seed);
        let mut reps: Vec<f64> = (0..replicates)
            .map(|_| {
                let mut pick = (0..n)
                    .map(|_| rng.random_range(0..n))
                    .collect::<Vec<_>>()
                    .into_iter();
                match half_crossing(&pool(&mut pick)) {
                    Ok(r) => r,
                    Err(e) if e.starts_with("censored") => f64::INFINITY,
                    Err(_) => 0.0,
                }
            })
            .collect();
        reps.sort_by(f64::total_cmp);
        let q = |p: f64| reps[((p * (reps.len() - 1) as f64).round() as usize).min(reps.len() - 1)];
        let (a, b) = (q(0.025), q(0.975));
        if a > 0.0 && b.is_finite() {
            Ok([a, b])
        } else {
            Err("a bootstrap resample of the recordings moves the 50 % crossing out of the clear scene: the interval is unbounded".into())
        }
    };
    HalfSurvival {
        range,
        ci95,
        recordings: n,
        trials: trials as u64,
    }
}

/// The standardised distance `z` at which the fitted keep probability is
/// ½: `π + (1 − ε − π)·S(z) = ½` (bisection; `None` when ½ is out of the
/// curve's range).
pub fn half_z(edge: EdgeShape, dropout: f64, residual: f64) -> Option<f64> {
    let target = (0.5 - residual) / (1.0 - dropout - residual);
    if !(target > 0.0 && target < 1.0) {
        return None;
    }
    let (mut lo, mut hi) = (-40.0, 40.0);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if edge.sf(mid) > target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(0.5 * (lo + hi))
}

/// Upper tail of the χ² law with `dof` degrees of freedom at `x`
/// (regularised incomplete gamma `Q(dof/2, x/2)`: series below `a + 1`,
/// continued fraction above; Numerical Recipes §6.2).
pub fn chi2_sf(x: f64, dof: u32) -> f64 {
    let a = dof as f64 / 2.0;
    let x = x / 2.0;
    if x <= 0.0 {
        return 1.0;
    }
    let gln = libm::lgamma(a);
    if x < a + 1.0 {
        let (mut sum, mut del, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..1000 {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if del.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        (1.0 - sum * (-x + a * x.ln() - gln).exp()).clamp(0.0, 1.0)
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..1000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-15 {
                break;
            }
        }
        ((-x + a * x.ln() - gln).exp() * h).clamp(0.0, 1.0)
    }
}

/// The χ² lack-of-fit test of a law against per-bin ranges: `bins` are
/// `(range, [low, high], law's range)`; returns `(statistic, dof, p,
/// worst ratio)` or `None` with fewer than two bins.
pub fn lack_of_fit(bins: &[(f64, [f64; 2], f64)]) -> Option<(f64, u32, f64, f64)> {
    let z975 = 1.959_963_984_540_054;
    let mut stat = 0.0;
    let mut k = 0u32;
    let mut worst: f64 = 1.0;
    for &(r, [lo, hi], l) in bins {
        let se = (hi.ln() - lo.ln()) / (2.0 * z975);
        if !(se > 0.0 && r > 0.0 && l > 0.0) {
            continue;
        }
        stat += ((r.ln() - l.ln()) / se).powi(2);
        k += 1;
        if (r / l).ln().abs() > worst.ln().abs() {
            worst = r / l;
        }
    }
    (k >= 2).then(|| (stat, k - 1, chi2_sf(stat, k - 1), worst))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Recordings whose observations sit on the bin centres of `step`
    /// (anchor 0), as the survival histogram gives them.
    fn binned_recordings(step: f64) -> Vec<RecordingTrials> {
        [7.0, 19.0, 42.0, 150.0]
            .iter()
            .enumerate()
            .map(|(j, &mor)| {
                let bands = vec![
                    (0..40)
                        .map(|k| Obs {
                            u: ((k as f64 - 20.0 + 0.5) * step).exp(),
                            kept: (k * (j + 1) % 13) as f64,
                            total: 13.0 + (k % 5) as f64,
                        })
                        .collect(),
                ];
                RecordingTrials {
                    clear: vec![vec![1.0; 40]],
                    bands,
                    ln_mor_scaled: f64::ln(mor),
                    mor,
                    classes: Vec::new(),
                }
            })
            .collect()
    }

    /// A known answer for the reflectivity term: expected (noise-free)
    /// counts of a law `D = 0.9·MOR^0.7·e^(0.2·δ)` over five classes
    /// `δ` and 8 MORs from 5 to 60 m, probit edge of width 0.1, ε 0.01.
    /// The fit recovers `c` and `k` from either start (the line's 1 and
    /// 0.5), the two within the searches' precision of each other, and
    /// with the line kept (`None`) it recovers `k` with `c` held at 1 on
    /// counts made so.
    #[test]
    fn reflectivity_term_known_answer_from_either_start() {
        let make_with = |c_true: f64, g_true: f64| -> Vec<RecordingTrials> {
            (0..8)
                .map(|j| {
                    let mor = 5.0 * (12f64).powf(j as f64 / 7.0);
                    let classes: Vec<(f64, Vec<Obs>)> = [-1.0, -0.5, 0.0, 0.5, 1.0]
                        .iter()
                        .map(|&delta: &f64| {
                            let k = 0.2 + g_true * (mor / 20.0).ln();
                            let d = 0.9 * mor.powf(c_true) * (k * delta).exp();
                            let obs = (0..110)
                                .map(|i| {
                                    let r = 0.5 * (1.0f64 + 0.04).powi(i);
                                    let p = 0.99
                                        * murk_types::EdgeShape::Probit.sf((r - d) / (0.1 * d));
                                    Obs {
                                        u: r / mor,
                                        kept: 100.0 * p,
                                        total: 100.0,
                                    }
                                })
                                .collect();
                            (delta, obs)
                        })
                        .collect();
                    RecordingTrials {
                        bands: vec![classes.iter().flat_map(|(_, o)| o.clone()).collect()],
                        clear: vec![vec![]],
                        ln_mor_scaled: mor.ln(),
                        mor,
                        classes: vec![classes],
                    }
                })
                .collect()
        };
        let make = |c_true: f64| make_with(c_true, 0.0);
        let opts = SurvivalOptions {
            edge: EdgeShape::Probit,
            shared_width: true,
            fixed_dropout: None,
            dropout_init: 0.01,
            min_trials: 1,
            min_beyond: 0,
        };
        let bin = Binning {
            step: 0.03,
            anchor: 0.0,
        };
        let recs = make(0.7);
        let refs: Vec<&RecordingTrials> = recs.iter().collect();
        let a = fit_reflectivity(&refs, 1, 0, Some(1.0), None, &opts, bin).unwrap();
        let b = fit_reflectivity(&refs, 1, 0, Some(0.5), None, &opts, bin).unwrap();
        for f in [&a, &b] {
            assert!((f.exponent - 0.7).abs() < 0.01, "c {}", f.exponent);
            assert!(
                (f.reflectivity_exponent - 0.2).abs() < 0.01,
                "k {}",
                f.reflectivity_exponent
            );
        }
        assert!(
            (a.exponent - b.exponent).abs() < 3.0 * EXPONENT_TOL
                && (a.reflectivity_exponent - b.reflectivity_exponent).abs() < 3.0 * EXPONENT_TOL,
            "{} {} vs {} {}",
            a.exponent,
            a.reflectivity_exponent,
            b.exponent,
            b.reflectivity_exponent
        );
        let recs = make(1.0);
        let refs: Vec<&RecordingTrials> = recs.iter().collect();
        let l = fit_reflectivity(&refs, 1, 0, None, None, &opts, bin).unwrap();
        assert_eq!(l.exponent, 1.0);
        assert!(
            (l.reflectivity_exponent - 0.2).abs() < 0.01,
            "k {}",
            l.reflectivity_exponent
        );
        let slope = *l.fit.bands[0].slope.as_ref().unwrap();
        assert!((slope / 0.9 - 1.0).abs() < 0.01, "a {slope}");
        // `k` changing with MOR, 0.2 + 0.05·ln(MOR/20): with `vary` the
        // fit recovers c, k at 20 m and g; without it, one k between.
        let recs = make_with(0.7, 0.05);
        let refs: Vec<&RecordingTrials> = recs.iter().collect();
        let v = fit_reflectivity(&refs, 1, 0, Some(1.0), Some(20f64.ln()), &opts, bin).unwrap();
        assert!((v.exponent - 0.7).abs() < 0.01, "c {}", v.exponent);
        assert!(
            (v.reflectivity_exponent - 0.2).abs() < 0.01,
            "k {}",
            v.reflectivity_exponent
        );
        assert!((v.per_ln_mor - 0.05).abs() < 0.005, "g {}", v.per_ln_mor);
        assert_eq!(v.term().at(20f64.ln()), v.reflectivity_exponent);
        let one = fit_reflectivity(&refs, 1, 0, Some(1.0), None, &opts, bin).unwrap();
        assert_eq!(one.per_ln_mor, 0.0);
        assert!(
            one.fit.nll > v.fit.nll + 1.0,
            "{} {}",
            one.fit.nll,
            v.fit.nll
        );
    }

    /// Linear binning: `c = 1` gives the observations back, every `c`
    /// keeps the trials, the survivors and each observation's mean `ln u`,
    /// and a small change of `c` moves little (continuity, which flooring
    /// into one bin does not have: there a trial jumps a whole bin).
    #[test]
    fn shifted_observations_are_linear_binned() {
        let step = 0.05;
        let recs = binned_recordings(step);
        let refs: Vec<&RecordingTrials> = recs.iter().collect();
        let pooled = |c: f64| shifted_observations(&refs, 1, c, step, 0.0).remove(0);
        // c = 1: the pooled observations, bin for bin.
        let one = pooled(1.0);
        assert_eq!(one.len(), 40);
        for (k, o) in one.iter().enumerate() {
            let want: f64 = recs.iter().map(|r| r.bands[0][k].total).sum();
            assert_eq!(o.total, want, "bin {k}");
            assert!((o.u.ln() - recs[0].bands[0][k].u.ln()).abs() < 1e-12);
        }
        let (kept0, total0): (f64, f64) = recs
            .iter()
            .flat_map(|r| &r.bands[0])
            .fold((0.0, 0.0), |(a, b), o| (a + o.kept, b + o.total));
        for c in [0.3, 0.55, 0.713, 0.9, 1.37] {
            let obs = pooled(c);
            let (kept, total): (f64, f64) = obs
                .iter()
                .fold((0.0, 0.0), |(a, b), o| (a + o.kept, b + o.total));
            assert!(
                (kept - kept0).abs() < 1e-9 && (total - total0).abs() < 1e-9,
                "{c}"
            );
            // First moment of ln u: Σ n·(ln u + (1 − c)·ln MOR).
            let want: f64 = recs
                .iter()
                .flat_map(|r| r.bands[0].iter().map(move |o| (o, r.mor)))
                .map(|(o, mor)| o.total * (o.u.ln() + (1.0 - c) * mor.ln()))
                .sum();
            let got: f64 = obs.iter().map(|o| o.total * o.u.ln()).sum();
            assert!((got - want).abs() < 1e-6 * total0, "{c}: {got} {want}");
        }
        // Continuity: moving c by dc moves each observation by
        // dc·ln MOR / step bins, so at most that share of its trials
        // changes bin (counted out and in). Flooring moves a whole
        // observation whenever one crosses a bin edge, which at these
        // 1,000 exponents happens about ten times.
        let dc = 1e-6;
        let bound: f64 = recs
            .iter()
            .flat_map(|r| r.bands[0].iter().map(move |o| (o, r.mor)))
            .map(|(o, mor)| 2.0 * o.total * dc * mor.ln().abs() / step)
            .sum();
        for i in 0..1000 {
            let c = 0.3 + 1.4 * i as f64 / 1000.0;
            let (a, b) = (pooled(c), pooled(c + dc));
            let mut m: std::collections::BTreeMap<i64, f64> = Default::default();
            for o in &a {
                *m.entry((o.u.ln() / step).floor() as i64).or_default() += o.total;
            }
            for o in &b {
                *m.entry((o.u.ln() / step).floor() as i64).or_default() -= o.total;
            }
            let moved: f64 = m.values().map(|x| x.abs()).sum();
            assert!(
                moved <= bound * (1.0 + 1e-6) + 1e-9,
                "c {c}: {moved} trials moved, bound {bound}"
            );
        }
    }

    #[test]
    fn jackknife_interval_known_answer() {
        // Five leave-out fits 0.9, 0.95, 1.0, 1.05, 1.1: mean 1, Σ dev² =
        // 0.025, variance 4/5 · 0.025 = 0.02, t₄ = 2.776.
        let th = [Some(0.9), Some(0.95), Some(1.0), Some(1.05), Some(1.1)];
        let [lo, hi] = jackknife_interval(1.0, &th).unwrap();
        let half = 2.776_445 * 0.02f64.sqrt();
        assert!((lo - (1.0 - half)).abs() < 1e-3, "{lo}");
        assert!((hi - (1.0 + half)).abs() < 1e-3, "{hi}");
        assert!(jackknife_interval(1.0, &th[..2]).is_err());
        assert!(jackknife_interval(1.0, &[Some(1.0), None, Some(1.0)]).is_err());
        assert!(jackknife_interval(1.0, &[Some(0.2), Some(1.0), Some(1.0)]).is_err());
    }

    #[test]
    fn chi2_known_values() {
        // Tables: P(χ²₁ > 3.841) = 0.05, P(χ²₅ > 11.07) = 0.05,
        // P(χ²₁₀ > 2.558) = 0.99.
        assert!((chi2_sf(3.841_458_8, 1) - 0.05).abs() < 1e-6);
        assert!((chi2_sf(11.070_497_7, 5) - 0.05).abs() < 1e-6);
        assert!((chi2_sf(2.558_212_1, 10) - 0.99).abs() < 1e-6);
    }

    #[test]
    fn isotonic_crossing_known_answer() {
        // Kept shares 1, 0.9, 0.7 (violated by 0.8), 0.3 at ln r bins 0..4:
        // the block (0.7, 0.8) pools to 0.75; 0.5 is crossed between it and
        // 0.3, at t = 0.25/0.45 of the way.
        let rows = [
            (0, 10.0, 10.0),
            (1, 9.0, 10.0),
            (2, 7.0, 10.0),
            (3, 8.0, 10.0),
            (4, 3.0, 10.0),
        ];
        let r = half_crossing(&rows).unwrap();
        let xa = 3.0 * RANGE_STEP; // centre of the pooled block (2.5 and 3.5 bins)
        let xb = 4.5 * RANGE_STEP;
        let want = (xa + 0.25 / 0.45 * (xb - xa)).exp();
        assert!((r - want).abs() < 1e-12, "{r} {want}");
        assert!(
            half_crossing(&[(0, 9.0, 10.0)])
                .unwrap_err()
                .starts_with("censored")
        );
        assert!(half_crossing(&[(0, 1.0, 10.0)]).is_err());
    }

    #[test]
    fn half_z_of_a_clean_edge_is_zero() {
        assert!(half_z(EdgeShape::Probit, 0.0, 0.0).unwrap().abs() < 1e-9);
        // With 10 % dropout the curve starts at 0.9 and is 0.45 at the
        // centre: ½ lies before it, where S = 5/9 (z = −0.1397).
        let z = half_z(EdgeShape::Probit, 0.1, 0.0).unwrap();
        assert!((z + 0.139_710_298).abs() < 1e-6, "{z}");
        assert!(half_z(EdgeShape::Probit, 0.6, 0.0).is_none());
    }
}
