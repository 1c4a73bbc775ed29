//! `murk diagnose CAMPAIGN --weather W [--coefficients T.json] --out report.json`:
//! what the fitted model gets wrong on held-out recordings, why, and what
//! extending it gains.
//!
//! Glue only: flags → [`murk_diagnose::DiagnoseParams`] →
//! [`murk_diagnose::DiagnoseValidParams::run`] → the report (and the extended
//! table, and figures) written atomically.

use std::path::PathBuf;

use anyhow::Context as _;
use murk_campaign::Campaign;
use murk_diagnose::DiagnoseParams;
use murk_diagnose::scene::VoxelBox;
use murk_types::{CoefficientTable, WeatherClass};

/// Arguments of `murk diagnose`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The campaign folder.
    pub campaign: PathBuf,
    /// The weather to diagnose: fog, rain or snow.
    #[arg(long)]
    pub weather: String,
    /// A baseline coefficient table (default: fit one per fold).
    #[arg(long)]
    pub coefficients: Option<PathBuf>,
    /// Where to write the report (JSON, written atomically).
    #[arg(long)]
    pub out: PathBuf,
    /// Where to write the coefficient table to apply (default: beside the
    /// report, `<out stem>.extended.json`): the baseline plus the extension
    /// term of the top finding, or the baseline alone when nothing is found.
    #[arg(long)]
    pub extended_table: Option<PathBuf>,
    /// Folder for the figures (PNG and SVG); created when missing.
    #[arg(long)]
    pub figures: Option<PathBuf>,
    /// Folds by recording.
    #[arg(long, default_value_t = 3)]
    pub folds: usize,
    /// Seed of the fold split, permutations and simulations.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Null draws per test.
    #[arg(long, default_value_t = 1999)]
    pub permutations: usize,
    /// Family-wise error rate.
    #[arg(long, default_value_t = 0.05)]
    pub alpha: f64,
    /// Simulations per held-out recording.
    #[arg(long, default_value_t = 2)]
    pub sims: usize,
    /// Voxel size of the scene metrics, metres.
    #[arg(long, default_value_t = 1.0)]
    pub voxel: f64,
    /// Box of the localised voxel difference: `xmin,ymin,zmin,xmax,ymax,zmax`.
    #[arg(long, value_delimiter = ',', num_args = 6)]
    pub local_box: Option<Vec<f64>>,
    /// Megabytes of kept returns held in memory; the recordings beyond
    /// spill theirs to an anonymous temporary file (same output; 0 spills
    /// all).
    #[arg(long, default_value_t = 256.0)]
    pub kept_memory_mb: f64,
    /// Megabytes of clear recordings' cell images held in memory while the
    /// clear reference is built; the recordings beyond spill theirs to an
    /// anonymous temporary file (same output; 0 spills all).
    #[arg(long, default_value_t = 256.0)]
    pub clear_memory_mb: f64,
    /// Folder of the temporary files (default: the system's temporary
    /// folder; put it on a disk, not a RAM-backed /tmp).
    #[arg(long)]
    pub spill_dir: Option<PathBuf>,
}

