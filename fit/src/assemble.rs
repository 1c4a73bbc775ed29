//! From accumulated statistics to the coefficient table (no I/O).

use murk_types::{
    CountLaw, CountLawChoice, EdgeTest, Gaussian, Interval, LackOfFit, LawChoice, MorBin, NoiseLaw,
    RainConversion, ReflectivityChoice, ReturnMoments, SlopeBand, SurvivalBin, SurvivalFit,
    SweepBand, Uncertainty, WeatherClass, WeatherCoefficients,
};

use crate::bend::{
    Binning, TermComparison, compare_laws, compare_reflectivity, fit_powers, fit_reflectivities,
    half_survival, half_z, lack_of_fit,
};

use crate::FitValidParams;
use crate::accumulate::{NoiseAcc, OCCLUDER_STEP_M, WeatherAcc};
use crate::accumulate::{ROW_OCCLUDER_STEP_M, RecordingRow};
use crate::diagnostics::{NoiseHistograms, RangeMorDensity, WeatherDiagnostics};
use crate::hyperparams::Band;
use crate::quantile_slope::{
    BandCells, BinQuantile, MorBinStats, bin_quantile, quantile_slope, quantile_slope_interval,
};
use crate::reference::ClearReference;
use crate::stats::bootstrap::{RateUncertainty, bootstrap_rate};
use crate::stats::counts::{CountFit, CountLawFailure, Family, fit_count_law};
use crate::stats::dist::normal_cdf;
use crate::stats::regress::line;
use crate::stats::truncnorm::{
    Histogram, NormalFit, Visibility, degeneracy, fit_truncated_normal,
    fit_truncated_normal_rounded, fit_truncated_normal_seen, is_quantized,
};
use crate::survival::{
    EdgeEvidence, Partition, RecordingTrials, RobustIntervals, SurvivalOptions, SurvivalResult,
    edge_test, fit_slope_only, fit_survival, precheck, robust_covariance, robust_intervals,
};

/// Converts a bootstrap summary to the table's type.
pub fn uncertainty(u: RateUncertainty) -> Uncertainty {
    Uncertainty {
        std: u.std,
        ci95_low: u.ci95_low,
        ci95_high: u.ci95_high,
        replicates: u.replicates,
    }
}

/// One rain recording for the conversion: every rain gauge's reading of it
/// (mm/h) and its MOR (metres).
#[derive(Debug, Clone, PartialEq)]
pub struct RainSample {
    /// The non-empty readings of the rule set's rain-rate gauges.
    pub readings: Vec<f64>,
    /// The recording's MOR.
    pub mor: f64,
}

/// Variance of a recording's MOR reading error in `ln MOR`, averaged over
/// the recordings of a weather, from the visibility sensors' disagreement,
/// with its standard error.
///
/// `readings` holds each recording's visibility readings (metres; its MOR
/// is their mean). The per-sensor variance `σ²` of `ln` reading is pooled
/// over the recordings read by two or more sensors (`(k − 1)` degrees of
/// freedom each); a recording's MOR, the mean of `k` readings, carries
/// `σ²/k`; the mean of that over the recordings is the estimate. Its
/// standard error is the jackknife's over recordings (no assumption on the
/// noise's distribution). What the sensors share — a common calibration
/// error, or a MOR along the beam other than at the sensors — does not
/// show in their disagreement and is not in this. Errors say why nothing
/// can be estimated.
pub fn mor_reading_variance(readings: &[Vec<f64>]) -> Result<ReadingVariance, String> {
    if readings.is_empty() {
        return Err("no recording".into());
    }
    if readings.iter().any(Vec::is_empty) {
        return Err(
            "some recordings have no visibility reading (their MOR comes from the rain conversion)"
                .into(),
        );
    }
    if readings
        .iter()
        .flatten()
        .any(|&m| !(m.is_finite() && m > 0.0))
    {
        return Err("a visibility reading is not positive".into());
    }
    // Per recording: sum of squares of ln readings about their mean, the
    // degrees of freedom, 1/k.
    let parts: Vec<(f64, usize, f64)> = readings
        .iter()
        .map(|r| {
            let k = r.len() as f64;
            let mu = r.iter().map(|m| m.ln()).sum::<f64>() / k;
            let ss = r.iter().map(|m| (m.ln() - mu).powi(2)).sum::<f64>();
            (ss, r.len() - 1, 1.0 / k)
        })
        .collect();
    let (ss, dof, inv_k) = parts
        .iter()
        .fold((0.0, 0usize, 0.0), |a, p| (a.0 + p.0, a.1 + p.1, a.2 + p.2));
    if dof == 0 {
        return Err(
            "every recording is read by one visibility sensor: the reading noise cannot be estimated"
                .into(),
        );
    }
    let n = parts.len() as f64;
    let estimate = |ss: f64, dof: usize, inv_k: f64, n: f64| ss / dof as f64 * inv_k / n;
    let variance = estimate(ss, dof, inv_k, n);
    // Delete-one jackknife over recordings (no error when one recording
    // holds every degree of freedom: leaving it out leaves nothing).
    let std_error = (parts.len() >= 2 && parts.iter().all(|p| p.1 < dof)).then(|| {
        let loo: Vec<f64> = parts
            .iter()
            .map(|p| estimate(ss - p.0, dof - p.1, inv_k - p.2, n - 1.0))
            .collect();
        let m = loo.iter().sum::<f64>() / n;
        ((n - 1.0) / n * loo.iter().map(|v| (v - m).powi(2)).sum::<f64>()).sqrt()
    });
    Ok(ReadingVariance {
        variance,
        std_error,
    })
}

/// [`mor_reading_variance`]'s answer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReadingVariance {
    /// Mean variance of a recording's MOR reading error in `ln MOR`.
    pub variance: f64,
    /// Its standard error over recordings (`None` when one recording
    /// holds every degree of freedom).
    pub std_error: Option<f64>,
}

/// The interval of the corrected width: the fitted width's interval
/// `[lo, hi]` about `w`, and `t` standard errors `dv` of the reading
/// variance `v`, combined in quadrature in `w²` (where the correction is a
/// subtraction), then deconvolved.
pub fn deconvolve_interval(w: f64, [lo, hi]: [f64; 2], v: f64, dv: f64) -> [f64; 2] {
    let c = w * w - v;
    let down = c - ((w * w - lo * lo).powi(2) + dv * dv).sqrt();
    let up = c + ((hi * hi - w * w).powi(2) + dv * dv).sqrt();
    [down.max(0.0).sqrt(), up.max(0.0).sqrt()]
}

/// Reliabilities below this are not corrected: the gauges disagree so much
/// that the corrected slope would be noise (the OLS line is kept and the
/// reliability reported).
const MIN_RELIABILITY: f64 = 0.5;

