//! The survival boundary: maximum likelihood of where clear returns vanish.
//!
//! A clear return at range `r` (reference range of its cell), in weather of
//! visibility `MOR`, on a sensor of range scale `ρ`, is kept with probability
//!
//! ```text
//! P(kept | r, MOR, band b) = π + (1 − ε − π) · (1 − F((u − s_b) / (w_b · s_b))),   u = r / (MOR · ρ)
//! ```
//!
//! with `F` a unit-variance CDF ([`EdgeShape`], murk-types' one definition
//! of the edge law, which infer applies), `s_b` the vanishing slope of
//! reflectivity band `b`, `w_b` the relative edge width, `ε` the dropout of
//! returns well inside the vanishing distance and `π` the residual survival of
//! returns far beyond it (retro-reflectors, chance pairings).
//!
//! Because the model depends on `r` and `MOR` only through `u`, every trial is
//! aggregated into a histogram over `ln u` per reflectivity class
//! ([`SurvivalHistogram`]): the likelihood then costs one term per occupied
//! bin however many recordings and points went in, and the histogram is the
//! only state the driver keeps across recordings. With the default bin width
//! of 0.25 % in `u`, binning moves a slope by far less than its statistical
//! error.
//!
//! Unlike the seed's quantile estimator, this uses the *disappeared* returns
//! too: where the scene thins out with range, the quantile of the survivors
//! sits below the edge (few survivors exist near it), but the likelihood
//! locates the edge from the kept/lost ratio at each `u`, which does not depend
//! on how many clear returns the scene offers there.

use std::ops::Range;

use crate::hyperparams::{Band, EdgeShape};
use crate::stats::dist::{logit, sigmoid};
use crate::stats::optim::{INVALID, hessian, invert, minimize};

/// Reflectivity classes: the finest partition made of every band edge in use
/// (table bands and sweep bands), so any band is a union of classes.
#[derive(Debug, Clone, PartialEq)]
pub struct Partition {
    edges: Vec<f64>,
}

impl Partition {
    /// The partition of the union of `edges` (sorted, deduplicated).
    pub fn new(edges: impl IntoIterator<Item = f64>) -> Self {
        let mut e: Vec<f64> = edges.into_iter().filter(|x| x.is_finite()).collect();
        e.sort_by(f64::total_cmp);
        e.dedup();
        Partition { edges: e }
    }

    /// Number of classes (`edges + 1`: below the first edge is a class).
    pub fn classes(&self) -> usize {
        self.edges.len() + 1
    }

    /// The class of reflectivity `x`.
    #[inline]
    pub fn class_of(&self, x: f64) -> usize {
        self.edges.partition_point(|e| *e <= x)
    }

    /// The classes making up `band` (whose edges must be partition edges).
    pub fn classes_in(&self, band: &Band) -> Range<usize> {
        let a = self.class_of(band.min);
        let b = band.max.map_or(self.classes(), |m| self.class_of(m));
        a..b
    }
}

/// Kept / total counts of clear returns per reflectivity class and `ln u` bin.
#[derive(Debug, Clone, PartialEq)]
pub struct SurvivalHistogram {
    ln_u0: f64,
    step: f64,
    bins: usize,
    classes: usize,
    kept: Vec<u64>,
    total: Vec<u64>,
}

/// Range of `u = r/(MOR·ρ)` covered; trials outside go to the end bins,
/// which lie far from any plausible edge (slopes of 0.01–10).
const U_MIN: f64 = 1e-4;
const U_MAX: f64 = 1e3;

impl SurvivalHistogram {
    /// An empty histogram for `classes` classes with bins `step` wide in `ln u`.
    pub fn new(classes: usize, step: f64) -> Self {
        let bins = ((U_MAX / U_MIN).ln() / step).ceil() as usize;
        SurvivalHistogram {
            ln_u0: U_MIN.ln(),
            step,
            bins,
            classes,
            kept: vec![0; classes * bins],
            total: vec![0; classes * bins],
        }
    }

    /// The bin of `ln u`.
    #[inline]
    pub fn bin_of(&self, ln_u: f64) -> usize {
        let k = ((ln_u - self.ln_u0) / self.step).floor();
        if k <= 0.0 {
            0
        } else {
            (k as usize).min(self.bins - 1)
        }
    }

    /// Adds `total` trials of which `kept` survived, in `class` at bin `bin`.
    #[inline]
    pub fn add(&mut self, class: usize, bin: usize, kept: u64, total: u64) {
        let i = class * self.bins + bin;
        self.kept[i] += kept;
        self.total[i] += total;
    }

