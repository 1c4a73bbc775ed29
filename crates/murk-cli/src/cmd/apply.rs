//! `murk apply`: degrade clear-weather point clouds with a fitted model.
//!
//! ```text
//! murk apply --coefficients T.json --weather fog --mor 60 INPUTS... --out DIR
//!            [--rain-rate R [--clamp]] [--format F] [--pcd-data D]
//!            [--near-range [--near-range-count-scale S]] [--range-noise SIGMA]
//!            [--attenuate-intensity] [--soft-edge] [--slope survival|quantile]
//!            [--seed N] [--range-scale K] [--intensity-scale NAME]
//!            [--campaign DIR] [--clear-mor-threshold M] [--summary FILE]
//!            [--columns x,y,z,intensity,ring] [--bin-layout xyzi|xyzir|xyzit]
//!            [--keep-partial]
//! ```
//!
//! Glue only: flags → [`murk_infer::ApplyParams`] → [`murk_infer::batch`].
//! INPUTS are files or folders (walked recursively; files that are not point
//! clouds are listed, not read); outputs keep their names below `--out`, in
//! the input's format or `--format`. Nothing is written when an output would
//! overwrite an input. A `.pcap` is applied per revolution into
//! `OUT/<stem>/frame-NNNNNN.<ext>` (give `--format`); its partial first and
//! last revolutions are left out unless `--keep-partial`. The summary says
//! in which intensity scale the inputs were read and whether that scale was
//! declared (`--intensity-scale`, `--campaign`), recorded in the file or
//! assumed from the format.

use std::path::PathBuf;

use anyhow::{Context, bail};
use murk_infer::batch;
use murk_infer::{ApplyParams, ApplySummary, BatchOptions, Severity, SlopeSource};
use murk_io::{PcdData, ReadOptions};
use murk_types::{BinLayout, IntensityScale, PcapReturn, PointFormat, WeatherClass};

