//! What a model predicts for a measured recording, and how far off it is.
//!
//! Per held-out recording the model is built at the recording's MOR with
//! every component the table holds (soft survival edge when fitted,
//! near-range returns when the table has their laws, and any extension
//! terms), then
//!
//! - **survival**: every reference cell's keep probability
//!   ([`murk_infer::Applier::survival_probability`], unconditioned: the cell
//!   is the reference, not one clear recording) against what was kept;
//! - **range** and **intensity**: the predicted change of each kept return
//!   (none for the baseline; the extension's bias or factor) against the
//!   measured range minus the reference range, and the log ratio of the
//!   measured to the reference reflectivity, both less what pairing alone
//!   gives the same cell in clear weather;
//! - **count** and the scene: the recording is *simulated* with murk-infer
//!   from the nearest clear recording (`sims` seeded draws), the simulation
//!   is classified by the same pairing as the measurement, and its ghost and
//!   ring returns are counted, in total and per laser, azimuth sector and
//!   range bin ([`crate::data::NearHistogram`]); the simulated clouds are compared with the
//!   measured one by [`crate::scene::SceneMetrics`].

use std::collections::BTreeMap;
use std::sync::Arc;

use murk_fit::FitValidParams;
use murk_fit::observe::cell_points;
use murk_fit::observe::pair_frames;
use murk_infer::{Applier, ApplyParams, Severity};
use murk_types::{
    CoefficientTable, CovariateValue, ExtensionObservable, PointCloud, PointCovariates,
    combine_extensions,
};
use rayon::prelude::*;
use serde::Serialize;

use crate::DiagnoseError;
use crate::data::{
    CellInfo, Kept, KeptView, Loaded, NearHistogram, Rec, log_ratio, read_calibrated,
};
use crate::scene::{SceneMetrics, VoxelBox};

/// Keep probabilities are clipped into `[P_FLOOR, 1 − P_FLOOR]` for the log
/// loss (a hard threshold predicts 0 and 1).
pub const P_FLOOR: f64 = 1e-3;

/// Options of the simulation half.
#[derive(Debug, Clone, PartialEq)]
pub struct SimOptions {
    /// Seeded simulations per recording.
    pub sims: usize,
    /// Voxel size, metres.
    pub voxel_m: f64,
    /// Box of the localised difference.
    pub local_box: Option<VoxelBox>,
    /// Master seed.
    pub seed: u64,
}

/// One recording evaluated under one model.
///
/// It holds what the simulations gave (a few numbers per recording) and the
/// table it was evaluated under, not its per-unit predictions: those (a keep
/// probability per reference cell, a range and an intensity residual per
/// kept return, megabytes per recording) are computed again from the
/// recording's per-cell summaries each time they are read ([`RecEval::p`],
/// [`RecEval::kept_residuals`]), bit for bit as the evaluation would have
/// held them, so a diagnosis's memory does
/// not grow with the evaluation sets it keeps.
#[derive(Debug, Clone, PartialEq)]
pub struct RecEval {
    /// Index into `Loaded::recs`.
    pub rec: usize,
    /// The table the recording was evaluated under (shared by one
    /// [`evaluate`] call's evaluations).
    table: Arc<CoefficientTable>,
    /// Whether its applier simulated the near-range returns, and its seed
    /// (the applier is built again with them).
    near: bool,
    /// See `near`.
    seed: u64,
    /// Mean ghost + ring count of the simulations (`None` without them).
    pub near_sim: Option<f64>,
    /// The same per laser, azimuth sector and range bin.
    pub near_bins_sim: Option<NearHistogram>,
    /// Mean scene metrics of the simulations.
    pub scene: Option<SceneMetrics>,
}

/// The residuals of the kept returns of one reference cell of a recording
/// ([`RecEval::kept_residuals`]): `n` returns (1 for a listed return), the
/// sum of their residuals and of their squares. Everything
/// computed from kept returns is a sum of these.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KeptUnit {
    /// Reference cell.
    pub cell: u32,
    /// Kept returns.
    pub n: f64,
    /// Σ residual.
    pub sum: f64,
    /// Σ residual².
    pub sum_sq: f64,
}

