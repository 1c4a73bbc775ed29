//! `murk._murk`: the extension module behind the `murk` Python package.
//!
//! A thin layer over the library crates' public APIs — murk-io's readers and
//! writers, murk-types' [`CoefficientTable`], murk-infer's
//! [`ApplyParams`] → [`murk_infer::Applier`], murk-fit's
//! [`murk_fit::FitParams`] → `fit`, murk-diagnose's `run` — with numpy arrays in and
//! out. The Python side (`python/murk/__init__.py`) re-exports these names
//! and adds `Augment`; `python/murk/__init__.pyi` documents every signature.
//!
//! - The GIL is released while murk works (`Python::detach`), and the work
//!   runs on a rayon pool owned by the `pool` module (safe after `fork`).
//! - Errors are `murk.MurkError` subclasses with the CLI's messages
//!   (the `errors` module).
//! - `apply` on a scan gives the bytes `murk apply` writes for the same scan
//!   with the same seed when `key` is the CLI's scan key (the file's path
//!   relative to the input argument: its name for a file argument).

mod cloud;
mod errors;
mod pool;

use std::path::PathBuf;
use std::sync::Arc;

use murk_infer::{ApplyParams, Severity, SlopeSource};
use murk_io::{PcdData, ReadOptions, WriteOptions};
use murk_types::{CoefficientTable, CovariateValue, IntensityScale, PointFormat, WeatherClass};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyTuple};

use crate::cloud::Output;
use crate::errors::input;

/// A fitted coefficient table (`weather-noise-coefficients/1`), validated.
#[pyclass(frozen, module = "murk")]
struct Table {
    inner: Arc<CoefficientTable>,
    /// The file it was read from, when read from one.
    path: Option<String>,
}

impl Table {
    /// How errors name this table (its file, as `murk apply` names it).
    fn label(&self) -> String {
        self.path
            .clone()
            .unwrap_or_else(|| format!("table of campaign {:?}", self.inner.campaign))
    }
}

#[pymethods]
impl Table {
    /// Reads and validates a table file written by `murk fit`.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Table> {
        let t = py
            .detach(|| CoefficientTable::read(&path))
            .map_err(|e| errors::types(&e))?;
        Ok(Table {
            inner: Arc::new(t),
            path: Some(path.display().to_string()),
        })
    }

    /// Parses and validates a table from its JSON text.
    #[staticmethod]
    fn from_json(text: &str) -> PyResult<Table> {
        let t = CoefficientTable::from_json(text).map_err(|e| errors::types(&e))?;
        Ok(Table {
            inner: Arc::new(t),
            path: None,
        })
    }

    /// The table as JSON text, byte for byte what `murk fit` writes.
    fn to_json(&self) -> PyResult<String> {
        self.inner.to_json().map_err(|e| errors::types(&e))
    }

    /// The degraded weathers the table has coefficients for, sorted.
    #[getter]
    fn weathers(&self) -> Vec<String> {
        self.inner
            .weathers
            .keys()
            .map(|w| w.name().to_string())
            .collect()
    }

    /// Weathers the fit left out, with the reason.
    #[getter]
    fn absent(&self) -> Vec<(String, String)> {
        self.inner
            .absent
            .iter()
            .map(|(w, r)| (w.name().to_string(), r.clone()))
            .collect()
    }

    /// The campaign the table was fitted on.
    #[getter]
    fn campaign(&self) -> String {
        self.inner.campaign.clone()
    }

    /// The file the table was loaded from (None when built in memory).
    #[getter]
    fn path(&self) -> Option<String> {
        self.path.clone()
    }

    fn __repr__(&self) -> String {
        format!(
            "murk.Table(campaign={:?}, weathers={:?})",
            self.inner.campaign,
            self.weathers()
        )
    }

    fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
        other
            .cast::<Table>()
            .is_ok_and(|o| *o.get().inner == *self.inner)
    }

    /// Pickles as its JSON text (for multiprocessing, Ray, DataLoader
    /// workers started with spawn).
    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        let ctor = py.get_type::<Table>().getattr("from_json")?;
        let args = PyTuple::new(py, [self.to_json()?])?;
        PyTuple::new(py, [ctor.into_any(), args.into_any()])
    }
}

/// A table argument: a `murk.Table` or the path of a table file.
fn table_arg(obj: &Bound<'_, PyAny>) -> PyResult<(Arc<CoefficientTable>, String)> {
    if let Ok(t) = obj.cast::<Table>() {
        let t = t.get();
        return Ok((t.inner.clone(), t.label()));
    }
    let path: PathBuf = obj.extract().map_err(|_| {
        input(
            "table: expected a murk.Table or the path of a coefficient table (str or os.PathLike)",
        )
    })?;
    let t = CoefficientTable::read(&path).map_err(|e| errors::types(&e))?;
    Ok((Arc::new(t), path.display().to_string()))
}

