//! `murk generate` (placeholder until its library lands).

/// Arguments of `murk generate`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `murk generate`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("murk generate is not implemented yet")
}
