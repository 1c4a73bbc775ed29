//! Writes the campaigns issue #12 is measured on into `OUT`, one folder
//! each, so that any `murk fit` (this one, or an older one) can be run on
//! them and the clear no-change rates compared:
//!
//! - `on-grid-S`: the small preset, firings on multiples of the declared 1°
//!   (seeds 1–3);
//! - `free-running-S`: the same at phase 0.37°, free-running, azimuth
//!   jitter σ 0.01° (seeds 4–6);
//! - `real-0.2`, `real-0.4`: the real VLP-16 capture's revolutions (30
//!   clear, 10 unchanged "fog"), declared at 0.2° and at 0.4°;
//! - `real-pcap`: the capture's first half as three clear `.pcap` cuts of
//!   several revolutions each, fog of one revolution from the second half.
//!
//! `cargo run --example issue12_campaigns -- OUT`. The real-capture ones
//! are skipped when `../shared/data/real` is absent.

use std::path::{Path, PathBuf};

use murk_fixtures::semi_real::{self, SemiRealConfig};
use murk_fixtures::{Generator, GeneratorConfig, OutputOptions, Preset};

fn generated(out: &Path, name: &str, seed: u64, edit: impl Fn(&mut GeneratorConfig)) {
    let mut c = GeneratorConfig::preset(Preset::Small);
    c.campaign.recordings = 40;
    edit(&mut c);
    let path = out.join(name);
    Generator::new(c)
        .expect("generator config")
        .write_campaign(seed, &OutputOptions::new(&path))
        .expect("campaign written");
    println!("{}", path.display());
}

fn main() {
    let out: PathBuf = std::env::args_os()
        .nth(1)
        .map(PathBuf::from)
        .expect("usage: issue12_campaigns OUT");
    for seed in [1, 2, 3] {
        generated(&out, &format!("on-grid-{seed}"), seed, |_| {});
    }
    for seed in [4, 5, 6] {
        generated(&out, &format!("free-running-{seed}"), seed, |c| {
            c.sensor.azimuth_phase_deg = 0.37;
            c.sensor.free_running = true;
            c.sensor.azimuth_jitter_deg = 0.01;
        });
    }
    let Some(capture) = semi_real::vlp16_capture(env!("CARGO_MANIFEST_DIR")) else {
        return;
    };
    for declared in [0.2, 0.4] {
        let cfg = SemiRealConfig {
            clear: 30,
            degraded: 10,
            null_weather: true,
            declared_azimuth_deg: declared,
            ..SemiRealConfig::default()
        };
        let path = out.join(format!("real-{declared}"));
        semi_real::vlp16_campaign(&capture, &path, &cfg, 1).expect("semi-real campaign");
        println!("{}", path.display());
    }
    let cfg = SemiRealConfig {
        clear_pcap_parts: 3,
        degraded: 24,
        ..SemiRealConfig::default()
    };
    let path = out.join("real-pcap");
    semi_real::vlp16_campaign(&capture, &path, &cfg, 2).expect("semi-real campaign");
    println!("{}", path.display());
}