/// An intensity-scale argument: a preset name or `(gain, offset)`.
fn scale_arg(obj: Option<&Bound<'_, PyAny>>) -> PyResult<Option<IntensityScale>> {
    let Some(obj) = obj else { return Ok(None) };
    if obj.is_none() {
        return Ok(None);
    }
    if let Ok(name) = obj.extract::<String>() {
        return IntensityScale::from_name(&name)
            .map(Some)
            .map_err(|e| input(format!("intensity_scale: {}", errors::message(&e))));
    }
    if let Ok((gain, offset)) = obj.extract::<(f32, f32)>() {
        return IntensityScale::linear(gain, offset)
            .map(Some)
            .map_err(|e| input(format!("intensity_scale: {}", errors::message(&e))));
    }
    Err(input(
        "intensity_scale: expected a name (calibrated, kitti, six-bit, nuscenes, …) or a (gain, offset) tuple",
    ))
}

fn weather_arg(name: &str) -> PyResult<WeatherClass> {
    name.parse::<WeatherClass>()
        .map_err(|e| input(format!("weather: {}", errors::message(&e))))
}

fn format_arg(name: Option<&str>) -> PyResult<Option<PointFormat>> {
    name.map(|n| {
        PointFormat::from_name(n).map_err(|_| {
            input(format!(
                "format: unknown format {n:?}: expected pcd, bin, nuscenes, csv, parquet or pcap"
            ))
        })
    })
    .transpose()
}

fn pool_err(e: String) -> PyErr {
    errors::MurkError::new_err(e)
}

/// Reads a point-cloud file into a dict of numpy columns.
#[pyfunction]
#[pyo3(signature = (path, *, format=None, intensity_scale=None, frames=false, pcap_return=None))]
fn read(
    py: Python<'_>,
    path: PathBuf,
    format: Option<&str>,
    intensity_scale: Option<&Bound<'_, PyAny>>,
    frames: bool,
    pcap_return: Option<&str>,
) -> PyResult<Py<PyAny>> {
    let opts = ReadOptions {
        format: format_arg(format)?,
        intensity_scale: scale_arg(intensity_scale)?,
        pcap_return: pcap_return
            .map(|r| {
                r.parse::<murk_types::PcapReturn>()
                    .map_err(|e| input(format!("pcap_return: {e}")))
            })
            .transpose()?,
        ..ReadOptions::default()
    };
    let clouds = py
        .detach(|| {
            pool::run(None, || {
                if frames {
                    murk_io::read_frames(&path, &opts)
                } else {
                    murk_io::read_cloud(&path, &opts).map(|c| vec![c])
                }
            })
        })
        .map_err(pool_err)?
        .map_err(|e| errors::io(&e))?;
    if frames {
        let list = pyo3::types::PyList::empty(py);
        for c in clouds {
            list.append(cloud::cloud_to_dict(py, c)?)?;
        }
        return Ok(list.into_any().unbind());
    }
    let c = clouds.into_iter().next().unwrap_or_default();
    Ok(cloud::cloud_to_dict(py, c)?.into_any().unbind())
}

/// Writes a cloud (dict of columns or array of records) atomically.
#[pyfunction]
#[pyo3(signature = (path, cloud, *, format=None, pcd_data="binary", layout=None, intensity_scale=None))]
fn write(
    py: Python<'_>,
    path: PathBuf,
    cloud: &Bound<'_, PyAny>,
    format: Option<&str>,
    pcd_data: &str,
    layout: Option<&str>,
    intensity_scale: Option<&Bound<'_, PyAny>>,
) -> PyResult<()> {
    let points = cloud::extract(cloud, layout, "cloud")?;
    let scale = scale_arg(intensity_scale)?.unwrap_or_else(|| points.default_scale());
    let format = match format_arg(format)? {
        Some(f) => f,
        None => PointFormat::from_path(&path).map_err(|e| errors::types(&e))?,
    };
    if !format.writable() {
        return Err(input(format!(
            "format: murk does not write {format:?} files (pcd, bin, nuscenes, csv, parquet)"
        )));
    }
    let pcd_data = pcd_data
        .parse::<PcdData>()
        .map_err(|e| input(format!("pcd_data: {e}")))?;
    let view = points.view()?;
    let opts = WriteOptions { format, pcd_data };
    py.detach(|| {
        pool::run(None, || -> PyResult<()> {
            let c = view.decode(scale, "cloud")?;
            murk_io::write_cloud_with(&path, &c, &opts).map_err(|e| errors::io(&e))
        })
    })
    .map_err(pool_err)?
}

