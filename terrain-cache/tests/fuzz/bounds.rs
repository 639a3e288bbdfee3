//! Target `bounds`: the per-level bounds files through `LevelBounds::from_bytes` and
//! `World::bounds`: valid files, mutated ones (checksum fixed or not), any tile count, and
//! fields that contradict each other.

use crate::worlds::small_world;
use glam::UVec2;
use terrain_cache::manifest::bounds_key;
use terrain_cache::{Layer, LevelBounds};
use terrain_test_support::fuzz::{Case, Class, Rng};

fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// Recomputes the trailing checksum of a bounds file, so a mutation reaches the parser.
fn fix_checksum(bytes: &mut [u8]) {
    if bytes.len() >= 8 {
        let n = bytes.len() - 8;
        let sum = fnv1a(&bytes[..n]);
        bytes[n..].copy_from_slice(&sum.to_le_bytes());
    }
}

fn random_bounds(rng: &mut Rng) -> LevelBounds {
    let tiles = UVec2::new(rng.range_u32(1, 40), rng.range_u32(1, 40));
    let mut b = LevelBounds::empty(tiles);
    for mm in &mut b.min_max {
        let (x, y) = (rng.next_u32() as u16, rng.next_u32() as u16);
        *mm = [x.min(y), x.max(y)];
    }
    b
}

/// Checks a parse: `Ok` only with the expected tile count and one entry per tile.
fn check_bounds(tiles: UVec2, got: &Result<LevelBounds, String>) -> Result<(), String> {
    if let Ok(b) = got
        && (b.tiles != tiles || b.min_max.len() as u64 != u64::from(tiles.x) * u64::from(tiles.y))
    {
        return Err(format!(
            "parsed bounds of {} tiles with {} entries, {tiles} expected",
            b.tiles,
            b.min_max.len()
        ));
    }
    Ok(())
}

/// Valid files parse back to themselves.
fn bounds_valid(_: &(), case: &mut Case) -> Result<(), String> {
    let b = random_bounds(&mut case.rng);
    match LevelBounds::from_bytes(&b.to_bytes(), b.tiles) {
        Ok(back) if back == b => Ok(()),
        other => Err(format!(
            "{} tiles: valid bounds parsed as {other:?}",
            b.tiles
        )),
    }
}

/// Valid files truncated, grown, bit-flipped, or with the magic, version or tile counts set to
/// edge values, with the checksum fixed or not.
fn bounds_mutated(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let b = random_bounds(rng);
    let mut bytes = b.to_bytes();
    match rng.below(5) {
        0 => {
            let n = bytes.len();
            bytes.truncate(rng.index(n));
        }
        1 => {
            let n = rng.range_usize(1, 64);
            bytes.extend(rng.bytes(n));
        }
        2 => rng.flip_bits(&mut bytes),
        3 => {
            let field = rng.index(4) * 4;
            bytes[field..field + 4].copy_from_slice(&rng.u32_edge().to_le_bytes());
        }
        _ => {
            // The tile counts changed together with the length, so only the checksum or the
            // manifest's counts can catch it.
            let t = UVec2::new(rng.range_u32(1, 40), rng.range_u32(1, 40));
            bytes[8..12].copy_from_slice(&t.x.to_le_bytes());
            bytes[12..16].copy_from_slice(&t.y.to_le_bytes());
            bytes.resize(16 + 4 * (t.x * t.y) as usize + 8, 0);
        }
    }
    if rng.chance(1, 2) {
        fix_checksum(&mut bytes);
    }
    let tiles = if rng.chance(3, 4) {
        b.tiles
    } else {
        UVec2::new(rng.range_u32(0, 41), rng.range_u32(0, 41))
    };
    check_bounds(tiles, &LevelBounds::from_bytes(&bytes, tiles))
}

