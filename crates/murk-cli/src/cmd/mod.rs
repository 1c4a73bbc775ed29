//! One module per subcommand: clap arguments and a `run` that calls the libraries.

pub mod apply;
pub mod camera;
pub mod campaign;
pub mod convert;
pub mod diagnose;
pub mod diagnose_figures;
pub mod fit;
pub mod generate;
pub mod rain;

/// The progress bar of a batch of `n` items named `unit` on stderr; hidden
/// when `quiet` or when stderr is not a terminal (logs stay clean).
pub fn progress_bar(n: usize, unit: &str, quiet: bool) -> indicatif::ProgressBar {
    use std::io::IsTerminal as _;
    let bar = if quiet || !std::io::stderr().is_terminal() {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(n as u64)
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(&format!(
            "{{bar:40}} {{pos}}/{{len}} {unit} {{elapsed}} (eta {{eta}}) {{msg}}"
        ))
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    bar
}
