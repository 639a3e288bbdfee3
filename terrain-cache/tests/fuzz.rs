//! Fuzz targets for the files of a world, through terrain-cache's public decoding functions:
//! tile files (`tile`: `.tile` files and the PNG16 / PNG8 tiles of version-1 worlds, via
//! `World::decode_tile` and `World::read_tile`), the manifest (`manifest`: `Manifest::from_json`, `read_manifest`, and
//! the store keys) and the per-level bounds files (`bounds`: `LevelBounds::from_bytes`,
//! `World::bounds`). Each target is time-bounded (`TERRAIN_FUZZ_SECONDS`, default 2 s; `cargo
//! xtask fuzz --seconds N` runs them longer, in release mode); see `terrain_test_support::fuzz`
//! for the seed, replay and class selection variables.
//!
//! Seeds are valid files written by the crate itself, then truncated, bit-flipped (with and
//! without the checksum fixed), given edge values in their header fields, grown, or replaced by
//! random bytes. A valid file must decode to what was written; any other must give `Ok` or
//! `Err`, never a panic or a hang, and an `Ok` must be well-formed (a tile of the world's
//! shape, a manifest that validates, bounds of the level's tile count).

#[path = "fuzz/bounds.rs"]
mod bounds;
#[path = "fuzz/manifest.rs"]
mod manifest;
#[path = "fuzz/tile.rs"]
mod tile;
#[path = "fuzz/worlds.rs"]
mod worlds;

use glam::UVec2;
use std::time::Duration;
use terrain_cache::LevelBounds;
use terrain_test_support::fuzz::{self, Target};

/// Decoding a tile of at most 64^2 texels, parsing a manifest or a bounds file takes well
/// under a millisecond; 250 ms leaves room for debug builds on a loaded machine.
const PER_CASE_LIMIT: Duration = Duration::from_millis(250);

#[test]
fn fuzz_tile() {
    fuzz::run(
        Target {
            name: "tile",
            per_case_limit: PER_CASE_LIMIT,
            classes: tile::classes(),
            disabled: &[],
        },
        tile::TileCtx::new(),
    );
}

#[test]
fn fuzz_manifest() {
    fuzz::run(
        Target {
            name: "manifest",
            per_case_limit: PER_CASE_LIMIT,
            classes: manifest::classes(),
            disabled: &[],
        },
        (),
    );
}

#[test]
fn fuzz_bounds() {
    fuzz::run(
        Target {
            name: "bounds",
            per_case_limit: PER_CASE_LIMIT,
            classes: bounds::classes(),
            disabled: &[],
        },
        (),
    );
}

// ---------------------------------------------------------------------------------------------
// Regressions: inputs the targets found, kept as they were found

/// `bounds/any_tile_count` (replay `any_tile_count:0x119d0fdb2d0f520b`): the expected file
/// length of `4294967293 x 4294967295` tiles overflowed `u64` (a panic in debug builds).
#[test]
fn regression_bounds_file_length_of_huge_tile_counts() {
    let bytes = [
        84, 67, 66, 78, 1, 0, 0, 0, 253, 255, 255, 255, 255, 255, 255, 255, 113, 108, 26, 169, 157,
        69, 149, 11, 208, 173, 145, 117, 24, 122, 117, 228, 100, 219, 167, 92,
    ];
    let tiles = UVec2::new(4_294_967_293, 4_294_967_295);
    assert!(LevelBounds::from_bytes(&bytes, tiles).is_err());
    assert!(LevelBounds::from_bytes(&[], UVec2::splat(u32::MAX)).is_err());
}

/// `bounds/inconsistent_fields` (seed 1): bounds of 260 entries claiming `16777215 x
/// 4294967295` tiles reserved a buffer for the claimed count and aborted the process on
/// allocation.
#[test]
fn regression_bounds_encode_sizes_from_entries() {
    let mut b = LevelBounds::empty(UVec2::new(20, 13));
    b.tiles = UVec2::new(16_777_215, 4_294_967_295);
    assert_eq!(b.to_bytes().len(), 24 + 4 * 260);
}