/// Any bytes against any expected tile count, up to `u32::MAX` tiles per side.
fn bounds_any_tiles(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let tiles = UVec2::new(rng.u32_edge(), rng.u32_edge());
    let n = rng.range_usize(0, 200);
    let mut bytes = rng.bytes(n);
    if bytes.len() >= 16 && rng.chance(1, 2) {
        bytes[..4].copy_from_slice(b"TCBN");
        bytes[4..8].copy_from_slice(&1u32.to_le_bytes());
        bytes[8..12].copy_from_slice(&tiles.x.to_le_bytes());
        bytes[12..16].copy_from_slice(&tiles.y.to_le_bytes());
        fix_checksum(&mut bytes);
    }
    check_bounds(tiles, &LevelBounds::from_bytes(&bytes, tiles))
}

/// Bounds files read through a world, at any level (inside the pyramid or not); files of
/// another level, damaged ones, oversized ones.
fn bounds_world(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let world = small_world(rng);
    let m = *world.manifest();
    let level = if rng.chance(3, 4) {
        rng.range_u32(0, m.levels - 1)
    } else {
        rng.u32_edge()
    };
    let write_level = if rng.chance(1, 2) {
        level
    } else {
        rng.range_u32(0, m.levels - 1)
    };
    let tiles = m.layer_tiles(Layer::Height, write_level);
    if tiles != UVec2::ZERO {
        let mut b = LevelBounds::empty(tiles);
        for mm in &mut b.min_max {
            *mm = [rng.next_u32() as u16, rng.next_u32() as u16];
        }
        world
            .write_bounds(write_level, &b)
            .map_err(|e| e.to_string())?;
        if rng.chance(1, 2) {
            let key = bounds_key(Layer::Height, write_level);
            let mut bytes = b.to_bytes();
            match rng.below(3) {
                0 => rng.flip_bits(&mut bytes),
                1 => bytes.extend(rng.bytes(8)),
                _ => {
                    let n = bytes.len();
                    bytes.truncate(rng.index(n));
                }
            }
            if rng.chance(1, 2) {
                fix_checksum(&mut bytes);
            }
            world
                .store()
                .write(&key, &bytes)
                .map_err(|e| e.to_string())?;
        }
    }
    match world.bounds(level) {
        Ok(Some(b)) => check_bounds(m.layer_tiles(Layer::Height, level), &Ok(b)),
        Ok(None) | Err(_) => Ok(()),
    }
}

/// Bounds whose public fields disagree (tile counts against entries, up to `u32::MAX` tiles)
/// must encode without a panic, and a world must refuse to write them.
fn bounds_inconsistent(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let mut b = random_bounds(rng);
    b.tiles = UVec2::new(rng.u32_edge(), rng.u32_edge());
    let bytes = b.to_bytes();
    if bytes.len() != 24 + 4 * b.min_max.len() {
        return Err(format!(
            "bounds of {} entries encoded as {} bytes",
            b.min_max.len(),
            bytes.len()
        ));
    }
    let _ = b.get(rng.u32_edge(), rng.u32_edge());
    let world = small_world(rng);
    let level = rng.range_u32(0, world.manifest().levels - 1);
    let tiles = world.manifest().layer_tiles(Layer::Height, level);
    match world.write_bounds(level, &b) {
        Ok(()) if b.tiles != tiles || b.min_max.len() as u64 != u64::from(tiles.x * tiles.y) => {
            Err(format!(
                "a world of {tiles} tiles at level {level} wrote bounds of {}",
                b.tiles
            ))
        }
        _ => Ok(()),
    }
}

/// The target's classes, in the order they run.
pub(crate) fn classes() -> Vec<Class<()>> {
    fn c(name: &'static str, f: fn(&(), &mut Case) -> Result<(), String>) -> Class<()> {
        Class { name, run: f }
    }
    vec![
        c("valid_roundtrip", bounds_valid),
        c("mutated", bounds_mutated),
        c("any_tile_count", bounds_any_tiles),
        c("through_world", bounds_world),
        c("inconsistent_fields", bounds_inconsistent),
    ]
}
