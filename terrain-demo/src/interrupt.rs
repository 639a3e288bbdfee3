//! Ctrl-C: the first one asks the run to stop after the frame in progress (the driver then
//! writes the report of the frames done); a second one stops at once. SIGTERM and SIGHUP are
//! treated the same way.

use crate::usage_error::INTERRUPTED_EXIT;
use std::sync::atomic::{AtomicBool, Ordering};

/// Set by the first Ctrl-C.
static REQUESTED: AtomicBool = AtomicBool::new(false);

/// Installs the handler. Without one (the platform refused it) Ctrl-C ends the process as
/// usual, which is said once on stderr.
pub fn install() {
    let installed = ctrlc::set_handler(|| {
        if REQUESTED.swap(true, Ordering::SeqCst) {
            crate::console::note!("\ninterrupted again: stopping now");
            std::process::exit(INTERRUPTED_EXIT);
        }
        crate::console::note!(
            "\ninterrupted: ending after the frame in progress and writing the report \
             (Ctrl-C again to stop now)"
        );
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
