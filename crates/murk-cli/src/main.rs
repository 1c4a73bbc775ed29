//! `murk`: the command-line front end of murk.
//!
//! This binary is glue: it parses flags with clap, turns them into the
//! libraries' checked settings, calls the libraries and maps errors to a
//! message and an exit code. No statistics or file formats live here.
//!
//! ```text
//! murk generate --out fixtures/default-campaign --seed 7
//! murk campaign summary fixtures/default-campaign
//! murk convert scan.pcap --out frames/ --format pcd
//! murk camera --generator fog_heavy.onnx images/ --out foggy/
//! ```

use clap::{Parser, Subcommand};

#[cfg(not(any(feature = "tract", feature = "native")))]
compile_error!(
    "murk: enable one ONNX backend for `murk camera`: feature `tract` (default) or `native` \
     (`--no-default-features --features native`)"
);

#[macro_use]
mod out;
mod cmd;

/// mimalloc instead of the system allocator: batch jobs allocate and free
/// file-sized buffers (columns, masks, outputs) once per file, and glibc
/// hands buffers that large back to the kernel on every free, so the next
/// file pays a page fault per 4 KiB again. Measured on `murk apply` (fog
/// MOR 60): 8 CSV files of 250k rows in 65 ms instead of 85, 32 in 225
/// instead of 280; the 54 small real scans take the same time either way.
/// The price is memory kept for reuse: peak RSS 113 MB instead of 49 on
/// the 8 files, 47 instead of 21 on the real scans.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// Data-driven weather noise models for automotive LiDAR.
#[derive(Parser, Debug)]
#[command(
    name = "murk",
    version,
    about = "Data-driven weather noise models for automotive LiDAR: fit them from a campaign of \
             field recordings, apply them to clear-weather point clouds, diagnose what they miss.",
    long_about = None,
    after_help = "A first run, from the checkout:\n  \
        murk fit fixtures/default-campaign --out out/coefficients.json\n  \
        murk convert fixtures/default-campaign/lidar --out scans/ --format bin\n  \
        murk apply --coefficients out/coefficients.json --weather fog --mor 60 scans/ --out foggy/\n\n\
        `murk <COMMAND> --help` lists every flag of a command."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Convert point clouds between formats (a pcap becomes one file per frame).
    Convert(cmd::convert::Args),
    /// Inspect a campaign folder.
    Campaign(cmd::campaign::Args),
    /// Generate a synthetic campaign whose truth is known.
    Generate(cmd::generate::Args),
    /// Fit the weather noise models of a campaign into a coefficient table.
    Fit(cmd::fit::Args),
    /// Apply a fitted weather model to clear-weather point clouds.
    Apply(cmd::apply::Args),
    /// Show what a fitted model gets wrong on held-out recordings, why, and what extending it gains.
    Diagnose(cmd::diagnose::Args),
    /// Render physics-based rain on camera images (depth from PNGs or LiDAR);
    /// with --generator, on a CycleGAN translation first (GAN+PBR).
    Rain(cmd::rain::Args),
    /// Translate camera images with a CycleGAN weather generator (ONNX).
    Camera(cmd::camera::Args),
}

fn main() {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Convert(a) => cmd::convert::run(a),
        Command::Campaign(a) => cmd::campaign::run(a),
        Command::Generate(a) => cmd::generate::run(a),
        Command::Fit(a) => cmd::fit::run(a),
        Command::Apply(a) => cmd::apply::run(a),
        Command::Rain(a) => cmd::rain::run(a),
        Command::Diagnose(a) => cmd::diagnose::run(a),
        Command::Camera(a) => cmd::camera::run(a),
    };
    if let Err(e) = result {
        if let Some(stopped) = e.downcast_ref::<cmd::Interrupted>() {
            errln!("murk: {stopped}");
            std::process::exit(130);
        }
        errln!("murk: error: {}", message(&e));
        std::process::exit(1);
    }
}

/// The error and its causes, joined by `: ` like anyhow's `{:#}`, but a
/// cause whose text the message already holds is left out: the library
/// errors put their source in their own text ("…: No such file or directory
/// (os error 2)"), and printing the chain again repeated it.
fn message(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in e.chain() {
        let c = cause.to_string();
        if c.is_empty() || text.contains(&c) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&c);
    }
    text
}