/// Arguments of `murk apply`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Coefficient table written by `murk fit`.
    #[arg(long)]
    pub coefficients: PathBuf,
    /// Weather to apply: fog, rain or snow.
    #[arg(long)]
    pub weather: WeatherClass,
    /// Meteorological optical range, metres.
    #[arg(
        long,
        required_unless_present = "rain_rate",
        conflicts_with = "rain_rate"
    )]
    pub mor: Option<f64>,
    /// Rain rate, mm/h (rain only), converted with the table's rate → MOR fit.
    #[arg(long)]
    pub rain_rate: Option<f64>,
    /// Clamp a rain rate outside the conversion's validity into it (warned)
    /// instead of failing.
    #[arg(long, requires = "rain_rate")]
    pub clamp: bool,
    /// Files or folders of clear-weather scans.
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// Output folder (created when missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Output format (pcd, bin, nuscenes, csv, parquet); default: each input's.
    #[arg(long, value_parser = parse_writable_format)]
    pub format: Option<PointFormat>,
    /// PCD data encoding of PCD outputs: ascii, binary or binary_compressed.
    #[arg(long, default_value = "binary")]
    pub pcd_data: PcdData,
    /// Add ghost and ring returns from the table's laws.
    #[arg(long)]
    pub near_range: bool,
    /// Multiply the table's ghost/ring count per scan. The table counts per
    /// revolution (`lidar.count_unit`), so 1 gives each input scan one
    /// revolution's worth; give N for an input that accumulates N revolutions.
    #[arg(long, default_value_t = 1.0, requires = "near_range")]
    pub near_range_count_scale: f64,
    /// σ (metres) of Gaussian range noise on kept returns.
    #[arg(long, value_name = "SIGMA")]
    pub range_noise: Option<f64>,
    /// Attenuate kept intensities by exp(−2·α·r), α = ln(20)/MOR.
    #[arg(long)]
    pub attenuate_intensity: bool,
    /// Stochastic survival edge from the table's survival fit.
    #[arg(long)]
    pub soft_edge: bool,
    /// Slope estimate: survival (the table's vanishing_slope) or quantile
    /// (vanishing_slope_q99, the seed's method).
    #[arg(long, default_value = "survival", value_parser = parse_slope)]
    pub slope: SlopeSource,
    /// Master seed of every random draw.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Value of a scan-level covariate for the table's extension terms
    /// (from `murk diagnose`), `NAME=VALUE`; repeatable.
    #[arg(long = "covariate", value_name = "NAME=VALUE")]
    pub covariates: Vec<String>,
    /// Apply the baseline model of an extended table (ignore its extension terms).
    #[arg(long)]
    pub no_extensions: bool,
    /// Range-scale coefficient of the target sensor; default: the table's.
    #[arg(long)]
    pub range_scale: Option<f64>,
    /// Scale the inputs' intensity is in (calibrated, kitti, six-bit, …);
    /// default: what each file records, else its format's own.
    #[arg(long)]
    pub intensity_scale: Option<IntensityScale>,
    /// Column names of header-less CSV inputs, in order (e.g.
    /// x,y,z,intensity,ring).
    #[arg(long, value_delimiter = ',', value_name = "NAMES")]
    pub columns: Option<Vec<String>>,
    /// Record layout of `.bin` inputs: xyzi (KITTI), xyzir (Seeing Through
    /// Fog), xyzit; default: KITTI where the file size leaves no doubt.
    #[arg(long, value_name = "LAYOUT")]
    pub bin_layout: Option<BinLayout>,
    /// Which return of each firing to read from dual-return `.pcap`
    /// inputs: strongest or last (default: the campaign's `pcap_return`, else as recorded: both).
    #[arg(long, value_name = "RETURN")]
    pub pcap_return: Option<PcapReturn>,
    /// Also apply to the partial first and last revolutions of captures.
    #[arg(long)]
    pub keep_partial: bool,
    /// A campaign folder whose `[lidar]` describes the input sensor (ring
    /// elevations for ring derivation and near-range rays, azimuth grid,
    /// `min_range_m`).
    #[arg(long)]
    pub campaign: Option<PathBuf>,
    /// Points nearer than this (metres) are not returns — the no-return
    /// firings nuScenes and Ouster files keep as points at the origin, the
    /// vehicle's body: written as they were (default: the campaign's
    /// `min_range_m`, else every point is a return).
    #[arg(long, value_name = "M")]
    pub min_range: Option<f64>,
    /// MOR (m) at and above which applying is the identity (default 2000,
    /// the PDD rules' clear threshold; the table does not record one).
    #[arg(long)]
    pub clear_mor_threshold: Option<f64>,
    /// Also write the JSON report (murk-apply-summary/1) here.
    #[arg(long)]
    pub summary: Option<PathBuf>,
}

fn parse_writable_format(s: &str) -> Result<PointFormat, String> {
    match PointFormat::from_name(s) {
        Ok(f) if f.writable() => Ok(f),
        _ => Err(format!(
            "{s:?} is not a format murk writes: expected pcd, bin, nuscenes, csv or parquet"
        )),
    }
}

fn parse_slope(s: &str) -> Result<SlopeSource, String> {
    match s {
        "survival" => Ok(SlopeSource::Survival),
        "quantile" | "q99" => Ok(SlopeSource::Quantile),
        _ => Err(format!("{s:?}: expected survival or quantile")),
    }
}