/// The model options shared by `apply` and `apply_file` (`murk apply`'s flags).
struct ApplyArgs<'a, 'py> {
    weather: &'a str,
    mor: Option<f64>,
    rain_rate: Option<f64>,
    seed: u64,
    near_range: bool,
    near_range_count_scale: f64,
    soft_edge: bool,
    range_noise: Option<f64>,
    attenuate_intensity: bool,
    slope: &'a str,
    clamp: bool,
    covariates: Option<&'a Bound<'py, PyDict>>,
    extensions: bool,
    range_scale: Option<f64>,
    clear_mor_threshold: Option<f64>,
    min_range: Option<f64>,
}

/// `ApplyArgs` → `ApplyParams`, as `murk apply` builds them from its flags.
fn apply_params(a: &ApplyArgs<'_, '_>) -> PyResult<ApplyParams> {
    let weather = weather_arg(a.weather)?;
    let severity = match (a.mor, a.rain_rate) {
        (Some(m), None) => Severity::Mor(m),
        (None, Some(r)) => Severity::RainRate(r),
        (Some(_), Some(_)) => return Err(input("give one of mor and rain_rate, not both")),
        (None, None) => return Err(input("give mor (metres) or rain_rate (mm/h)")),
    };
    let slope = match a.slope {
        "survival" => SlopeSource::Survival,
        "quantile" | "q99" => SlopeSource::Quantile,
        s => {
            return Err(input(format!(
                "slope: {s:?}: expected \"survival\" or \"quantile\""
            )));
        }
    };
    let mut params = ApplyParams::new(weather, severity)
        .clamp_rain_rate(a.clamp)
        .near_range(a.near_range)
        .near_range_count_scale(a.near_range_count_scale)
        .range_noise_m(a.range_noise.unwrap_or(0.0))
        .attenuate_intensity(a.attenuate_intensity)
        .soft_edge(a.soft_edge)
        .slope_source(slope)
        .seed(a.seed)
        .extensions(a.extensions);
    if let Some(c) = a.covariates {
        for (k, v) in c.iter() {
            let name: String = k
                .extract()
                .map_err(|_| input("covariates: names must be strings"))?;
            let value = v.str()?.to_string();
            params = params.covariate(name.trim(), CovariateValue::parse(&value));
        }
    }
    if let Some(k) = a.range_scale {
        params = params.range_scale(k);
    }
    if let Some(m) = a.clear_mor_threshold {
        params = params.clear_mor_threshold_m(m);
    }
    if let Some(m) = a.min_range {
        params = params.min_range_m(m);
    }
    Ok(params)
}

/// Degrades one scan with a table's weather model.
#[pyfunction]
#[pyo3(signature = (
    points, table, weather, *, mor=None, rain_rate=None, seed=0, key=None, layout=None,
    intensity_scale=None, near_range=false, near_range_count_scale=1.0, soft_edge=false,
    range_noise=None, attenuate_intensity=false, slope="survival", clamp=false,
    covariates=None, extensions=true, range_scale=None, clear_mor_threshold=None,
    min_range=None, threads=None, summary=false
))]
#[allow(clippy::too_many_arguments)]
fn apply(
    py: Python<'_>,
    points: &Bound<'_, PyAny>,
    table: &Bound<'_, PyAny>,
    weather: &str,
    mor: Option<f64>,
    rain_rate: Option<f64>,
    seed: u64,
    key: Option<String>,
    layout: Option<&str>,
    intensity_scale: Option<&Bound<'_, PyAny>>,
    near_range: bool,
    near_range_count_scale: f64,
    soft_edge: bool,
    range_noise: Option<f64>,
    attenuate_intensity: bool,
    slope: &str,
    clamp: bool,
    covariates: Option<&Bound<'_, PyDict>>,
    extensions: bool,
    range_scale: Option<f64>,
    clear_mor_threshold: Option<f64>,
    min_range: Option<f64>,
    threads: Option<usize>,
    summary: bool,
) -> PyResult<Py<PyAny>> {
    let (table, label) = table_arg(table)?;
    if threads == Some(0) {
        return Err(input("threads: must be at least 1 (None: the default)"));
    }
    let params = apply_params(&ApplyArgs {
        weather,
        mor,
        rain_rate,
        seed,
        near_range,
        near_range_count_scale,
        soft_edge,
        range_noise,
        attenuate_intensity,
        slope,
        clamp,
        covariates,
        extensions,
        range_scale,
        clear_mor_threshold,
        min_range,
    })?;
    let points = cloud::extract(points, layout, "points")?;
    let scale = scale_arg(intensity_scale)?.unwrap_or_else(|| points.default_scale());
    let shape = points.shape();
    let view = points.view()?;
    let key = key.unwrap_or_default();
    let (out, summary_json) = py
        .detach(|| {
            pool::run(threads, || -> PyResult<(Output, Option<String>)> {
                let applier = params
                    .build_labelled(&table, &label)
                    .map_err(|e| errors::infer(&e))?;
                let cloud = view.decode(scale, "points")?;
                let (out, s) = applier.apply(&cloud, &key).map_err(|e| errors::infer(&e))?;
                drop(cloud);
                let json = if summary {
                    let model = applier.describe();
                    Some(
                        serde_json::to_string(&serde_json::json!({
                            "model": model, "scan": s
                        }))
                        .map_err(|e| errors::MurkError::new_err(e.to_string()))?,
                    )
                } else {
                    None
                };
                Ok((Output::new(out, shape), json))
            })
        })
        .map_err(pool_err)??;
    let out = out.into_py(py)?;
    match summary_json {
        None => Ok(out),
        Some(j) => {
            let s = py.import("json")?.call_method1("loads", (j,))?;
            Ok(PyTuple::new(py, [out, s.unbind()])?.into_any().unbind())
        }
    }
}

