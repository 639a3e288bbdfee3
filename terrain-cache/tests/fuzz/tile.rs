//! Target `tile`: `.tile` files (and the PNG16 / PNG8 tiles of version-1 worlds) through
//! `World::decode_tile` and `World::read_tile` (through a store in memory and the local file
//! store): valid tiles, mutated ones, foreign files and random bytes.

use crate::worlds::{any_tile, random_tile, small_world, tile_in};
use std::sync::Arc;
use terrain_cache::tile_file::{self, HEADER_LEN, TileCodec};
use terrain_cache::{CacheError, FsStore, Layer, TileData, TileFormat, TileRead, TileStore, World};
use terrain_core::Grid;
use terrain_core::io::{encode_png8, encode_png16};
use terrain_test_support::fuzz::{Case, Class, Rng};
use terrain_test_support::png::{chunks_of, fix_crcs};

// ---------------------------------------------------------------------------------------------
// PNG mutations

/// One mutation of a PNG file: truncation, bit flips (CRCs fixed or not), an IHDR field set
/// to an edge value, a chunk removed / duplicated / length-grown, or trailing bytes.
fn mutate_png(png: &mut Vec<u8>, rng: &mut Rng) {
    let chunks = chunks_of(png);
    match rng.below(7) {
        0 => {
            let n = png.len();
            png.truncate(rng.index(n));
        }
        1 => rng.flip_bits(png),
        2 => {
            rng.flip_bits(png);
            fix_crcs(png);
        }
        3 => {
            // IHDR at byte 8: width, height, depth, colour type, compression, filter, interlace.
            if png.len() >= 29 {
                match rng.below(4) {
                    0 => png[16..20].copy_from_slice(&rng.u32_edge().to_be_bytes()),
                    1 => png[20..24].copy_from_slice(&rng.u32_edge().to_be_bytes()),
                    2 => png[24] = rng.pick(&[0, 1, 2, 4, 8, 16, 255]),
                    _ => png[25 + rng.index(4)] = rng.pick(&[0, 1, 2, 3, 4, 6, 255]),
                }
                fix_crcs(png);
            }
        }
        4 => {
            if !chunks.is_empty() {
                let (at, len) = chunks[rng.index(chunks.len())];
                if rng.chance(1, 2) {
                    png.drain(at..at + 12 + len);
                } else {
                    let c = png[at..at + 12 + len].to_vec();
                    png.splice(at..at, c);
                }
            }
        }
        5 => {
            if !chunks.is_empty() {
                let (at, len) = chunks[rng.index(chunks.len())];
                let v = if rng.chance(1, 2) {
                    rng.u32_edge()
                } else {
                    len as u32 + rng.range_u32(1, 64)
                };
                png[at..at + 4].copy_from_slice(&v.to_be_bytes());
            }
        }
        _ => {
            let n = rng.range_usize(1, 64);
            png.extend(rng.bytes(n));
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Tile file mutations

/// Recomputes a tile file's checksum, so a mutation reaches the checks behind it.
fn fix_checksum(b: &mut [u8]) {
    if b.len() >= HEADER_LEN {
        let mut covered = b[..20].to_vec();
        covered.extend_from_slice(&b[HEADER_LEN..]);
        let sum = crc32fast::hash(&covered);
        b[20..24].copy_from_slice(&sum.to_le_bytes());
    }
}

/// One mutation of a `.tile` file: truncation, bit flips (checksum fixed or not), a header
/// field set to an edge value (checksum fixed), the payload replaced by random bytes with a
/// consistent length and checksum (a crafted file), or trailing bytes.
fn mutate_tile(b: &mut Vec<u8>, rng: &mut Rng) {
    match rng.below(6) {
        0 => {
            let n = b.len();
            b.truncate(rng.index(n));
        }
        1 => rng.flip_bits(b),
        2 => {
            rng.flip_bits(b);
            fix_checksum(b);
        }
        3 => {
            if b.len() >= HEADER_LEN {
                match rng.below(4) {
                    0 => b[4 + rng.index(4)] = rng.pick(&[0, 1, 2, 8, 16, 255]),
                    1 => b[8..12].copy_from_slice(&rng.u32_edge().to_le_bytes()),
                    2 => b[12..16].copy_from_slice(&rng.u32_edge().to_le_bytes()),
                    _ => b[16..20].copy_from_slice(&rng.u32_edge().to_le_bytes()),
                }
                fix_checksum(b);
            }
        }
        4 => {
            if b.len() >= HEADER_LEN {
                let n = rng.range_usize(0, 3000);
                b.truncate(HEADER_LEN);
                b.extend(rng.bytes(n));
                b[16..20].copy_from_slice(&(n as u32).to_le_bytes());
                fix_checksum(b);
            }
        }
        _ => {
            let n = rng.range_usize(1, 64);
            b.extend(rng.bytes(n));
        }
    }
}

/// A mutation of a tile file in the world's format.
fn mutate(world: &World, bytes: &mut Vec<u8>, rng: &mut Rng) {
    match world.manifest().tile_format {
        TileFormat::Tile => mutate_tile(bytes, rng),
        TileFormat::Png => mutate_png(bytes, rng),
    }
}

// ---------------------------------------------------------------------------------------------
// Classes

/// Checks a decode result: `Ok` only with the layer's sample type and the world's tile size.
fn check_tile(
    world: &World,
    layer: Layer,
    got: &Result<TileData, CacheError>,
) -> Result<(), String> {
    if let Ok(d) = got {
        world
            .check_data(layer, d)
            .map_err(|e| format!("decode_tile returned a tile of the wrong shape: {e}"))?;
    }
    Ok(())
}

fn random_layer(world: &World, rng: &mut Rng) -> Layer {
    if world.manifest().detail.is_some() && rng.chance(1, 2) {
        Layer::Detail
    } else {
        Layer::Height
    }
}

/// Tiles encoded by the world decode to themselves; written ones read back the same (a tile
/// equal to the fill value reads as the zero tile).
fn tile_valid(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let world = small_world(rng);
    let layer = random_layer(&world, rng);
    let id = tile_in(&world, layer, rng);
    let data = random_tile(&world, layer, rng);
    let bytes = world.encode_tile(layer, &data).map_err(|e| e.to_string())?;
    let back = world
        .decode_tile(layer, id, &bytes)
        .map_err(|e| format!("a valid {layer:?} tile did not decode: {e}"))?;
    if back != data {
        return Err(format!("{layer:?} tile {id} decoded to other samples"));
    }
    world
        .write_tile(layer, id, &data)
        .map_err(|e| e.to_string())?;
    match world.read_tile(layer, id) {
        Ok(TileRead::Stored(d)) if d == data => Ok(()),
        Ok(TileRead::Zero) if data.uniform_value() == world.manifest().layer_fill(layer).ok() => {
            Ok(())
        }
        other => Err(format!("{layer:?} tile {id} read back as {other:?}")),
    }
}

/// Valid tile files mutated (truncated, flipped, header fields, payloads, PNG chunks, lengths,
/// trailing bytes), decoded as the layer they were written for.
fn tile_mutated(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let world = small_world(rng);
    let layer = random_layer(&world, rng);
    let id = tile_in(&world, layer, rng);
    let data = random_tile(&world, layer, rng);
    let mut bytes = world.encode_tile(layer, &data).map_err(|e| e.to_string())?;
    for _ in 0..rng.range_u32(1, 3) {
        mutate(&world, &mut bytes, rng);
    }
    check_tile(&world, layer, &world.decode_tile(layer, id, &bytes))
}

/// Foreign files where a tile should be: the other layer's depth, other sizes (including one
/// texel off the tile size), with the tile size as the read limit, as the world's format (PNG
/// or `.tile` with either codec) or the other one. Never `Ok` but for a same-shape, same-depth
/// file of the world's format.
fn tile_foreign(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let world = small_world(rng);
    let layer = random_layer(&world, rng);
    let id = tile_in(&world, layer, rng);
    let t = world.manifest().layer_tile_size(layer).unwrap();
    let side = |rng: &mut Rng| match rng.below(3) {
        0 => t + 1,
        1 => t - 1,
        _ => rng.range_u32(1, 2 * t),
    };
    let (w, h) = (side(rng), side(rng));
    let other_depth = rng.chance(1, 2);
    let as_png = rng.chance(1, 2);
    let codec = rng.pick(&[TileCodec::Raw, TileCodec::Lz4]);
    let sixteen = matches!(
        (layer, other_depth),
        (Layer::Height, false) | (Layer::Detail, true)
    );
    let bytes = match (sixteen, as_png) {
        (true, true) => encode_png16(&Grid::new(w, h, rng.next_u32() as u16).unwrap()).unwrap(),
        (false, true) => encode_png8(&Grid::new(w, h, rng.next_u32() as u8).unwrap()).unwrap(),
        (true, false) => {
            tile_file::encode_u16(&Grid::new(w, h, rng.next_u32() as u16).unwrap(), codec)
        }
        (false, false) => {
            tile_file::encode_u8(&Grid::new(w, h, rng.next_u32() as u8).unwrap(), codec)
        }
    };
    let same_shape = w == t && h == t;
    let other_format = as_png != (world.manifest().tile_format == TileFormat::Png);
    match world.decode_tile(layer, id, &bytes) {
        Ok(_) if other_depth || !same_shape || other_format => Err(format!(
            "a {w}x{h} file of the {} depth (PNG: {as_png}) decoded as a {layer:?} tile of \
             side {t} in a {:?} world",
            if other_depth { "other" } else { "same" },
            world.manifest().tile_format
        )),
        got => check_tile(&world, layer, &got),
    }
}

/// Random bytes, bare or after the PNG signature or the tile file's magic and version, as a
/// tile file.
fn tile_random_bytes(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let world = small_world(rng);
    let layer = random_layer(&world, rng);
    let id = tile_in(&world, layer, rng);
    let n = rng.range_usize(0, 3000);
    let mut bytes = match rng.below(3) {
        0 => vec![0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A],
        1 => [&tile_file::MAGIC[..], &[tile_file::VERSION]].concat(),
        _ => Vec::new(),
    };
    bytes.extend(rng.bytes(n));
    match world.decode_tile(layer, id, &bytes) {
        Ok(_) => Err(format!("{n} random bytes decoded as a tile")),
        Err(_) => Ok(()),
    }
}

/// Tile reads through the store: files of any content and length (over the largest valid
/// tile file too) at the tile's key, missing files, ids inside and outside the pyramid.
fn tile_read_store(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let world = small_world(rng);
    let layer = random_layer(&world, rng);
    let id = any_tile(&world, layer, rng);
    let max = world.max_tile_file_bytes(layer);
    let inside = world.manifest().check_tile(layer, id).is_ok();
    let stored = if inside && rng.chance(4, 5) {
        let mut bytes = if rng.chance(1, 2) {
            let data = random_tile(&world, layer, rng);
            let mut b = world.encode_tile(layer, &data).map_err(|e| e.to_string())?;
            mutate(&world, &mut b, rng);
            b
        } else {
            let n = rng.range_usize(0, 2000);
            rng.bytes(n)
        };
        if rng.chance(1, 8) {
            let grow = max as usize + rng.range_usize(1, 3) - bytes.len().min(max as usize);
            bytes.extend(std::iter::repeat_n(0u8, grow));
        }
        world
            .store()
            .write(&world.manifest().tile_key(layer, id), &bytes)
            .map_err(|e| e.to_string())?;
        Some(bytes.len() as u64)
    } else {
        None
    };
    match (world.read_tile(layer, id), stored) {
        (Err(CacheError::TileOutOfRange { .. }), _) if !inside => Ok(()),
        (Ok(TileRead::Zero), None) if inside => Ok(()),
        (Err(CacheError::TileTooLarge { len, .. }), Some(n)) if n > max && len == n => Ok(()),
        (Ok(TileRead::Stored(d)), Some(n)) if n <= max => world
            .check_data(layer, &d)
            .map_err(|e| format!("read_tile returned a tile of the wrong shape: {e}")),
        (Err(_), Some(n)) if n <= max => Ok(()),
        (got, stored) => Err(format!(
            "tile {id} (inside: {inside}, stored: {stored:?} bytes, max {max}) read as {:?}",
            got.map(|r| matches!(r, TileRead::Zero))
        )),
    }
}

/// The local file store's read path (length checked from the file's metadata, bounded read).
fn tile_read_fs(dir: &std::path::Path, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let root = dir.join(format!("{:016x}", rng.next_u64()));
    let store: Arc<dyn TileStore> = Arc::new(FsStore::open(&root).map_err(|e| e.to_string())?);
    let mem = small_world(rng);
    // The world's manifest goes through the file store's own atomic write.
    let world = World::create(store, *mem.manifest()).map_err(|e| e.to_string())?;
    let layer = random_layer(&world, rng);
    let id = tile_in(&world, layer, rng);
    let data = random_tile(&world, layer, rng);
    let mut bytes = world.encode_tile(layer, &data).map_err(|e| e.to_string())?;
    if rng.chance(2, 3) {
        mutate(&world, &mut bytes, rng);
    }
    if rng.chance(1, 8) {
        bytes.resize(world.max_tile_file_bytes(layer) as usize + 1, 0);
    }
    let path = root.join(world.manifest().tile_key(layer, id));
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(|e| e.to_string())?;
    }
    std::fs::write(&path, &bytes).map_err(|e| e.to_string())?;
    let got = world.read_tile(layer, id);
    let _ = std::fs::remove_dir_all(&root);
    match got {
        Ok(TileRead::Stored(d)) => world
            .check_data(layer, &d)
            .map_err(|e| format!("read_tile returned a tile of the wrong shape: {e}")),
        Ok(TileRead::Zero) => Err("a tile with a file read as the zero tile".into()),
        Err(_) => Ok(()),
    }
}

/// The context of the tile target: a folder for the file store class.
pub(crate) struct TileCtx {
    dir: std::path::PathBuf,
}

impl TileCtx {
    /// A new, empty folder under the system's temporary folder.
    pub(crate) fn new() -> Self {
        let dir = std::env::temp_dir().join(format!("terrain-cache-fuzz-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Self { dir }
    }
}

impl Drop for TileCtx {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// Adapts a context-free class to the tile target's context.
macro_rules! no_ctx {
    ($f:ident) => {{
        fn run(_: &TileCtx, case: &mut Case) -> Result<(), String> {
            $f(&(), case)
        }
        run
    }};
}

/// The target's classes, in the order they run.
pub(crate) fn classes() -> Vec<Class<TileCtx>> {
    vec![
        Class {
            name: "valid_roundtrip",
            run: no_ctx!(tile_valid),
        },
        Class {
            name: "mutated_file",
            run: no_ctx!(tile_mutated),
        },
        Class {
            name: "foreign_file",
            run: no_ctx!(tile_foreign),
        },
        Class {
            name: "random_bytes",
            run: no_ctx!(tile_random_bytes),
        },
        Class {
            name: "read_through_store",
            run: no_ctx!(tile_read_store),
        },
        Class {
            name: "read_fs_store",
            run: |ctx: &TileCtx, case: &mut Case| tile_read_fs(&ctx.dir, case),
        },
    ]
}
