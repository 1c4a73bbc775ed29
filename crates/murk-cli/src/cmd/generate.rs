//! `murk generate`: write a synthetic campaign whose truth is known.
//!
//! Glue only: flags → a checked [`murk_fixtures::Generator`] → one call to
//! [`murk_fixtures::Generator::write_campaign`] → a summary line. The output
//! is byte-identical for identical seed and configuration whatever the
//! number of threads (set it with `RAYON_NUM_THREADS`).

use std::path::PathBuf;

use anyhow::Context as _;
use murk_fixtures::{Generator, GeneratorConfig, OutputOptions, Preset};
use murk_types::WeatherClass;

/// Arguments of `murk generate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Campaign folder to write (created; must not exist unless --force).
    #[arg(long)]
    pub out: PathBuf,
    /// Campaign seed: identical seed and configuration give identical bytes.
    #[arg(long)]
    pub seed: u64,
    /// TOML configuration read over the preset (only what differs).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Preset to start from: default (0.2° VLP-16, 200 recordings),
    /// seed-tables (the seed's hard-threshold model), small (1°, 80 recordings).
    #[arg(long, default_value = "default", value_parser = ["default", "seed-tables", "small"])]
    pub preset: String,
    /// Number of recordings (overrides the configuration).
    #[arg(long)]
    pub recordings: Option<usize>,
    /// Point-file format (overrides the configuration).
    #[arg(long, value_parser = ["pcd", "bin", "pcd.bin", "csv", "parquet"])]
    pub format: Option<String>,
    /// Truth file (default: `<out>.truth.json`, beside the campaign).
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Replace an existing campaign folder (one holding campaign.toml).
    #[arg(long)]
    pub force: bool,
}

/// Runs `murk generate`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let preset = Preset::from_name(&args.preset)
        .with_context(|| format!("unknown preset {:?}", args.preset))?;
    let base = GeneratorConfig::preset(preset);
    let (mut config, source) = match &args.config {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("{}: cannot read configuration", path.display()))?;
            let name = path.display().to_string();
            (
                GeneratorConfig::merge_toml(&base, &text, &name)?,
                Some((name, text)),
            )
        }
        None => (base, None),
    };
    if let Some(n) = args.recordings {
        config.campaign.recordings = n;
    }
    if let Some(f) = &args.format {
        config.campaign.format = f.clone();
    }
    let generator = match &source {
        Some((name, text)) => Generator::with_source(config, name, Some(text))?,
        None => Generator::with_source(config, &format!("<preset {}>", preset.name()), None)?,
    };
    let opts = OutputOptions {
        out: args.out.clone(),
        truth: args.truth.clone(),
        force: args.force,
    };
    let started = std::time::Instant::now();
    let truth = generator.write_campaign(args.seed, &opts)?;
    let points: usize = truth.recordings.iter().map(|r| r.counts.points).sum();
    let per_class: Vec<String> = WeatherClass::ALL
        .iter()
        .map(|c| {
            let n = truth.recordings.iter().filter(|r| r.class == *c).count();
            format!("{c} {n}")
        })
        .collect();
    outln!(
        "wrote {} recordings ({}), {points} points, to {} in {:.1} s; truth: {}",
        truth.recordings.len(),
        per_class.join(", "),
        args.out.display(),
        started.elapsed().as_secs_f64(),
        opts.truth_path().display()
    );
    Ok(())
}