/// `MOR = a·R + b` from rain recordings, with its validity range.
///
/// The rate of a recording is the mean of its gauges' readings. Gauge noise
/// in that rate flattens an ordinary least-squares line (regression
/// dilution: at 12 % relative noise on a few high-rate recordings the OLS
/// slope comes out ~10 % shallow), so the slope is corrected by the method of
/// moments, `a = Sxy / (Sxx − Σ vᵢ)`, where `vᵢ` is the noise variance of
/// recording i's mean rate estimated from its gauges' disagreement (`s²/k`;
/// for a recording read by one gauge, the pooled relative variance of the
/// others times its rate²). With one gauge everywhere nothing can be
/// estimated and the line is the OLS one. The OLS line and the reliability
/// `1 − Σvᵢ/Sxx` are reported beside it.
pub fn rain_conversion(samples: &[RainSample]) -> Result<RainConversion, String> {
    let samples: Vec<&RainSample> = samples
        .iter()
        .filter(|s| !s.readings.is_empty() && s.mor.is_finite())
        .collect();
    if samples.len() < 2 {
        return Err(format!(
            "{} rain recordings carry both a rain rate and a MOR; at least 2 are needed",
            samples.len()
        ));
    }
    let r: Vec<f64> = samples
        .iter()
        .map(|s| s.readings.iter().sum::<f64>() / s.readings.len() as f64)
        .collect();
    let m: Vec<f64> = samples.iter().map(|s| s.mor).collect();
    let (a_ols, b_ols) = line(&r, &m).ok_or_else(|| {
        "every rain recording has the same rain rate: the line is not determined".to_string()
    })?;
    let n = r.len() as f64;
    let mean_r = r.iter().sum::<f64>() / n;
    let mean_m = m.iter().sum::<f64>() / n;
    let sxx: f64 = r.iter().map(|x| (x - mean_r).powi(2)).sum();
    let sxy: f64 = r
        .iter()
        .zip(&m)
        .map(|(x, y)| (x - mean_r) * (y - mean_m))
        .sum();

    // Noise variance of each recording's mean rate.
    let sample_var = |s: &RainSample| {
        let k = s.readings.len() as f64;
        let mu = s.readings.iter().sum::<f64>() / k;
        s.readings.iter().map(|x| (x - mu).powi(2)).sum::<f64>() / (k - 1.0)
    };
    let rel: Vec<f64> = samples
        .iter()
        .zip(&r)
        .filter(|(s, x)| s.readings.len() >= 2 && **x > 0.0)
        .map(|(s, x)| sample_var(s) / (x * x))
        .collect();
    let noise: Option<f64> = (!rel.is_empty()).then(|| {
        let pooled = rel.iter().sum::<f64>() / rel.len() as f64;
        samples
            .iter()
            .zip(&r)
            .map(|(s, x)| match s.readings.len() {
                1 => pooled * x * x,
                k => sample_var(s) / k as f64,
            })
            .sum::<f64>()
            * (1.0 - 1.0 / n)
    });
    let reliability = noise.map(|v| 1.0 - v / sxx);
    let corrected = reliability.is_some_and(|rel| (MIN_RELIABILITY..1.0).contains(&rel));
    let (a, b) = match (corrected, noise) {
        (true, Some(v)) => {
            let a = sxy / (sxx - v);
            (a, mean_m - a * mean_r)
        }
        _ => (a_ols, b_ols),
    };
    let lo = r.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = r.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    // Least-squares standard errors from the residual scatter about the line
    // used, on the noise-free share of the spread of rates.
    let sxx_true = sxx
        * if corrected {
            reliability.unwrap_or(1.0)
        } else {
            1.0
        };
    let rss: f64 = r.iter().zip(&m).map(|(x, y)| (y - a * x - b).powi(2)).sum();
    let (se_a, se_b) = if samples.len() > 2 && sxx_true > 0.0 {
        let s2 = rss / (n - 2.0);
        (
            Some((s2 / sxx_true).sqrt()),
            Some((s2 * (1.0 / n + mean_r * mean_r / sxx_true)).sqrt()),
        )
    } else {
        (None, None)
    };
    Ok(RainConversion {
        slope: a,
        intercept: b,
        points: samples.len() as u64,
        slope_std_error: se_a,
        intercept_std_error: se_b,
        rain_rate_min: Some(lo),
        rain_rate_max: Some(hi),
        zero_mor_rain_rate: (a < 0.0 && b > 0.0).then(|| -b / a),
        slope_ols: corrected.then_some(a_ols),
        intercept_ols: corrected.then_some(b_ols),
        rain_rate_reliability: reliability,
    })
}

/// The mean MOR of each MOR bin's recordings, in row order.
fn bin_means(acc: &WeatherAcc, width: f64) -> Vec<(i64, f64)> {
    acc.bins
        .keys()
        .map(|&k| {
            let ms: Vec<f64> = acc
                .rows
                .iter()
                .filter(|r| (r.mor / width).floor() as i64 == k)
                .map(|r| r.mor)
                .collect();
            (k, ms.iter().sum::<f64>() / ms.len().max(1) as f64)
        })
        .collect()
}

fn to_mor_bin(b: &BinQuantile) -> MorBin {
    MorBin {
        mor_m: b.mor_mean,
        mor_lo_m: Some(b.lo),
        mor_hi_m: Some(b.hi),
        recordings: b.recordings,
        q99_range_m: b.quantile,
        points: b.points,
        censored: b.censored,
        used: b.used,
        reason: b.reason.clone(),
    }
}

/// Quantiles of one band over every MOR bin.
fn band_quantiles(
    acc: &WeatherAcc,
    means: &[(i64, f64)],
    cells: &BandCells,
    params: &FitValidParams,
    ml_slope: Option<f64>,
    range_scale: f64,
) -> Vec<BinQuantile> {
    let w = params.mor_bin_width_m();
    means
        .iter()
        .map(|&(k, mean)| {
            let (n, kept) = &acc.bins[&k];
            let stats = MorBinStats {
                lo: k as f64 * w,
                hi: (k + 1) as f64 * w,
                mor_mean: mean,
                recordings: *n,
                kept,
            };
            bin_quantile(
                cells,
                &stats,
                params,
                ml_slope.map(|s| s * mean * range_scale),
            )
        })
        .collect()
}

/// Share of a `N(μ, σ²)` law on `[lo, hi)` that a recording could show: the
/// law's mass per occluder step times the share of its rays open there.
fn row_visibility(row: &RecordingRow, mu: f64, sigma: f64, lo: f64, hi: f64) -> f64 {
    let cdf = |x: f64| normal_cdf((x - mu) / sigma);
    let all = cdf(hi) - cdf(lo);
    if all <= 0.0 {
        return 1.0;
    }
    let open = row.open_rays();
    let mut seen = 0.0;
    let mut a = lo;
    while a < hi {
        let k = (a / ROW_OCCLUDER_STEP_M).floor();
        let b = ((k + 1.0) * ROW_OCCLUDER_STEP_M).min(hi).max(a + 1e-9);
        let v = open.get(k.max(0.0) as usize).copied().unwrap_or(1.0);
        seen += v * (cdf(b) - cdf(a));
        a = b;
    }
    seen / all
}

/// The table's form of a fitted count law, with its intervals.
fn table_count_law(f: &CountFit) -> CountLaw {
    let iv = |c: Option<[f64; 2]>| {
        c.filter(|c| c[0].is_finite() && c[1].is_finite())
            .map(|c| Interval {
                low: c[0],
                high: c[1],
                level: 0.95,
                method: f.method.to_string(),
            })
    };
    let finite = |x: Option<f64>| x.filter(|x| x.is_finite());
    match f.family {
        Family::Power => CountLaw::Power {
            n_ref: f.n_ref(),
            mor_ref_m: f.mor_ref,
            exponent: f.exponent(),
            n_ref_std_error: finite(f.n_ref_std_error()),
            exponent_std_error: finite(f.exponent_std_error()),
            n_ref_ci95: iv(f.n_ref_ci()),
            exponent_ci95: iv(f.exponent_ci()),
        },
        Family::Onset => CountLaw::Onset {
            n_ref: f.n_ref(),
            mor_ref_m: f.mor_ref,
            exponent: f.exponent(),
            onset_mor_m: f.onset_mor().unwrap_or(f64::NAN),
            onset_steepness: f.onset_steepness().unwrap_or(f64::NAN),
            n_ref_ci95: iv(f.n_ref_ci()),
            exponent_ci95: iv(f.exponent_ci()),
            onset_mor_ci95: iv(f.onset_mor_ci()),
            onset_steepness_ci95: iv(f.onset_steepness_ci()),
        },
    }
}

/// Mean and population standard deviation of a histogram's values (bin
/// centres; integer values when the histogram holds integers).
fn histogram_moments(h: &Histogram) -> (f64, f64) {
    let shift = if is_quantized(h, 1.0) {
        -0.5 * h.width()
    } else {
        0.0
    };
    let n = h.total().max(1) as f64;
    let mean = h.bins().map(|(x, c)| (x + shift) * c as f64).sum::<f64>() / n;
    let var = h
        .bins()
        .map(|(x, c)| c as f64 * (x + shift - mean).powi(2))
        .sum::<f64>()
        / n;
    (mean, var.sqrt())
}

