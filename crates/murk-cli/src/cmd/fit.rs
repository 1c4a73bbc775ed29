//! `murk fit CAMPAIGN --out T.json [--figures DIR]`: fits the coefficient
//! table of a campaign, prints a summary and optionally draws the figures.
//! `murk fit CAMPAIGN --partial OUT.state [--recordings ID,…|--shard K/N]
//! [--reference CLEAR.state]` maps part of it into a fit state, and
//! `murk fit --merge A.state B.state … --out T.json|OUT.state` merges states
//! (see [`murk_fit::FitState`]).
//!
//! Glue only: flags → [`murk_fit::FitParams`] → [`murk_fit::FitValidParams::fit`]
//! (or `fit_partial`, `FitState::merge`) → table or state file, summary and
//! figure data.

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use murk_campaign::Campaign;
use murk_figures::table::{SweepData, noise_laws, range_mor_lines, sweep_series};
use murk_figures::{
    FigureOptions, GaussianPanel, RangeMorFigure, SweepFigure, gaussian_histograms, mor_histogram,
    range_vs_mor, slope_vs_reflectivity,
};
use murk_fit::{FitInputs, FitParams, FitState, FittedTable, NoiseHistograms, Selection};
use murk_types::NoiseLaw;

/// Arguments of `murk fit`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The campaign folder (not with --merge).
    #[arg(required_unless_present = "merge")]
    pub campaign: Option<PathBuf>,
    /// Where to write the coefficient table (JSON, written atomically; its
    /// folder is created when missing). With --merge, a path ending in
    /// `.state` gets the merged state instead of a table.
    #[arg(long, required_unless_present = "partial")]
    pub out: Option<PathBuf>,
    /// Map part of the campaign into a fit state file instead of fitting it:
    /// its clear recordings, or with --reference its degraded ones.
    #[arg(long, value_name = "OUT.state", conflicts_with_all = ["out", "merge", "figures"])]
    pub partial: Option<PathBuf>,
    /// With --partial: only these recordings (ids, comma separated).
    #[arg(
        long,
        value_delimiter = ',',
        requires = "partial",
        conflicts_with = "shard"
    )]
    pub recordings: Vec<String>,
    /// With --partial: block K (1-based) of N nearly equal blocks of the
    /// phase's recordings in campaign order, for example 3/8.
    #[arg(long, value_name = "K/N", requires = "partial")]
    pub shard: Option<String>,
    /// With --partial: the merged state of every clear recording; the
    /// degraded recordings are then mapped against it.
    #[arg(long, value_name = "CLEAR.state", requires = "partial")]
    pub reference: Option<PathBuf>,
    /// Merge these fit states (of one campaign and parameters; the fit
    /// parameters are the states', the flags are not used) into --out.
    #[arg(long, num_args = 1.., value_name = "STATE", conflicts_with = "campaign")]
    pub merge: Vec<PathBuf>,
    /// Folder for the figures (PNG and SVG); created when missing.
    #[arg(long)]
    pub figures: Option<PathBuf>,
    /// Quantile of the seed's estimator.
    #[arg(long, default_value_t = 0.99)]
    pub quantile: f64,
    /// MOR bin width of the quantile estimator, metres.
    #[arg(long, default_value_t = 10.0)]
    pub mor_bin_width: f64,
    /// Reflectivity band edges of the table, comma separated (last band unbounded).
    #[arg(long, value_delimiter = ',', default_value = "0,10")]
    pub bands: Vec<f64>,
    /// Reflectivity band edges of the slope-vs-reflectivity sweep.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "0,5,10,15,20,30,40,60,100"
    )]
    pub sweep: Vec<f64>,
    /// Ghost window `lo,hi`, metres.
    #[arg(long, value_delimiter = ',', num_args = 2, default_values_t = [3.0, 10.0])]
    pub ghost_range: Vec<f64>,
    /// Ring window `lo,hi`, metres.
    #[arg(long, value_delimiter = ',', num_args = 2, default_values_t = [0.0, 3.0])]
    pub ring_range: Vec<f64>,
    /// Absolute pairing tolerance, metres.
    #[arg(long, default_value_t = 0.5)]
    pub pairing_tolerance: f64,
    /// Relative pairing tolerance.
    #[arg(long, default_value_t = 0.02)]
    pub pairing_tolerance_rel: f64,
    /// No-change returns a MOR bin needs.
    #[arg(long, default_value_t = 50)]
    pub min_points_per_bin: u64,
    /// Censoring share of clear returns beyond the quantile.
    #[arg(long, default_value_t = 0.02)]
    pub censor_fraction: f64,
    /// Shape of the soft survival edge: probit or logistic.
    #[arg(long, default_value = "probit")]
    pub edge: String,
    /// Fit one edge width per band instead of a shared one.
    #[arg(long)]
    pub per_band_width: bool,
    /// Fix the dropout to the clear-weather value instead of fitting it.
    #[arg(long)]
    pub fixed_dropout: bool,
    /// Keep a slope that the held-out edge test does not confirm, with the
    /// test's verdict in the band's `reason`, instead of reporting it null
    /// (the default: a slope only where the data show an edge).
    #[arg(long)]
    pub keep_unconfirmed_slopes: bool,
    /// Apply the vanishing law that bends (`a·MOR^b`) where it predicts
    /// held-out recordings better than the line. Off by default: the
    /// comparison is always made and written in `law_choice`, but a bend
    /// chosen from pooled recordings can stand in for a covariate left out
    /// (see `murk diagnose`).
    #[arg(long)]
    pub bend: bool,
    /// Skip the held-out comparison of the bending law with the line
    /// (`law_choice` then says the laws were not compared): the bend's
    /// exponent is profiled in every band and in each fold, most of a fit's
    /// time. Not with `--bend`, which needs it.
    #[arg(long, conflicts_with = "bend")]
    pub no_law_comparison: bool,
    /// Fit a reflectivity term inside each band (`·(x/x_ref)^k`: the lidar
    /// equation in fog gives each return its own vanishing distance by its
    /// reflectivity) and compare it with the chosen law on held-out
    /// recordings (`law_choice.reflectivity`); once it wins, also whether
    /// `k` changes with MOR (`k + g·ln(MOR/M_ref)`,
    /// `law_choice.reflectivity.mor`); applied with `--bend`. A fit takes
    /// several times as long (measured: 3.7 s → 17 s on a 50-recording
    /// campaign, about twice that again where the term wins).
    #[arg(long, conflicts_with = "no_law_comparison")]
    pub reflectivity_law: bool,
    /// Bootstrap replicates for rate uncertainties.
    #[arg(long, default_value_t = 1000)]
    pub bootstrap: u32,
    /// Seed of the bootstrap.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Radar pairing distance, metres.
    #[arg(long, default_value_t = 0.5)]
    pub radar_tolerance: f64,
    /// Megabytes of clear recordings' cell images held in memory while the
    /// clear reference is built; the recordings beyond spill theirs to an
    /// anonymous temporary file (same output; 0 spills all).
    #[arg(long, default_value_t = 256.0)]
    pub clear_memory_mb: f64,
    /// Folder of that temporary file (default: the system's temporary
    /// folder; put it on a disk, not a RAM-backed /tmp).
    #[arg(long)]
    pub spill_dir: Option<PathBuf>,
}

