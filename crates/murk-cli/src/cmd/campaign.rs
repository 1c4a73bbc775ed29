//! `murk campaign`: inspect a campaign folder.
//!
//! `murk campaign summary DIR [--figures OUT] [--json]` opens the campaign,
//! applies its selection rules and review, prints the summary (counts per
//! weather class before and after review, outages, ambiguity, MOR
//! distribution) as a table or as JSON, and with `--figures` writes
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
    if args.json {
        outln!("{}", serde_json::to_string_pretty(summary)?);
    } else {
        out!("{summary}");
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
