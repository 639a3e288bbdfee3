//! The worlds the `tile` and `manifest` targets start from: a store in memory (the crate's
//! stores write atomically with fsync: too slow per case), random valid manifests, small
//! worlds, their tiles and tile ids.

use glam::UVec2;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use terrain_cache::manifest::DetailLayout;
use terrain_cache::store::check_key;
use terrain_cache::{CacheError, Layer, Manifest, TileData, TileFormat, TileId, TileStore, World};
use terrain_core::{Grid, HeightEncoding, WrapMode};
use terrain_test_support::fuzz::Rng;

// ---------------------------------------------------------------------------------------------
// A store in memory

#[derive(Debug, Default)]
pub(crate) struct MemStore {
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
// Worlds

/// A random valid manifest: any world size up to 65536 tiles per side, tile sizes 16..=4096,
/// texel sizes and encodings over a wide range, either wrap mode, with or without detail.
pub(crate) fn random_manifest(rng: &mut Rng) -> Manifest {
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
        old_format(&mut m, rng);
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

/// One world in four made a version-1 world of PNG tiles (they still open and are written).
fn old_format(m: &mut Manifest, rng: &mut Rng) {
    if rng.chance(1, 4) {
        m.format_version = 1;
        m.tile_format = TileFormat::Png;
    }
}

/// A small world (tiles of 16 to 64 texels) with a detail layer, in memory; `.tile` files or
/// (one in four) PNG.
pub(crate) fn small_world(rng: &mut Rng) -> World {
    let tile = 1u32 << rng.range_u32(4, 6);
    let size = UVec2::new(rng.range_u32(1, 5 * tile), rng.range_u32(1, 5 * tile));
    let enc = HeightEncoding::spanning::<u16>(-10.0, 500.0).unwrap();
    let mut m = Manifest::new(size, tile, 0.5, enc, WrapMode::Repeat).unwrap();
    m.height_fill = rng.next_u32() as u16;
    old_format(&mut m, rng);
    let dt = 1u32 << rng.range_u32(4, 6);
    m.detail = Some(DetailLayout::covering(m.extent_m().as_vec2(), dt, 0.25).unwrap());
    World::create(Arc::new(MemStore::default()), m).unwrap()
}

/// A random tile of `layer` with the world's tile size.
pub(crate) fn random_tile(world: &World, layer: Layer, rng: &mut Rng) -> TileData {
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
        Layer::Detail | Layer::Hole => {
            TileData::U8(Grid::from_vec(size, size, v.iter().map(|&x| x as u8).collect()).unwrap())
        }
        Layer::Material | Layer::Color => TileData::Rgba8(
            Grid::from_vec(
                size,
                size,
                v.iter().map(|&x| [x as u8, (x >> 8) as u8, 0, 1]).collect(),
            )
            .unwrap(),
        ),
    }
}

/// A tile id of `layer` inside the pyramid.
pub(crate) fn tile_in(world: &World, layer: Layer, rng: &mut Rng) -> TileId {
    let m = world.manifest();
    let level = rng.range_u32(0, m.layer_levels(layer) - 1);
    let t = m.layer_tiles(layer, level);
    TileId::new(level, rng.range_u32(0, t.x - 1), rng.range_u32(0, t.y - 1))
}

/// A tile id anywhere: inside the pyramid, just outside it, or at the ends of `u32`.
pub(crate) fn any_tile(world: &World, layer: Layer, rng: &mut Rng) -> TileId {
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
