//! Which errors are the user's to fix: bad flags and unreadable input exit with status 2,
//! found before the first frame; everything that fails while the run goes on exits with 1.
//!
//! An error is a usage error when [`UsageError`] is anywhere in its chain, so context added
//! on the way up keeps the classification.

use std::fmt;

/// Exit status of a usage error (bad flags, unreadable input, a run above `--max-memory`).
pub const USAGE_EXIT: i32 = 2;
/// Exit status of a failure while the run goes on.
pub const FAILURE_EXIT: i32 = 1;
/// Exit status of a run ended by Ctrl-C (128 + SIGINT, as shells report it).
pub const INTERRUPTED_EXIT: i32 = 130;

/// An error the user fixes by changing the command line or its input files. It shows as the
/// error it wraps: the same message, the same causes.
#[derive(Debug)]
pub struct UsageError(anyhow::Error);

impl fmt::Display for UsageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(&self.0, f)
    }
}

impl std::error::Error for UsageError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        self.0.source()
    }
}

/// `e` marked as a usage error.
pub fn usage(e: impl Into<anyhow::Error>) -> anyhow::Error {
    anyhow::Error::new(UsageError(e.into()))
}

/// Marks the error of a result as a usage error.
pub trait UsageExt<T> {
    /// The result, its error marked as a usage error.
    fn usage(self) -> anyhow::Result<T>;
}

impl<T, E: Into<anyhow::Error>> UsageExt<T> for Result<T, E> {
    fn usage(self) -> anyhow::Result<T> {
        self.map_err(usage)
    }
}

/// The exit status for `e`: [`USAGE_EXIT`] for a usage error, else [`FAILURE_EXIT`].
pub fn exit_status(e: &anyhow::Error) -> i32 {
    if e.chain().any(|c| c.is::<UsageError>()) {
        USAGE_EXIT
    } else {
        FAILURE_EXIT
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use anyhow::Context;

    #[test]
    fn usage_errors_keep_their_status_and_message_under_context() {
        let plain = anyhow::anyhow!("disk full");
        assert_eq!(exit_status(&plain), FAILURE_EXIT);
        let e: anyhow::Result<()> = Err(anyhow::anyhow!("bad flag")).usage();
        let e = e.context("while opening the scenario").unwrap_err();
        assert_eq!(exit_status(&e), USAGE_EXIT);
        let texts: Vec<String> = e.chain().map(ToString::to_string).collect();
        assert_eq!(texts, ["while opening the scenario", "bad flag"]);
        let io = std::io::Error::other("gone");
        let e = anyhow::Error::new(io).context("reading x");
        let u = usage(e);
        assert_eq!(u.to_string(), "reading x");
        assert_eq!(
            u.chain().nth(1).map(ToString::to_string),
            Some("gone".into())
        );
    }
}
