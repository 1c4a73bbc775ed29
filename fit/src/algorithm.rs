//! The fit as a whole: checked parameters + campaign → [`FittedTable`].

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use murk_campaign::Campaign;
use murk_types::{
    ClearCoefficients, CoefficientTable, CountUnit, ExcludedRecording, InputDigest, Provenance,
    RadarCoefficients, SensorGeometry, TABLE_FORMAT, TableLidar, WeatherClass,
};
use rayon::prelude::*;

use crate::accumulate::WeatherAcc;
use crate::assemble::{WeatherContext, uncertainty, weather};
use crate::diagnostics::Diagnostics;
use crate::driver::{FitInputs, RecordingInput, relative, sha256_hex};
use crate::radar::{Detections, RadarReference};
use crate::reference::ClearReference;
use crate::state::{degraded_jobs, partition};
use crate::stats::bootstrap::bootstrap_rate;
use crate::{FitError, FitState, FitValidParams};

/// Name and version written in the table's provenance.
pub const TOOL: &str = concat!("murk-fit ", env!("CARGO_PKG_VERSION"));

/// A fitted campaign: the coefficient table and the data behind its figures.
#[derive(Debug, Clone, PartialEq)]
pub struct FittedTable {
    table: CoefficientTable,
    diagnostics: Diagnostics,
}

impl FitValidParams {
    /// Fits the coefficient table of `campaign` (its rules and review decide
    /// the recordings).
    pub fn fit(&self, campaign: &Campaign) -> Result<FittedTable, FitError> {
        self.fit_inputs(&FitInputs::from_campaign(campaign))
    }

    /// Fits the coefficient table of already-selected inputs.
    pub fn fit_inputs(&self, inputs: &FitInputs) -> Result<FittedTable, FitError> {
        fit_inputs(inputs, self)
    }
}

/// The one-shot fit is map over everything, then finish: one code path
/// with the distributed fit ([`crate::FitState`]), the clear images
/// released once the reference is built ([`FitState::fit_all`]).
fn fit_inputs(inputs: &FitInputs, params: &FitValidParams) -> Result<FittedTable, FitError> {
    FitState::fit_all(inputs, params)
}

/// What a complete [`FitState`] hands to [`assemble_table`].
pub(crate) struct Parts<'a> {
    pub inputs: &'a FitInputs,
    pub params: &'a FitValidParams,
    /// The table's geometry and the measured one's warnings.
    pub geometry: (SensorGeometry, Vec<String>),
    pub reference: &'a ClearReference,
    /// Clear recordings left out (no point), in campaign order.
    pub empty_clear: Vec<ExcludedRecording>,
    /// SHA-256 of every LiDAR file read.
    pub lidar_digests: Vec<(PathBuf, String)>,
    /// Degraded recordings left out (no point), positions ascending.
    pub empty_degraded: Vec<usize>,
    pub accs: &'a BTreeMap<WeatherClass, WeatherAcc>,
    pub radar: &'a BTreeMap<usize, (Detections, String)>,
    pub metadata: &'a [(PathBuf, String)],
}

