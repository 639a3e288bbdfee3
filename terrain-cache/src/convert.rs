//! [`convert_world`]: rewrites a world of PNG tiles (format version 1) as `.tile` files
//! (format version 2) in its own store.

use crate::CacheError;
use crate::manifest::{FORMAT_VERSION, MANIFEST_KEY, TileFormat, parse_tile_key};
use crate::tile::Layer;
use crate::world::World;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};

/// What a conversion did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ConvertReport {
    /// Tile files rewritten.
    pub tiles: u64,
    /// Bytes of the PNG files read.
    pub png_bytes: u64,
    /// Bytes of the `.tile` files written.
    pub tile_bytes: u64,
}

/// Rewrites every tile file of a world of PNG tiles as a `.tile` file in the same store, then
/// switches the manifest to format version 2 and removes the PNG files; returns the converted
/// world. A world already of `.tile` files is returned as it is.
///
/// Safe to interrupt: until the manifest is rewritten (one atomic write) the world is the PNG
/// world, with stray `.tile` files that a later conversion overwrites; after it, the `.tile`
/// world, with stray PNG files that a later conversion removes. A tile that does not decode
/// stops the conversion with its error, before the manifest changes. Nothing else may write
/// to the world meanwhile.
pub fn convert_world(world: &World) -> Result<(World, ConvertReport), CacheError> {
    let store = world.store().clone();
    let old = *world.manifest();
    let mut new = old;
    new.format_version = FORMAT_VERSION;
    new.tile_format = TileFormat::Tile;
    let converted = World::unwritten(store.clone(), new);
    let mut png_keys = Vec::new();
    for layer in Layer::ALL {
        png_keys.extend(
            store
                .list(layer.folder())?
                .into_iter()
                .filter(|k| k.ends_with(".png"))
                .filter_map(|k| parse_tile_key(&k).map(|(l, id)| (k, l, id))),
        );
    }
    let report = if old.tile_format == TileFormat::Tile {
        ConvertReport::default()
    } else {
        let (png, tile) = (AtomicU64::new(0), AtomicU64::new(0));
        png_keys.par_iter().try_for_each(|(key, layer, id)| {
            let bytes = store
                .read(key, world.max_tile_file_bytes(*layer))?
                .unwrap_or_default();
            png.fetch_add(bytes.len() as u64, Ordering::Relaxed);
            let data = world.decode_tile(*layer, *id, &bytes)?;
            tile.fetch_add(converted.write_tile(*layer, *id, &data)?, Ordering::Relaxed);
            Ok::<(), CacheError>(())
        })?;
        store.write(MANIFEST_KEY, new.to_json().as_bytes())?;
        ConvertReport {
            tiles: png_keys.len() as u64,
            png_bytes: png.into_inner(),
            tile_bytes: tile.into_inner(),
        }
    };
    for (key, _, _) in &png_keys {
        store.remove(key)?;
    }
    Ok((converted, report))
}