/// Runs `murk apply`.
pub fn run(a: Args) -> anyhow::Result<()> {
    super::check_folder_target("--out", &a.out)?;
    if let Some(p) = &a.summary {
        super::check_file_target("--summary", p)?;
    }
    let severity = match (a.mor, a.rain_rate) {
        (Some(m), None) => Severity::Mor(m),
        (None, Some(r)) => Severity::RainRate(r),
        _ => bail!("give exactly one of --mor and --rain-rate"),
    };
    let lidar = match &a.campaign {
        Some(dir) => Some(
            murk_campaign::Campaign::open(dir)
                .with_context(|| format!("reading the sensor description of {}", dir.display()))?
                .lidar()
                .clone(),
        ),
        None => None,
    };
    let mut params = ApplyParams::new(a.weather, severity)
        .clamp_rain_rate(a.clamp)
        .near_range(a.near_range)
        .near_range_count_scale(a.near_range_count_scale)
        .range_noise_m(a.range_noise.unwrap_or(0.0))
        .attenuate_intensity(a.attenuate_intensity)
        .soft_edge(a.soft_edge)
        .slope_source(a.slope)
        .seed(a.seed)
        .extensions(!a.no_extensions);
    for c in &a.covariates {
        let (name, value) = c
            .split_once('=')
            .with_context(|| format!("--covariate {c:?}: expected NAME=VALUE"))?;
        params = params.covariate(name.trim(), murk_types::CovariateValue::parse(value));
    }
    if let Some(k) = a.range_scale {
        params = params.range_scale(k);
    }
    if let Some(m) = a.clear_mor_threshold {
        params = params.clear_mor_threshold_m(m);
    }
    if let Some(spec) = &lidar {
        params = params.lidar(spec.clone());
    }
    if let Some(m) = a.min_range {
        params = params.min_range_m(m);
    }
    let applier = params.build_from_file(&a.coefficients)?;
    for w in applier.warnings() {
        errln!("murk: warning: {w}");
    }

    let opts = BatchOptions {
        read: ReadOptions {
            format: None,
            lidar,
            intensity_scale: a.intensity_scale,
            bin_layout: a.bin_layout,
            csv_columns: a.columns.clone(),
            pcap_return: a.pcap_return,
        },
        format: a.format,
        pcd_data: a.pcd_data,
        keep_partial: a.keep_partial,
    };
    let plan = batch::plan(&a.inputs, &a.out, &opts)?;
    for s in &plan.skipped {
        errln!("murk: skipped {}: {}", s.path.display(), s.reason);
    }
    if plan.jobs.is_empty() {
        let n = plan.skipped.len();
        bail!(
            "no point-cloud file among the inputs ({n} other {} listed above {} left out)",
            if n == 1 { "entry" } else { "entries" },
            if n == 1 { "was" } else { "were" }
        );
    }
    // Temporary files of killed runs, in the folders this run writes to.
    super::clean_stale(
        std::iter::once(a.out.clone()).chain(
            plan.jobs
                .iter()
                .filter_map(|j| j.output.parent().map(std::path::Path::to_path_buf)),
        ),
    );

    let stop = super::interrupt_flag()?;
    let bar = super::progress_bar(plan.jobs.len(), "files", false);
    let report = batch::run_until(
        &applier,
        &plan,
        &opts,
        &|f| {
            bar.set_message(f.summary.scan.clone());
            bar.inc(1);
        },
        &stop,
    );
    bar.finish_and_clear();
    let report = match report {
        Err(murk_infer::InferError::Interrupted { done, total }) => {
            return Err(super::Interrupted(format!(
                "interrupted: {done} of {total} file{} written to {} (each complete); \
                 the others were not started and no temporary file is left",
                if total == 1 { "" } else { "s" },
                a.out.display()
            ))
            .into());
        }
        r => r?,
    };

    if let Some(path) = &a.summary {
        report.write(path)?;
    }
    // The model's warnings were printed above (and are `model.warnings` in
    // the report); the totals carry the scans' own.
    for w in &report.totals.warnings {
        errln!("murk: warning: {w}");
    }
    if let Some(w) = report.totals.near_origin_warning() {
        errln!("murk: warning: {w}");
    }
    print_summary(&report.totals, &report.model, &report.files, &a.out);
    Ok(())
}