/// Runs `murk fit`.
pub fn run(args: Args) -> anyhow::Result<()> {
    super::clear_spill(args.clear_memory_mb, args.spill_dir.clone())?;
    // Before minutes of fitting, not after.
    if let Some(out) = &args.out {
        super::check_file_target("--out", out)?;
    }
    if let Some(out) = &args.partial {
        super::check_file_target("--partial", out)?;
    }
    if let Some(dir) = &args.figures {
        super::check_folder_target("--figures", dir)?;
    }
    if !args.merge.is_empty() {
        return merge(&args);
    }
    let params = FitParams::default()
        .quantile(args.quantile)
        .mor_bin_width_m(args.mor_bin_width)
        .band_edges(args.bands.clone())
        .sweep_edges(args.sweep.clone())
        .ghost_range_m([args.ghost_range[0], args.ghost_range[1]])
        .ring_range_m([args.ring_range[0], args.ring_range[1]])
        .pairing_tolerance_m(args.pairing_tolerance)
        .pairing_tolerance_rel(args.pairing_tolerance_rel)
        .min_points_per_bin(args.min_points_per_bin)
        .censor_fraction(args.censor_fraction)
        .edge(murk_fit::parse_edge(&args.edge)?)
        .shared_edge_width(!args.per_band_width)
        .free_dropout(!args.fixed_dropout)
        .require_edge(!args.keep_unconfirmed_slopes)
        .apply_bend(args.bend)
        .compare_laws(!args.no_law_comparison)
        .reflectivity_law(args.reflectivity_law)
        .bootstrap_replicates(args.bootstrap)
        .seed(args.seed)
        .radar_tolerance_m(args.radar_tolerance)
        .check()?;
    let Some(dir) = &args.campaign else {
        anyhow::bail!("give a campaign folder, or --merge STATE…");
    };
    let campaign = Campaign::open(dir)?;
    if let Some(state_out) = &args.partial {
        let selection = match (&args.shard, args.recordings.is_empty()) {
            (Some(s), _) => Selection::parse_shard(s)?,
            (None, false) => Selection::Recordings(args.recordings.clone()),
            (None, true) => Selection::All,
        };
        let reference = args.reference.as_deref().map(FitState::read).transpose()?;
        let inputs = FitInputs::from_campaign(&campaign);
        let bar = super::spinner(format!("mapping {}", dir.display()));
        let state = params.fit_partial(&inputs, &selection, reference.as_ref());
        bar.finish_and_clear();
        let state = state?;
        state.write(state_out)?;
        outln!(
            "{} recordings of {} mapped; state written to {}",
            state.recordings().len(),
            state.campaign(),
            state_out.display()
        );
        if let Some(m) = state.missing_description() {
            outln!("still to map: {m}");
        }
        return Ok(());
    }
    let bar = super::spinner(format!("fitting {}", dir.display()));
    let fitted = params.fit(&campaign);
    bar.finish_and_clear();
    write_table(&args, fitted?)
}