/// Reads a `[lo, hi]` pair.
fn pair(name: &str, v: &Bound<'_, PyAny>) -> PyResult<[f64; 2]> {
    let (a, b): (f64, f64) = v
        .extract()
        .map_err(|_| input(format!("{name}: expected a (lo, hi) pair of numbers")))?;
    Ok([a, b])
}

/// Batch read options: forced intensity scale, as `--intensity-scale`.
fn batch_options(
    format: Option<&str>,
    pcd_data: &str,
    intensity_scale: Option<&Bound<'_, PyAny>>,
) -> PyResult<murk_infer::BatchOptions> {
    let format = format_arg(format)?;
    if format.is_some_and(|f| !f.writable()) {
        return Err(input(
            "format: murk does not write pcap files (pcd, bin, nuscenes, csv, parquet)",
        ));
    }
    Ok(murk_infer::BatchOptions {
        read: ReadOptions {
            intensity_scale: scale_arg(intensity_scale)?,
            ..ReadOptions::default()
        },
        format,
        pcd_data: pcd_data
            .parse::<PcdData>()
            .map_err(|e| input(format!("pcd_data: {e}")))?,
        keep_partial: false,
    })
}

/// A planned job: input, output, scan key.
type PlannedJob = (String, String, String);
/// A file of an input folder left out, and why.
type SkippedFile = (String, String);

/// `murk apply`'s plan: which input goes to which output under `out`, with
/// the scan key of each; and the files of input folders left out.
#[pyfunction]
#[pyo3(signature = (inputs, out, *, format=None))]
fn plan(
    py: Python<'_>,
    inputs: Vec<PathBuf>,
    out: PathBuf,
    format: Option<&str>,
) -> PyResult<(Vec<PlannedJob>, Vec<SkippedFile>)> {
    let opts = batch_options(format, "binary", None)?;
    let plan = py
        .detach(|| murk_infer::batch::plan(&inputs, &out, &opts))
        .map_err(|e| errors::infer(&e))?;
    Ok((
        plan.jobs
            .iter()
            .map(|j| {
                (
                    j.input.display().to_string(),
                    j.output.display().to_string(),
                    j.key.clone(),
                )
            })
            .collect(),
        plan.skipped
            .iter()
            .map(|s| (s.path.display().to_string(), s.reason.clone()))
            .collect(),
    ))
}