/// Runs `murk diagnose`.
pub fn run(a: Args) -> anyhow::Result<()> {
    super::check_file_target("--out", &a.out)?;
    let extended_path = a.extended_table.clone().unwrap_or_else(|| {
        let stem = a
            .out
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("report");
        a.out.with_file_name(format!("{stem}.extended.json"))
    });
    super::check_file_target("--extended-table", &extended_path)?;
    if let Some(dir) = &a.figures {
        super::check_folder_target("--figures", dir)?;
    }
    super::clear_spill(a.clear_memory_mb, a.spill_dir.clone())?;
    let weather: WeatherClass = a
        .weather
        .parse()
        .map_err(|e| anyhow::anyhow!("--weather {:?}: {e}", a.weather))?;
    let campaign = Campaign::open(&a.campaign)
        .with_context(|| format!("opening campaign {}", a.campaign.display()))?;
    let table = match &a.coefficients {
        Some(p) => Some(
            CoefficientTable::read(p)
                .with_context(|| format!("reading coefficient table {}", p.display()))?,
        ),
        None => None,
    };
    let local_box = a.local_box.as_ref().map(|v| VoxelBox {
        min: [v[0], v[1], v[2]],
        max: [v[3], v[4], v[5]],
    });
    let params = DiagnoseParams::new(weather)
        .folds(a.folds)
        .seed(a.seed)
        .permutations(a.permutations)
        .alpha(a.alpha)
        .sims(a.sims)
        .voxel_m(a.voxel)
        .local_box(local_box)
        .coefficients(table)
        .kept_memory_mb(a.kept_memory_mb)
        .spill_dir(a.spill_dir.clone())
        .check()?;
    let bar = super::spinner(format!(
        "diagnosing {weather} in {} ({} folds)",
        a.campaign.display(),
        a.folds
    ));
    let d = params.run(&campaign);
    bar.finish_and_clear();
    let d = d?;
    let r = &d.report;
    if let Some(parent) = a.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("creating {}", parent.display()))?;
    }
    murk_types::write_atomic(&a.out, r.to_json().as_bytes())
        .with_context(|| format!("writing {}", a.out.display()))?;
    let m = &r.baseline.metrics;
    outln!(
        "{}: {} recordings held out over {} folds; baseline survival log loss {:.4}, voxel global difference {}",
        r.weather,
        r.heldout_recordings,
        r.folds,
        m.survival_log_loss,
        m.voxel_global_difference
            .map_or("n/a".to_string(), |v| format!("{v:.3}"))
    );
    let sig: Vec<_> = r.findings.iter().filter(|f| f.significant).collect();
    if sig.is_empty() {
        outln!(
            "no significant finding (Holm-adjusted p < {} and effect ≥ threshold)",
            a.alpha
        );
    }
    for f in &sig {
        outln!(
            "  {} vs {:?}: strength {:.2} (effect {:.4}, p_adj {:.4}) — {}",
            f.observable,
            f.covariate,
            f.strength,
            f.effect,
            f.p_adjusted,
            f.cause
        );
    }
    // What the tests that found nothing could have found.
    let power = r.power_summary();
    if !power.is_empty() {
        outln!(
            "not found, with what each test could have found on this campaign (worst step along the covariate, α/m per test):"
        );
        for line in &power {
            outln!("  {line}");
        }
    }
    for (i, st) in r.steps.iter().enumerate() {
        let params: Vec<String> = st
            .parameters
            .iter()
            .map(|p| match p.ci95 {
                Some([lo, hi]) => format!("{} = {:.4} ({:.4}–{:.4})", p.name, p.value, lo, hi),
                None => format!("{} = {:.4}", p.name, p.value),
            })
            .collect();
        let shape = if params.is_empty() {
            st.shape.clone()
        } else {
            format!("{} {}", st.shape, params.join(", "))
        };
        outln!(
            "step {}: {} along {:?} [{}]: {} {:.4} → {:.4} on held-out recordings ({:+.1} %, paired p {:.4})",
            i + 1,
            st.observable,
            st.covariate,
            shape,
            st.gain.metric,
            st.gain.before,
            st.gain.after,
            100.0 * st.gain.relative,
            st.p_value
        );
    }
    for x in &r.rejected {
        outln!(
            "  turned down: {} along {:?} — {}",
            x.observable,
            x.covariate,
            x.reason
        );
    }
    if let Some(g) = &r.gain {
        outln!(
            "extended with {} term{}: {} {:.4} → {:.4} on held-out recordings ({:+.1} %)",
            r.steps.len(),
            if r.steps.len() == 1 { "" } else { "s" },
            g.metric,
            g.before,
            g.after,
            100.0 * g.relative
        );
    }
    if let Some(t) = &d.extended_table {
        let path = &extended_path;
        let json = t.to_json().context("serialising the extended table")?;
        murk_types::write_atomic(path, json.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
        if r.gain.is_some() {
            outln!("extended table: {}", path.display());
        } else {
            outln!(
                "table to apply: {} (the baseline{}, no extension term: nothing was found to extend along)",
                path.display(),
                if a.coefficients.is_some() {
                    " given"
                } else {
                    " fitted on every recording"
                }
            );
        }
    }
    if let Some(dir) = &a.figures {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        crate::cmd::diagnose_figures::write(&d, dir)?;
    }
    outln!("report: {}", a.out.display());
    Ok(())
}