/// The table of a complete fit's statistics.
pub(crate) fn assemble_table(parts: Parts<'_>) -> Result<FittedTable, FitError> {
    let Parts {
        inputs,
        params,
        geometry: (geometry, geometry_warnings),
        reference,
        empty_clear,
        lidar_digests: mut digests,
        empty_degraded,
        accs,
        radar: radar_detections,
        metadata,
    } = parts;
    let range_scale = inputs.lidar.range_scale;
    let clear: Vec<&RecordingInput> = inputs
        .recordings
        .iter()
        .filter(|r| r.class == WeatherClass::Clear)
        .collect();
    // Clear recordings the reference is built from (not the empty ones).
    let clear_used = clear.len() - empty_clear.len();
    let loo = reference.leave_one_out();
    let (lk, lt) = loo.iter().fold((0u64, 0u64), |a, r| (a.0 + r.0, a.1 + r.1));
    let clear_rate = (clear_used >= 2 && lt > 0).then(|| lk as f64 / lt as f64);
    let dropout_clear = clear_rate.map(|r| 1.0 - r);

    let degraded = degraded_jobs(inputs);
    let conversion = degraded.conversion;
    let partition = partition(params);
    let mut excluded = empty_clear;
    excluded.extend(degraded.excluded.into_iter().map(|(_, e)| e));
    excluded.extend(
        empty_degraded
            .into_iter()
            .map(|i| crate::driver::empty_recording(&inputs.recordings[i])),
    );

    let mut weathers = BTreeMap::new();
    let mut diagnostics = Diagnostics::default();
    let mut absent = inputs.absent.clone();
    for class in WeatherClass::DEGRADED {
        let Some(acc) = accs.get(&class) else {
            absent.entry(class).or_insert_with(|| {
                "every selected recording of this weather was excluded (see excluded_recordings)"
                    .into()
            });
            continue;
        };
        let cx = WeatherContext {
            class,
            reference,
            partition: &partition,
            params,
            range_scale,
            dropout_clear,
            rain: (class == WeatherClass::Rain)
                .then(|| conversion.clone())
                .flatten(),
            mor_reading_variance: {
                // The recordings the weather's fit holds (not the excluded
                // ones), in campaign order (a row's index is its job's).
                let mut held: Vec<usize> = acc.rows.iter().map(|r| r.index).collect();
                held.sort_unstable();
                crate::assemble::mor_reading_variance(
                    &held
                        .iter()
                        .map(|&j| degraded.jobs[j].input.mor_readings.clone())
                        .collect::<Vec<_>>(),
                )
            },
        };
        let (c, d) = weather(acc, &cx);
        weathers.insert(class, c);
        diagnostics.weathers.insert(class, d);
    }
    diagnostics.clear_mor = clear.iter().filter_map(|r| r.mor).collect();

    let clear_coefficients = ClearCoefficients {
        recordings: clear_used as u32,
        reference_cells: reference.present().len() as u64,
        no_change_rate: clear_rate,
        no_change_rate_uncertainty: bootstrap_rate(
            loo,
            params.bootstrap_replicates(),
            params.seed(),
            "lidar/clear",
        )
        .map(uncertainty),
        no_change_rate_reason: clear_rate
            .is_none()
            .then(|| "a single clear recording: no reference can be built without it".into()),
    };

    let (radar, radar_digests) = radar(inputs, params, radar_detections)?;
    digests.extend(radar_digests);
    digests.extend(metadata.iter().cloned());

    // Provenance: every file read, sorted by relative path.
    let mut inputs_list: Vec<InputDigest> = digests
        .into_iter()
        .map(|(p, d)| InputDigest {
            path: relative(&inputs.dir, &p),
            sha256: d,
        })
        .collect();
    inputs_list.sort_by(|a, b| a.path.cmp(&b.path));
    inputs_list.dedup();
    let mut combined = String::new();
    for i in &inputs_list {
        let _ = writeln!(combined, "{}  {}", i.sha256, i.path);
    }
    let table = CoefficientTable {
        format: TABLE_FORMAT.to_string(),
        campaign: inputs.name.clone(),
        lidar: TableLidar {
            model: inputs.lidar.model.clone(),
            range_scale,
            geometry: Some(geometry),
            warnings: geometry_warnings,
            count_unit: CountUnit::PerRevolution,
        },
        weathers,
        absent,
        clear: Some(clear_coefficients),
        radar,
        excluded_recordings: excluded,
        provenance: Provenance {
            tool: TOOL.to_string(),
            inputs_sha256: sha256_hex(combined.as_bytes()),
            inputs: inputs_list,
            parameters: params.to_json(),
        },
    };
    table.validate()?;
    Ok(FittedTable { table, diagnostics })
}

