//! Fuzz targets for the files of a world, through terrain-cache's public decoding functions:
//! tile files (`tile`: PNG16 height tiles and PNG8 detail tiles, via `World::decode_tile` and
//! `World::read_tile`), the manifest (`manifest`: `Manifest::from_json`, `read_manifest`, and
//! the store keys) and the per-level bounds files (`bounds`: `LevelBounds::from_bytes`,
//! `World::bounds`). Each target is time-bounded (`TERRAIN_FUZZ_SECONDS`, default 2 s; `cargo
//! xtask fuzz --seconds N` runs them longer, in release mode); see `fuzz/harness.rs` for the
//! seed, replay and class selection variables.
//!
//! Seeds are valid files written by the crate itself, then truncated, bit-flipped (with and
//! without the checksum fixed), given edge values in their header fields, grown, or replaced by
//! random bytes. A valid file must decode to what was written; any other must give `Ok` or
//! `Err`, never a panic or a hang, and an `Ok` must be well-formed (a tile of the world's
//! shape, a manifest that validates, bounds of the level's tile count).

#[path = "fuzz/harness.rs"]
mod harness;

use glam::UVec2;
use harness::{Case, Class, Rng, Target};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use terrain_cache::manifest::{DetailLayout, MANIFEST_KEY, bounds_key, parse_tile_key, tile_key};
use terrain_cache::store::check_key;
use terrain_cache::world::read_manifest;
use terrain_cache::{
    CacheError, FsStore, Layer, LevelBounds, Manifest, TileData, TileId, TileRead, TileStore, World,
};
use terrain_core::io::{encode_png8, encode_png16};
use terrain_core::{Grid, HeightEncoding, WrapMode};

/// Decoding a tile of at most 64^2 texels, parsing a manifest or a bounds file takes well
/// under a millisecond; 250 ms leaves room for debug builds on a loaded machine.
const PER_CASE_LIMIT: Duration = Duration::from_millis(250);

// ---------------------------------------------------------------------------------------------
// A store in memory (the crate's stores write atomically with fsync: too slow per case)

#[derive(Debug, Default)]
struct MemStore {
    files: Mutex<HashMap<String, Vec<u8>>>,
}

