//! The world files of terrain-cache: the manifest, the per-level bounds files and the tile
//! files (`.tile`, and the PNG tiles of version-1 worlds), through its public decoding API.

use super::{Outcome, check_error, check_message, le32, params};
use glam::UVec2;
use std::sync::{Arc, OnceLock};
use terrain_cache::manifest::{DetailLayout, MANIFEST_KEY};
use terrain_cache::tile_file::{self, TileCodec};
use terrain_cache::world::read_manifest;
use terrain_cache::{
    CacheError, Layer, LevelBounds, Manifest, TileData, TileFormat, TileId, TileStore, World,
};
use terrain_core::{Grid, HeightEncoding, WrapMode};

/// A store holding at most a manifest, which writes nothing: enough for `read_manifest` and
/// for `World::create`, and no file is touched.
#[derive(Debug, Default)]
struct ManifestOnly(Vec<u8>);

impl TileStore for ManifestOnly {
    fn read(&self, key: &str, max_len: u64) -> Result<Option<Vec<u8>>, CacheError> {
        if key != MANIFEST_KEY {
            return Ok(None);
        }
        let len = self.0.len() as u64;
        if len > max_len {
            let key = key.into();
            return Err(CacheError::TooLarge {
                key,
                len,
                max: max_len,
            });
        }
        Ok(Some(self.0.clone()))
    }
    fn write(&self, _: &str, _: &[u8]) -> Result<(), CacheError> {
        Ok(())
    }
    fn remove(&self, _: &str) -> Result<(), CacheError> {
        Ok(())
    }
    fn exists(&self, key: &str) -> Result<bool, CacheError> {
        Ok(key == MANIFEST_KEY)
    }
    fn list(&self, _: &str) -> Result<Vec<String>, CacheError> {
        Ok(vec![MANIFEST_KEY.to_owned()])
    }
}

/// The world manifest: the bytes of `manifest.json` through `read_manifest` (its size limit,
/// UTF-8, `Manifest::from_json`). A manifest that parses validates, survives `to_json` /
/// `from_json` unchanged, creates a world, and answers its queries for any level and tile.
/// The input is the file.
pub fn manifest(data: &[u8]) -> Outcome {
    let m = match read_manifest(&ManifestOnly(data.to_vec())) {
        Ok(m) => m,
        Err(e) => {
            check_error("manifest", &e);
            return Outcome::Refused;
        }
    };
    if let Err(e) = m.validate() {
        panic!("manifest: read_manifest accepted a manifest that does not validate: {e}");
    }
    let json = m.to_json();
    match Manifest::from_json(&json) {
        Ok(back) => assert!(back == m, "manifest: {m:?} parsed back as {back:?}"),
        Err(e) => panic!("manifest: {json} does not parse back: {e}"),
    }
    if let Err(e) = World::create(Arc::new(ManifestOnly::default()), m) {
        panic!("manifest: a valid manifest creates no world: {e}");
    }
    let _ = (m.max_levels(), m.extent_m());
    for layer in Layer::ALL {
        let levels = m.layer_levels(layer);
        let _ = (m.layer_tile_size(layer), m.layer_fill(layer));
        for level in [0, levels.saturating_sub(1), levels, u32::MAX] {
            let tiles = m.layer_tiles(layer, level);
            let _ = (m.level_size(level), m.tiles_at(level));
            let _ = m.tile_extent_m(layer, level);
            let last = TileId::new(level, tiles.x.saturating_sub(1), tiles.y.saturating_sub(1));
            for id in [last, TileId::new(level, tiles.x, 0)] {
                if let Err(e) = m.check_tile(layer, id) {
                    check_error("manifest (check_tile)", &e);
                }
                let _ = m.tile_key(layer, id);
            }
            let _ = m.tiles_of(layer, level).take(2).count();
        }
    }
    Outcome::Decoded
}

/// A level's bounds file (`LevelBounds::from_bytes`): 8 bytes of parameters (the tile count
/// the manifest expects, across and down, u32 little-endian), then the file. Bounds that parse
/// have that count, one entry per tile, and encode back to the same bytes.
pub fn bounds(data: &[u8]) -> Outcome {
    let Some((p, file)) = params::<8>(data) else {
        return Outcome::Refused;
    };
    let tiles = UVec2::new(le32(p, 0), le32(p, 4));
    let b = match LevelBounds::from_bytes(file, tiles) {
        Ok(b) => b,
        Err(m) => {
            check_message("bounds", &m);
            return Outcome::Refused;
        }
    };
    assert_eq!(b.tiles, tiles, "bounds: parsed another tile count");
    assert_eq!(
        b.min_max.len() as u64,
        u64::from(tiles.x) * u64::from(tiles.y),
        "bounds: {tiles} tiles parsed with another entry count"
    );
    assert!(
        b.to_bytes() == file,
        "bounds: {tiles} tiles encode to other bytes"
    );
    assert!(b.get(tiles.x, 0).is_none() && b.get(0, tiles.y).is_none());
    if tiles.min_element() > 0 {
        assert!(b.get(tiles.x - 1, tiles.y - 1).is_some());
    }
    Outcome::Decoded
}