    /// Adds another histogram of the same shape.
    pub fn merge(&mut self, other: &SurvivalHistogram) {
        for (a, b) in self.kept.iter_mut().zip(&other.kept) {
            *a += b;
        }
        for (a, b) in self.total.iter_mut().zip(&other.total) {
            *a += b;
        }
    }

    /// The occupied bins of the classes in `classes`, summed over classes.
    pub fn observations(&self, classes: Range<usize>) -> Vec<Obs> {
        let mut out = Vec::new();
        for b in 0..self.bins {
            let (mut k, mut n) = (0u64, 0u64);
            for c in classes.clone() {
                k += self.kept[c * self.bins + b];
                n += self.total[c * self.bins + b];
            }
            if n > 0 {
                out.push(Obs {
                    u: (self.ln_u0 + (b as f64 + 0.5) * self.step).exp(),
                    kept: k as f64,
                    total: n as f64,
                });
            }
        }
        out
    }

    /// Number of classes.
    pub fn classes(&self) -> usize {
        self.classes
    }
}

/// One histogram bin: `total` trials at `u`, `kept` survived.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Obs {
    /// `r / (MOR · ρ)` at the bin centre.
    pub u: f64,
    /// Survivors.
    pub kept: f64,
    /// Trials.
    pub total: f64,
}

/// Settings of a survival fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurvivalOptions {
    /// Edge shape.
    pub edge: EdgeShape,
    /// One width for all bands.
    pub shared_width: bool,
    /// `Some(ε)` fixes the dropout; `None` fits it.
    pub fixed_dropout: Option<f64>,
    /// Starting dropout when it is fitted.
    pub dropout_init: f64,
    /// Fewest trials a band needs.
    pub min_trials: u64,
    /// Fewest trials beyond the fitted edge for the edge to count as seen.
    pub min_beyond: u64,
}

/// The fit of one band.
#[derive(Debug, Clone, PartialEq)]
pub struct BandFit {
    /// The slope, or why there is none.
    pub slope: Result<f64, String>,
    /// Standard error of the slope (inverse observed information).
    pub std_error: Option<f64>,
    /// Relative edge width.
    pub width: Option<f64>,
    /// Trials of the band.
    pub trials: u64,
}

/// The joint fit of all bands of one weather.
#[derive(Debug, Clone, PartialEq)]
pub struct SurvivalResult {
    /// Per band, in input order.
    pub bands: Vec<BandFit>,
    /// Dropout ε.
    pub dropout: f64,
    /// Residual survival π.
    pub residual: f64,
    /// Negative log-likelihood at the optimum.
    pub nll: f64,
    /// Trials in the likelihood.
    pub trials: u64,
}

/// `(1 − F(z), F(z))` of the shared edge law, each accurate in its own tail.
#[inline]
fn tails(edge: EdgeShape, z: f64) -> (f64, f64) {
    edge.tails(z)
}

/// Negative log-likelihood of one band's observations.
fn band_nll(obs: &[Obs], edge: EdgeShape, s: f64, w: f64, eps: f64, pi: f64) -> f64 {
    let a = 1.0 - eps - pi;
    let scale = 1.0 / (w * s);
    let mut nll = 0.0;
    for o in obs {
        let (sf, cdf) = tails(edge, (o.u - s) * scale);
        let p = (pi + a * sf).max(1e-300);
        let q = (eps + a * cdf).max(1e-300);
        nll -= o.kept * p.ln() + (o.total - o.kept) * q.ln();
    }
    nll
}

/// Upper bound of the residual survival π as a share of `1 − ε`: beyond
/// the edge most returns must be lost, otherwise "edge" has no meaning and a
/// nearly flat survival curve could be fitted by an edge anywhere.
const RESIDUAL_MAX: f64 = 0.5;

/// Where the parameters live in θ.
struct Layout {
    active: Vec<usize>,
    shared: bool,
    free_eps: bool,
}

impl Layout {
    fn n_width(&self) -> usize {
        if self.shared { 1 } else { self.active.len() }
    }
    fn len(&self) -> usize {
        self.active.len() + self.n_width() + usize::from(self.free_eps) + 1
    }
    fn width_of(&self, theta: &[f64], j: usize) -> f64 {
        let k = self.active.len() + if self.shared { 0 } else { j };
        theta[k].exp()
    }
    fn eps_pi(&self, theta: &[f64], fixed: Option<f64>) -> (f64, f64) {
        let base = self.active.len() + self.n_width();
        let eps = match fixed {
            Some(e) => e,
            None => sigmoid(theta[base]),
        };
        let rho = theta[base + usize::from(self.free_eps)];
        (eps, (1.0 - eps) * RESIDUAL_MAX * sigmoid(rho))
    }
}

