//! `murk convert` (placeholder until its library lands).

/// Arguments of `murk convert`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `murk convert`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("murk convert is not implemented yet")
}