/// `murk fit --merge A.state B.state … --out T.json|OUT.state`.
fn merge(args: &Args) -> anyhow::Result<()> {
    let Some(out) = &args.out else {
        anyhow::bail!("--merge needs --out T.json (a table) or --out OUT.state (a merged state)");
    };
    let mut merged: Option<FitState> = None;
    for path in &args.merge {
        let s = FitState::read(path)?;
        merged = Some(match merged {
            None => s,
            Some(m) => m.merge(s)?,
        });
    }
    let Some(state) = merged else {
        anyhow::bail!("--merge needs at least one state file");
    };
    if out.extension().is_some_and(|e| e == "state") {
        state.write(out)?;
        outln!(
            "{} states merged ({} recordings of {}); state written to {}",
            args.merge.len(),
            state.recordings().len(),
            state.campaign(),
            out.display()
        );
        if let Some(m) = state.missing_description() {
            outln!("still to map: {m}");
        }
        return Ok(());
    }
    let fitted = state.finish().with_context(|| {
        format!(
            "{}: a table needs every recording; write the merge to a .state file to keep it",
            out.display()
        )
    })?;
    write_table(args, fitted)
}

fn write_table(args: &Args, fitted: FittedTable) -> anyhow::Result<()> {
    let Some(out) = &args.out else {
        anyhow::bail!("give --out T.json");
    };
    if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("{}: cannot create the folder", parent.display()))?;
    }
    fitted.write(out)?;
    out!("{}", fitted.summary());
    outln!("table written to {}", out.display());
    if let Some(dir) = &args.figures {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create the figure folder", dir.display()))?;
        let written = figures(&fitted, dir)?;
        outln!("{} figures written to {}", written, dir.display());
    }
    Ok(())
}

