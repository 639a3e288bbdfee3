//! Helpers for GPU tests: a context, or a skip with a printed reason, or a failure when
//! `TERRAIN_REQUIRE_GPU=1` (set by `cargo xtask ci`) and no adapter exists.

use crate::device::context::GpuContext;

/// Environment variable that turns a missing adapter into a test failure.
pub const REQUIRE_GPU_ENV: &str = "TERRAIN_REQUIRE_GPU";

/// A headless context for `test`, or `None` (after printing why) when no adapter exists and
/// `TERRAIN_REQUIRE_GPU` is not `1`.
///
/// # Panics
/// When no adapter exists and `TERRAIN_REQUIRE_GPU=1`: CI must not silently skip GPU tests.
pub fn context_or_skip(test: &str) -> Option<GpuContext> {
    match GpuContext::new_headless() {
        Ok(ctx) => Some(ctx),
        Err(e) => {
            if std::env::var(REQUIRE_GPU_ENV).is_ok_and(|v| v == "1") {
                panic!("{test}: {REQUIRE_GPU_ENV}=1 but no GPU context: {e}");
            }
            eprintln!("skipping {test}: {e}");
            None
        }
    }
}