impl KeptUnit {
    /// The unit of `n` returns whose centred values `x` sum to `d` (their
    /// squares to `d2`) when each residual is `x − a`: `Σ(x − a) = d − n·a`,
    /// `Σ(x − a)² = d2 − 2a·d + n·a²` (the values are centred on the
    /// reference, so `a`, `d/n` and the residuals are all small and the
    /// difference loses nothing that matters).
    pub fn of_sums(cell: u32, n: u32, d: f64, d2: f64, a: f64) -> KeptUnit {
        let n = n as f64;
        KeptUnit {
            cell,
            n,
            sum: d - n * a,
            sum_sq: (d2 - 2.0 * a * d + n * a * a).max(0.0),
        }
    }

    /// Mean residual.
    pub fn mean(&self) -> f64 {
        self.sum / self.n
    }
}

/// A kept return's range residual given the table's range extension
/// `bias` ([`RecEval::kept_residuals`]).
fn range_residual(k: &Kept, c: &CellInfo, bias: f64) -> f64 {
    k.range as f64 - c.cov.range - c.clear_range_offset - bias
}

/// A kept return's intensity residual given the table's intensity factor
/// `fac` ([`RecEval::kept_residuals`]).
fn intensity_residual(k: &Kept, c: &CellInfo, fac: f64) -> f64 {
    log_ratio(k.reflectivity as f64, c.cov.reflectivity)
        - c.clear_log_reflectivity_offset
        - fac.max(1e-6).ln()
}

impl RecEval {
    /// Keep probability per survival unit (aligned with `Rec::units`).
    pub fn p(&self, loaded: &Loaded) -> Vec<f64> {
        let rec = &loaded.recs[self.rec];
        let table = self.table.as_ref();
        let ap = applier(table, loaded, rec, self.near, self.seed)
            .expect("the applier was built when the recording was evaluated");
        let cell = |c: u32| loaded.cells[c as usize].expect("units are reference cells");
        rec.units
            .iter()
            .map(|u| {
                let c = cell(u.cell);
                let f = extension_value(
                    table,
                    loaded,
                    ExtensionObservable::Survival,
                    &c.cov,
                    &rec.scan,
                    rec.mor,
                );
                ap.survival_probability(c.cov.range, c.cov.reflectivity, f, false)
            })
            .collect()
    }

    /// The range (`Range`) or intensity (`Intensity`) residuals of the
    /// recording's kept returns, as [`KeptUnit`]s: one per listed return
    /// (in pairing order), then one per cell whose returns are summed
    /// ([`crate::data::KeptReturns`]). A range residual is the measured range less
    /// the reference cell's, less what pairing gives the cell in clear
    /// weather, less the table's range extension; an intensity residual the
    /// log ratio of measured to reference reflectivity, less the
    /// clear-weather offset, less the log of the table's intensity factor.
    pub fn kept_residuals(&self, loaded: &Loaded, obs: ExtensionObservable) -> Vec<KeptUnit> {
        self.kept_residuals_of(loaded, &loaded.recs[self.rec].kept.get(), obs)
    }

    /// [`Self::kept_residuals`] of kept returns already read (a caller that
    /// needs both observables reads a spilled recording once).
    fn kept_residuals_of(
        &self,
        loaded: &Loaded,
        kept: &KeptView<'_>,
        obs: ExtensionObservable,
    ) -> Vec<KeptUnit> {
        let rec = &loaded.recs[self.rec];
        let info = |c: u32| {
            loaded.cells[c as usize]
                .as_ref()
                .expect("pairs are reference cells")
        };
        let ext =
            |c: &CellInfo| extension_value(&self.table, loaded, obs, &c.cov, &rec.scan, rec.mor);
        let range = obs == ExtensionObservable::Range;
        let mut out = Vec::with_capacity(kept.singles.len() + kept.cells.len());
        for k in kept.singles.iter() {
            let c = info(k.cell);
            let e = if range {
                range_residual(k, c, ext(c))
            } else {
                intensity_residual(k, c, ext(c))
            };
            out.push(KeptUnit {
                cell: k.cell,
                n: 1.0,
                sum: e,
                sum_sq: e * e,
            });
        }
        for s in kept.cells.iter() {
            let c = info(s.cell);
            // Each return's residual is its centred value less `a`.
            let (a, d, d2) = if range {
                (c.clear_range_offset + ext(c), s.range, s.range_sq)
            } else {
                (
                    c.clear_log_reflectivity_offset + ext(c).max(1e-6).ln(),
                    s.log_ratio,
                    s.log_ratio_sq,
                )
            };
            out.push(KeptUnit::of_sums(s.cell, s.n, d, d2, a));
        }
        out
    }

