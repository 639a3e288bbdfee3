//! Writing to the standard streams without panicking. `println!` and `eprintln!` panic when
//! their stream is closed or full (a pipe whose reader has gone, `/dev/full`), which would end
//! a run with exit status 101 and without its report. Messages on stderr are best effort
//! ([`note!`]); what the user asked to see on stdout fails with an error instead
//! ([`stdout`]).

use anyhow::{Context, Result};
use std::io::Write;

/// Writes a line to stderr, ignoring a closed or full stream (like `eprintln!`, which would
/// panic there).
macro_rules! note {
    () => {
        $crate::console::stderr(format_args!("\n"))
    };
    ($($arg:tt)*) => {
        $crate::console::stderr(format_args!("{}\n", format_args!($($arg)*)))
    };
}
pub(crate) use note;

/// Writes `args` to stderr as they are (no newline added), ignoring a failed write.
pub fn stderr(args: std::fmt::Arguments<'_>) {
    let mut err = std::io::stderr().lock();
    let _ = err.write_fmt(args);
    let _ = err.flush();
}

/// Writes `text` to stdout and flushes it; a closed or full stdout is an error.
pub fn stdout(text: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())
        .and_then(|()| out.flush())
        .context("writing to standard output")
}