/// `calibrated (declared) for 3 files, kitti (assumed (format default)) for
/// 1 file`: the scales the inputs were read in.
fn scales_line(files: &[murk_infer::FileReport]) -> String {
    let mut counts: std::collections::BTreeMap<(String, &str), usize> = Default::default();
    for f in files {
        *counts
            .entry((f.intensity_scale.clone(), f.intensity_scale_source))
            .or_default() += 1;
    }
    counts
        .iter()
        .map(|((scale, source), n)| {
            format!(
                "{scale} ({source}) for {n} file{}",
                if *n == 1 { "" } else { "s" }
            )
        })
        .collect::<Vec<_>>()
        .join(", ")
}

fn print_summary(
    t: &ApplySummary,
    m: &murk_infer::ModelSummary,
    reports: &[murk_infer::FileReport],
    out: &std::path::Path,
) {
    let files = reports.len();
    let mor = m
        .mor_m
        .map_or("∞ (no rain)".into(), |v| format!("{v:.2} m"));
    let effects: Vec<&str> = [
        (m.near_range, "near-range returns"),
        (m.range_noise_m.is_some(), "range noise"),
        (m.attenuation_alpha_per_m.is_some(), "intensity attenuation"),
    ]
    .iter()
    .filter(|(on, _)| *on)
    .map(|(_, n)| *n)
    .collect();
    outln!(
        "applied {} at MOR {mor} ({} vanishing{}{}) to {files} file{} → {}",
        m.weather,
        m.vanishing,
        if effects.is_empty() { "" } else { ", " },
        effects.join(", "),
        if files == 1 { "" } else { "s" },
        out.display()
    );
    if m.identity {
        outln!(
            "  clear weather (MOR ≥ {} m): outputs equal inputs",
            m.clear_mor_threshold_m
        );
    }
    outln!(
        "  points in {}, out {}, vanished {} ({:.2} % kept)",
        t.points_in,
        t.points_out,
        t.vanished,
        100.0 * t.kept_fraction()
    );
    if !reports.is_empty() {
        outln!("  intensity read as {}", scales_line(reports));
    }
    if t.below_bands > 0
        && let Some(first) = m.bands.first()
    {
        outln!(
            "  reflectivity below {} (under the table's first band): {} in, {} vanished (at the first band's distance)",
            first.reflectivity_min,
            t.below_bands,
            t.below_bands_vanished
        );
    }
    for (b, r) in t.bands.iter().zip(&m.bands) {
        let hi = b
            .reflectivity_max
            .map_or("∞".to_string(), |v| format!("{v}"));
        let d = r
            .vanishing_distance_m
            .map_or("∞".to_string(), |v| format!("{v:.2} m"));
        // Each return its own distance: say at which reflectivity.
        let d = match &r.reflectivity {
            Some(t) => format!(
                "{d} at reflectivity {:.1}, times (x/{:.1})^{:.3}",
                t.reference, t.reference, t.exponent
            ),
            None => d,
        };
        outln!(
            "  reflectivity [{}, {hi}): {} in, {} vanished (beyond {d})",
            b.reflectivity_min,
            b.points_in,
            b.vanished
        );
    }
    for (name, c) in [("ghost", &t.ghost), ("ring", &t.ring)] {
        if let Some(c) = c {
            outln!(
                "  {name}: {} drawn, {} replaced, {} added, {} occluded{}",
                c.drawn,
                c.replaced,
                c.added,
                c.occluded,
                if c.unplaced > 0 {
                    format!(", {} not placed", c.unplaced)
                } else {
                    String::new()
                }
            );
        }
    }
    if t.range_noise_points > 0 {
        outln!("  range noise on {} points", t.range_noise_points);
    }
    if t.attenuated_points > 0 {
        outln!("  intensity attenuated on {} points", t.attenuated_points);
    }
    if t.not_returns > 0 {
        outln!(
            "  {} points nearer than the minimum range written as they were (not returns)",
            t.not_returns
        );
    }
}