/// One file of `murk apply`: reads `input`, applies with scan key `key`,
/// writes `output` atomically (what `murk apply` writes for that job, byte
/// for byte); returns the file's summary.
#[pyfunction]
#[pyo3(signature = (
    input, output, key, table, weather, *, mor=None, rain_rate=None, seed=0, format=None,
    pcd_data="binary", intensity_scale=None, near_range=false, near_range_count_scale=1.0,
    soft_edge=false, range_noise=None, attenuate_intensity=false, slope="survival", clamp=false,
    covariates=None, extensions=true, range_scale=None, clear_mor_threshold=None, min_range=None,
    threads=None
))]
#[allow(clippy::too_many_arguments)]
fn apply_file(
    py: Python<'_>,
    input: PathBuf,
    output: PathBuf,
    key: String,
    table: &Bound<'_, PyAny>,
    weather: &str,
    mor: Option<f64>,
    rain_rate: Option<f64>,
    seed: u64,
    format: Option<&str>,
    pcd_data: &str,
    intensity_scale: Option<&Bound<'_, PyAny>>,
    near_range: bool,
    near_range_count_scale: f64,
    soft_edge: bool,
    range_noise: Option<f64>,
    attenuate_intensity: bool,
    slope: &str,
    clamp: bool,
    covariates: Option<&Bound<'_, PyDict>>,
    extensions: bool,
    range_scale: Option<f64>,
    clear_mor_threshold: Option<f64>,
    min_range: Option<f64>,
    threads: Option<usize>,
) -> PyResult<Py<PyAny>> {
    let (table, label) = table_arg(table)?;
    let params = apply_params(&ApplyArgs {
        weather,
        mor,
        rain_rate,
        seed,
        near_range,
        near_range_count_scale,
        soft_edge,
        range_noise,
        attenuate_intensity,
        slope,
        clamp,
        covariates,
        extensions,
        range_scale,
        clear_mor_threshold,
        min_range,
    })?;
    let opts = batch_options(format, pcd_data, intensity_scale)?;
    let parent = output
        .parent()
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("."));
    let json = py
        .detach(|| {
            pool::run(threads, || -> PyResult<String> {
                let applier = params
                    .build_labelled(&table, &label)
                    .map_err(|e| errors::infer(&e))?;
                // A one-file plan gives the job of `input` in `parent` (its
                // output name follows the same rule as in a folder plan);
                // the key is the caller's, as in the folder plan it came from.
                let mut p = murk_infer::batch::plan(std::slice::from_ref(&input), &parent, &opts)
                    .map_err(|e| errors::infer(&e))?;
                let mut job = p
                    .jobs
                    .pop()
                    .ok_or_else(|| input_err(&input, "is not a point-cloud file"))?;
                if job.output.file_name() != output.file_name() {
                    return Err(input_err(
                        &input,
                        &format!(
                            "its output would be named {}, not {}",
                            job.output.display(),
                            output.display()
                        ),
                    ));
                }
                if job.format_in == PointFormat::Pcap {
                    return Err(input_err(
                        &input,
                        "is a capture: it gives one output per revolution; use apply_files",
                    ));
                }
                job.key = key;
                let reports = murk_infer::batch::run_job(&applier, &job, &opts)
                    .map_err(|e| errors::infer(&e))?;
                let report = reports
                    .first()
                    .ok_or_else(|| input_err(&input, "gave no output"))?;
                serde_json::to_string(&report.summary)
                    .map_err(|e| errors::MurkError::new_err(e.to_string()))
            })
        })
        .map_err(pool_err)??;
    Ok(py.import("json")?.call_method1("loads", (json,))?.unbind())
}

fn input_err(path: &std::path::Path, reason: &str) -> PyErr {
    input(format!("{}: {reason}", path.display()))
}

/// `murk fit`'s flags as keyword arguments → checked fit parameters.
fn fit_params(params: Option<&Bound<'_, PyDict>>) -> PyResult<murk_fit::FitValidParams> {
    let mut p = murk_fit::FitParams::default();
    if let Some(d) = params {
        for (k, v) in d.iter() {
            let name: String = k.extract()?;
            let f = |v: &Bound<'_, PyAny>| -> PyResult<f64> {
                v.extract()
                    .map_err(|_| input(format!("{name}: expected a number")))
            };
            let u = |v: &Bound<'_, PyAny>| -> PyResult<u64> {
                v.extract()
                    .map_err(|_| input(format!("{name}: expected a non-negative integer")))
            };
            let b = |v: &Bound<'_, PyAny>| -> PyResult<bool> {
                v.extract()
                    .map_err(|_| input(format!("{name}: expected True or False")))
            };
            let edges = |v: &Bound<'_, PyAny>| -> PyResult<Vec<f64>> {
                v.extract()
                    .map_err(|_| input(format!("{name}: expected a list of numbers")))
            };
            p = match name.as_str() {
                "quantile" => p.quantile(f(&v)?),
                "mor_bin_width" | "mor_bin_width_m" => p.mor_bin_width_m(f(&v)?),
                "bands" | "band_edges" => p.band_edges(edges(&v)?),
                "sweep" | "sweep_edges" => p.sweep_edges(edges(&v)?),
                "ghost_range" | "ghost_range_m" => p.ghost_range_m(pair(&name, &v)?),
                "ring_range" | "ring_range_m" => p.ring_range_m(pair(&name, &v)?),
                "pairing_tolerance" | "pairing_tolerance_m" => p.pairing_tolerance_m(f(&v)?),
                "pairing_tolerance_rel" => p.pairing_tolerance_rel(f(&v)?),
                "min_points_per_bin" => p.min_points_per_bin(u(&v)?),
                "censor_fraction" => p.censor_fraction(f(&v)?),
                "edge" => {
                    let s: String = v.extract()?;
                    p.edge(
                        s.parse::<murk_fit::EdgeShape>()
                            .map_err(|e| input(format!("edge: {e}")))?,
                    )
                }
                "per_band_width" => p.shared_edge_width(!b(&v)?),
                "keep_unconfirmed_slopes" => p.require_edge(!b(&v)?),
                "bend" => p.apply_bend(b(&v)?),
                "no_law_comparison" => p.compare_laws(!b(&v)?),
                "reflectivity_law" => p.reflectivity_law(b(&v)?),
                "fixed_dropout" => p.free_dropout(!b(&v)?),
                "bootstrap" | "bootstrap_replicates" => {
                    let n = u(&v)?;
                    p.bootstrap_replicates(
                        u32::try_from(n).map_err(|_| input(format!("{name}: {n} is too large")))?,
                    )
                }
                "seed" => p.seed(u(&v)?),
                "radar_tolerance" | "radar_tolerance_m" => p.radar_tolerance_m(f(&v)?),
                other => {
                    return Err(input(format!(
                        "unknown fit parameter {other:?}: expected quantile, mor_bin_width, bands, sweep, ghost_range, ring_range, pairing_tolerance, pairing_tolerance_rel, min_points_per_bin, censor_fraction, edge, per_band_width, keep_unconfirmed_slopes, bend, no_law_comparison, reflectivity_law, fixed_dropout, bootstrap, seed, radar_tolerance (the flags of murk fit)"
                    )));
                }
            };
        }
    }
    p.check().map_err(|e| errors::fit(&e))
}