type Digests = Vec<(PathBuf, String)>;

fn radar(
    inputs: &FitInputs,
    params: &FitValidParams,
    read: &BTreeMap<usize, (Detections, String)>,
) -> Result<(Option<RadarCoefficients>, Digests), FitError> {
    let with_radar: Vec<&RecordingInput> = read.keys().map(|&i| &inputs.recordings[i]).collect();
    if with_radar.is_empty() {
        return Ok((None, Vec::new()));
    }
    let mut det = Vec::with_capacity(read.len());
    let mut digests = Vec::new();
    for (r, (d, h)) in with_radar.iter().zip(read.values()) {
        digests.push((r.radar.clone().unwrap_or_default(), h.clone()));
        det.push(d.clone());
    }
    let tol = params.radar_tolerance_m();
    let clear_idx: Vec<usize> = (0..with_radar.len())
        .filter(|&i| with_radar[i].class == WeatherClass::Clear)
        .collect();
    let mut out = RadarCoefficients {
        no_change_rate: BTreeMap::new(),
        uncertainty: BTreeMap::new(),
        recordings: BTreeMap::new(),
        absent: BTreeMap::new(),
        tolerance_m: Some(tol),
    };
    if clear_idx.is_empty() {
        for class in WeatherClass::ALL {
            out.absent.insert(
                class,
                "no clear recording has a radar file: no radar reference".into(),
            );
        }
        return Ok((Some(out), digests));
    }
    let clear_det: Vec<Detections> = clear_idx.iter().map(|&i| det[i].clone()).collect();
    let radar_err = |reason: String| FitError::Radar {
        path: inputs.dir.join("radar"),
        line: 0,
        reason,
    };
    let (reference, baseline) =
        RadarReference::build(&clear_det, tol, params.radar_min_presence()).map_err(radar_err)?;
    for class in WeatherClass::ALL {
        let rows: Vec<(u64, u64)> = if class == WeatherClass::Clear {
            if clear_idx.len() < 2 {
                out.absent.insert(
                    class,
                    "a single clear radar recording: no reference can be built without it".into(),
                );
                continue;
            }
            baseline.clone()
        } else {
            let idx: Vec<usize> = (0..with_radar.len())
                .filter(|&i| with_radar[i].class == class)
                .collect();
            if idx.is_empty() {
                out.absent.insert(
                    class,
                    "no recording of this weather has a radar file".into(),
                );
                continue;
            }
            idx.par_iter()
                .map(|&i| reference.score(&det[i], tol))
                .collect::<Result<Vec<_>, String>>()
                .map_err(radar_err)?
        };
        let (k, t) = rows
            .iter()
            .fold((0u64, 0u64), |a, r| (a.0 + r.0, a.1 + r.1));
        if t == 0 {
            out.absent.insert(
                class,
                "the radar reference is empty (no recurring detection)".into(),
            );
            continue;
        }
        out.no_change_rate.insert(class, k as f64 / t as f64);
        out.recordings.insert(class, rows.len() as u32);
        if let Some(u) = bootstrap_rate(
            &rows,
            params.bootstrap_replicates(),
            params.seed(),
            &format!("radar/{}", class.name()),
        ) {
            out.uncertainty.insert(class, uncertainty(u));
        }
    }
    Ok((Some(out), digests))
}

impl FittedTable {
    /// The coefficient table.
    pub fn table(&self) -> &CoefficientTable {
        &self.table
    }

    /// The data behind the figures.
    pub fn diagnostics(&self) -> &Diagnostics {
        &self.diagnostics
    }

    /// The table as JSON (byte-identical for identical inputs and parameters).
    pub fn to_json(&self) -> Result<String, FitError> {
        Ok(self.table.to_json()?)
    }

    /// Writes the table atomically: a temporary file in the same folder,
    /// flushed, then renamed over `path`.
    pub fn write(&self, path: &Path) -> Result<(), FitError> {
        write_atomic(path, self.to_json()?.as_bytes())
    }

