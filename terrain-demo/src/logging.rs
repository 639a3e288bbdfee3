//! The demo's log subscriber: the libraries' `tracing` events on stderr, by `-v` or RUST_LOG.

use tracing_subscriber::EnvFilter;

/// Installs the subscriber: warnings by default, `-v` info, `-vv` debug, `-vvv` trace;
/// RUST_LOG (`terrain_cache=debug,terrain_gpu=info`) replaces the level when set.
pub fn install(verbose: u8) {
    let level = match verbose {
        0 => "warn",
        1 => "info",
        2 => "debug",
        _ => "trace",
    };
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(level));
    // A second install (never in the demo) would fail; logging is not worth an exit then.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .try_init();
}