/// Fits a campaign folder into a coefficient table.
#[pyfunction]
#[pyo3(signature = (campaign, *, threads=None, **params))]
fn fit(
    py: Python<'_>,
    campaign: PathBuf,
    threads: Option<usize>,
    params: Option<&Bound<'_, PyDict>>,
) -> PyResult<Table> {
    let valid = fit_params(params)?;
    let table = py
        .detach(|| {
            pool::run(threads, || -> PyResult<CoefficientTable> {
                let c =
                    murk_campaign::Campaign::open(&campaign).map_err(|e| errors::campaign(&e))?;
                let fitted = valid.fit(&c).map_err(|e| errors::fit(&e))?;
                Ok(fitted.table().clone())
            })
        })
        .map_err(pool_err)??;
    Ok(Table {
        inner: Arc::new(table),
        path: None,
    })
}

/// What `__reduce__` returns: the constructor and its arguments.
type Reduced<'py> = (Bound<'py, PyAny>, (Bound<'py, PyBytes>, String));

/// The statistics of part of a campaign's recordings (`murk fit
/// --partial`'s state): merge states with [`FitState::merge`], and finish
/// a complete one into its table. Picklable (its bytes are the state file).
#[pyclass(frozen, module = "murk")]
struct FitState {
    inner: Arc<murk_fit::FitState>,
}

#[pymethods]
impl FitState {
    /// Reads a state file written by `murk fit --partial` or `FitState.write`.
    #[staticmethod]
    fn read(py: Python<'_>, path: PathBuf) -> PyResult<FitState> {
        let s = py
            .detach(|| murk_fit::FitState::read(&path))
            .map_err(|e| errors::fit(&e))?;
        Ok(FitState { inner: Arc::new(s) })
    }

    /// Writes the state file atomically (`murk fit --merge` reads it).
    fn write(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let s = self.inner.clone();
        py.detach(move || s.write(&path))
            .map_err(|e| errors::fit(&e))
    }

    /// The state file's bytes.
    fn to_bytes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let s = self.inner.clone();
        let b = py
            .detach(move || s.to_bytes())
            .map_err(|e| errors::fit(&e))?;
        Ok(PyBytes::new(py, &b))
    }

    /// A state from the bytes of a state file.
    #[staticmethod]
    #[pyo3(signature = (data, label="state bytes"))]
    fn from_bytes(py: Python<'_>, data: &[u8], label: &str) -> PyResult<FitState> {
        let s = py
            .detach(|| murk_fit::FitState::from_bytes(data, label))
            .map_err(|e| errors::fit(&e))?;
        Ok(FitState { inner: Arc::new(s) })
    }

    /// Pickling: the state file's bytes.
    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<Reduced<'py>> {
        let cls = py
            .import("murk")?
            .getattr("FitState")?
            .getattr("from_bytes")?;
        Ok((cls, (self.to_bytes(py)?, self.inner.label().to_string())))
    }

    /// This state merged with `other` (a new state; neither is changed).
    /// Raises FitError when they are of different campaigns, parameters or
    /// murk versions, hold the same recording, or were paired against
    /// different clear references.
    fn merge(&self, py: Python<'_>, other: &FitState) -> PyResult<FitState> {
        let (a, b) = (self.inner.clone(), other.inner.clone());
        let m = py
            .detach(move || (*a).clone().merge((*b).clone()))
            .map_err(|e| errors::fit(&e))?;
        Ok(FitState { inner: Arc::new(m) })
    }

    /// The coefficient table of a complete state; FitError naming the
    /// missing recordings otherwise.
    #[pyo3(signature = (*, threads=None))]
    fn finish(&self, py: Python<'_>, threads: Option<usize>) -> PyResult<Table> {
        let s = self.inner.clone();
        let table = py
            .detach(|| {
                pool::run(threads, || -> PyResult<CoefficientTable> {
                    Ok(s.finish().map_err(|e| errors::fit(&e))?.table().clone())
                })
            })
            .map_err(pool_err)??;
        Ok(Table {
            inner: Arc::new(table),
            path: None,
        })
    }

    /// Whether every selected recording is in the state.
    #[getter]
    fn complete(&self) -> bool {
        self.inner.is_complete()
    }

    /// What the state lacks before it gives a table, or None.
    #[getter]
    fn missing(&self) -> Option<String> {
        self.inner.missing_description()
    }

    /// Ids of the recordings in the state, in campaign order.
    #[getter]
    fn recordings(&self) -> Vec<String> {
        self.inner.recordings()
    }

    /// The campaign's name.
    #[getter]
    fn campaign(&self) -> String {
        self.inner.campaign().to_string()
    }

    fn __repr__(&self) -> String {
        format!(
            "<murk.FitState of {} recordings of {}{}>",
            self.inner.recordings().len(),
            self.inner.campaign(),
            if self.inner.is_complete() {
                ", complete"
            } else {
                ""
            }
        )
    }
}