    /// Survival residuals `kept/trials − p` with their weights.
    pub fn survival_residuals<'a>(
        &self,
        loaded: &Loaded,
        rec: &'a Rec,
    ) -> impl Iterator<Item = (f64, f64)> + 'a {
        rec.units
            .iter()
            .zip(self.p(loaded))
            .map(|(u, p)| (u.kept as f64 / u.trials as f64 - p, u.trials as f64))
    }

    /// The count residual `ln((N_obs + 1) / (N_sim + 1))`.
    pub fn count_residual(&self, rec: &Rec) -> Option<f64> {
        self.near_sim
            .map(|s| ((rec.near as f64 + 1.0) / (s + 1.0)).ln())
    }

    /// The point-level count residuals: per laser, azimuth sector and range
    /// bin (those with a return measured or simulated) of the ghost and ring
    /// returns, [`CountUnit::residual`] and [`CountUnit::excess`], with
    /// weight `n_sim + ½` (empty without simulations).
    pub fn count_bin_residuals(&self, loaded: &Loaded, rec: &Rec) -> Vec<CountUnit> {
        let Some(sim) = &self.near_bins_sim else {
            return Vec::new();
        };
        let o = &rec.near_bins;
        let unit = |obs: f64, s: f64, cov: CountCovariates| CountUnit {
            cov,
            residual: ((obs + 0.5) / (s + 0.5)).ln(),
            excess: (obs - s) / (s + 0.5),
            weight: s + 0.5,
            observed: obs,
            simulated: s,
        };
        let mut out = Vec::with_capacity(sim.ring.len() + sim.sector.len() + sim.range.len());
        for (r, (&obs, &s)) in o.ring.iter().zip(&sim.ring).enumerate() {
            let elevation = loaded.spec.elevation_deg.get(r).copied();
            out.push(unit(
                obs,
                s,
                CountCovariates {
                    ring: Some(r as f64),
                    elevation,
                    ..CountCovariates::default()
                },
            ));
        }
        for (k, (&obs, &s)) in o.sector.iter().zip(&sim.sector).enumerate() {
            out.push(unit(
                obs,
                s,
                CountCovariates {
                    azimuth: Some(NearHistogram::sector_centre(k)),
                    ..CountCovariates::default()
                },
            ));
        }
        // Range bins outside the ring and ghost windows hold nothing.
        for (k, (&obs, &s)) in o.range.iter().zip(&sim.range).enumerate() {
            if obs + s > 0.0 {
                out.push(unit(
                    obs,
                    s,
                    CountCovariates {
                        range: Some(NearHistogram::range_centre(k)),
                        ..CountCovariates::default()
                    },
                ));
            }
        }
        out
    }
}

/// The covariates of one point-level count unit (a laser, an azimuth
/// sector or a range bin): the names it does not carry are `None`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CountCovariates {
    /// Laser id.
    pub ring: Option<f64>,
    /// The laser's elevation, degrees.
    pub elevation: Option<f64>,
    /// Centre of the azimuth sector, degrees.
    pub azimuth: Option<f64>,
    /// Centre of the range bin of the returns' own range, metres.
    pub range: Option<f64>,
}

impl CountCovariates {
    /// The value of a point-level covariate by name.
    pub fn get(&self, name: &str) -> Option<f64> {
        match name {
            "ring" => self.ring,
            "elevation" => self.elevation,
            "azimuth" => self.azimuth,
            "range" => self.range,
            _ => None,
        }
    }
}