/// The seed's Table 5 moments of the returns themselves.
fn return_moments(acc: &NoiseAcc) -> Option<ReturnMoments> {
    let n = acc.distance.total();
    if n == 0 {
        return None;
    }
    let (dm, ds) = histogram_moments(&acc.distance);
    let (rm, rs) = histogram_moments(&acc.reflectivity);
    Some(ReturnMoments {
        points: n,
        distance_mean_m: dm,
        distance_std_m: ds,
        reflectivity_mean: rm,
        reflectivity_std: rs,
    })
}

/// The table's Gaussian for a truncated fit on `[lo, hi)`: the fitted law,
/// or, when [`degeneracy`] says the data cannot pin it down, the returns'
/// own moments with the reason.
fn table_gaussian(f: &NormalFit, h: &Histogram, lo: f64, hi: f64) -> Gaussian {
    let upper = hi.is_finite().then_some(hi);
    match degeneracy(f, lo, hi) {
        None => Gaussian {
            mean: f.mean,
            std: f.std,
            lower: Some(lo),
            upper,
            mean_std_error: f.mean_std_error.is_finite().then_some(f.mean_std_error),
            std_std_error: f.std_std_error.is_finite().then_some(f.std_std_error),
            reason: None,
        },
        Some(reason) => {
            let (m, sd) = histogram_moments(h);
            Gaussian {
                mean: m,
                std: sd.max(h.width()),
                lower: Some(lo),
                upper,
                mean_std_error: None,
                std_std_error: None,
                reason: Some(reason),
            }
        }
    }
}

/// Share of a recording's rays without a return of the scene (kept,
/// unpaired scene or far): where a weather return that only replaces lost
/// returns can show (one return per ray).
fn row_open_share(row: &RecordingRow) -> f64 {
    let scene = row.points.saturating_sub(row.ghosts + row.rings);
    (1.0 - scene as f64 / row.rays.max(1) as f64).clamp(0.0, 1.0)
}

#[allow(clippy::too_many_arguments)]
fn noise_law(
    name: &str,
    weather: &str,
    acc: &NoiseAcc,
    window: [f64; 2],
    floor: f64,
    counts: &[(&RecordingRow, u64)],
    params: &FitValidParams,
    replaced: bool,
) -> Result<NoiseLaw, String> {
    let n = acc.distance.total();
    if n == 0 {
        return Err(format!("no {name} return was found"));
    }
    // Near returns that hide what is behind them are themselves hidden by
    // nearer returns, more so at shorter distances; near returns that only
    // replace lost returns show on any ray without a kept one, whatever
    // their distance (`crate::occlusion`).
    let v = if replaced { None } else { acc.visibility() };
    let vis = v.as_deref().map(|v| Visibility {
        step: OCCLUDER_STEP_M,
        v,
    });
    let d =
        fit_truncated_normal_seen(&acc.distance, window[0], window[1], vis).ok_or_else(|| {
            format!("{n} {name} returns are too few or too concentrated for a distance law")
        })?;
    let r = if is_quantized(&acc.reflectivity, 1.0) {
        fit_truncated_normal_rounded(&acc.reflectivity, floor, f64::INFINITY, 1.0)
    } else {
        fit_truncated_normal(&acc.reflectivity, floor, f64::INFINITY)
    };
    let r = r.ok_or_else(|| {
        format!("{n} {name} returns are too few or too concentrated for a reflectivity law")
    })?;
    let distance_m = table_gaussian(&d, &acc.distance, window[0], window[1]);
    let reflectivity = table_gaussian(&r, &acc.reflectivity, floor, f64::INFINITY);
    // The visibility of the law that is published.
    let visible = if distance_m.reason.is_some() {
        let vis = v.as_deref().map(|v| Visibility {
            step: OCCLUDER_STEP_M,
            v,
        });
        vis.map_or(1.0, |vis| {
            vis.visible_share(distance_m.mean, distance_m.std, window[0], window[1])
        })
    } else {
        d.visible
    };
    // Counts per revolution: a recording of many revolutions (a one-minute
    // `.pcap` holds ~600) contributes its count over its revolutions.
    let all: f64 = counts.iter().map(|c| c.1 as f64).sum();
    let revolutions: f64 = counts.iter().map(|c| c.0.revolutions.max(1) as f64).sum();
    let per_scan = all / revolutions.max(1.0);
    let per_recording = all / counts.len().max(1) as f64;
    // Each recording's count is seen through its own visibility: denser
    // weather hides more of its own returns behind nearer ones; its exposure
    // is its number of revolutions, so the law is per revolution.
    let exposed: Vec<(f64, u64, f64)> = counts
        .iter()
        .map(|(row, c)| {
            let seen = if replaced {
                row_open_share(row)
            } else {
                row_visibility(row, distance_m.mean, distance_m.std, window[0], window[1])
            };
            (row.mor, *c, seen * row.revolutions.max(1) as f64)
        })
        .collect();
    let seed = murk_types::seed::derive(
        params.seed(),
        &murk_types::seed::key(&["count-law", weather, name]),
        murk_types::seed::Purpose::Bootstrap,
    )
    .bytes();
    let (count_law, count_law_reason, count_law_choice) =
        match fit_count_law(&exposed, params.count_mor_ref_m(), seed) {
            Ok((f, c)) => (
                Some(table_count_law(&f)),
                None,
                Some(CountLawChoice {
                    chosen: f.family.name().to_string(),
                    folds: c.folds as u32,
                    power_heldout_log_likelihood: c.power_ll,
                    onset_heldout_log_likelihood: c.onset_ll,
                    onset_gain_p: c.onset_p,
                    reason: c.reason,
                }),
            ),
            Err(CountLawFailure::NoCounts) => (None, Some("no count".to_string()), None),
            Err(CountLawFailure::SingleMor) => (
                None,
                Some(
                    "not identifiable: every recording has the same MOR, so the exponent is not determined"
                        .to_string(),
                ),
                None,
            ),
            Err(CountLawFailure::NotIdentifiable(r)) => (None, Some(r), None),
        };
    Ok(NoiseLaw {
        distance_m,
        reflectivity,
        points_per_scan: per_scan,
        points_per_recording: Some(per_recording),
        points: n,
        visible_fraction: Some(visible),
        count_law,
        count_law_reason,
        count_law_choice,
    })
}

/// Everything a weather's assembly needs besides its accumulator.
pub struct WeatherContext<'a> {
    /// The weather.
    pub class: WeatherClass,
    /// The reference.
    pub reference: &'a ClearReference,
    /// Reflectivity classes of the survival histogram.
    pub partition: &'a Partition,
    /// Parameters.
    pub params: &'a FitValidParams,
    /// Sensor range scale.
    pub range_scale: f64,
    /// The clear-weather dropout, when known.
    pub dropout_clear: Option<f64>,
    /// The rain conversion (rain only).
    pub rain: Option<Result<RainConversion, String>>,
    /// Variance of the recordings' MOR reading error in `ln MOR`
    /// ([`mor_reading_variance`]), or why it is unknown.
    pub mor_reading_variance: Result<ReadingVariance, String>,
}

fn band_obs(acc: &WeatherAcc, partition: &Partition, band: &Band) -> Vec<crate::survival::Obs> {
    acc.survival.observations(partition.classes_in(band))
}

/// Where each reflectivity class sits in its band, for the law's
/// reflectivity term.
struct ReflectivityDeltas {
    /// Per class, its mean `ln max(x, floor)` less its band's reference
    /// (NaN for a class without reference cells: it holds no trials).
    delta: Vec<f64>,
    /// Per band, the reference `ln x_ref`: the trial-weighted mean of its
    /// classes' `ln x` (NaN for a band without trials).
    ln_reference: Vec<f64>,
    /// The floor (the first reflectivity class edge).
    floor: f64,
}

