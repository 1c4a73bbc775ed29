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

/// A batch stopped by Ctrl-C (SIGINT) after committing what it had
/// finished; the message says what is done. `main` prints it and exits
/// with 130, the shell's code for "ended by SIGINT".
#[derive(Debug)]
pub struct Interrupted(pub String);

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Interrupted {}

/// A flag that Ctrl-C (SIGINT) sets instead of killing the process, so a
/// batch can stop between files with every written file complete and no
/// temporary file left. A second Ctrl-C while the flag is set ends the
/// process at once (exit 130); the temporary files it may leave are
/// removed by the next run ([`clean_stale`]).
///
/// signal-hook, not the `ctrlc` crate: it is already in the build (polars
/// uses it), and its flag registration is async-signal-safe by design (the
/// handler only stores to an atomic), which is all a batch needs.
pub fn interrupt_flag() -> anyhow::Result<std::sync::Arc<std::sync::atomic::AtomicBool>> {
    use signal_hook::consts::SIGINT;
    let flag = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    // Registered first, so it sees the flag before the second handler sets
    // it: the first Ctrl-C only sets the flag, the second exits.
    signal_hook::flag::register_conditional_shutdown(SIGINT, 130, std::sync::Arc::clone(&flag))
        .and_then(|_| signal_hook::flag::register(SIGINT, std::sync::Arc::clone(&flag)))
        .map_err(|e| anyhow::anyhow!("cannot install the Ctrl-C handler: {e}"))?;
    Ok(flag)
}

/// Removes the temporary files that killed murk runs left in `dirs`
/// ([`murk_types::remove_stale_temporaries`]: only murk's own
/// `.murk-<pid>-<random>.tmp` names, only when that process has ended) and
/// says so on stderr. A folder that cannot be cleaned is a warning, not an
/// error: the run itself does not need it.
pub fn clean_stale(dirs: impl IntoIterator<Item = std::path::PathBuf>) {
    let dirs: std::collections::BTreeSet<std::path::PathBuf> = dirs.into_iter().collect();
    for d in dirs {
        match murk_types::remove_stale_temporaries(&d) {
            Ok(removed) => {
                for p in removed {
                    errln!(
                        "murk: removed {}, a temporary file left by an interrupted murk run",
                        p.display()
                    );
                }
            }
            Err(e) => errln!(
                "murk: warning: {}: cannot look for stale temporary files: {e}",
                d.display()
            ),
        }
    }
}

/// Sets how much of the clear images a fit holds in memory and where the
/// rest spills (`--clear-memory-mb`, `--spill-dir`).
pub fn clear_spill(mb: f64, dir: Option<std::path::PathBuf>) -> anyhow::Result<()> {
    anyhow::Context::context(murk_fit::set_clear_image_memory_mb(mb), "--clear-memory-mb")?;
    murk_fit::set_clear_image_dir(dir);
    Ok(())
}

/// Checks, before any work, that `path` (given with `flag`) can become a
/// file: not an existing folder, and not below an existing file. A fit or
/// a diagnosis that runs for minutes must not fail only at its last step.
pub fn check_file_target(flag: &str, path: &std::path::Path) -> anyhow::Result<()> {
    if path.is_dir() {
        anyhow::bail!(
            "{flag} {}: is a folder; give the file to write (for example {})",
            path.display(),
            path.join("out.json").display()
        );
    }
    check_parent(flag, path)
}

/// Checks, before any work, that `path` (given with `flag`) can be a
/// folder: it is one, or nothing exists there yet (and no file above it).
pub fn check_folder_target(flag: &str, path: &std::path::Path) -> anyhow::Result<()> {
    if path.exists() && !path.is_dir() {
        anyhow::bail!(
            "{flag} {}: exists and is not a folder; give a folder (created when missing)",
            path.display()
        );
    }
    check_parent(flag, path)
}

/// The nearest existing folder above `path` must be a folder, not a file.
fn check_parent(flag: &str, path: &std::path::Path) -> anyhow::Result<()> {
    let nearest = path
        .ancestors()
        .skip(1)
        .take_while(|d| !d.as_os_str().is_empty())
        .find(|d| d.exists());
    match nearest {
        Some(d) if !d.is_dir() => anyhow::bail!(
            "{flag} {}: {} is a file, not a folder",
            path.display(),
            d.display()
        ),
        _ => Ok(()),
    }
}

/// A spinner with `msg` and the elapsed time on stderr while a library call
/// that reads many files runs (fit, diagnose: they report no per-file
/// progress, so a bar would have no length); hidden when stderr is not a
/// terminal. Clear it with `finish_and_clear`.
pub fn spinner(msg: String) -> indicatif::ProgressBar {
    use std::io::IsTerminal as _;
    if !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new_spinner();
    bar.set_style(
        indicatif::ProgressStyle::with_template("{spinner} {msg} {elapsed}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
    );
    bar.set_message(msg);
    bar.enable_steady_tick(std::time::Duration::from_millis(120));
    bar
}