/// One point-level count residual.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CountUnit {
    /// What the unit groups.
    pub cov: CountCovariates,
    /// `ln((n_obs + ½)/(n_sim + ½))`: what the held-out loss reads
    /// ([`count_bin_loss`]).
    pub residual: f64,
    /// `(n_obs − n_sim)/(n_sim + ½)`: what the attribution tests read.
    /// Weighted by [`CountUnit::weight`] it sums to `n_obs − n_sim`, zero
    /// in expectation where the model is right whatever the bin's count;
    /// the log ratio is not (of a Poisson count of mean 1 it is −0.24 on
    /// average, of mean 10 about −0.05), so bins of few returns beside bins
    /// of many gave a profile, consistent over recordings, on campaigns
    /// where nothing was hidden.
    pub excess: f64,
    /// `n_sim + ½`.
    pub weight: f64,
    /// `n_obs`: returns measured.
    pub observed: f64,
    /// `n_sim`: returns simulated (mean over the simulations).
    pub simulated: f64,
}

/// The per-recording point-level count loss along `covariate`: the
/// weighted mean of |[`CountUnit::residual`]| over the units that carry it
/// (the lasers for `ring` and `elevation`, the azimuth sectors for
/// `azimuth`; `None` without simulations). Each axis is judged on its own
/// units, so a misfit along another axis does not mask a term's gain.
pub fn count_bin_loss(units: &[CountUnit], covariate: &str) -> Option<f64> {
    let (s, w) = units
        .iter()
        .filter(|u| u.cov.get(covariate).is_some())
        .fold((0.0, 0.0), |(s, w), u| {
            (s + u.weight * u.residual.abs(), w + u.weight)
        });
    (w > 0.0).then(|| s / w)
}

/// True when the table's weather can use the soft edge.
pub fn has_soft_edge(table: &CoefficientTable, loaded: &Loaded) -> bool {
    table.weathers.get(&loaded.weather).is_some_and(|w| {
        w.survival.is_some()
            && w.vanishing_slope
                .iter()
                .all(|b| b.edge_width.is_some_and(|e| e.is_finite() && e > 0.0))
    })
}

/// The applier of `table` at `rec`'s MOR with every component the table
/// holds.
pub fn applier(
    table: &CoefficientTable,
    loaded: &Loaded,
    rec: &Rec,
    near: bool,
    seed: u64,
) -> Result<Applier, DiagnoseError> {
    let w = table.weathers.get(&loaded.weather);
    let has_near = near && w.is_some_and(|w| w.ghost.is_some() || w.ring.is_some());
    let mut p = ApplyParams::new(loaded.weather, Severity::Mor(rec.mor))
        .soft_edge(has_soft_edge(table, loaded))
        .near_range(has_near)
        .lidar(loaded.spec.clone())
        .seed(seed);
    for (k, v) in &rec.scan {
        p = p.covariate(k.clone(), v.clone());
    }
    p.build(table).map_err(|e| DiagnoseError::Infer {
        what: format!("recording {}", rec.id),
        source: Box::new(e),
    })
}

/// The combined extension value of `table` on `obs` for a point of a
/// recording.
pub fn extension_value(
    table: &CoefficientTable,
    loaded: &Loaded,
    obs: ExtensionObservable,
    point: &PointCovariates,
    scan: &BTreeMap<String, CovariateValue>,
    mor: f64,
) -> f64 {
    let terms = table
        .weathers
        .get(&loaded.weather)
        .map(|w| w.extensions.as_slice())
        .unwrap_or(&[]);
    combine_extensions(
        obs,
        terms
            .iter()
            .filter(|t| t.observable == obs)
            .map(|t| t.value(Some(point), scan, mor)),
    )
}

/// Evaluates the recordings `which` (indices into `loaded.recs`) under
/// `table`; simulates them when `sim` is given.
pub fn evaluate(
    loaded: &Loaded,
    table: &CoefficientTable,
    which: &[usize],
    sim: Option<&SimOptions>,
    fit_params: &FitValidParams,
) -> Result<Vec<RecEval>, DiagnoseError> {
    let shared = Arc::new(table.clone());
    let results: Vec<Result<RecEval, DiagnoseError>> = which
        .par_iter()
        .map(|&j| evaluate_one(loaded, &shared, j, sim, fit_params))
        .collect();
    results.into_iter().collect()
}