/// The classes' `ln x` (mean over the reference cells of each class, the
/// cells whose trials it holds) less their band's reference; `None`
/// without a reflectivity term.
fn reflectivity_deltas(
    acc: &WeatherAcc,
    cx: &WeatherContext<'_>,
    classes: &[std::ops::Range<usize>],
) -> Option<ReflectivityDeltas> {
    let floor = *cx.params.reflectivity_law_edges().first()?;
    let n = cx.partition.classes();
    let mut sum = vec![(0.0f64, 0u64); n];
    for &cell in cx.reference.present() {
        let x = cx.reference.reflectivity(cell as usize) as f64;
        let e = &mut sum[cx.partition.class_of(x)];
        e.0 += x.max(floor).ln();
        e.1 += 1;
    }
    let ln_x: Vec<f64> = sum
        .iter()
        .map(|&(s, k)| if k > 0 { s / k as f64 } else { f64::NAN })
        .collect();
    let trials: Vec<f64> = (0..n)
        .map(|c| {
            acc.survival
                .observations(c..c + 1)
                .iter()
                .map(|o| o.total)
                .sum()
        })
        .collect();
    let ln_reference: Vec<f64> = classes
        .iter()
        .map(|cs| {
            let (s, w) = cs
                .clone()
                .filter(|&c| trials[c] > 0.0 && ln_x[c].is_finite())
                .fold((0.0, 0.0), |(s, w), c| {
                    (s + trials[c] * ln_x[c], w + trials[c])
                });
            if w > 0.0 { s / w } else { f64::NAN }
        })
        .collect();
    let mut delta = vec![f64::NAN; n];
    for (b, cs) in classes.iter().enumerate() {
        for c in cs.clone() {
            delta[c] = ln_x[c] - ln_reference[b];
        }
    }
    Some(ReflectivityDeltas {
        delta,
        ln_reference,
        floor,
    })
}

/// An exponent's interval from its estimate and its fits without each fold.
type JackknifeInterval = fn(f64, &[Option<f64>]) -> Result<[f64; 2], String>;

/// Per band, the grouped-jackknife interval of an exponent estimated on all
/// recordings (`estimates`) from the held-out comparison's fits without
/// each fold (`interval`: [`crate::bend::jackknife_interval`] or its
/// reflectivity form); `None` when the comparison failed.
fn fold_intervals(
    estimates: impl Iterator<Item = Option<f64>>,
    evidence: &Result<crate::bend::LawEvidence, String>,
    interval: JackknifeInterval,
) -> Option<Vec<Option<Interval>>> {
    let e = evidence.as_ref().ok()?;
    Some(
        estimates
            .enumerate()
            .map(|(b, estimate)| {
                let leave_out: Vec<Option<f64>> = e.fold_exponents.iter().map(|fe| fe[b]).collect();
                let [low, high] = interval(estimate?, &leave_out).ok()?;
                Some(Interval {
                    low,
                    high,
                    level: 0.95,
                    method: format!(
                        "grouped jackknife over {} folds of recordings (Student t on {} df)",
                        leave_out.len(),
                        leave_out.len() - 1
                    ),
                })
            })
            .collect(),
    )
}

/// A weather's per-recording trials as the law comparisons read them.
struct Trials<'a> {
    /// Per recording.
    recordings: &'a [RecordingTrials],
    /// Their binning in `ln u` (the survival histogram's).
    bin: Binning,
    /// Where their reflectivity classes sit (with a reflectivity term).
    deltas: Option<&'a ReflectivityDeltas>,
}

