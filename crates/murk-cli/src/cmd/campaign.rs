//! `murk campaign`: inspect a campaign folder.
//!
//! `murk campaign summary DIR [--figures OUT] [--json]` opens the campaign,
//! applies its selection rules and review, prints the summary (counts per
//! weather class before and after review, outages, ambiguity, MOR
//! distribution) and the LiDAR geometry measured from the clear recordings
//! (per ring firing step, phase and elevation, and what contradicts
//! campaign.toml; `lidar_geometry` and `lidar_warnings` in the JSON) as a
//! table or as JSON. Measuring reads point clouds, which `murk-campaign`
//! never does, so the CLI calls `murk_fit::observe::measure_geometry`; a
//! campaign whose clouds cannot be read still gets its summary, with the
//! reason in place of the geometry. With `--figures` it writes
//! `mor-histogram.png` and `mor-histogram.svg` (MOR of the kept recordings of
//! each degraded class) into `OUT`.

use std::path::PathBuf;

use anyhow::Context;
use murk_campaign::Campaign;
use murk_figures::{FigureOptions, write_mor_histograms};
use murk_types::WeatherClass;

/// Arguments of `murk campaign`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Subcommand, Debug)]
enum Command {
    /// Print what the selection rules and the review make of a campaign.
    Summary(SummaryArgs),
}

/// Arguments of `murk campaign summary`.
#[derive(clap::Args, Debug)]
struct SummaryArgs {
    /// The campaign folder (campaign.toml, weather.csv, lidar/, …).
    dir: PathBuf,
    /// Also write mor-histogram.png and mor-histogram.svg into this folder
    /// (created when missing).
    #[arg(long, value_name = "DIR")]
    figures: Option<PathBuf>,
    /// Print the summary as JSON instead of a table.
    #[arg(long)]
    json: bool,
}

/// Runs `murk campaign`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        Command::Summary(a) => summary(a),
    }
}

fn summary(args: SummaryArgs) -> anyhow::Result<()> {
    if let Some(dir) = &args.figures {
        super::check_folder_target("--figures", dir)?;
    }
    let campaign = Campaign::open(&args.dir)
        .with_context(|| format!("cannot open campaign {}", args.dir.display()))?;
    let selection = campaign.select();
    let summary = selection.summary();
    let inputs = murk_fit::FitInputs::from_campaign(&campaign);
    let geometry = murk_fit::observe::measure_geometry(&inputs);
    if args.json {
        let mut v = serde_json::to_value(summary)?;
        if let Some(o) = v.as_object_mut() {
            match &geometry {
                Ok((g, w)) => {
                    o.insert("lidar_geometry".into(), serde_json::to_value(g)?);
                    o.insert("lidar_warnings".into(), serde_json::to_value(w)?);
                }
                Err(e) => {
                    o.insert("lidar_geometry".into(), serde_json::Value::Null);
                    o.insert(
                        "lidar_geometry_reason".into(),
                        format!("cannot measure: {e}").into(),
                    );
                }
            }
        }
        outln!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        out!("{summary}");
        match &geometry {
            Ok((g, w)) => out!("{}", geometry_text(g, w)),
            Err(e) => outln!("lidar geometry: cannot measure: {e}"),
        }
    }
    if let Some(dir) = &args.figures {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create figure folder {}", dir.display()))?;
        let degraded: Vec<WeatherClass> = WeatherClass::DEGRADED
            .into_iter()
            .filter(|c| campaign.rules().class(*c).is_some())
            .collect();
        let data = selection.kept_mor(&degraded);
        let series: Vec<(&str, &[f64])> =
            data.iter().map(|(c, v)| (c.name(), v.as_slice())).collect();
        let opts = FigureOptions {
            title: Some(format!(
                "MOR of the kept recordings, {} ({})",
                campaign.name(),
                campaign.rules().name()
            )),
            ..FigureOptions::default()
        };
        let written = write_mor_histograms(&series, &opts, dir)?;
        for path in written {
            errln!("wrote {}", path.display());
        }
    }
    Ok(())
}

/// The measured geometry as text: one line overall, one per ring, then the
/// warnings.
fn geometry_text(g: &murk_types::SensorGeometry, warnings: &[String]) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "lidar geometry ({} from {} clear recordings, {} scans): azimuth step {:.4}° (campaign.toml: {})",
        g.source, g.recordings, g.frames, g.azimuth_step_deg, g.declared_azimuth_step_deg
    );
    let _ = writeln!(
        s,
        "  ring  step°    phase°   locking  elevation°  declared°  returns"
    );
    for r in &g.rings {
        let el = r
            .elevation_deg
            .map_or("-".to_string(), |e| format!("{e:.2}"));
        let de = r
            .declared_elevation_deg
            .map_or("-".to_string(), |e| format!("{e}"));
        let _ = writeln!(
            s,
            "  {:>4}  {:.4}{}  {:.4}   {:.2}     {el:>9}  {de:>9}  {}",
            r.ring,
            r.azimuth_step_deg,
            if r.measured { " " } else { "*" },
            r.azimuth_phase_deg,
            r.phase_locking,
            r.returns
        );
    }
    if g.rings.iter().any(|r| !r.measured) {
        let _ = writeln!(s, "  * too few returns: the other rings' step");
    }
    for w in warnings {
        let _ = writeln!(s, "warning: {w}");
    }
    s
}