fn evaluate_one(
    loaded: &Loaded,
    table: &Arc<CoefficientTable>,
    j: usize,
    sim: Option<&SimOptions>,
    fit_params: &FitValidParams,
) -> Result<RecEval, DiagnoseError> {
    let rec = &loaded.recs[j];
    let seed = sim.map_or(0, |s| s.seed);
    let near = sim.is_some();
    let ap = applier(table, loaded, rec, near, seed)?;
    let (near_sim, near_bins_sim, scene) = match sim {
        None => (None, None, None),
        Some(opts) => {
            let (n, h, s) = simulate(loaded, rec, &ap, opts, fit_params)?;
            (Some(n), Some(h), Some(s))
        }
    };
    Ok(RecEval {
        rec: j,
        table: Arc::clone(table),
        near,
        seed,
        near_sim,
        near_bins_sim,
        scene,
    })
}

/// Points of a cloud as `[x, y, z]`.
pub fn xyz(cloud: &PointCloud) -> Vec<[f32; 3]> {
    (0..cloud.len())
        .map(|i| [cloud.x[i], cloud.y[i], cloud.z[i]])
        .collect()
}

/// Simulates `rec` from its nearest clear recording `opts.sims` times:
/// the mean ghost + ring count (classified by the fit's pairing) and the
/// mean scene metrics against the measured cloud.
fn simulate(
    loaded: &Loaded,
    rec: &Rec,
    ap: &Applier,
    opts: &SimOptions,
    fit_params: &FitValidParams,
) -> Result<(f64, NearHistogram, SceneMetrics), DiagnoseError> {
    let clear_rec = &loaded.clear[rec.clear];
    let clear = &clear_rec.read(&loaded.spec)?;
    let measured = xyz(&read_calibrated(&rec.lidar, &loaded.spec)?);
    let grid = loaded.reference.grid();
    let mut near = 0.0;
    let mut bins = NearHistogram::default();
    let mut acc = SceneMetrics {
        voxel_global_difference: 0.0,
        voxel_difference: 0.0,
        voxel_local_difference: opts.local_box.map(|_| 0.0),
        chamfer_m: 0.0,
    };
    let n = opts.sims.max(1);
    for s in 0..n {
        let key = format!("{}#{s}", rec.id);
        let (out, _) = ap.apply(clear, &key).map_err(|e| DiagnoseError::Infer {
            what: format!("recording {}", rec.id),
            source: Box::new(e),
        })?;
        let pts = cell_points(grid, &out, &clear_rec.lidar).map_err(|e| DiagnoseError::Read {
            path: clear_rec.lidar.clone(),
            reason: e.to_string(),
        })?;
        let t = pair_frames(&loaded.reference, &pts, clear_rec.frames, fit_params);
        near += (t.ghosts.len() + t.rings.len()) as f64;
        bins.add_scaled(&NearHistogram::of_tally(&t, grid), 1.0 / n as f64);
        let m = SceneMetrics::compare(&measured, &xyz(&out), opts.voxel_m, opts.local_box.as_ref());
        acc.voxel_global_difference += m.voxel_global_difference;
        acc.voxel_difference += m.voxel_difference;
        acc.chamfer_m += m.chamfer_m;
        acc.voxel_local_difference = match (acc.voxel_local_difference, m.voxel_local_difference) {
            (Some(a), Some(b)) => Some(a + b),
            _ => None,
        };
    }
    let k = n as f64;
    acc.voxel_global_difference /= k;
    acc.voxel_difference /= k;
    acc.chamfer_m /= k;
    acc.voxel_local_difference = acc.voxel_local_difference.map(|v| v / k);
    Ok((near / k, bins, acc))
}

