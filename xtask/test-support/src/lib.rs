//! Code the workspace's integration tests share. Not published, and not part of any crate's
//! API: like wgpu's `wgpu-test`, a crate of its own so that the crates' `tests/` folders
//! stop carrying copies of the same helpers (and checks that keep the copies equal). It lives
//! under `xtask/` beside the other development tooling, so that the repository's top level
//! holds only the crates users depend on.
//!
//! - [`fuzz`]: the time-bounded fuzz harness every `tests/fuzz.rs` target runs on (terrain-core,
//!   terrain-cache, terrain-physics, terrain-lod), with its RNG and its output lines, which
//!   `cargo xtask fuzz` parses.
//! - [`png`]: PNG byte helpers (CRC-32, Adler-32, chunk framing and walking) for tests that
//!   build or damage PNG files independently of the decoders under test.
//! - [`granular`]: the granular test rig (bumpy map, moving objects, parameters) that
//!   terrain-core's CPU reference tests and terrain-gpu's GPU step tests both run.
//!
//! The crates take it as a dev-dependency and use it from their integration tests (`tests/`)
//! only. It depends on terrain-core, so a `#[cfg(test)]` unit test inside terrain-core (or a
//! crate above it) must not use it: there it would link a second copy of the crate under test,
//! whose types differ from the ones the test sees.

pub mod fuzz;
pub mod granular;
pub mod png;

/// The repository README's code blocks, compiled and run as doc tests (`cargo xtask ci`'s
/// test step) so that the front page cannot show an API that no longer exists. They live here,
/// in the one crate that is never published, because the README is outside every crate.
#[cfg(doctest)]
#[doc = include_str!("../../../README.md")]
struct RootReadmeDoctests;