/// The law that bends ([`crate::bend`]): fits `a·MOR^c` beside the line,
/// chooses on held-out recordings, writes the chosen law into the bands,
/// and fills each band's per-MOR-bin 50 % ranges and the line's lack of
/// fit. Returns the choice (`None` when no band has a slope).
fn bend_and_check(
    bands: &mut [SlopeBand],
    line: &SurvivalResult,
    trials: &Trials<'_>,
    means: &[(i64, f64)],
    opts: &SurvivalOptions,
    cx: &WeatherContext<'_>,
) -> Option<LawChoice> {
    let p = cx.params;
    let (recs, bin, deltas) = (trials.recordings, trials.bin, trials.deltas);
    if bands.iter().all(|b| b.slope.is_none()) {
        return None;
    }
    let seed = |what: &str, extra: &str| {
        murk_types::seed::derive(
            p.seed(),
            &murk_types::seed::key(&[what, cx.class.name(), extra]),
            murk_types::seed::Purpose::Bootstrap,
        )
        .bytes()
    };
    let alpha = p.edge_test_alpha();
    let folds = p.edge_test_folds();
    let all: Vec<&RecordingTrials> = recs.iter().collect();
    let fitted: Vec<bool> = bands.iter().map(|b| b.slope.is_some()).collect();
    let (powers, evidence) = if p.compare_laws() {
        (
            fit_powers(&all, &fitted, opts, bin),
            compare_laws(
                recs,
                &fitted,
                opts,
                bin,
                folds as usize,
                seed("law-choice", ""),
            ),
        )
    } else {
        (
            vec![None; fitted.len()],
            Err("the laws were not compared (compare_laws is off): the line is kept".to_string()),
        )
    };
    // False when the laws were not compared (no power law was fitted).
    let all_fitted = powers.iter().zip(&fitted).all(|(p, f)| !*f || p.is_some());
    let wins = all_fitted && matches!(&evidence, Ok(e) if e.gain > 0.0 && e.p <= alpha);
    let bent = wins && p.apply_bend();
    let mut choice = LawChoice {
        chosen: if bent { "power" } else { "linear" }.into(),
        exponents: powers
            .iter()
            .map(|f| f.as_ref().map(|f| f.exponent))
            .collect(),
        exponent_ci95: fold_intervals(
            powers.iter().map(|f| f.as_ref().map(|f| f.exponent)),
            &evidence,
            crate::bend::jackknife_interval,
        )
        .unwrap_or_default(),
        gain_nats_per_recording: evidence.as_ref().map_or(0.0, |e| e.gain),
        recordings_better: evidence.as_ref().map_or(0, |e| e.better as u32),
        recordings: evidence.as_ref().map_or(0, |e| e.recordings as u32),
        p_value: evidence.as_ref().map_or(1.0, |e| e.p),
        alpha,
        folds,
        reason: match (all_fitted, &evidence) {
            (_, Err(e)) if !p.compare_laws() => Some(e.clone()),
            (false, _) => Some("the power law could not be fitted in every band".into()),
            (_, Err(e)) => Some(e.clone()),
            _ if wins && !bent => Some(
                "the power law predicts held-out recordings better, but it is not applied: apply_bend is off (murk fit --bend), since a bend chosen from pooled recordings cannot tell a law that bends from a covariate left out"
                    .into(),
            ),
            _ => None,
        },
        reflectivity: None,
    };
    // The reflectivity term beside the law the comparison above prefers
    // (the power law when it wins, whether or not it is applied).
    // The applied term's fits, and M_ref when its exponent changes with MOR.
    type AppliedTerm = (Vec<Option<crate::bend::ReflectivityFit>>, Option<f64>);
    let refl: Option<AppliedTerm> = deltas.map(|d| {
        // Start from the power law's exponent when it wins.
        let from: Vec<Option<f64>> = powers
            .iter()
            .map(|f| f.as_ref().map(|f| f.exponent).filter(|_| wins))
            .collect();
        let fits = fit_reflectivities(&all, &fitted, &from, None, opts, bin);
        let ev = compare_reflectivity(
            recs,
            &fitted,
            TermComparison::Term { bend: wins },
            opts,
            bin,
            folds as usize,
            seed("reflectivity-choice", ""),
        );
        let all_fitted = fits.iter().zip(&fitted).all(|(f, x)| !*x || f.is_some());
        let refl_wins = all_fitted && matches!(&ev, Ok(e) if e.gain > 0.0 && e.p <= alpha);
        let applied = refl_wins && p.apply_bend();
        choice.reflectivity = Some(ReflectivityChoice {
            chosen: applied,
            exponents: fits
                .iter()
                .map(|f| f.as_ref().map(|f| f.reflectivity_exponent))
                .collect(),
            exponent_ci95: fold_intervals(
                fits.iter().map(|f| f.as_ref().map(|f| f.reflectivity_exponent)),
                &ev,
                crate::bend::reflectivity_jackknife_interval,
            )
            .unwrap_or_else(|| vec![None; fits.len()]),
            references: d
                .ln_reference
                .iter()
                .zip(&fits)
                .map(|(l, f)| f.as_ref().and(l.is_finite().then(|| l.exp())))
                .collect(),
            floor: d.floor,
            gain_nats_per_recording: ev.as_ref().map_or(0.0, |e| e.gain),
            recordings_better: ev.as_ref().map_or(0, |e| e.better as u32),
            recordings: ev.as_ref().map_or(0, |e| e.recordings as u32),
            p_value: ev.as_ref().map_or(1.0, |e| e.p),
            reason: match (all_fitted, &ev) {
                (false, _) => Some(
                    "the reflectivity term could not be fitted in every band (a band's trials in one class, or no slope)"
                        .into(),
                ),
                (_, Err(e)) => Some(e.clone()),
                _ if refl_wins && !applied => Some(
                    "the reflectivity term predicts held-out recordings better, but it is not applied: apply_bend is off (murk fit --bend)"
                        .into(),
                ),
                _ => None,
            },
            mor: None,
        });
        if !refl_wins {
            return (vec![None; fitted.len()], None);
        }
        // The term won: does its exponent change with MOR? `k` at the
        // recordings' geometric mean MOR and its change per unit of
        // `ln MOR`, against one `k`, on the same folds.
        let ln_mor_ref = recs.iter().map(|r| r.mor.ln()).sum::<f64>() / recs.len() as f64;
        let varied = fit_reflectivities(&all, &fitted, &from, Some(ln_mor_ref), opts, bin);
        let ev = compare_reflectivity(
            recs,
            &fitted,
            TermComparison::MorVarying {
                bend: wins,
                ln_mor_ref,
            },
            opts,
            bin,
            folds as usize,
            seed("reflectivity-mor-choice", ""),
        );
        let all_varied = varied.iter().zip(&fitted).all(|(f, x)| !*x || f.is_some());
        let mor_wins = all_varied && matches!(&ev, Ok(e) if e.gain > 0.0 && e.p <= alpha);
        let mor_applied = mor_wins && applied;
        if let Some(r) = choice.reflectivity.as_mut() {
            r.mor = Some(murk_types::ReflectivityMorChoice {
                chosen: mor_applied,
                mor_reference_m: ln_mor_ref.exp(),
                exponents: varied
                    .iter()
                    .map(|f| f.as_ref().map(|f| f.reflectivity_exponent))
                    .collect(),
                per_ln_mor: varied
                    .iter()
                    .map(|f| f.as_ref().map(|f| f.per_ln_mor))
                    .collect(),
                per_ln_mor_ci95: fold_intervals(
                    varied.iter().map(|f| f.as_ref().map(|f| f.per_ln_mor)),
                    &ev,
                    crate::bend::mor_slope_jackknife_interval,
                )
                .unwrap_or_else(|| vec![None; varied.len()]),
                gain_nats_per_recording: ev.as_ref().map_or(0.0, |e| e.gain),
                recordings_better: ev.as_ref().map_or(0, |e| e.better as u32),
                recordings: ev.as_ref().map_or(0, |e| e.recordings as u32),
                p_value: ev.as_ref().map_or(1.0, |e| e.p),
                reason: match (all_varied, &ev) {
                    (false, _) => Some(
                        "the term with an exponent that changes with MOR could not be fitted in every band"
                            .into(),
                    ),
                    (_, Err(e)) => Some(e.clone()),
                    _ if mor_wins && !applied => Some(
                        "an exponent that changes with MOR predicts held-out recordings better, but the term is not applied: apply_bend is off (murk fit --bend)"
                            .into(),
                    ),
                    _ => None,
                },
            });
        }
        match (applied, mor_applied) {
            (false, _) => (vec![None; fitted.len()], None),
            (true, false) => (fits, None),
            (true, true) => (varied, Some(ln_mor_ref.exp())),
        }
    });
    let rs = cx.range_scale;
    let z_line = half_z(opts.edge, line.dropout, line.residual);
    let w = p.mor_bin_width_m();
    for (i, band) in bands.iter_mut().enumerate() {
        if band.slope.is_none() {
            continue;
        }
        let power_band = powers[i].as_ref().filter(|_| bent).and_then(|f| {
            let a = *f.fit.bands[i].slope.as_ref().ok()?;
            let z = half_z(opts.edge, f.fit.dropout, f.fit.residual)?;
            Some((a, f.exponent, f.fit.bands[i].width?, z))
        });
        band.law = power_band.map(|(a, b, _, _)| murk_types::VanishingLaw::Power {
            a,
            b,
            reflectivity: None,
        });
        // An applied reflectivity term replaces the law: its own exponent
        // of MOR (1 when the line was kept), coefficient and edge width.
        let mor_reference_m = refl.as_ref().and_then(|(_, m)| *m);
        let refl_band = refl
            .as_ref()
            .and_then(|(f, _)| f[i].as_ref())
            .zip(deltas)
            .and_then(|(f, d)| {
                let a = *f.fit.bands[i].slope.as_ref().ok()?;
                let ln_ref = d.ln_reference[i];
                ln_ref.is_finite().then_some((f, a, ln_ref.exp(), d.floor))
            });
        if let Some((f, a, reference, floor)) = refl_band {
            band.law = Some(murk_types::VanishingLaw::Power {
                a,
                b: f.exponent,
                reflectivity: Some(murk_types::ReflectivityDependence {
                    exponent: f.reflectivity_exponent,
                    reference,
                    floor,
                    edge_width: f.fit.bands[i].width,
                    exponent_per_ln_mor: mor_reference_m.map(|_| f.per_ln_mor),
                    mor_reference_m,
                }),
            });
        }
        let line_half = |mor: f64| {
            let (s, wd) = (band.slope?, band.edge_width?);
            Some(s * mor * rs * (1.0 + wd * z_line?))
        };
        let law_half = |mor: f64| match power_band {
            Some((a, b, wd, z)) => Some(a * mor.powf(b) * rs * (1.0 + wd * z)),
            None => line_half(mor),
        };
        let mut bins = Vec::new();
        let mut tested = Vec::new();
        for &(k, mean) in means {
            let in_bin: Vec<&RecordingTrials> = recs
                .iter()
                .filter(|r| (r.mor / w).floor() as i64 == k)
                .collect();
            let h = half_survival(
                &in_bin,
                i,
                p.bootstrap_replicates(),
                seed("half-survival", &format!("{i}/{k}")),
            );
            if h.trials == 0 {
                continue;
            }
            let lm = line_half(mean);
            let am = match refl_band {
                // Each return its own distance: the law's crossing over
                // the bin's own returns, pooled by range as the data's.
                Some((f, ..)) => crate::bend::predicted_half_crossing(&in_bin, i, |r, delta, u| {
                    let ln_mor = r.mor.ln();
                    let shift = (1.0 - f.exponent) * ln_mor - f.term().at(ln_mor) * delta;
                    f.fit.keep_probability(opts, i, (u.ln() + shift).exp())
                })
                .ok(),
                None => law_half(mean),
            };
            if let (Ok(r), Ok(ci), Some(l)) = (&h.range, &h.ci95, lm) {
                tested.push((*r, *ci, l));
            }
            bins.push(SurvivalBin {
                mor_m: mean,
                mor_lo_m: k as f64 * w,
                mor_hi_m: (k + 1) as f64 * w,
                recordings: h.recordings as u32,
                trials: h.trials,
                half_survival_range_m: h.range.as_ref().ok().copied(),
                ci95: h.ci95.as_ref().ok().map(|&[low, high]| Interval {
                    low,
                    high,
                    level: 0.95,
                    method: "bootstrap over recordings".into(),
                }),
                line_m: lm,
                law_m: am,
                reason: h.range.err().or(h.ci95.err()),
            });
        }
        band.survival_bins = bins;
        band.lack_of_fit =
            lack_of_fit(&tested).map(|(statistic, dof, p_value, worst_ratio)| LackOfFit {
                statistic,
                dof,
                bins: tested.len() as u32,
                p_value,
                alpha,
                lack_of_fit: p_value <= alpha,
                worst_ratio,
            });
    }
    Some(choice)
}