/// Metrics over a set of evaluated recordings (the report's `metrics`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Metrics {
    /// Recordings.
    pub recordings: usize,
    /// Mean log loss per expected return (natural log).
    pub survival_log_loss: f64,
    /// Mean over recordings of |predicted − measured| no-change rate.
    pub no_change_rate_error: f64,
    /// Mean over recordings of |ln((N_obs + 1)/(N_sim + 1))| of ghost and
    /// ring counts.
    pub count_abs_log_error: Option<f64>,
    /// Mean over recordings of the ghost and ring counts' weighted mean
    /// |ln((n_obs + ½)/(n_sim + ½))| per laser ([`count_bin_loss`]): how
    /// they fall over the lasers, not only how many there are.
    pub count_laser_abs_log_error: Option<f64>,
    /// The same per azimuth sector.
    pub count_sector_abs_log_error: Option<f64>,
    /// The same per 1 m bin of the returns' own range (how they fall
    /// along the rays: the seed-004 per-echo range law).
    pub count_range_abs_log_error: Option<f64>,
    /// Mean range residual of kept returns, metres.
    pub range_bias_m: f64,
    /// RMS range residual of kept returns, metres.
    pub range_rmse_m: f64,
    /// Mean log ratio of measured to predicted reflectivity of kept returns.
    pub intensity_bias: f64,
    /// RMS of that log ratio.
    pub intensity_rmse: f64,
    /// Seed 004 eq. 6, mean over recordings.
    pub voxel_global_difference: Option<f64>,
    /// Bounded per-voxel difference, mean over recordings.
    pub voxel_difference: Option<f64>,
    /// Seed 004 eq. 8 in the box given, mean over recordings.
    pub voxel_local_difference: Option<f64>,
    /// Chamfer distance, metres, mean over recordings.
    pub chamfer_m: Option<f64>,
}

impl Metrics {
    /// Aggregates `evals` of `loaded`'s recordings.
    pub fn of(loaded: &Loaded, evals: &[RecEval]) -> Metrics {
        // Per recording in parallel (its keep probabilities and residuals
        // are computed again from its summaries, the cost of a metric),
        // then summed in recording order: the same bits on any thread
        // count.
        struct Part {
            ll: f64,
            tr: f64,
            ncr: Option<f64>,
            kept: [f64; 5],
            count: Option<f64>,
            lasers: Option<f64>,
            sectors: Option<f64>,
            ranges: Option<f64>,
            scene: Option<SceneMetrics>,
        }
        let parts: Vec<Part> = evals
            .par_iter()
            .map(|e| {
                let rec = &loaded.recs[e.rec];
                let (mut ll, mut pk, mut ok, mut tr) = (0.0, 0.0, 0.0, 0.0);
                for (u, p) in rec.units.iter().zip(e.p(loaded)) {
                    let p = p.clamp(P_FLOOR, 1.0 - P_FLOOR);
                    let (k, n) = (u.kept as f64, u.trials as f64);
                    ll -= k * p.ln() + (n - k) * (1.0 - p).ln();
                    pk += p * n;
                    ok += k;
                    tr += n;
                }
                let mut kept = [0.0f64; 5];
                let read = rec.kept.get();
                let (range, intensity) = (
                    e.kept_residuals_of(loaded, &read, ExtensionObservable::Range),
                    e.kept_residuals_of(loaded, &read, ExtensionObservable::Intensity),
                );
                for (r, i) in range.iter().zip(&intensity) {
                    kept[0] += r.sum;
                    kept[1] += r.sum_sq;
                    kept[2] += i.sum;
                    kept[3] += i.sum_sq;
                    kept[4] += r.n;
                }
                let units = e.count_bin_residuals(loaded, rec);
                Part {
                    ll,
                    tr,
                    ncr: (tr > 0.0).then(|| (pk - ok).abs() / tr),
                    kept,
                    count: e.count_residual(rec).map(f64::abs),
                    lasers: count_bin_loss(&units, "ring"),
                    sectors: count_bin_loss(&units, "azimuth"),
                    ranges: count_bin_loss(&units, "range"),
                    scene: e.scene,
                }
            })
            .collect();
        let (mut ll, mut trials, mut ncr) = (0.0, 0.0, 0.0);
        let (mut rs, mut rs2, mut is, mut is2, mut nk) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
        let mut count = Vec::new();
        let (mut count_lasers, mut count_sectors, mut count_ranges) =
            (Vec::new(), Vec::new(), Vec::new());
        let mut scenes = Vec::new();
        for part in parts {
            ll += part.ll;
            trials += part.tr;
            ncr += part.ncr.unwrap_or(0.0);
            rs += part.kept[0];
            rs2 += part.kept[1];
            is += part.kept[2];
            is2 += part.kept[3];
            nk += part.kept[4];
            count.extend(part.count);
            count_lasers.extend(part.lasers);
            count_sectors.extend(part.sectors);
            count_ranges.extend(part.ranges);
            scenes.extend(part.scene);
        }
        let n = evals.len().max(1) as f64;
        let mean = |v: Vec<f64>| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
        Metrics {
            recordings: evals.len(),
            survival_log_loss: ll / trials.max(1.0),
            no_change_rate_error: ncr / n,
            count_abs_log_error: mean(count),
            count_laser_abs_log_error: mean(count_lasers),
            count_sector_abs_log_error: mean(count_sectors),
            count_range_abs_log_error: mean(count_ranges),
            range_bias_m: rs / nk.max(1.0),
            range_rmse_m: (rs2 / nk.max(1.0)).sqrt(),
            intensity_bias: is / nk.max(1.0),
            intensity_rmse: (is2 / nk.max(1.0)).sqrt(),
            voxel_global_difference: mean(
                scenes.iter().map(|s| s.voxel_global_difference).collect(),
            ),
            voxel_difference: mean(scenes.iter().map(|s| s.voxel_difference).collect()),
            voxel_local_difference: mean(
                scenes
                    .iter()
                    .filter_map(|s| s.voxel_local_difference)
                    .collect(),
            ),
            chamfer_m: mean(
                scenes
                    .iter()
                    .map(|s| s.chamfer_m)
                    .filter(|c| c.is_finite())
                    .collect(),
            ),
        }
    }

