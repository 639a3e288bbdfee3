//! Fuzz targets for terrain-core's map decoders: PNG 16-bit (`png16`), PNG 8-bit and RGBA8
//! captures (`png8`), RAW16 (`raw16`) and GeoTIFF DEMs (`geotiff`, seeded by the tests' own
//! TIFF writer, `terrain_test_support::tiff`: every sample type, strips and tiles, both byte
//! orders, classic and BigTIFF, with GeoTIFF tags). Each target is time-bounded
//! (`TERRAIN_FUZZ_SECONDS`, default 2 s; `cargo xtask fuzz --seconds N` runs them longer, in
//! release mode) and prints how many cases each input class ran; see
//! `terrain_test_support::fuzz` for the seed, replay and class selection variables. The classes
//! live in `fuzz/`, one module per format (the PNG targets' expectations and mutations in
//! modules of their own).
//!
//! These classes are structure-aware: they know the formats' checksums and compression, which
//! byte-level coverage-guided fuzzing (`terrain_test_support::decoders`, `cargo xtask fuzz
//! --engine libfuzzer`) rarely gets past. Seeds are valid files made by an encoder independent
//! of the png crate (`terrain_test_support::png_encoder`: every bit depth and colour type,
//! Adam7 interlacing, all five row filters, stored deflate blocks of random sizes, image data
//! split over several IDAT chunks, ancillary chunks) and by terrain-core's own encoder
//! (compressed deflate). They are then truncated, bit-flipped, their header fields
//! overwritten, their chunks removed / duplicated / grown, their zlib stream damaged (with
//! chunk CRCs fixed, so the damage reaches the parsers behind the CRC check), or replaced by
//! random bytes. Valid inputs must decode to exactly the samples encoded (or to the error the
//! header calls for); every other input must give `Ok` or `Err`, never a panic or a hang, and
//! an `Ok` must respect the read limits.

#[path = "fuzz/geotiff.rs"]
mod geotiff;
#[path = "fuzz/png.rs"]
mod png;
#[path = "fuzz/png_expect.rs"]
mod png_expect;
#[path = "fuzz/png_mutations.rs"]
mod png_mutations;
#[path = "fuzz/raw16.rs"]
mod raw16;

use std::path::PathBuf;
use std::time::Duration;
use terrain_test_support::fuzz::{self, Case, Class, Target};

/// A decode of small images takes well under a millisecond; 250 ms leaves room for debug
/// builds on a loaded machine while still catching a decoder that loops.
const PER_CASE_LIMIT: Duration = Duration::from_millis(250);

/// Shared state: a folder for the file-reader classes.
struct Ctx {
    dir: PathBuf,
}

impl Ctx {
    fn new(target: &str) -> Self {
        let dir =
            std::env::temp_dir().join(format!("terrain-core-fuzz-{target}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Self { dir }
    }
}

impl Drop for Ctx {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// A class of these targets, for their class lists (one line a class).
fn class(name: &'static str, run: fn(&Ctx, &mut Case) -> Result<(), String>) -> Class<Ctx> {
    Class { name, run }
}

#[test]
fn fuzz_png16() {
    fuzz::run(
        Target {
            name: "png16",
            per_case_limit: PER_CASE_LIMIT,
            classes: png::classes::<{ png_expect::GRAY16 }>(false),
            disabled: &[],
        },
        Ctx::new("png16"),
    );
}

#[test]
fn fuzz_png8() {
    fuzz::run(
        Target {
            name: "png8",
            per_case_limit: PER_CASE_LIMIT,
            classes: png::classes::<{ png_expect::GRAY8 }>(true),
            disabled: &[],
        },
        Ctx::new("png8"),
    );
}

#[test]
fn fuzz_raw16() {
    fuzz::run(
        Target {
            name: "raw16",
            per_case_limit: PER_CASE_LIMIT,
            classes: raw16::classes(),
            disabled: &[],
        },
        Ctx::new("raw16"),
    );
}

#[test]
fn fuzz_geotiff() {
    fuzz::run(
        Target {
            name: "geotiff",
            per_case_limit: PER_CASE_LIMIT,
            classes: geotiff::classes(),
            disabled: &[],
        },
        Ctx::new("geotiff"),
    );
}
