//! Time and peak memory of `murk diagnose` against the number of recordings
//! (issue #13 item 6): prints figures, it is not a timed test.
//!
//! Generates a campaign of `N` recordings of HDL-64 size (an HDL-64-like
//! sensor: 64 rings, +2° to −24.33°, fired every 0.2°; the small preset's
//! scene gives about 45 k points per scan; 20 % clear, 80 % fog; generator
//! seed 1) into `DIR/hdl64-N`
//! unless it is there already, diagnoses fog with the default parameters
//! (seed 0) and prints the wall time, the peak resident memory of the
//! process (`VmHWM` from `/proc/self/status`, so run one `N` per process
//! for a clean figure). The report and extended
//! table are written to `DIR/hdl64-N.report.json` and
//! `DIR/hdl64-N.extended.json`, so that two builds can be compared byte for
//! byte. Delete `DIR` afterwards: 1,000 recordings are about 2 GB.
//!
//! `cargo build --workspace --release --examples`, then
//! `target/release/examples/diagnose_bench DIR N [--vlp16] [--azimuth DEG] [--hide] [--keep] [--kept-memory-mb MB] [--clear-memory-mb MB]`
//! (`--vlp16`: the small preset's VLP-16 instead; `--azimuth 0.09`: the
//! HDL-64 fired every 0.09° instead of 0.2°, about 100 k points per scan
//! as at 5 Hz, the campaign named `hdl64-0.09-N`; `--hide`: the campaign
//! hides a survival effect (fog survival × elevation, a factor 0.8 on the
//! vanishing distance below −10°), so that the run fits a survival term,
//! the name ending in `-hide`; `--keep` keeps the campaign, which is
//! otherwise removed after the run; `--kept-memory-mb`: the diagnosis's
//! memory budget for kept returns, 256 by default, beyond which they spill
//! to a temporary file — `inf` holds them all; `--clear-memory-mb`: the
//! same for the clear recordings' cell images while the reference is
//! built, 256 by default). The mean points
//! per scan of the first recording is printed with the figures.

use std::path::PathBuf;
use std::time::Instant;

use murk_campaign::Campaign;
use murk_diagnose::DiagnoseParams;
use murk_fixtures::{
    EffectFunction, EffectSpec, Generator, GeneratorConfig, Observable, OutputOptions, PerClass,
    Preset,
};
use murk_types::WeatherClass;

/// A `/proc/self/status` field in MB (`VmHWM`: peak resident set).
fn status_mb(field: &str) -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with(field))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: diagnose_bench DIR N [--vlp16] [--azimuth DEG] [--hide] [--keep] [--kept-memory-mb MB] [--clear-memory-mb MB]";
    let dir: PathBuf = args.first().map(PathBuf::from).ok_or(usage)?;
    let n: usize = args.get(1).ok_or(usage)?.parse()?;
    let vlp16 = args.iter().any(|a| a == "--vlp16");
    let keep = args.iter().any(|a| a == "--keep");
    let hide = args.iter().any(|a| a == "--hide");
    let kept_mb: f64 = match args.iter().position(|a| a == "--kept-memory-mb") {
        Some(i) => args.get(i + 1).ok_or(usage)?.parse()?,
        None => 256.0,
    };
    if let Some(i) = args.iter().position(|a| a == "--clear-memory-mb") {
        let mb: f64 = args.get(i + 1).ok_or(usage)?.parse()?;
        murk_fit::set_clear_image_memory_mb(mb)?;
    }
    let azimuth: Option<f64> = match args.iter().position(|a| a == "--azimuth") {
        Some(i) => Some(args.get(i + 1).ok_or(usage)?.parse()?),
        None => None,
    };
    let name = match (vlp16, azimuth) {
        (true, _) => format!("vlp16-{n}"),
        (false, None) => format!("hdl64-{n}"),
        (false, Some(a)) => format!("hdl64-{a}-{n}"),
    } + if hide { "-hide" } else { "" };
    let path = dir.join(&name);
    if !path.join("campaign.toml").is_file() {
        let t = Instant::now();
        let mut c = GeneratorConfig::preset(Preset::Small);
        if !vlp16 {
            c.lidar.model = "HDL64".into();
            c.lidar.elevation_deg = (0..32)
                .map(|k| 2.0 - k as f64 / 3.0)
                .chain((0..32).map(|k| -8.83 - k as f64 * 0.5))
                .collect();
            c.lidar.azimuth_resolution_deg = azimuth.unwrap_or(0.2);
            c.sensor.azimuth_phase_deg = 0.13;
        }
        c.campaign.recordings = n;
        c.weather.mix = PerClass {
            clear: 0.2,
            fog: 0.8,
            rain: 0.0,
            snow: 0.0,
        };
        if hide {
            c.effects = vec![EffectSpec {
                name: "lower beams see less far".into(),
                observable: Observable::Survival,
                survival_mode: None,
                covariate: "elevation".into(),
                weathers: vec![WeatherClass::Fog],
                function: EffectFunction::Step {
                    threshold: -10.0,
                    below: 0.8,
                    above: 1.0,
                },
                returns: None,
            }];
        }
        Generator::new(c)?.write_campaign(1, &OutputOptions::new(&path))?;
        println!(
            "generated {} in {:.1} s",
            path.display(),
            t.elapsed().as_secs_f64()
        );
    }
    let before = status_mb("VmHWM").unwrap_or(f64::NAN);
    let campaign = Campaign::open(&path)?;
    let points = match campaign.recordings().first() {
        Some(r) => {
            let (cloud, scans) =
                murk_diagnose::data::read_revolutions(&r.lidar().path, campaign.lidar())?;
            cloud.len() as f64 / scans as f64
        }
        None => f64::NAN,
    };
    let t = Instant::now();
    let d = DiagnoseParams::new(WeatherClass::Fog)
        .kept_memory_mb(kept_mb)
        .check()?
        .run(&campaign)?;
    let secs = t.elapsed().as_secs_f64();
    let peak = status_mb("VmHWM").unwrap_or(f64::NAN);
    std::fs::write(dir.join(format!("{name}.report.json")), d.report.to_json())?;
    if let Some(t) = &d.extended_table {
        std::fs::write(dir.join(format!("{name}.extended.json")), t.to_json()?)?;
    }
    println!(
        "{name}: {} recordings ({} fog held out), {points:.0} points per scan, {} rayon threads",
        campaign.recordings().len(),
        d.report.heldout_recordings,
        rayon::current_num_threads()
    );
    println!(
        "diagnose: {secs:.1} s, peak RSS {peak:.0} MB (before the run {before:.0} MB, kept returns held up to {kept_mb} MB); {} steps, {} findings",
        d.report.steps.len(),
        d.report.findings.iter().filter(|f| f.significant).count()
    );
    if !keep {
        std::fs::remove_dir_all(&path)?;
    }
    Ok(())
}