    /// The metric that measures `observable` along `covariate` (counts
    /// along the lasers, azimuth or range:
    /// [`Metrics::count_laser_abs_log_error`],
    /// [`Metrics::count_sector_abs_log_error`],
    /// [`Metrics::count_range_abs_log_error`]).
    pub fn of_test(
        &self,
        obs: ExtensionObservable,
        covariate: &str,
    ) -> (&'static str, Option<f64>) {
        match (obs, covariate) {
            (ExtensionObservable::Count, "ring" | "elevation") => {
                ("count_laser_abs_log_error", self.count_laser_abs_log_error)
            }
            (ExtensionObservable::Count, "azimuth") => (
                "count_sector_abs_log_error",
                self.count_sector_abs_log_error,
            ),
            (ExtensionObservable::Count, "range") => {
                ("count_range_abs_log_error", self.count_range_abs_log_error)
            }
            _ => self.of_observable(obs),
        }
    }

    /// The metric that measures `observable`.
    pub fn of_observable(&self, obs: ExtensionObservable) -> (&'static str, Option<f64>) {
        match obs {
            ExtensionObservable::Survival => ("survival_log_loss", Some(self.survival_log_loss)),
            ExtensionObservable::Count => ("count_abs_log_error", self.count_abs_log_error),
            ExtensionObservable::Range => ("range_rmse_m", Some(self.range_rmse_m)),
            ExtensionObservable::Intensity => ("intensity_rmse", Some(self.intensity_rmse)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cell_of_several_returns_gives_the_sums_of_their_residuals() {
        // Centred ranges of four returns of one cell; residual x − a.
        let x = [0.031, -0.012, 0.004, 0.027];
        let a = 0.0125;
        let d: f64 = x.iter().sum();
        let d2: f64 = x.iter().map(|v| v * v).sum();
        let u = KeptUnit::of_sums(7, 4, d, d2, a);
        let sum: f64 = x.iter().map(|v| v - a).sum();
        let sum_sq: f64 = x.iter().map(|v| (v - a) * (v - a)).sum();
        assert_eq!((u.cell, u.n), (7, 4.0));
        assert!((u.sum - sum).abs() < 1e-15, "{} {sum}", u.sum);
        assert!((u.sum_sq - sum_sq).abs() < 1e-15, "{} {sum_sq}", u.sum_sq);
        assert!((u.mean() - sum / 4.0).abs() < 1e-15);
        // Equal values: the sum of squares is 0, not a rounding below it.
        let u = KeptUnit::of_sums(1, 3, 0.3, 0.03, 0.1);
        assert!(u.sum_sq >= 0.0 && u.sum_sq < 1e-15, "{}", u.sum_sq);
    }
}