/// The tile sides of the tile target's worlds, by bits 2-3 of its parameter byte.
const TILE_SIDES: [u32; 4] = [16, 32, 64, 16];

/// The worlds the tile target decodes in: for each tile side of [`TILE_SIDES`] (but the
/// repeated one), a world of `.tile` files and one of PNG tiles (a version-1 world), both 3x2
/// tiles with a detail layer of the same tile side. Made once.
fn tile_world(side: u32, png: bool) -> &'static World {
    static WORLDS: OnceLock<Vec<World>> = OnceLock::new();
    let worlds = WORLDS.get_or_init(|| {
        let mut out = Vec::new();
        for side in &TILE_SIDES[..3] {
            for png in [false, true] {
                let enc = HeightEncoding::spanning::<u16>(-10.0, 500.0).expect("encoding");
                let size = UVec2::new(3 * side, 2 * side);
                let mut m = Manifest::new(size, *side, 0.5, enc, WrapMode::Clamp)
                    .expect("a small manifest");
                if png {
                    m.tile_format = TileFormat::Png;
                    m.format_version = TileFormat::Png.format_version();
                }
                let extent = m.extent_m().as_vec2();
                m.detail = Some(DetailLayout::covering(extent, *side, 0.5).expect("detail"));
                let store = Arc::new(ManifestOnly::default());
                out.push(World::create(store, m).expect("a small world"));
            }
        }
        out
    });
    let i = TILE_SIDES[..3].iter().position(|s| *s == side).unwrap_or(0);
    &worlds[2 * i + usize::from(png)]
}

/// The parameters of the tile target's byte: bit 0 the layer (detail when set), bit 1 the
/// world's format (PNG when set), bits 2-3 the tile side ([`TILE_SIDES`]).
pub(super) fn tile_params(p: u8) -> (Layer, bool, u32) {
    let layer = if p & 1 == 1 {
        Layer::Detail
    } else {
        Layer::Height
    };
    (layer, p & 2 == 2, TILE_SIDES[usize::from((p >> 2) & 3)])
}

/// The world a tile target's parameter byte names.
pub(super) fn world_of(p: u8) -> (&'static World, Layer) {
    let (layer, png, side) = tile_params(p);
    (tile_world(side, png), layer)
}

/// A tile file through `World::decode_tile`: one byte of parameters (bit 0: the detail layer,
/// else heights; bit 1: a world of PNG tiles, else `.tile` files; bits 2-3: a tile side of 16,
/// 32, 64 or 16), then the file. A tile that decodes has the layer's sample type and the
/// world's tile side, and decodes again unchanged from the world's encoding of it (and, in a
/// world of `.tile` files, from either codec's).
pub fn tile(data: &[u8]) -> Outcome {
    let Some((&[p], file)) = params::<1>(data) else {
        return Outcome::Refused;
    };
    let (world, layer) = world_of(p);
    let id = TileId::new(0, 0, 0);
    let t = match world.decode_tile(layer, id, file) {
        Ok(t) => t,
        Err(e) => {
            check_error("tile", &e);
            return Outcome::Refused;
        }
    };
    let side = world
        .manifest()
        .layer_tile_size(layer)
        .expect("the layer's tile side");
    assert!(
        t.bits() == layer.bits() && t.size() == UVec2::splat(side),
        "tile: a {layer:?} tile of side {side} decoded as {} bits, {}",
        t.bits(),
        t.size()
    );
    let mut again = vec![
        world
            .encode_tile(layer, &t)
            .expect("encoding a decoded tile"),
    ];
    if world.manifest().tile_format == TileFormat::Tile {
        again.extend([TileCodec::Raw, TileCodec::Lz4].map(|c| tile_file::encode(&t, c)));
    }
    for bytes in again {
        match world.decode_tile(layer, id, &bytes) {
            Ok(back) => assert!(back == t, "tile: a re-encoded {layer:?} tile differs"),
            Err(e) => panic!("tile: a re-encoded {layer:?} tile does not decode: {e}"),
        }
    }
    Outcome::Decoded
}

/// A tile of `layer` in `world` for the seeds: a ramp, or noise from `seed` when it is odd.
pub(super) fn seed_tile(world: &World, layer: Layer, seed: u64) -> TileData {
    let side = world
        .manifest()
        .layer_tile_size(layer)
        .expect("the layer's tile side");
    let mut rng = crate::fuzz::Rng::new(seed);
    let v: Vec<u16> = (0..side * side)
        .map(|i| {
            if seed % 2 == 1 {
                rng.next_u32() as u16
            } else {
                (i % side * 37 + i / side * 11) as u16
            }
        })
        .collect();
    match layer {
        Layer::Height => TileData::U16(Grid::from_vec(side, side, v).expect("a tile")),
        Layer::Detail | Layer::Hole => {
            let v = v.into_iter().map(|x| x as u8).collect();
            TileData::U8(Grid::from_vec(side, side, v).expect("a tile"))
        }
        Layer::Material | Layer::Color => {
            let v = v
                .into_iter()
                .map(|x| (x as u32 * 0x0101_0101).to_le_bytes())
                .collect();
            TileData::Rgba8(Grid::from_vec(side, side, v).expect("a tile"))
        }
    }
}