/// Why a band's observations cannot locate an edge, if they cannot: too
/// few trials, nothing lost, or nothing kept.
pub fn precheck(obs: &[Obs], min_trials: u64) -> Result<(), String> {
    let kept: f64 = obs.iter().map(|o| o.kept).sum();
    let total: f64 = obs.iter().map(|o| o.total).sum();
    if (total as u64) < min_trials.max(1) {
        Err(format!(
            "too few clear returns in this band ({} < {})",
            total as u64,
            min_trials.max(1)
        ))
    } else if kept == total {
        Err("no clear return of this band disappeared: the edge lies beyond the clear scene (censored)".into())
    } else if kept == 0.0 {
        Err("every clear return of this band disappeared".into())
    } else {
        Ok(())
    }
}

/// Fits the survival boundary jointly over `bands` (one observation list per
/// band), sharing ε and π (and `w` when `shared_width`).
///
/// Bands with fewer than `min_trials` trials, or with no lost or no kept
/// return, are left out with a reason. A band whose fitted edge lies beyond
/// (almost) every clear return of the band — the likelihood then only bounds
/// the slope from below — gets a null slope and says so. `None` when no band
/// can be fitted.
pub fn fit_survival(bands: &[Vec<Obs>], opts: &SurvivalOptions) -> Option<SurvivalResult> {
    let trials: Vec<u64> = bands
        .iter()
        .map(|b| b.iter().map(|o| o.total).sum::<f64>() as u64)
        .collect();
    let mut out: Vec<BandFit> = trials
        .iter()
        .map(|&t| BandFit {
            slope: Err(String::new()),
            std_error: None,
            width: None,
            trials: t,
        })
        .collect();
    let mut active = Vec::new();
    for (i, b) in bands.iter().enumerate() {
        match precheck(b, opts.min_trials) {
            Ok(()) => active.push(i),
            Err(e) => out[i].slope = Err(e),
        }
    }
    if active.is_empty() {
        return None;
    }
    let layout = Layout {
        active: active.clone(),
        shared: opts.shared_width,
        free_eps: opts.fixed_dropout.is_none(),
    };
    let eps0 = opts
        .fixed_dropout
        .unwrap_or(opts.dropout_init)
        .clamp(1e-4, 0.5);
    let pi0 = 1e-3;
    let w0 = 0.1;

    // Starting slopes: a grid search per band with the other parameters at
    // their starting values.
    let mut theta = Vec::with_capacity(layout.len());
    for &i in &active {
        let (lo, hi) = bands[i].iter().fold((f64::INFINITY, 0.0f64), |(a, b), o| {
            (a.min(o.u), b.max(o.u))
        });
        let (llo, lhi) = (lo.max(1e-4).ln(), hi.max(lo * 1.01).ln());
        let mut best = (f64::INFINITY, 0.5 * (llo + lhi));
        for k in 0..=160 {
            let ls = llo + (lhi - llo) * k as f64 / 160.0;
            let c = band_nll(&bands[i], opts.edge, ls.exp(), w0, eps0, pi0);
            if c < best.0 {
                best = (c, ls);
            }
        }
        theta.push(best.1);
    }
    for _ in 0..layout.n_width() {
        theta.push(w0.ln());
    }
    if layout.free_eps {
        theta.push(logit(eps0));
    }
    theta.push(logit(pi0 / ((1.0 - eps0) * RESIDUAL_MAX)));

    let bounds: Vec<(f64, f64)> = active
        .iter()
        .map(|&i| {
            let (lo, hi) = bands[i].iter().fold((f64::INFINITY, 0.0f64), |(a, b), o| {
                (a.min(o.u), b.max(o.u))
            });
            ((lo.max(1e-4) / 10.0).ln(), (hi * 10.0).ln())
        })
        .collect();
    let nll = |t: &[f64]| {
        let (eps, pi) = layout.eps_pi(t, opts.fixed_dropout);
        let mut s = 0.0;
        for (j, &i) in layout.active.iter().enumerate() {
            if t[j] < bounds[j].0 || t[j] > bounds[j].1 {
                return INVALID;
            }
            let w = layout.width_of(t, j);
            if !(1e-4..=5.0).contains(&w) {
                return INVALID;
            }
            s += band_nll(&bands[i], opts.edge, t[j].exp(), w, eps, pi);
        }
        s
    };
    let mut steps = vec![0.1; active.len()];
    steps.extend(std::iter::repeat_n(0.5, layout.n_width()));
    if layout.free_eps {
        steps.push(0.5);
    }
    steps.push(1.0);
    let m = minimize(&nll, &theta, &steps);
    if m.cost >= INVALID {
        return None;
    }
    let theta = m.x;
    let (eps, pi) = layout.eps_pi(&theta, opts.fixed_dropout);

    // Standard errors from the observed information in θ, with π held at
    // its optimum (it is often at its bound, where the likelihood is flat).
    let n_free = theta.len() - 1;
    let rho = theta[n_free];
    let sub = |t: &[f64]| {
        let mut full = t.to_vec();
        full.push(rho);
        nll(&full)
    };
    let h: Vec<f64> = vec![1e-4; n_free];
    let cov = invert(&hessian(&sub, &theta[..n_free], &h));
    for (j, &i) in active.iter().enumerate() {
        let s = theta[j].exp();
        let w = layout.width_of(&theta, j);
        let beyond: f64 = bands[i]
            .iter()
            .filter(|o| o.u > s * (1.0 + w))
            .map(|o| o.total)
            .sum();
        out[i].width = Some(w);
        out[i].std_error = cov
            .as_ref()
            .map(|c| c[j][j])
            .filter(|v| v.is_finite() && *v > 0.0)
            .map(|v| s * v.sqrt());
        out[i].slope = if (beyond as u64) < opts.min_beyond.max(1) {
            Err(format!(
                "censored: only {} clear returns of this band lie beyond the fitted edge (slope {s:.4} + one width): the edge is not seen",
                beyond as u64
            ))
        } else {
            Ok(s)
        };
    }
    Some(SurvivalResult {
        bands: out,
        dropout: eps,
        residual: pi,
        nll: m.cost,
        trials: active.iter().map(|&i| trials[i]).sum(),
    })
}

