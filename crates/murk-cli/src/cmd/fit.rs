//! `murk fit` (placeholder until its library lands).

/// Arguments of `murk fit`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `murk fit`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("murk fit is not implemented yet")
}