    /// A short human-readable summary: per weather, recordings, slopes (ML and
    /// quantile), censored bins and the no-change rate.
    pub fn summary(&self) -> String {
        let t = &self.table;
        let mut s = String::new();
        let _ = writeln!(s, "campaign {} ({})", t.campaign, t.lidar.model);
        if let Some(g) = &t.lidar.geometry {
            let _ = writeln!(
                s,
                "  lidar geometry: {} azimuth step {:.4}° (declared {}), {} rings, from {} clear recordings ({} scans)",
                g.source,
                g.azimuth_step_deg,
                g.declared_azimuth_step_deg,
                g.rings.len(),
                g.recordings,
                g.frames
            );
        }
        for w in &t.lidar.warnings {
            let _ = writeln!(s, "  warning: {w}");
        }
        if let Some(c) = &t.clear {
            let _ = writeln!(
                s,
                "  clear: {} recordings, {} reference cells, no-change rate {}",
                c.recordings,
                c.reference_cells,
                fmt_opt(c.no_change_rate, 3)
            );
        }
        for (w, c) in &t.weathers {
            let _ = writeln!(
                s,
                "  {w}: {} recordings, MOR {}–{} m, no-change rate {}",
                c.recordings,
                fmt_opt(c.mor_min_m, 0),
                fmt_opt(c.mor_max_m, 0),
                fmt_opt(c.no_change_rate, 3)
            );
            for (ml, q) in c.vanishing_slope.iter().zip(&c.vanishing_slope_q99) {
                let band = match ml.reflectivity_max {
                    Some(m) => format!("[{}, {})", ml.reflectivity_min, m),
                    None => format!("[{}, ∞)", ml.reflectivity_min),
                };
                let censored = q.mor_bins.iter().filter(|b| b.censored).count();
                let _ = writeln!(
                    s,
                    "    reflectivity {band:<10} slope ML {} (q{} {}), {censored} of {} MOR bins censored",
                    fmt_opt(ml.slope, 4),
                    (c.quantile * 100.0).round(),
                    fmt_opt(q.slope, 4),
                    q.mor_bins.len()
                );
                if let Some(r) = &ml.reason {
                    let _ = writeln!(s, "      ML: {r}");
                }
                if let Some(l) = &ml.law {
                    let _ = writeln!(s, "      applied law: {}", l.describe());
                }
                if let Some(f) = &ml.lack_of_fit {
                    let _ = writeln!(
                        s,
                        "      lack of fit of the line against {} per-MOR-bin 50 % ranges: {} (χ² {:.1} on {} dof, p {:.3}; worst bin at {:.2}× the line)",
                        f.bins,
                        if f.lack_of_fit { "yes" } else { "no" },
                        f.statistic,
                        f.dof,
                        f.p_value,
                        f.worst_ratio
                    );
                }
            }
            if let Some(l) = &c.law_choice {
                let _ = writeln!(
                    s,
                    "    vanishing law: {} (MOR exponents {}; held-out gain of the bend {:.3} nats per recording, better in {} of {}, sign-flip p {:.4}){}",
                    l.chosen,
                    l.exponents
                        .iter()
                        .map(|e| e.map_or("–".to_string(), |e| format!("{e:.3}")))
                        .collect::<Vec<_>>()
                        .join(", "),
                    l.gain_nats_per_recording,
                    l.recordings_better,
                    l.recordings,
                    l.p_value,
                    l.reason
                        .as_deref()
                        .map(|r| format!(": {r}"))
                        .unwrap_or_default()
                );
                let list = |v: &[Option<f64>]| {
                    v.iter()
                        .map(|e| e.map_or("–".to_string(), |e| format!("{e:.3}")))
                        .collect::<Vec<_>>()
                        .join(", ")
                };
                if let Some(r) = &l.reflectivity {
                    let _ = writeln!(
                        s,
                        "    reflectivity term: {} (k {}; held-out gain {:.3} nats per recording, better in {} of {}, sign-flip p {:.4}){}",
                        if r.chosen { "applied" } else { "not applied" },
                        list(&r.exponents),
                        r.gain_nats_per_recording,
                        r.recordings_better,
                        r.recordings,
                        r.p_value,
                        r.reason
                            .as_deref()
                            .map(|r| format!(": {r}"))
                            .unwrap_or_default()
                    );
                    if let Some(m) = &r.mor {
                        let _ = writeln!(
                            s,
                            "      k changing with MOR: {} (k at {:.1} m {}, per ln MOR {}; held-out gain over one k {:.3} nats per recording, better in {} of {}, sign-flip p {:.4}){}",
                            if m.chosen { "applied" } else { "not applied" },
                            m.mor_reference_m,
                            list(&m.exponents),
                            list(&m.per_ln_mor),
                            m.gain_nats_per_recording,
                            m.recordings_better,
                            m.recordings,
                            m.p_value,
                            m.reason
                                .as_deref()
                                .map(|r| format!(": {r}"))
                                .unwrap_or_default()
                        );
                    }
                }
            }
            if let Some(o) = &c.occlusion {
                let _ = writeln!(s, "    {}", occlusion_line(o));
            }
            if let Some(r) = &c.mor_from_rain_rate {
                let _ = writeln!(
                    s,
                    "    MOR = {:.4}·R + {:.2} from {} recordings",
                    r.slope, r.intercept, r.points
                );
            }
        }
        for (w, r) in &t.absent {
            let _ = writeln!(s, "  {w}: absent — {r}");
        }
        for e in &t.excluded_recordings {
            let _ = writeln!(
                s,
                "  excluded {} ({}): {}",
                e.recording, e.weather, e.reason
            );
        }
        if let Some(r) = &t.radar {
            let rates: Vec<String> = r
                .no_change_rate
                .iter()
                .map(|(w, x)| format!("{w} {x:.3}"))
                .collect();
            let _ = writeln!(s, "  radar no-change rate: {}", rates.join(", "));
        }
        s
    }
}

