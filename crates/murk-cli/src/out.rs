//! What `murk` prints: every line to stdout or stderr goes through here, so
//! that a closed pipe (`murk convert … | head -1`) ends the printing quietly
//! instead of panicking like `println!` does.
//!
//! Rust ignores SIGPIPE, so a write to a closed pipe fails with
//! [`std::io::ErrorKind::BrokenPipe`]. Then the stream is marked closed and
//! later lines to it are dropped; the command goes on and finishes its work
//! (outputs, tables, reports are files, not stdout), so what a reader that
//! stopped early did not read is the only thing lost. Any other write error
//! of stdout is reported once on stderr; one of stderr is dropped (there is
//! nowhere left to say it).

use std::io::Write as _;
use std::sync::atomic::{AtomicBool, Ordering};

static STDOUT_CLOSED: AtomicBool = AtomicBool::new(false);
static STDERR_CLOSED: AtomicBool = AtomicBool::new(false);

/// Writes `args` to stdout; after a failed write, nothing more.
pub fn stdout(args: std::fmt::Arguments<'_>) {
    if STDOUT_CLOSED.load(Ordering::Relaxed) {
        return;
    }
    let mut o = std::io::stdout().lock();
    if let Err(e) = o.write_fmt(args).and_then(|()| o.flush()) {
        STDOUT_CLOSED.store(true, Ordering::Relaxed);
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            stderr(format_args!(
                "murk: warning: cannot write to standard output ({e}); printing stops\n"
            ));
        }
    }
}

/// Writes `args` to stderr; after a failed write, nothing more.
pub fn stderr(args: std::fmt::Arguments<'_>) {
    if STDERR_CLOSED.load(Ordering::Relaxed) {
        return;
    }
    let mut o = std::io::stderr().lock();
    if o.write_fmt(args).and_then(|()| o.flush()).is_err() {
        STDERR_CLOSED.store(true, Ordering::Relaxed);
    }
}

/// `println!` that stops quietly at a closed stdout (see the module docs).
macro_rules! outln {
    ($($t:tt)*) => {
        $crate::out::stdout(format_args!("{}\n", format_args!($($t)*)))
    };
}

/// `print!` that stops quietly at a closed stdout.
macro_rules! out {
    ($($t:tt)*) => {
        $crate::out::stdout(format_args!($($t)*))
    };
}

/// `eprintln!` that stops quietly at a closed stderr.
macro_rules! errln {
    ($($t:tt)*) => {
        $crate::out::stderr(format_args!("{}\n", format_args!($($t)*)))
    };
}
