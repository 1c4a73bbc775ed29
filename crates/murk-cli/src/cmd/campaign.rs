//! `murk campaign` (placeholder until its library lands).

/// Arguments of `murk campaign`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `murk campaign`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("murk campaign is not implemented yet")
}