/// The summary's line on a weather's occlusion test.
fn occlusion_line(o: &murk_types::OcclusionTest) -> String {
    let pct = |x: Option<f64>| x.map_or("–".to_string(), |x| format!("{:.1} %", x * 100.0));
    if let Some(r) = &o.reason {
        return format!("near returns: cannot tell whether they replace lost returns — {r}");
    }
    let ratio = o
        .odds_ratio
        .map_or("unbounded".to_string(), |r| format!("{r:.3}"));
    format!(
        "near returns {}: beyond the noise windows {} of the returns the weather loses are hidden, {} of those it keeps (odds ratio {ratio} over {} recordings, p {}){}",
        if o.replaced {
            "replace the returns the weather loses"
        } else {
            "hide returns whatever their fate"
        },
        pct(o.hidden_where_lost),
        pct(o.hidden_where_kept),
        o.recordings,
        o.p_value.map_or("–".to_string(), |p| format!("{p:.2e}")),
        if o.replaced {
            "; hidden returns count as lost"
        } else {
            ""
        }
    )
}

fn fmt_opt(x: Option<f64>, digits: usize) -> String {
    match x {
        Some(v) => format!("{v:.digits$}"),
        None => "null".into(),
    }
}

/// Writes `bytes` to `path` atomically ([`murk_types::write_atomic`]),
/// creating its folder when missing.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), FitError> {
    let err = |reason: String| FitError::File {
        path: path.to_path_buf(),
        reason,
    };
    // A fresh checkout has no `out/`: make the folder, as `--figures` does.
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| err(format!("cannot write: {e}")))?;
    }
    murk_types::write_atomic(path, bytes).map_err(|e| err(format!("cannot write: {e}")))
}