/// Maps part of a campaign into a FitState (`murk fit --partial`): without
/// `reference` its clear recordings, with `reference` (a state holding every
/// clear recording) its degraded ones, paired against it.
#[pyfunction]
#[pyo3(signature = (campaign, recordings=None, *, shard=None, reference=None, threads=None, **params))]
fn fit_partial(
    py: Python<'_>,
    campaign: PathBuf,
    recordings: Option<Vec<String>>,
    shard: Option<(usize, usize)>,
    reference: Option<&FitState>,
    threads: Option<usize>,
    params: Option<&Bound<'_, PyDict>>,
) -> PyResult<FitState> {
    let valid = fit_params(params)?;
    let selection = match (recordings, shard) {
        (Some(_), Some(_)) => {
            return Err(input("give recordings or shard, not both"));
        }
        (Some(r), None) => murk_fit::Selection::Recordings(r),
        (None, Some((k, n))) => murk_fit::Selection::parse_shard(&format!("{k}/{n}"))
            .map_err(|e| input(format!("shard: {e}")))?,
        (None, None) => murk_fit::Selection::All,
    };
    let reference = reference.map(|r| r.inner.clone());
    let state = py
        .detach(|| {
            pool::run(threads, || -> PyResult<murk_fit::FitState> {
                let c =
                    murk_campaign::Campaign::open(&campaign).map_err(|e| errors::campaign(&e))?;
                let inputs = murk_fit::FitInputs::from_campaign(&c);
                valid
                    .fit_partial(&inputs, &selection, reference.as_deref())
                    .map_err(|e| errors::fit(&e))
            })
        })
        .map_err(pool_err)??;
    Ok(FitState {
        inner: Arc::new(state),
    })
}

/// Diagnoses a weather of a campaign; returns the report (`murk diagnose`'s
/// JSON) as a dict, and the extended table when asked.
#[pyfunction]
#[pyo3(signature = (
    campaign, weather, *, coefficients=None, folds=3, seed=0, permutations=1999, alpha=0.05,
    sims=2, voxel=1.0, local_box=None, threads=None, kept_memory_mb=256.0, spill_dir=None,
    extended_table=false
))]
#[allow(clippy::too_many_arguments)]
fn diagnose(
    py: Python<'_>,
    campaign: PathBuf,
    weather: &str,
    coefficients: Option<&Bound<'_, PyAny>>,
    folds: usize,
    seed: u64,
    permutations: usize,
    alpha: f64,
    sims: usize,
    voxel: f64,
    local_box: Option<[f64; 6]>,
    threads: Option<usize>,
    kept_memory_mb: f64,
    spill_dir: Option<PathBuf>,
    extended_table: bool,
) -> PyResult<Py<PyAny>> {
    let weather = weather_arg(weather)?;
    let table = match coefficients {
        Some(t) if !t.is_none() => Some((*table_arg(t)?.0).clone()),
        _ => None,
    };
    let params = murk_diagnose::DiagnoseParams::new(weather)
        .folds(folds)
        .seed(seed)
        .permutations(permutations)
        .alpha(alpha)
        .sims(sims)
        .voxel_m(voxel)
        .local_box(local_box.map(|v| murk_diagnose::scene::VoxelBox {
            min: [v[0], v[1], v[2]],
            max: [v[3], v[4], v[5]],
        }))
        .coefficients(table)
        .kept_memory_mb(kept_memory_mb)
        .spill_dir(spill_dir)
        .check()
        .map_err(|e| errors::diagnose(&e))?;
    let (json, ext) = py
        .detach(|| {
            pool::run(
                threads,
                || -> PyResult<(String, Option<CoefficientTable>)> {
                    let c = murk_campaign::Campaign::open(&campaign)
                        .map_err(|e| errors::campaign(&e))?;
                    let d = params.run(&c).map_err(|e| errors::diagnose(&e))?;
                    Ok((d.report.to_json(), d.extended_table))
                },
            )
        })
        .map_err(pool_err)??;
    let report = py.import("json")?.call_method1("loads", (json,))?;
    if !extended_table {
        return Ok(report.unbind());
    }
    let t: Py<PyAny> = match ext {
        Some(t) => Py::new(
            py,
            Table {
                inner: Arc::new(t),
                path: None,
            },
        )?
        .into_any(),
        None => py.None(),
    };
    Ok(PyTuple::new(py, [report.unbind(), t])?.into_any().unbind())
}

