//! Ctrl-C: the first one asks the run to stop after the frame in progress (the driver then
//! writes the report of the frames done); a second one stops at once. SIGTERM and SIGHUP are
//! treated the same way.

use crate::usage_error::INTERRUPTED_EXIT;
use std::sync::atomic::{AtomicBool, Ordering};

/// Set by the first Ctrl-C.
static REQUESTED: AtomicBool = AtomicBool::new(false);

/// What the first Ctrl-C ends, as its message says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stops {
    /// A run: after the frame in progress, with the report of the frames done.
    Run,
    /// `verify-world`: before the next tile, with no verdict.
    Check,
}

/// Installs the handler. Without one (the platform refused it) Ctrl-C ends the process as
/// usual, which is said once on stderr.
pub fn install(stops: Stops) {
    let installed = ctrlc::set_handler(move || {
        if REQUESTED.swap(true, Ordering::SeqCst) {
            crate::console::note!("\ninterrupted again: stopping now");
            std::process::exit(INTERRUPTED_EXIT);
        }
        match stops {
            Stops::Run => crate::console::note!(
                "\ninterrupted: ending after the frame in progress and writing the report \
                 (Ctrl-C again to stop now)"
            ),
            Stops::Check => crate::console::note!(
                "\ninterrupted: ending the check before its next tile (Ctrl-C again to stop now)"
            ),
        }
    });
    if let Err(e) = installed {
        crate::console::note!(
            "warning: no Ctrl-C handler ({e}): an interrupted run leaves no report.json"
        );
    }
}

/// Whether a stop was asked for.
pub fn requested() -> bool {
    REQUESTED.load(Ordering::SeqCst)
}