/// Draws every figure of a fit into `dir` (PNG and SVG); returns how many
/// files were written.
fn figures(fitted: &FittedTable, dir: &Path) -> anyhow::Result<usize> {
    let t = fitted.table();
    let diag = fitted.diagnostics();
    let rs = t.lidar.range_scale;
    let opts = FigureOptions::default();
    let mut n = 0;

    // Figure 24: MOR histograms.
    let mut series: Vec<(&str, &[f64])> = Vec::new();
    for (w, d) in &diag.weathers {
        series.push((w.name(), &d.mor));
    }
    if !series.is_empty() {
        for ext in ["png", "svg"] {
            mor_histogram(&series, &opts, &dir.join(format!("mor-histogram.{ext}")))?;
            n += 1;
        }
    }

    let mut sweep_weathers = Vec::new();
    for (w, c) in &t.weathers {
        let Some(d) = diag.weathers.get(w) else {
            continue;
        };
        // Figure 26: range vs MOR with the table's quantiles and lines, one
        // colour per reflectivity band, nulls said with their reasons.
        let l = range_mor_lines(c, rs);
        let fig = RangeMorFigure {
            weather: w.name(),
            mor: &d.density.mor,
            mor_bin_width: d.density.mor_bin_width_m,
            range_step: d.density.range_step_m,
            kept: &d.density.kept,
            lost: &d.density.lost,
            quantiles: &l.quantiles,
            lines: &l.lines,
            notes: &l.notes,
        };
        for ext in ["png", "svg"] {
            range_vs_mor(&fig, &opts, &dir.join(format!("range-vs-mor-{w}.{ext}")))?;
            n += 1;
        }
        sweep_weathers.push((w.name(), c));

        // Figure 29: ghost and ring histograms with their laws.
        let mut panels = Vec::new();
        for (name, law, reason, hist) in [
            ("ghost", &c.ghost, &c.ghost_reason, &d.ghost),
            ("ring", &c.ring, &c.ring_reason, &d.ring),
        ] {
            if let Some(h) = hist {
                panels.extend(noise_panels(name, law.as_ref(), reason.as_deref(), h));
            }
        }
        if !panels.is_empty() {
            let o = FigureOptions {
                title: Some(format!("{w}: ghost and ring returns")),
                ..FigureOptions::default()
            };
            for ext in ["png", "svg"] {
                gaussian_histograms(&panels, &o, &dir.join(format!("noise-{w}.{ext}")))?;
                n += 1;
            }
        }
    }
    if !sweep_weathers.is_empty() {
        // Figure 27: slope against reflectivity, solid ML and dashed seed
        // quantile estimate, with a key for both.
        let SweepData {
            series,
            names,
            notes,
        } = sweep_series(&sweep_weathers);
        let sweep = SweepFigure {
            series: &series,
            group_names: &names,
            notes: &notes,
        };
        for ext in ["png", "svg"] {
            slope_vs_reflectivity(
                &sweep,
                &opts,
                &dir.join(format!("slope-vs-reflectivity.{ext}")),
            )?;
            n += 1;
        }
    }
    Ok(n)
}

fn noise_panels(
    name: &str,
    law: Option<&NoiseLaw>,
    reason: Option<&str>,
    h: &NoiseHistograms,
) -> [GaussianPanel; 2] {
    let [(dl, dt), (rl, rt)] = noise_laws(name, law, reason);
    [
        GaussianPanel {
            title: format!("{name} distance (m)"),
            lo: h.distance.lo,
            step: h.distance.step,
            counts: h.distance.counts.clone(),
            law: dl,
            truncation: dt,
        },
        GaussianPanel {
            title: format!("{name} reflectivity"),
            lo: h.reflectivity.lo,
            step: h.reflectivity.step,
            counts: h.reflectivity.counts.clone(),
            law: rl,
            truncation: rt,
        },
    ]
}