/// Fits every coefficient of one weather.
pub fn weather(
    acc: &WeatherAcc,
    cx: &WeatherContext<'_>,
) -> (WeatherCoefficients, WeatherDiagnostics) {
    let p = cx.params;
    let bands = p.bands();
    let sweep = p.sweep_bands();
    let rs = cx.range_scale;

    // Do the weather's near returns replace the returns it loses? Then the
    // returns they hide are lost ones, and every estimator below counts
    // them so (see `crate::occlusion`).
    let occlusion = crate::occlusion::test(acc, p.edge_test_alpha(), p.noise_reach_m());
    let replaced_acc;
    let acc = if occlusion.replaced {
        replaced_acc = crate::occlusion::with_hidden_as_lost(acc);
        &replaced_acc
    } else {
        acc
    };

    // Survival ML over the table's bands.
    let opts = SurvivalOptions {
        edge: p.edge(),
        shared_width: p.shared_edge_width(),
        fixed_dropout: if p.free_dropout() {
            None
        } else {
            Some(cx.dropout_clear.unwrap_or(0.01))
        },
        dropout_init: cx.dropout_clear.unwrap_or(0.01),
        min_trials: p.min_points_per_bin(),
        min_beyond: p.censor_min_points(),
    };
    let obs: Vec<_> = bands
        .iter()
        .map(|b| band_obs(acc, cx.partition, b))
        .collect();
    let ml: Option<SurvivalResult> = fit_survival(&obs, &opts);
    let ml_slope = |i: usize| {
        ml.as_ref()
            .and_then(|m| m.bands[i].slope.as_ref().ok().copied())
    };
    // Each recording's share of the likelihood: intervals over recordings
    // and the held-out test of the edge against range alone.
    let classes: Vec<_> = bands.iter().map(|b| cx.partition.classes_in(b)).collect();
    // The reflectivity classes' offsets from their band's reference, when a
    // reflectivity term is fitted.
    let deltas = reflectivity_deltas(acc, cx, &classes);
    let per_recording: Vec<RecordingTrials> = acc
        .rows
        .iter()
        .map(|r| RecordingTrials {
            bands: classes
                .iter()
                .map(|c| acc.survival.cell_observations(&r.survival, c.clone()))
                .collect(),
            clear: classes
                .iter()
                .map(|c| {
                    acc.survival
                        .cell_clear_rates(&r.survival, &r.survival_clear, c.clone())
                })
                .collect(),
            ln_mor_scaled: r.ln_mor_scaled,
            mor: r.mor,
            classes: match &deltas {
                None => Vec::new(),
                Some(d) => classes
                    .iter()
                    .map(|cs| {
                        cs.clone()
                            .filter(|&c| d.delta[c].is_finite())
                            .filter_map(|c| {
                                let o = acc.survival.cell_observations(&r.survival, c..c + 1);
                                (!o.is_empty()).then(|| (d.delta[c], o))
                            })
                            .collect()
                    })
                    .collect(),
            },
        })
        .collect();
    let (robust, evidence) = match &ml {
        Some(m) => {
            let clusters: Vec<Vec<Vec<crate::survival::Obs>>> =
                per_recording.iter().map(|r| r.bands.clone()).collect();
            let remove = |g: usize, h: &mut crate::survival::SurvivalHistogram| {
                h.add_cells(&acc.rows[g].survival, -1)
            };
            (
                robust_intervals(
                    m,
                    robust_covariance(m, &clusters, &opts).as_ref(),
                    &opts,
                    bands.len(),
                ),
                edge_test(
                    &acc.survival,
                    &per_recording,
                    &classes,
                    &remove,
                    &opts,
                    p.edge_test_folds() as usize,
                    murk_types::seed::derive(
                        p.seed(),
                        &murk_types::seed::key(&["edge-test", cx.class.name()]),
                        murk_types::seed::Purpose::Bootstrap,
                    )
                    .bytes(),
                ),
            )
        }
        None => (RobustIntervals::default(), vec![]),
    };
    let interval = |[low, high]: [f64; 2]| Interval {
        low,
        high,
        level: 0.95,
        method: "cluster-robust over recordings (leave-one-recording-out, CR3)".into(),
    };
    let reading_var = cx.mor_reading_variance.as_ref().ok().copied();
    let t_recordings = crate::survival::student_t_975((acc.rows.len() as f64 - 1.0).max(1.0));
    let alpha = p.edge_test_alpha();
    let edge_record = |e: &EdgeEvidence| EdgeTest {
        gain_nats_per_recording: e.gain,
        recordings_better: e.better as u32,
        recordings: e.recordings as u32,
        p_value: e.p,
        alpha,
        gain_over_constant_nats_per_recording: e.gain_constant,
        p_value_over_constant: e.p_constant,
        mor_spread: e.mor_spread,
        p_value_range_better: Some(e.p_range),
        basis: crate::survival::EDGE_TEST_BASIS.into(),
        folds: p.edge_test_folds(),
        edge_seen: e.verdict(alpha).is_ok(),
    };

    let vanishing_slope: Vec<SlopeBand> = bands
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let trials: u64 = obs[i].iter().map(|o| o.total as u64).sum();
            match &ml {
                Some(m) => {
                    let test = evidence.get(i);
                    let mut slope = m.bands[i].slope.clone();
                    // Why the held-out test does not confirm the edge, if
                    // it does not: the slope is nulled with it when
                    // `require_edge` is on, kept with it as a warning
                    // otherwise.
                    let mut verdict: Result<(), String> = Ok(());
                    if let (Ok(_), Some(t)) = (&slope, test) {
                        match t {
                            Ok(e) => verdict = e.verdict(alpha),
                            Err(why) => verdict = Err(format!("no edge can be shown: {why}")),
                        }
                    }
                    let mut note = None;
                    if let Err(v) = verdict {
                        if p.require_edge() {
                            slope = Err(v);
                        } else {
                            note = Some(format!(
                                "slope kept although the held-out edge test does not confirm it (require_edge off): {v}"
                            ));
                        }
                    }
                    let seen = slope.is_ok();
                    SlopeBand {
                        reflectivity_min: b.min,
                        reflectivity_max: b.max,
                        slope: slope.as_ref().ok().copied(),
                        points: trials,
                        reason: slope.as_ref().err().cloned().or(note),
                        std_error: robust.slopes[i].map(|r| r.0).filter(|_| seen),
                        std_error_independent: m.bands[i].std_error.filter(|_| seen),
                        ci95: robust.slopes[i]
                            .filter(|_| seen)
                            .map(|(_, ci)| interval(ci)),
                        edge_test: test
                            .and_then(|t| t.as_ref().ok())
                            .map(edge_record),
                        edge_width: m.bands[i].width,
                        edge_width_ci95: robust.widths.get(i).copied().flatten().map(&interval),
                        edge_width_corrected: m.bands[i]
                            .width
                            .zip(reading_var)
                            .map(|(w, v)| murk_types::deconvolve_edge_width(w, v.variance)),
                        edge_width_corrected_ci95: m.bands[i]
                            .width
                            .zip(robust.widths.get(i).copied().flatten())
                            .zip(reading_var.and_then(|v| Some((v.variance, v.std_error?))))
                            .map(|((w, ci), (v, se))| {
                                interval(deconvolve_interval(w, ci, v, t_recordings * se))
                            }),
                        mor_bins: vec![],
                        law: None,
                        survival_bins: vec![],
                        lack_of_fit: None,
                    }
                }
                None => SlopeBand {
                    reflectivity_min: b.min,
                    reflectivity_max: b.max,
                    slope: None,
                    points: trials,
                    reason: Some(
                        precheck(&obs[i], p.min_points_per_bin())
                            .err()
                            .unwrap_or_else(|| {
                                "the survival likelihood has no finite optimum".into()
                            }),
                    ),
                    std_error: None,
                    std_error_independent: None,
                    ci95: None,
                    edge_test: None,
                    edge_width: None,
                    edge_width_ci95: None,
                    edge_width_corrected: None,
                    edge_width_corrected_ci95: None,
                    mor_bins: vec![],
                    law: None,
                    survival_bins: vec![],
                    lack_of_fit: None,
                },
            }
        })
        .collect();

    // The seed's quantile estimator, per band and over all reflectivities.
    let means = bin_means(acc, p.mor_bin_width_m());

    // A law that bends, chosen against the line on held-out recordings,
    // and the per-MOR-bin 50 % ranges with the line's lack of fit.
    let mut vanishing_slope = vanishing_slope;
    let law_choice = ml.as_ref().and_then(|m| {
        bend_and_check(
            &mut vanishing_slope,
            m,
            &Trials {
                recordings: &per_recording,
                bin: Binning {
                    step: acc.survival.step(),
                    anchor: acc.survival.anchor(),
                },
                deltas: deltas.as_ref(),
            },
            &means,
            &opts,
            cx,
        )
    });
    let vanishing_slope_q99: Vec<SlopeBand> = bands
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let cells = BandCells::new(cx.reference, b);
            let qs = band_quantiles(acc, &means, &cells, p, ml_slope(i), rs);
            let slope = quantile_slope(&qs, rs);
            let interval = quantile_slope_interval(&qs, rs).ok();
            SlopeBand {
                reflectivity_min: b.min,
                reflectivity_max: b.max,
                slope: slope.as_ref().ok().copied(),
                points: qs.iter().filter(|q| q.used).map(|q| q.points).sum(),
                reason: slope.err(),
                std_error: interval.map(|(se, _)| se),
                std_error_independent: None,
                ci95: interval.map(|(_, [low, high])| Interval {
                    low,
                    high,
                    level: 0.95,
                    method: "grouped jackknife over the used MOR bins of recordings (Student t on bins − 1 df)".into(),
                }),
                edge_test: None,
                edge_width: None,
                edge_width_ci95: None,
                edge_width_corrected: None,
                edge_width_corrected_ci95: None,
                mor_bins: qs.iter().map(to_mor_bin).collect(),
                law: None,
                survival_bins: vec![],
                lack_of_fit: None,
            }
        })
        .collect();
    let everything = Band {
        min: f64::NEG_INFINITY,
        max: None,
    };
    let all_cells = BandCells::new(cx.reference, &everything);
    let all_q = band_quantiles(acc, &means, &all_cells, p, None, rs);
    let all_q99 = quantile_slope(&all_q, rs).ok();

    // Figure 27: both estimators over the sweep bands; the ML one only
    // where some band of the table showed an edge (it reuses that fit's
    // width, ε and π, which describe no edge otherwise).
    let edge_seen = vanishing_slope.iter().any(|b| b.slope.is_some());
    let reflectivity_sweep: Vec<SweepBand> = sweep
        .iter()
        .map(|b| {
            let o = band_obs(acc, cx.partition, b);
            let trials: u64 = o.iter().map(|x| x.total as u64).sum();
            let slope = ml.as_ref().filter(|_| edge_seen).and_then(|m| {
                let w = m.bands.iter().find_map(|x| x.width)?;
                fit_slope_only(
                    &o,
                    p.edge(),
                    w,
                    m.dropout,
                    m.residual,
                    p.min_points_per_bin(),
                    p.censor_min_points(),
                )
                .ok()
            });
            let cells = BandCells::new(cx.reference, b);
            let qs = band_quantiles(acc, &means, &cells, p, slope, rs);
            SweepBand {
                reflectivity_min: b.min,
                reflectivity_max: b.max,
                slope,
                slope_q99: quantile_slope(&qs, rs).ok(),
                points: trials,
            }
        })
        .collect();

    // No-change rate and its bootstrap.
    let rows: Vec<(u64, u64)> = acc.rows.iter().map(|r| (r.kept, r.total)).collect();
    let (k, t) = rows
        .iter()
        .fold((0u64, 0u64), |a, r| (a.0 + r.0, a.1 + r.1));
    let (no_change_rate, no_change_rate_reason) = if t > 0 {
        (Some(k as f64 / t as f64), None)
    } else {
        (None, Some("the reference has no return".to_string()))
    };
    let no_change_rate_uncertainty = bootstrap_rate(
        &rows,
        p.bootstrap_replicates(),
        p.seed(),
        &format!("lidar/{}", cx.class.name()),
    )
    .map(uncertainty);

    // Ghost and ring laws and counts.
    let mors: Vec<f64> = acc.rows.iter().map(|r| r.mor).collect();
    let ghost_counts: Vec<(&RecordingRow, u64)> = acc.rows.iter().map(|r| (r, r.ghosts)).collect();
    let ring_counts: Vec<(&RecordingRow, u64)> = acc.rows.iter().map(|r| (r, r.rings)).collect();
    let floor = p.reflectivity_floor();
    let ghost = noise_law(
        "ghost",
        cx.class.name(),
        &acc.ghost,
        p.ghost_range_m(),
        floor,
        &ghost_counts,
        p,
        occlusion.replaced,
    );
    let ring = noise_law(
        "ring",
        cx.class.name(),
        &acc.ring,
        p.ring_range_m(),
        floor,
        &ring_counts,
        p,
        occlusion.replaced,
    );

    let (mor_from_rain_rate, mor_from_rain_rate_reason) = match &cx.rain {
        Some(Ok(c)) => (Some(c.clone()), None),
        Some(Err(e)) => (None, Some(e.clone())),
        None => (None, None),
    };
    let coefficients = WeatherCoefficients {
        recordings: acc.rows.len() as u32,
        mor_min_m: mors.iter().copied().reduce(f64::min),
        mor_max_m: mors.iter().copied().reduce(f64::max),
        vanishing_slope,
        vanishing_slope_q99,
        quantile: p.quantile(),
        mor_bins: all_q.iter().map(to_mor_bin).collect(),
        survival: ml.as_ref().map(|m| SurvivalFit {
            edge: p.edge(),
            dropout: m.dropout,
            dropout_clear: cx.dropout_clear,
            dropout_ci95: robust.dropout.map(&interval),
            residual: m.residual,
            neg_log_likelihood: m.nll,
            trials: m.trials,
            mor_reading_noise: reading_var.map(|v| v.variance.sqrt()),
            mor_reading_noise_reason: cx.mor_reading_variance.as_ref().err().cloned(),
        }),
        no_change_rate,
        no_change_rate_uncertainty,
        no_change_rate_reason,
        ghost: ghost.as_ref().ok().cloned(),
        ghost_reason: ghost.err(),
        ghost_returns: return_moments(&acc.ghost),
        ring: ring.as_ref().ok().cloned(),
        ring_reason: ring.err(),
        ring_returns: return_moments(&acc.ring),
        mor_from_rain_rate,
        mor_from_rain_rate_reason,
        reflectivity_sweep,
        extensions: Vec::new(),
        law_choice,
        occlusion: Some(occlusion),
    };
    let diagnostics = WeatherDiagnostics {
        mor: mors,
        density: RangeMorDensity::new(acc, &means, &all_cells, p.mor_bin_width_m()),
        q99_all_slope: all_q99,
        ghost: NoiseHistograms::from_acc(&acc.ghost),
        ring: NoiseHistograms::from_acc(&acc.ring),
    };
    (coefficients, diagnostics)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{SeedableRng, rngs::ChaCha8Rng};
    use rand_distr::{Distribution, Normal};

    fn sample(readings: &[f64], mor: f64) -> RainSample {
        RainSample {
            readings: readings.to_vec(),
            mor,
        }
    }

    #[test]
    fn exact_points_give_the_line_and_no_correction() {
        let s: Vec<RainSample> = [0.5, 5.0, 20.0, 60.0]
            .iter()
            .map(|r| sample(&[*r, *r], -0.8308 * r + 159.16))
            .collect();
        let c = rain_conversion(&s).unwrap();
        assert!((c.slope + 0.8308).abs() < 1e-9 && (c.intercept - 159.16).abs() < 1e-9);
        assert_eq!(c.slope_ols, None);
        assert_eq!(c.rain_rate_reliability, Some(1.0));
        assert!((c.zero_mor_rain_rate.unwrap() - 159.16 / 0.8308).abs() < 1e-6);
        assert!(rain_conversion(&s[..1]).is_err());
    }

    #[test]
    fn gauge_noise_is_corrected_where_ols_flattens_the_line() {
        // 40 recordings, rates 1–100 mm/h, two gauges with 25 % relative
        // noise, MOR exactly on the line: OLS is diluted, the corrected
        // slope is not (averaged over 20 seeds, within 3 %).
        let (mut ols, mut fixed) = (0.0, 0.0);
        for seed in 0..20 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let noise = Normal::new(0.0, 0.25).unwrap();
            let s: Vec<RainSample> = (0..40)
                .map(|i| {
                    let r = 1.0 + 99.0 * (i as f64 / 39.0).powi(2);
                    let g = [
                        r * (1.0 + noise.sample(&mut rng)),
                        r * (1.0 + noise.sample(&mut rng)),
                    ];
                    sample(&g, -0.8308 * r + 159.16)
                })
                .collect();
            let c = rain_conversion(&s).unwrap();
            ols += c.slope_ols.unwrap() / 20.0;
            fixed += c.slope / 20.0;
            assert!(c.rain_rate_reliability.unwrap() < 1.0);
        }
        assert!(ols > -0.8308 * 0.97, "OLS should be diluted: {ols}");
        assert!((fixed / -0.8308 - 1.0).abs() < 0.03, "corrected {fixed}");
    }

    #[test]
    fn mor_reading_variance_is_the_sensors_scatter_over_their_number() {
        // 300 recordings, MOR 20–400 m, read by two or three sensors with 7.5 %
        // log-normal noise each (a third of them by three): the variance of a
        // recording's mean reading is σ²/k, averaged (5 % at this size).
        let sigma = 0.075f64;
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let noise = Normal::new(0.0, sigma).unwrap();
        let readings: Vec<Vec<f64>> = (0..300)
            .map(|i| {
                let mor = 20.0 * 20f64.powf(i as f64 / 299.0);
                let k = if i % 3 == 0 { 3 } else { 2 };
                (0..k).map(|_| mor * noise.sample(&mut rng).exp()).collect()
            })
            .collect();
        let want = sigma * sigma * (100.0 / 3.0 + 200.0 / 2.0) / 300.0;
        let got = mor_reading_variance(&readings).unwrap();
        assert!((got.variance / want - 1.0).abs() < 0.1, "{got:?} vs {want}");
        // Normal theory: σ̂² on 400 degrees of freedom has a relative
        // standard error of √(2/400) ≈ 7 %; the jackknife agrees.
        let rel = got.std_error.unwrap() / got.variance;
        assert!((0.05..0.1).contains(&rel), "{rel}");
        // Exact readings: nothing to take out.
        let exact: Vec<Vec<f64>> = (1..20).map(|i| vec![i as f64 * 10.0; 2]).collect();
        let e = mor_reading_variance(&exact).unwrap();
        assert_eq!((e.variance, e.std_error), (0.0, Some(0.0)));
        // One sensor, or a recording without a reading: cannot tell.
        let one: Vec<Vec<f64>> = (1..20).map(|i| vec![i as f64 * 10.0]).collect();
        assert!(
            mor_reading_variance(&one)
                .unwrap_err()
                .contains("one visibility sensor")
        );
        let mut gap = exact.clone();
        gap.push(vec![]);
        assert!(
            mor_reading_variance(&gap)
                .unwrap_err()
                .contains("rain conversion")
        );
        assert!(mor_reading_variance(&[vec![50.0, -1.0]]).is_err());
    }

    #[test]
    fn deconvolved_width_undoes_the_reading_noise() {
        // A probit edge of width w seen through N(0, v) shifts of the edge is
        // a probit edge of width √(w² + v): deconvolution gives w back.
        let (w, v) = (0.08f64, 0.053f64.powi(2));
        assert!((murk_types::deconvolve_edge_width((w * w + v).sqrt(), v) - w).abs() < 1e-12);
        // The survival over the readings, averaged over the reading error
        // by quadrature (edge at 1): its 84.1 % and 15.9 % points, one
        // standard width either side of the edge, give the apparent width,
        // which is √(w² + v) to within 2 %.
        let sf = |x: f64| {
            let n = 4001;
            let (mut acc, mut wsum) = (0.0, 0.0);
            for j in 0..n {
                let z = -6.0 + 12.0 * j as f64 / (n - 1) as f64;
                let g = (-0.5 * z * z).exp();
                let d = (-(v.sqrt()) * z).exp();
                acc += g * murk_types::EdgeShape::Probit.sf((x - d) / (w * d));
                wsum += g;
            }
            acc / wsum
        };
        let solve = |p: f64| {
            let (mut lo, mut hi) = (0.5, 2.0);
            for _ in 0..100 {
                let mid = 0.5 * (lo + hi);
                if sf(mid) > p { lo = mid } else { hi = mid }
            }
            0.5 * (lo + hi)
        };
        let (x84, x50, x16) = (solve(0.841_344_75), solve(0.5), solve(0.158_655_25));
        let apparent = (x16 - x84) / (2.0 * x50);
        let want = (w * w + v).sqrt();
        assert!((apparent / want - 1.0).abs() < 0.02, "{apparent} vs {want}");
        assert!((murk_types::deconvolve_edge_width(apparent, v) / w - 1.0).abs() < 0.03);
        assert_eq!(murk_types::deconvolve_edge_width(0.03, v), 0.0);
        assert_eq!(murk_types::deconvolve_edge_width(w, 0.0), w);
        // An exactly known variance maps the ends; an uncertain one widens
        // the interval on both sides.
        let wa = (w * w + v).sqrt();
        let ci = [wa * 0.9, wa * 1.1];
        let [lo, hi] = deconvolve_interval(wa, ci, v, 2.0 * 0.0);
        assert!((lo - murk_types::deconvolve_edge_width(ci[0], v)).abs() < 1e-12);
        assert!((hi - murk_types::deconvolve_edge_width(ci[1], v)).abs() < 1e-12);
        let [lo2, hi2] = deconvolve_interval(wa, ci, v, 2.0 * 0.3 * v);
        assert!(lo2 < lo && hi2 > hi, "{lo2} {hi2} vs {lo} {hi}");
    }

    #[test]
    fn one_gauge_everywhere_is_plain_least_squares() {
        let s: Vec<RainSample> = [1.0, 2.0, 4.0, 8.0]
            .iter()
            .map(|r| sample(&[*r], -0.5 * r + 100.0 + if *r > 3.0 { 1.0 } else { -1.0 }))
            .collect();
        let c = rain_conversion(&s).unwrap();
        let (a, _) = line(
            &[1.0, 2.0, 4.0, 8.0],
            &s.iter().map(|s| s.mor).collect::<Vec<_>>(),
        )
        .unwrap();
        assert_eq!(c.slope, a);
        assert_eq!(c.rain_rate_reliability, None);
    }
}