/// Benchmark support: the Rust work of one `apply` call (build the applier,
/// decode the records, apply, lay the output out as records), timed in Rust
/// `repeats` times with the GIL released; seconds per repeat. What
/// `murk.apply` adds on top of this is the binding's overhead.
#[pyfunction]
#[pyo3(signature = (points, table, weather, mor, repeats, *, threads=None))]
fn _rust_apply_seconds(
    py: Python<'_>,
    points: &Bound<'_, PyAny>,
    table: &Bound<'_, PyAny>,
    weather: &str,
    mor: f64,
    repeats: usize,
    threads: Option<usize>,
) -> PyResult<Vec<f64>> {
    let (table, label) = table_arg(table)?;
    let params = ApplyParams::new(weather_arg(weather)?, Severity::Mor(mor));
    let points = cloud::extract(points, None, "points")?;
    let scale = points.default_scale();
    let shape = points.shape();
    let view = points.view()?;
    py.detach(|| {
        pool::run(threads, || -> PyResult<Vec<f64>> {
            let mut times = Vec::with_capacity(repeats);
            for _ in 0..repeats {
                let t = std::time::Instant::now();
                let applier = params
                    .build_labelled(&table, &label)
                    .map_err(|e| errors::infer(&e))?;
                let cloud = view.decode(scale, "points")?;
                let (out, _) = applier.apply(&cloud, "").map_err(|e| errors::infer(&e))?;
                drop(cloud);
                std::hint::black_box(Output::new(out, shape));
                times.push(t.elapsed().as_secs_f64());
            }
            Ok(times)
        })
    })
    .map_err(pool_err)?
}

/// Sets the default number of worker threads (0: back to
/// `MURK_NUM_THREADS`, else the CPU count).
#[pyfunction]
fn set_num_threads(n: usize) {
    pool::set_num_threads(n);
}

/// How many megabytes of clear recordings' cell images a fit or diagnosis
/// holds in memory while its clear reference is built, the rest spilled to
/// an anonymous temporary file in `spill_dir` (`murk fit
/// --clear-memory-mb`, `--spill-dir`; the process's setting, for the
/// calls that follow; it changes memory only, never a result).
#[pyfunction]
#[pyo3(signature = (mb, spill_dir=None))]
fn set_clear_memory(mb: f64, spill_dir: Option<PathBuf>) -> PyResult<()> {
    murk_fit::set_clear_image_memory_mb(mb).map_err(|e| errors::fit(&e))?;
    murk_fit::set_clear_image_dir(spill_dir);
    Ok(())
}

/// The default number of worker threads of a call.
#[pyfunction]
fn get_num_threads() -> usize {
    pool::num_threads()
}

/// The extension module.
#[pymodule]
fn _murk(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    errors::register(m)?;
    m.add_class::<Table>()?;
    m.add_function(wrap_pyfunction!(read, m)?)?;
    m.add_function(wrap_pyfunction!(write, m)?)?;
    m.add_function(wrap_pyfunction!(apply, m)?)?;
    m.add_function(wrap_pyfunction!(plan, m)?)?;
    m.add_function(wrap_pyfunction!(apply_file, m)?)?;
    m.add_function(wrap_pyfunction!(fit, m)?)?;
    m.add_function(wrap_pyfunction!(fit_partial, m)?)?;
    m.add_class::<FitState>()?;
    m.add_function(wrap_pyfunction!(diagnose, m)?)?;
    m.add_function(wrap_pyfunction!(set_num_threads, m)?)?;
    m.add_function(wrap_pyfunction!(set_clear_memory, m)?)?;
    m.add_function(wrap_pyfunction!(_rust_apply_seconds, m)?)?;
    m.add_function(wrap_pyfunction!(get_num_threads, m)?)?;
    Ok(())
}
