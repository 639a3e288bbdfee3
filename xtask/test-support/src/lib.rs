//! Code the workspace's integration tests share. Not published, and not part of any crate's
//! API: like wgpu's `wgpu-test`, a crate of its own so that the crates' `tests/` folders
//! stop carrying copies of the same helpers (and checks that keep the copies equal). It lives
//! under `xtask/` beside the other development tooling, so that the repository's top level
//! holds only the crates users depend on.
//!
//! - [`fuzz`]: the time-bounded fuzz harness every `tests/fuzz.rs` target runs on (terrain-core,
//!   terrain-cache, terrain-physics, terrain-lod, and this crate's own), with its RNG and its
//!   output lines, which `cargo xtask fuzz` parses.
//! - [`decoders`]: one checking function per decoder (PNG, RAW16, R32, GeoTIFF, the world
//!   manifest, bounds and tile files), the body both of a coverage-guided libFuzzer target
//!   (`xtask/fuzz/`) and of a harness class under `cargo test` (`tests/fuzz.rs` here), with
//!   their seeds.
//! - [`png`]: PNG byte helpers (CRC-32, Adler-32, chunk framing and walking) for tests that
//!   build or damage PNG files independently of the decoders under test; [`png_encoder`]: an
//!   encoder of every PNG format written without the png crate; [`tiff`]: a baseline TIFF
//!   writer with GeoTIFF tags, written without the tiff crate.
//! - [`granular`]: the granular test rig (bumpy map, moving objects, parameters) that
//!   terrain-core's CPU reference tests and terrain-gpu's GPU step tests both run.
//! - [`heights`]: a map's exact height bounds over a rect, which the streamed quadtree and
//!   tessellation tests of terrain-lod and terrain-gpu build their trees from.
//!
//! The crates take it as a dev-dependency and use it from their integration tests (`tests/`)
//! only. It depends on terrain-core and terrain-cache, so a `#[cfg(test)]` unit test inside terrain-core (or a
//! crate above it) must not use it: there it would link a second copy of the crate under test,
//! whose types differ from the ones the test sees.

pub mod decoders;
pub mod fuzz;
pub mod granular;
pub mod heights;
pub mod png;
pub mod png_encoder;
pub mod tiff;

/// The repository README's code blocks, compiled and run as doc tests (`cargo xtask ci`'s
/// test step) so that the front page cannot show an API that no longer exists. They live here,
/// in the one crate that is never published, because the README is outside every crate.
#[cfg(doctest)]
#[doc = include_str!("../../../README.md")]
struct RootReadmeDoctests;
