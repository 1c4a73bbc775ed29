//! Decodes a VLP-16 pcap and prints what it holds.
//!
//! `cargo run -p murk-velodyne --example pcap_info -- FILE.pcap [--skip-foreign]`

use std::path::PathBuf;
use std::process::ExitCode;

use murk_velodyne::{ForeignPolicy, PcapOptions, read_pcap_file};

fn main() -> ExitCode {
    let mut args = std::env::args().skip(1);
    let Some(path) = args.next().map(PathBuf::from) else {
        eprintln!("usage: pcap_info FILE.pcap [--skip-foreign]");
        return ExitCode::FAILURE;
    };
    let mut opts = PcapOptions::default();
    if args.any(|a| a == "--skip-foreign") {
        opts.on_foreign = ForeignPolicy::Skip;
    }
    let capture = match read_pcap_file(&path, &opts) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let s = &capture.stats;
    println!(
        "packets {} (data {}, position {}, foreign skipped {} {:?})",
        s.packets_total,
        s.packets_data,
        s.packets_position,
        s.packets_foreign_skipped,
        s.foreign_kinds
    );
    println!(
        "return modes {:?}, product ids {:?}",
        s.return_modes, s.product_ids
    );
    let mut full: Vec<usize> = s
        .frames
        .iter()
        .filter(|f| !f.partial)
        .map(|f| f.points)
        .collect();
    full.sort_unstable();
    println!(
        "frames {} (first partial {}, last partial {}), points {}, no-return records {}",
        s.frames.len(),
        s.first_frame_partial,
        s.last_frame_partial,
        s.points,
        s.no_return
    );
    if let (Some(min), Some(max)) = (full.first(), full.last()) {
        println!(
            "full frames {}: points min {min} median {} max {max}",
            full.len(),
            full[full.len() / 2]
        );
    }
    for (i, f) in s.frames.iter().enumerate().filter(|(_, f)| f.partial) {
        println!(
            "partial frame {i}: {} points, {:.2}°..{:.2}°",
            f.points, f.start_azimuth_deg, f.end_azimuth_deg
        );
    }
    ExitCode::SUCCESS
}
