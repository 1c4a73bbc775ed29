//! The fit as a whole: checked parameters + campaign → [`FittedTable`].

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use murk_campaign::Campaign;
use murk_types::{
    ClearCoefficients, CoefficientTable, CountUnit, ExcludedRecording, InputDigest, Provenance,
    RadarCoefficients, TABLE_FORMAT, TableLidar, WeatherClass,
};
use rayon::prelude::*;

use crate::assemble::{RainSample, WeatherContext, rain_conversion, uncertainty, weather};
use crate::diagnostics::Diagnostics;
use crate::driver::{
    DegradedJob, FitInputs, RecordingInput, accumulate_degraded, build_reference, measure_geometry,
    read_file, read_radar, relative, sha256_hex,
};
use crate::radar::{Detections, RadarReference};
use crate::reference::CellGrid;
use crate::stats::bootstrap::bootstrap_rate;
use crate::survival::Partition;
use crate::{FitError, FitValidParams};

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

fn fit_inputs(inputs: &FitInputs, params: &FitValidParams) -> Result<FittedTable, FitError> {
    inputs.lidar.validate().map_err(|e| FitError::File {
        path: inputs.dir.join("campaign.toml"),
        reason: e.to_string(),
    })?;
    let range_scale = inputs.lidar.range_scale;
    let clear: Vec<&RecordingInput> = inputs
        .recordings
        .iter()
        .filter(|r| r.class == WeatherClass::Clear)
        .collect();
    if clear.is_empty() {
        return Err(FitError::NoClearReference {
            path: inputs.dir.clone(),
            reason: "no recording was selected as clear (rules and review), so no degraded recording can be paired".into(),
        });
    }
    let (mut geometry, geometry_warnings) = measure_geometry(inputs)?;
    if params.declared_geometry() {
        geometry = crate::geometry::declared(&inputs.lidar);
    }
    let grid = CellGrid::from_geometry(&geometry);
    let (reference, mut digests, empty_clear) = build_reference(inputs, &clear, &grid, params)?;
    // Clear recordings the reference is built from (not the empty ones).
    let clear_used = clear.len() - empty_clear.len();
    if clear_used == 0 {
        return Err(FitError::NoClearReference {
            path: inputs.dir.clone(),
            reason: format!(
                "every one of the {} clear recordings holds no point",
                clear.len()
            ),
        });
    }
    if reference.present().is_empty() {
        return Err(FitError::NoClearReference {
            path: inputs.dir.clone(),
            reason: format!(
                "the {} clear recordings share no stable return (presence ≥ {})",
                clear_used,
                params.reference_min_presence()
            ),
        });
    }
    let loo = reference.leave_one_out();
    let (lk, lt) = loo.iter().fold((0u64, 0u64), |a, r| (a.0 + r.0, a.1 + r.1));
    let clear_rate = (clear_used >= 2 && lt > 0).then(|| lk as f64 / lt as f64);
    let dropout_clear = clear_rate.map(|r| 1.0 - r);

    // Rain conversion from the metadata, before any point is read: rain
    // recordings without a MOR borrow it.
    let rain_pairs: Vec<RainSample> = inputs
        .recordings
        .iter()
        .filter(|r| r.class == WeatherClass::Rain)
        .filter_map(|r| {
            let readings = match r.rain_readings.is_empty() {
                true => vec![r.rain_rate?],
                false => r.rain_readings.clone(),
            };
            Some(RainSample {
                readings,
                mor: r.mor?,
            })
        })
        .collect();
    let has_rain = inputs
        .recordings
        .iter()
        .any(|r| r.class == WeatherClass::Rain);
    let conversion = has_rain.then(|| rain_conversion(&rain_pairs));

    let mut excluded = empty_clear;
    let mut jobs = Vec::new();
    for r in inputs
        .recordings
        .iter()
        .filter(|r| r.class != WeatherClass::Clear)
    {
        let mor = match (r.mor, r.rain_rate, &conversion) {
            (Some(m), _, _) if m.is_finite() && m > 0.0 => Ok(m),
            (Some(m), _, _) => Err(format!("MOR {m} is not a positive distance")),
            (None, Some(rate), Some(Ok(c))) if c.mor(rate) > 0.0 => Ok(c.mor(rate)),
            (None, Some(rate), Some(Ok(c))) => Err(format!(
                "no MOR, and the rain conversion gives {:.1} m at {rate} mm/h",
                c.mor(rate)
            )),
            (None, _, _) => {
                Err("no MOR (every visibility column is empty) and no rain conversion".to_string())
            }
        };
        match mor {
            Ok(mor) => jobs.push(DegradedJob { input: r, mor }),
            Err(reason) => excluded.push(ExcludedRecording {
                recording: r.id.clone(),
                weather: r.class,
                reason,
            }),
        }
    }

    let partition = Partition::new(
        params
            .bands()
            .iter()
            .chain(params.sweep_bands().iter())
            .map(|b| b.min),
    );
    let (accs, degraded_digests, empty_degraded) =
        accumulate_degraded(inputs, &jobs, &reference, &partition, params)?;
    excluded.extend(empty_degraded);
    digests.extend(degraded_digests);

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
            reference: &reference,
            partition: &partition,
            params,
            range_scale,
            dropout_clear,
            rain: (class == WeatherClass::Rain)
                .then(|| conversion.clone())
                .flatten(),
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

    let (radar, radar_digests) = radar(inputs, params)?;
    digests.extend(radar_digests);

    // Provenance: every file read, sorted by relative path.
    let meta: Vec<Result<(PathBuf, String), FitError>> = inputs
        .metadata
        .par_iter()
        .map(|p| Ok((p.clone(), sha256_hex(&read_file(p)?))))
        .collect();
    for m in meta {
        digests.push(m?);
    }
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
) -> Result<(Option<RadarCoefficients>, Digests), FitError> {
    let with_radar: Vec<&RecordingInput> = inputs
        .recordings
        .iter()
        .filter(|r| r.radar.is_some())
        .collect();
    if with_radar.is_empty() {
        return Ok((None, Vec::new()));
    }
    let read: Vec<Result<(Detections, String), FitError>> = with_radar
        .par_iter()
        .map(|r| read_radar(r.radar.as_deref().unwrap_or(Path::new(""))))
        .collect();
    let mut det = Vec::with_capacity(read.len());
    let mut digests = Vec::new();
    for (r, res) in with_radar.iter().zip(read) {
        let (d, h) = res?;
        digests.push((r.radar.clone().unwrap_or_default(), h));
        det.push(d);
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