/// Fits one band's slope with the edge width, ε and π held at `fixed`'s
/// values (the sweep of Figure 27).
pub fn fit_slope_only(
    obs: &[Obs],
    edge: EdgeShape,
    width: f64,
    dropout: f64,
    residual: f64,
    min_trials: u64,
    min_beyond: u64,
) -> Result<f64, String> {
    let trials: f64 = obs.iter().map(|o| o.total).sum();
    let kept: f64 = obs.iter().map(|o| o.kept).sum();
    if (trials as u64) < min_trials.max(1) {
        return Err(format!("too few clear returns ({trials} < {min_trials})"));
    }
    if kept == trials || kept == 0.0 {
        return Err("no variation between kept and lost returns".into());
    }
    let (lo, hi) = obs.iter().fold((f64::INFINITY, 0.0f64), |(a, b), o| {
        (a.min(o.u), b.max(o.u))
    });
    let (llo, lhi) = (lo.max(1e-4).ln(), hi.max(lo * 1.01).ln());
    let f = |t: &[f64]| {
        if t[0] < llo - 2.3 || t[0] > lhi + 2.3 {
            return INVALID;
        }
        band_nll(obs, edge, t[0].exp(), width, dropout, residual)
    };
    let mut best = (f64::INFINITY, llo);
    for k in 0..=160 {
        let ls = llo + (lhi - llo) * k as f64 / 160.0;
        let c = f(&[ls]);
        if c < best.0 {
            best = (c, ls);
        }
    }
    let m = minimize(&f, &[best.1], &[0.05]);
    let s = m.x[0].exp();
    let beyond: f64 = obs
        .iter()
        .filter(|o| o.u > s * (1.0 + width))
        .map(|o| o.total)
        .sum();
    if (beyond as u64) < min_beyond.max(1) {
        return Err(format!(
            "censored: only {} clear returns lie beyond the fitted edge",
            beyond as u64
        ));
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng, rngs::ChaCha8Rng};

    /// Simulates kept/lost trials on a scene whose returns thin out with
    /// range (density ∝ 1/r² between 1 and 80 m) for a spread of MOR.
    fn simulate(slopes: &[f64], w: f64, eps: f64, edge: EdgeShape, seed: u64) -> Vec<Vec<Obs>> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut hs: Vec<SurvivalHistogram> = slopes
            .iter()
            .map(|_| SurvivalHistogram::new(1, 0.0025))
            .collect();
        for (b, &s) in slopes.iter().enumerate() {
            for _ in 0..150 {
                let mor: f64 = rng.random_range(40.0..300.0);
                for _ in 0..400 {
                    // Inverse-CDF draw of a 1/r² density on [1, 80].
                    let v: f64 = rng.random_range(0.0..1.0);
                    let r = 1.0 / (1.0 - v * (1.0 - 1.0 / 80.0));
                    let u = r / mor;
                    let (sf, _) = tails(edge, (u - s) / (w * s));
                    let p = (1.0 - eps) * sf;
                    let kept = rng.random_range(0.0..1.0) < p;
                    let h = &mut hs[b];
                    let bin = h.bin_of(u.ln());
                    h.add(0, bin, kept as u64, 1);
                }
            }
        }
        hs.iter().map(|h| h.observations(0..1)).collect()
    }

    fn opts(edge: EdgeShape) -> SurvivalOptions {
        SurvivalOptions {
            edge,
            shared_width: true,
            fixed_dropout: None,
            dropout_init: 0.01,
            min_trials: 100,
            min_beyond: 10,
        }
    }

    #[test]
    fn recovers_the_seed_fog_slopes_on_a_thinning_scene() {
        // Table 4 fog slopes, 5 % edge width, 1 % dropout; 60 000 trials per
        // band. Tolerance 3 % (the acceptance bound; the SE is ≈ 1 %).
        let truth = [0.302_865_36, 0.346_343_64];
        let bands = simulate(&truth, 0.05, 0.01, EdgeShape::Probit, 11);
        let r = fit_survival(&bands, &opts(EdgeShape::Probit)).unwrap();
        for (b, t) in r.bands.iter().zip(truth) {
            let s = *b.slope.as_ref().unwrap();
            assert!((s / t - 1.0).abs() < 0.03, "{s} vs {t}");
            let se = b.std_error.unwrap();
            assert!(se > 0.0 && se < 0.02 * t, "{se}");
        }
        assert!((r.dropout - 0.01).abs() < 0.005, "{}", r.dropout);
        assert!((r.bands[0].width.unwrap() - 0.05).abs() < 0.02);
    }

    #[test]
    fn logistic_edge_recovers_its_own_truth() {
        let truth = [0.156_886_75];
        let bands = simulate(&truth, 0.1, 0.02, EdgeShape::Logistic, 12);
        let r = fit_survival(&bands, &opts(EdgeShape::Logistic)).unwrap();
        let s = *r.bands[0].slope.as_ref().unwrap();
        assert!((s / truth[0] - 1.0).abs() < 0.03, "{s}");
    }

    #[test]
    fn edge_beyond_the_scene_is_censored() {
        // Slope 2: the edge at 2·MOR ≥ 80 m lies beyond every return.
        let bands = simulate(&[2.0], 0.05, 0.01, EdgeShape::Probit, 13);
        match fit_survival(&bands, &opts(EdgeShape::Probit)) {
            None => {}
            Some(r) => {
                let e = r.bands[0].slope.as_ref().unwrap_err();
                assert!(e.contains("censored") || e.contains("beyond"), "{e}");
            }
        }
    }

    #[test]
    fn sweep_fit_matches_joint_fit() {
        let truth = [0.25];
        let bands = simulate(&truth, 0.05, 0.01, EdgeShape::Probit, 14);
        let s = fit_slope_only(&bands[0], EdgeShape::Probit, 0.05, 0.01, 0.0, 100, 10).unwrap();
        assert!((s / 0.25 - 1.0).abs() < 0.03, "{s}");
    }

    #[test]
    fn partition_maps_bands_to_classes() {
        let p = Partition::new([0.0, 10.0, 5.0, 10.0, 20.0]);
        assert_eq!(p.classes(), 5);
        assert_eq!(p.class_of(-1.0), 0);
        assert_eq!(p.class_of(0.0), 1);
        assert_eq!(p.class_of(9.9), 2);
        assert_eq!(p.class_of(10.0), 3);
        assert_eq!(p.class_of(300.0), 4);
        let band = Band {
            min: 0.0,
            max: Some(10.0),
        };
        assert_eq!(p.classes_in(&band), 1..3);
        let band = Band {
            min: 10.0,
            max: None,
        };
        assert_eq!(p.classes_in(&band), 3..5);
    }
}