impl MemStore {
    fn files(&self) -> std::sync::MutexGuard<'_, HashMap<String, Vec<u8>>> {
        self.files.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl TileStore for MemStore {
    fn read(&self, key: &str, max_len: u64) -> Result<Option<Vec<u8>>, CacheError> {
        check_key(key)?;
        match self.files().get(key) {
            None => Ok(None),
            Some(b) if b.len() as u64 > max_len => Err(CacheError::TooLarge {
                key: key.into(),
                len: b.len() as u64,
                max: max_len,
            }),
            Some(b) => Ok(Some(b.clone())),
        }
    }
    fn write(&self, key: &str, bytes: &[u8]) -> Result<(), CacheError> {
        check_key(key)?;
        self.files().insert(key.into(), bytes.to_vec());
        Ok(())
    }
    fn remove(&self, key: &str) -> Result<(), CacheError> {
        check_key(key)?;
        self.files().remove(key);
        Ok(())
    }
    fn exists(&self, key: &str) -> Result<bool, CacheError> {
        check_key(key)?;
        Ok(self.files().contains_key(key))
    }
    fn list(&self, prefix: &str) -> Result<Vec<String>, CacheError> {
        let mut keys: Vec<String> = self
            .files()
            .keys()
            .filter(|k| k.starts_with(prefix))
            .cloned()
            .collect();
        keys.sort();
        Ok(keys)
    }
}

// ---------------------------------------------------------------------------------------------
// PNG chunk helpers for the mutations (CRC-32 as PNG computes it)

fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// The whole chunks of a PNG: (offset of the length field, data length).
fn chunks_of(png: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut at = 8;
    while at + 12 <= png.len() {
        let len = u32::from_be_bytes([png[at], png[at + 1], png[at + 2], png[at + 3]]) as usize;
        if len > png.len() || at + 12 + len > png.len() {
            break;
        }
        out.push((at, len));
        at += 12 + len;
    }
    out
}

/// Recomputes every whole chunk's CRC, so that a mutation reaches the parser behind it.
fn fix_crcs(png: &mut [u8]) {
    for (at, len) in chunks_of(png) {
        let crc = crc32(&png[at + 4..at + 8 + len]);
        png[at + 8 + len..at + 12 + len].copy_from_slice(&crc.to_be_bytes());
    }
}

fn flip_bits(bytes: &mut [u8], rng: &mut Rng) {
    if bytes.is_empty() {
        return;
    }
    for _ in 0..rng.range_u32(1, 16) {
        let i = rng.index(bytes.len());
        bytes[i] ^= 1 << rng.below(8);
    }
}

/// One mutation of a PNG file: truncation, bit flips (CRCs fixed or not), an IHDR field set
/// to an edge value, a chunk removed / duplicated / length-grown, or trailing bytes.
fn mutate_png(png: &mut Vec<u8>, rng: &mut Rng) {
    let chunks = chunks_of(png);
    match rng.below(7) {
        0 => {
            let n = png.len();
            png.truncate(rng.index(n));
        }
        1 => flip_bits(png, rng),
        2 => {
            flip_bits(png, rng);
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
// Worlds

/// A random valid manifest: any world size up to 65536 tiles per side, tile sizes 16..=4096,
/// texel sizes and encodings over a wide range, either wrap mode, with or without detail.
fn random_manifest(rng: &mut Rng) -> Manifest {
    loop {
        let tile_size = 1u32 << rng.range_u32(4, 12);
        let side = |rng: &mut Rng| match rng.below(3) {
            0 => rng.range_u32(1, 4 * tile_size),
            1 => rng.range_u32(1, u32::MAX),
            _ => tile_size.saturating_mul(rng.range_u32(1, 65536)),
        };
        let world = UVec2::new(side(rng), side(rng));
        let texel = rng.pick(&[1e-6f32, 0.01, 0.1, 0.5, 1.0, 30.0, 1e6]);
        let enc = HeightEncoding::new(
            rng.pick(&[1e-6f32, 0.001, 0.01, 1.0, 1e3]),
            rng.pick(&[-1e6f32, -100.0, 0.0, 50.0]),
        )
        .unwrap();
        let wrap = if rng.chance(1, 2) {
            WrapMode::Repeat
        } else {
            WrapMode::Clamp
        };
        let Ok(mut m) = Manifest::new(world, tile_size, texel, enc, wrap) else {
            continue; // too many tiles per side for this tile size
        };
        m.levels = rng.range_u32(1, m.max_levels());
        m.height_fill = rng.next_u32() as u16;
        m.generation = rng.next_u64();
        if rng.chance(1, 2) {
            let extent = m.extent_m().as_vec2();
            let dt = 1u32 << rng.range_u32(4, 12);
            let dts = rng.pick(&[0.01f32, 0.05, 1.0, 100.0]);
            if let Ok(d) = DetailLayout::covering(extent, dt, dts) {
                m.detail = Some(d);
            }
        }
        if m.validate().is_ok() {
            return m;
        }
    }
}

/// A small world (tiles of 16 to 64 texels) with a detail layer, in memory.
fn small_world(rng: &mut Rng) -> World {
    let tile = 1u32 << rng.range_u32(4, 6);
    let size = UVec2::new(rng.range_u32(1, 5 * tile), rng.range_u32(1, 5 * tile));
    let enc = HeightEncoding::spanning::<u16>(-10.0, 500.0).unwrap();
    let mut m = Manifest::new(size, tile, 0.5, enc, WrapMode::Repeat).unwrap();
    m.height_fill = rng.next_u32() as u16;
    let dt = 1u32 << rng.range_u32(4, 6);
    m.detail = Some(DetailLayout::covering(m.extent_m().as_vec2(), dt, 0.25).unwrap());
    World::create(Arc::new(MemStore::default()), m).unwrap()
}

/// A random tile of `layer` with the world's tile size.
fn random_tile(world: &World, layer: Layer, rng: &mut Rng) -> TileData {
    let size = world.manifest().layer_tile_size(layer).unwrap();
    let noisy = rng.chance(1, 2);
    let base = rng.next_u32() as u16;
    let n = (size * size) as usize;
    let v: Vec<u16> = (0..n)
        .map(|i| {
            if noisy {
                rng.next_u32() as u16
            } else {
                base.wrapping_add(i as u16)
            }
        })
        .collect();
    match layer {
        Layer::Height => TileData::U16(Grid::from_vec(size, size, v).unwrap()),
        Layer::Detail => {
            TileData::U8(Grid::from_vec(size, size, v.iter().map(|&x| x as u8).collect()).unwrap())
        }
    }
}

/// A tile id of `layer` inside the pyramid.
fn tile_in(world: &World, layer: Layer, rng: &mut Rng) -> TileId {
    let m = world.manifest();
    let level = rng.range_u32(0, m.layer_levels(layer) - 1);
    let t = m.layer_tiles(layer, level);
    TileId::new(level, rng.range_u32(0, t.x - 1), rng.range_u32(0, t.y - 1))
}

/// A tile id anywhere: inside the pyramid, just outside it, or at the ends of `u32`.
fn any_tile(world: &World, layer: Layer, rng: &mut Rng) -> TileId {
    if rng.chance(1, 2) {
        return tile_in(world, layer, rng);
    }
    let m = world.manifest();
    let level = rng.range_u32(0, m.layer_levels(layer) + 1);
    let t = m.layer_tiles(layer, level);
    let near = |rng: &mut Rng, n: u32| match rng.below(3) {
        0 => n,
        1 => rng.u32_edge(),
        _ => rng.range_u32(0, n.saturating_add(1)),
    };
    TileId::new(
        if rng.chance(1, 8) { u32::MAX } else { level },
        near(rng, t.x),
        near(rng, t.y),
    )
}

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

// ---------------------------------------------------------------------------------------------
// Target `tile`

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

/// Valid tile files mutated (truncated, flipped, header fields, chunks, lengths, trailing
/// bytes), decoded as the layer they were written for.
fn tile_mutated(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let world = small_world(rng);
    let layer = random_layer(&world, rng);
    let id = tile_in(&world, layer, rng);
    let data = random_tile(&world, layer, rng);
    let mut bytes = world.encode_tile(layer, &data).map_err(|e| e.to_string())?;
    for _ in 0..rng.range_u32(1, 3) {
        mutate_png(&mut bytes, rng);
    }
    check_tile(&world, layer, &world.decode_tile(layer, id, &bytes))
}

/// Foreign images where a tile should be: the other layer's depth, other sizes (including
/// one texel off the tile size), with the tile size as the read limit. Never `Ok`.
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
    let bytes = match (layer, other_depth) {
        (Layer::Height, false) | (Layer::Detail, true) => {
            encode_png16(&Grid::new(w, h, rng.next_u32() as u16).unwrap())
        }
        _ => encode_png8(&Grid::new(w, h, rng.next_u32() as u8).unwrap()),
    }
    .unwrap();
    let same_shape = w == t && h == t;
    match world.decode_tile(layer, id, &bytes) {
        Ok(_) if other_depth || !same_shape => Err(format!(
            "a {w}x{h} image of the {} depth decoded as a {layer:?} tile of side {t}",
            if other_depth { "other" } else { "same" }
        )),
        got => check_tile(&world, layer, &got),
    }
}

/// Random bytes, bare or after the PNG signature, as a tile file.
fn tile_random_bytes(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let world = small_world(rng);
    let layer = random_layer(&world, rng);
    let id = tile_in(&world, layer, rng);
    let n = rng.range_usize(0, 3000);
    let mut bytes = if rng.chance(1, 2) {
        vec![0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A]
    } else {
        Vec::new()
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
            mutate_png(&mut b, rng);
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
            .write(&tile_key(layer, id), &bytes)
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
        mutate_png(&mut bytes, rng);
    }
    if rng.chance(1, 8) {
        bytes.resize(world.max_tile_file_bytes(layer) as usize + 1, 0);
    }
    let path = root.join(tile_key(layer, id));
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
struct TileCtx {
    dir: std::path::PathBuf,
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

#[test]
fn fuzz_tile() {
    let dir = std::env::temp_dir().join(format!("terrain-cache-fuzz-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    harness::run(
        Target {
            name: "tile",
            per_case_limit: PER_CASE_LIMIT,
            classes: vec![
                Class {
                    name: "valid_roundtrip",
                    run: no_ctx!(tile_valid),
                },
                Class {
                    name: "mutated_png",
                    run: no_ctx!(tile_mutated),
                },
                Class {
                    name: "foreign_image",
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
            ],
            disabled: &[],
        },
        TileCtx { dir },
    );
}

// ---------------------------------------------------------------------------------------------
// Target `manifest`

/// Checks a manifest that parsed: it validates, and its queries answer for any level and tile
/// without panicking.
fn exercise_manifest(m: &Manifest, rng: &mut Rng) -> Result<(), String> {
    m.validate()
        .map_err(|e| format!("from_json accepted a manifest that does not validate: {e}"))?;
    let _ = (m.max_levels(), m.extent_m());
    for level in [
        0,
        1,
        m.levels - 1,
        m.levels,
        31,
        32,
        u32::MAX,
        rng.next_u32(),
    ] {
        let _ = (m.level_size(level), m.tiles_at(level));
        for layer in [Layer::Height, Layer::Detail] {
            let _ = (
                m.layer_tiles(layer, level),
                m.tile_extent_m(layer, level),
                m.tiles_of(layer, level).take(3).count(),
            );
            let id = TileId::new(level, rng.u32_edge(), rng.u32_edge());
            let _ = m.check_tile(layer, id);
        }
    }
    for layer in [Layer::Height, Layer::Detail] {
        let _ = (
            m.layer_levels(layer),
            m.layer_tile_size(layer),
            m.layer_fill(layer),
        );
    }
    let world = World::create(Arc::new(MemStore::default()), *m)
        .map_err(|e| format!("a valid manifest could not create a world: {e}"))?;
    let _ = world.max_tile_file_bytes(Layer::Height);
    let _ = world.max_tile_file_bytes(Layer::Detail);
    Ok(())
}

/// Random valid manifests survive `to_json` / `from_json` unchanged.
fn manifest_roundtrip(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let m = random_manifest(rng);
    let back = Manifest::from_json(&m.to_json())
        .map_err(|e| format!("a valid manifest did not parse back: {e}\n{}", m.to_json()))?;
    if back != m {
        return Err(format!("{m:?} parsed back as {back:?}"));
    }
    exercise_manifest(&back, rng)
}

/// A JSON value that code reading numbers, strings and objects tends to get wrong.
fn edge_json(rng: &mut Rng) -> serde_json::Value {
    use serde_json::json;
    match rng.below(12) {
        0 => json!(rng.u32_edge()),
        1 => json!(-(rng.below(3) as i64) - 1),
        2 => json!(u64::MAX),
        3 => json!(i64::MIN),
        4 => json!(rng.f32_edge()),
        5 => json!(rng.f32_bits()),
        6 => serde_json::from_str("1e39").unwrap(),
        7 => json!("repeat"),
        8 => json!(null),
        9 => json!([rng.u32_edge(), rng.u32_edge()]),
        10 => json!({ "tile_size": 16 }),
        _ => json!(rng.next_u64() as f64 * 1e-10),
    }
}

/// A valid manifest with one or more fields (or detail fields) set to edge values, removed, or
/// joined by unknown ones.
fn manifest_fields(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let m = random_manifest(rng);
    let mut v: serde_json::Value = serde_json::from_str(&m.to_json()).unwrap();
    for _ in 0..rng.range_u32(1, 3) {
        let detail = rng.chance(1, 3) && v.get("detail").is_some_and(|d| d.is_object());
        let Some(obj) = (if detail {
            v.get_mut("detail")
        } else {
            Some(&mut v)
        })
        .and_then(|o| o.as_object_mut()) else {
            continue;
        };
        let keys: Vec<String> = obj.keys().cloned().collect();
        // An earlier edit may have emptied the object (or replaced the detail object).
        let Some(key) = keys.get(rng.index(keys.len())).cloned() else {
            obj.insert("tile_size".into(), edge_json(rng));
            continue;
        };
        match rng.below(6) {
            0 => {
                obj.remove(&key);
            }
            1 => {
                obj.insert("unknown_field".into(), edge_json(rng));
            }
            2 if key == "world_size" || key == "tiles" => {
                obj.insert(key, serde_json::json!([rng.u32_edge(), rng.u32_edge()]));
            }
            3 if key == "wrap" => {
                obj.insert(
                    key,
                    serde_json::json!(rng.pick(&["Repeat", "clamp ", "", "mirror"])),
                );
            }
            _ => {
                obj.insert(key, edge_json(rng));
            }
        }
    }
    let text = v.to_string();
    match Manifest::from_json(&text) {
        Ok(m) => exercise_manifest(&m, rng),
        Err(_) => Ok(()),
    }
}

/// Byte-level damage to the JSON text (truncation, flips, inserted characters), read through
/// a store so that text that is not UTF-8 takes the store path.
fn manifest_text(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let m = random_manifest(rng);
    let mut bytes = m.to_json().into_bytes();
    match rng.below(4) {
        0 => {
            let n = bytes.len();
            bytes.truncate(rng.index(n));
        }
        1 => flip_bits(&mut bytes, rng),
        2 => {
            for _ in 0..rng.range_u32(1, 4) {
                let at = rng.index(bytes.len() + 1);
                let c = rng.pick(b"{}[]\",:-+.eE0123456789 \\\0\xff");
                bytes.insert(at, c);
            }
        }
        _ => {
            // A number replaced by a long run of digits.
            if let Some(at) = bytes.iter().position(u8::is_ascii_digit) {
                let n = rng.range_usize(20, 400);
                bytes.splice(at..at + 1, std::iter::repeat_n(b'9', n));
            }
        }
    }
    let store = MemStore::default();
    store
        .write(MANIFEST_KEY, &bytes)
        .map_err(|e| e.to_string())?;
    match read_manifest(&store) {
        Ok(m) => exercise_manifest(&m, rng),
        Err(_) => Ok(()),
    }
}

/// Random bytes and random JSON-ish text as a manifest; missing and oversized manifests.
fn manifest_random(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let store = MemStore::default();
    match rng.below(4) {
        0 => {
            let n = rng.range_usize(0, 600);
            store
                .write(MANIFEST_KEY, &rng.bytes(n))
                .map_err(|e| e.to_string())?;
        }
        1 => {
            let n = rng.range_usize(0, 300);
            let text: String = (0..n)
                .map(|_| char::from(rng.pick(b"{}[]\",:-.e0123456789 abcdefghijklmnopqrstuvwxyz_")))
                .collect();
            store
                .write(MANIFEST_KEY, text.as_bytes())
                .map_err(|e| e.to_string())?;
        }
        2 => {
            let mut big = m_json_padded(rng);
            big.extend(std::iter::repeat_n(b' ', 70_000));
            store.write(MANIFEST_KEY, &big).map_err(|e| e.to_string())?;
        }
        _ => {}
    }
    match read_manifest(&store) {
        Ok(m) => exercise_manifest(&m, rng),
        Err(_) => Ok(()),
    }
}

fn m_json_padded(rng: &mut Rng) -> Vec<u8> {
    random_manifest(rng).to_json().into_bytes()
}

/// Tile keys: every id's key parses back to it; random and damaged keys never panic the key
/// parser or the store's key check, and a key that parses is one `tile_key` writes.
fn keys(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let layer = if rng.chance(1, 2) {
        Layer::Height
    } else {
        Layer::Detail
    };
    let id = TileId::new(
        rng.range_u32(0, 255),
        rng.range_u32(0, 65535),
        rng.range_u32(0, 65535),
    );
    let key = tile_key(layer, id);
    if parse_tile_key(&key) != Some((layer, id)) {
        return Err(format!("{key} did not parse back to {layer:?} {id}"));
    }
    check_key(&key).map_err(|e| format!("{key} is not a valid store key: {e}"))?;
    let _ = bounds_key(layer, rng.next_u32());
    let mut bytes = key.into_bytes();
    match rng.below(4) {
        0 => flip_bits(&mut bytes, rng),
        1 => {
            let n = bytes.len();
            bytes.truncate(rng.index(n + 1));
        }
        2 => {
            let at = rng.index(bytes.len() + 1);
            let c = rng.pick(b"/.\\\0-xX\xc3\xa9");
            bytes.insert(at, c);
        }
        _ => {
            let n = rng.range_usize(0, 40);
            bytes = rng.bytes(n);
        }
    }
    let text = String::from_utf8_lossy(&bytes);
    if let Some((l, i)) = parse_tile_key(&text)
        && tile_key(l, i) != text
    {
        return Err(format!(
            "{text:?} parsed as {l:?} {i}, which is written {}",
            tile_key(l, i)
        ));
    }
    let _ = check_key(&text);
    Ok(())
}

#[test]
fn fuzz_manifest() {
    fn c(name: &'static str, f: fn(&(), &mut Case) -> Result<(), String>) -> Class<()> {
        Class { name, run: f }
    }
    harness::run(
        Target {
            name: "manifest",
            per_case_limit: PER_CASE_LIMIT,
            classes: vec![
                c("valid_roundtrip", manifest_roundtrip),
                c("field_values", manifest_fields),
                c("text_damage", manifest_text),
                c("random_bytes", manifest_random),
                c("tile_keys", keys),
            ],
            disabled: &[],
        },
        (),
    );
}

// ---------------------------------------------------------------------------------------------
// Target `bounds`

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
        2 => flip_bits(&mut bytes, rng),
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
                0 => flip_bits(&mut bytes, rng),
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

#[test]
fn fuzz_bounds() {
    fn c(name: &'static str, f: fn(&(), &mut Case) -> Result<(), String>) -> Class<()> {
        Class { name, run: f }
    }
    harness::run(
        Target {
            name: "bounds",
            per_case_limit: PER_CASE_LIMIT,
            classes: vec![
                c("valid_roundtrip", bounds_valid),
                c("mutated", bounds_mutated),
                c("any_tile_count", bounds_any_tiles),
                c("through_world", bounds_world),
                c("inconsistent_fields", bounds_inconsistent),
            ],
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
