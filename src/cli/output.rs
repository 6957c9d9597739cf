//! Lines for people and scripts on standard output and standard error.
//!
//! `println!` panics when its reader has gone (`eyebot-hil probe ... sonar 1 | head -3`), and
//! `eprintln!` does when standard error has (`... 2>&1 | head`). A C tool would die of
//! SIGPIPE there without a word. [`outln!`] and [`out!`] end the command the same quiet way, with exit
//! status 0 and no panic message. Standard error carries diagnostics only, so [`errln!`] and
//! [`err!`] ignore a failed write, as `tracing` does. Any other error on standard output (a full
//! disk behind `>`) ends the command with a message and status 1.
//!
//! Ending the process skips destructors, so neither is used where state must be flushed
//! or cleaned up first: a long-running command announces itself with [`readyln!`], which
//! ignores a reader that has gone and carries on, as the daemon's readiness lines do.

use std::io::Write;

/// Writes to standard output (see the module doc for a reader that has gone).
pub fn write_out(args: std::fmt::Arguments<'_>) {
    let written = std::io::stdout().lock().write_fmt(args);
    match written {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => std::process::exit(0),
        Err(e) => {
            write_err(format_args!(
                "eyebot-hil: cannot write to standard output: {e}"
            ));
            std::process::exit(1);
        }
    }
}

/// Writes to standard output, ignoring a failure: for the line a long-running command prints
/// when it is ready, after which a script may close the pipe while the command carries on
/// (the daemon's readiness lines do the same).
pub fn write_ready(args: std::fmt::Arguments<'_>) {
    let _ = std::io::stdout().lock().write_fmt(args);
}

/// Writes to standard error; a failure is ignored.
pub fn write_err(args: std::fmt::Arguments<'_>) {
    let _ = std::io::stderr().lock().write_fmt(args);
}

/// `print!` for command output: a reader that has gone ends the command quietly.
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::cli::output::write_out(format_args!($($arg)*))
    };
}

/// `println!` for command output.
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::cli::output::write_out(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// `println!` for a long-running command's readiness line: a reader that has gone is ignored.
macro_rules! readyln {
    ($($arg:tt)*) => {
        $crate::cli::output::write_ready(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// `eprint!` for diagnostics: a standard error that has gone is ignored.
macro_rules! err {
    ($($arg:tt)*) => {
        $crate::cli::output::write_err(format_args!($($arg)*))
    };
}

/// `eprintln!` for diagnostics.
macro_rules! errln {
    ($($arg:tt)*) => {
        $crate::cli::output::write_err(format_args!("{}\n", format_args!($($arg)*)))
    };
}

pub(crate) use {err, errln, out, outln, readyln};
