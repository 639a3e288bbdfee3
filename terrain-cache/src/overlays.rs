//! The layers laid over a streamed world's level 0: its holes ([`Layer::Hole`],
//! `terrain_core::holes`), its paint ([`Layer::Material`], `terrain_core::material_effect`) and
//! its colour ([`Layer::Color`]). Read a region of one ([`read_holes`], [`read_paint`],
//! [`read_color`]) and write one back ([`write_holes`], [`write_paint`], [`write_color`]).
//!
//! They are read and written on the world directly, not through the RAM pool: most tiles have
//! no file (no hole, no paint), and a cut or a crater's paint changes a few tiles, so a region
//! read when the camera moves on and a write of the tiles a change touched cost little. Each
//! tile is written atomically ([`World::write_tile`]); a tile left empty loses its file. Paint
//! and colour have coarser levels, which a write rebuilds above the tiles it changed, so the
//! VRAM pool streams them with the heights; holes are level 0 only.

use crate::error::CacheError;
use crate::overlay_pyramid::rebuild_overlay_ancestors;
use crate::tile::{Layer, TileData, TileId};
use crate::world::World;
use glam::{IVec2, UVec2};
use terrain_core::{Grid, Rect, WrapMode};

/// Most cells one read or write covers (a 16384^2 region): bounds the grid it allocates.
pub const MAX_OVERLAY_REGION_CELLS: u64 = 1 << 28;

/// The level-0 hole mask of `rect` (cells; on a repeating world it may cross the edges and
/// wraps, at most one world in size), row-major in the rect's own coordinates.
///
/// Fails on a rect off a clamped world, an empty or oversized rect (more than
/// [`MAX_OVERLAY_REGION_CELLS`]), and on a hole tile that does not decode (naming it).
pub fn read_holes(world: &World, rect: Rect) -> Result<Grid<u8>, CacheError> {
    read_region(
        world,
        Layer::Hole,
        rect,
        terrain_core::GROUND,
        TileData::as_u8,
    )
}

/// Writes `mask`, the level-0 hole mask of `rect` (as [`read_holes`] returns it), into the hole
/// tiles it covers: each tile is read, changed and written back atomically, and one left
/// without a hole loses its file. Returns the tiles whose content changed (holes have level 0
/// only).
///
/// Fails, before anything is written, on a mask of another size than the rect and on a rect
/// [`read_holes`] refuses; a tile that does not decode fails the call at that tile (the tiles
/// before it are written).
pub fn write_holes(world: &World, rect: Rect, mask: &Grid<u8>) -> Result<Vec<TileId>, CacheError> {
    write_region(world, Layer::Hole, rect, mask, TileData::as_u8_mut)
}

/// The level-0 material layer (painted weights, RGBA8) of `rect`, as [`read_holes`] reads
/// holes. Fails as it does, and with [`CacheError::NoSuchLayer`] on a version-1 (PNG) world.
pub fn read_paint(world: &World, rect: Rect) -> Result<Grid<[u8; 4]>, CacheError> {
    read_region(world, Layer::Material, rect, [0; 4], TileData::as_rgba8)
}

/// Writes `paint`, the material layer of `rect`, into the material tiles, as [`write_holes`]
/// writes holes (an unpainted tile loses its file), then the coarser levels' tiles above the
/// region's tiles (`overlay_pyramid`). Returns every tile whose file was rewritten, level 0
/// first: a RAM pool of the layer reloads them ([`RamPool::reload`](crate::RamPool::reload)).
/// One writer at a time per layer of a world: two writes under the same coarser tile on
/// different threads may each rebuild it from the other's old texels.
pub fn write_paint(
    world: &World,
    rect: Rect,
    paint: &Grid<[u8; 4]>,
) -> Result<Vec<TileId>, CacheError> {
    write_layer(world, Layer::Material, rect, paint)
}

/// The level-0 colour layer (sRGB, alpha its cover) of `rect`, as [`read_paint`] reads paint.
pub fn read_color(world: &World, rect: Rect) -> Result<Grid<[u8; 4]>, CacheError> {
    read_region(world, Layer::Color, rect, [0; 4], TileData::as_rgba8)
}

/// Writes `colors`, the colour layer of `rect`, into the colour tiles and their coarser levels,
/// as [`write_paint`] writes paint; a transparent tile loses its file.
pub fn write_color(
    world: &World,
    rect: Rect,
    colors: &Grid<[u8; 4]>,
) -> Result<Vec<TileId>, CacheError> {
    write_layer(world, Layer::Color, rect, colors)
}

/// Writes an RGBA layer's level-0 region, then the coarser tiles above every level-0 tile the
/// region touches, changed or not: writing a layer again builds the pyramid of a world written
/// before it had one, and finishes one a failed write left behind.
fn write_layer(
    world: &World,
    layer: Layer,
    rect: Rect,
    region: &Grid<[u8; 4]>,
) -> Result<Vec<TileId>, CacheError> {
    let mut changed = write_region(world, layer, rect, region, TileData::as_rgba8_mut)?;
    let mut touched = Vec::new();
    for_each_tile(world, &pieces(world, layer, rect)?, |id, _, _, _| {
        touched.push(id);
        Ok(())
    })?;
    touched.sort();
    touched.dedup();
    changed.extend(rebuild_overlay_ancestors(world, layer, &touched)?);
    Ok(changed)
}

fn read_region<T: Copy>(
    world: &World,
    layer: Layer,
    rect: Rect,
    empty: T,
    samples: fn(&TileData) -> Option<&Grid<T>>,
) -> Result<Grid<T>, CacheError> {
    let pieces = pieces(world, layer, rect)?;
    let mut out = Grid::new(rect.size.x, rect.size.y, empty)?;
    for_each_tile(
        world,
        &pieces,
        |id, tile_rect, piece_map, piece_unwrapped| {
            let tile = world.load_tile(layer, id)?;
            let cells = samples(tile.as_ref()).ok_or(CacheError::NoSuchLayer { layer })?;
            let Some(overlap) = piece_map.intersect(&tile_rect) else {
                return Ok(());
            };
            let at = (overlap.min - piece_map.min) + (piece_unwrapped.min - rect.min);
            let src = overlap.min - tile_rect.min;
            let w = overlap.size.x as usize;
            for row in 0..overlap.size.y {
                let from = &cells.row(src.y as u32 + row)[src.x as usize..src.x as usize + w];
                let to = out.row_mut(at.y as u32 + row);
                to[at.x as usize..at.x as usize + w].copy_from_slice(from);
            }
            Ok(())
        },
    )?;
    Ok(out)
}

fn write_region<T: Copy + PartialEq>(
    world: &World,
    layer: Layer,
    rect: Rect,
    region: &Grid<T>,
    samples: fn(&mut TileData) -> Option<&mut Grid<T>>,
) -> Result<Vec<TileId>, CacheError> {
    if region.size() != rect.size {
        return Err(CacheError::Core(terrain_core::CoreError::SizeMismatch {
            expected: rect.size,
            actual: region.size(),
        }));
    }
    let pieces = pieces(world, layer, rect)?;
    let mut changed = Vec::new();
    for_each_tile(
        world,
        &pieces,
        |id, tile_rect, piece_map, piece_unwrapped| {
            let Some(overlap) = piece_map.intersect(&tile_rect) else {
                return Ok(());
            };
            let mut tile = world.load_tile(layer, id)?.as_ref().clone();
            let cells = samples(&mut tile).ok_or(CacheError::NoSuchLayer { layer })?;
            let at = (overlap.min - piece_map.min) + (piece_unwrapped.min - rect.min);
            let dst = overlap.min - tile_rect.min;
            let w = overlap.size.x as usize;
            let mut differs = false;
            for row in 0..overlap.size.y {
                let from = &region.row(at.y as u32 + row)[at.x as usize..at.x as usize + w];
                let to = &mut cells.row_mut(dst.y as u32 + row)[dst.x as usize..dst.x as usize + w];
                differs |= to != from;
                to.copy_from_slice(from);
            }
            if differs {
                world.write_tile(layer, id, &tile)?;
                // A rect that wraps may reach one tile from two pieces.
                if !changed.contains(&id) {
                    changed.push(id);
                }
            }
            Ok(())
        },
    )?;
    Ok(changed)
}

/// The pieces of `rect` on the world's level 0 (split across the edges of a repeating world),
/// after the checks both directions share.
fn pieces(world: &World, layer: Layer, rect: Rect) -> Result<Vec<(Rect, Rect)>, CacheError> {
    let m = world.manifest();
    if m.layer_levels(layer) == 0 {
        return Err(CacheError::NoSuchLayer { layer });
    }
    let size = m.world_size;
    if rect.is_empty() || rect.area() > MAX_OVERLAY_REGION_CELLS {
        return Err(CacheError::OutOfRange {
            what: "level-0 region (cells)",
            value: rect.area() as f64,
            expected: "1 ..= 2^28 cells",
        });
    }
    match m.wrap {
        WrapMode::Repeat => {
            // A rect past i32::MAX would leave its data's last columns or rows unplaced.
            if rect.size.cmpgt(size).any() || !rect.is_representable() {
                return Err(region_off(rect, size));
            }
            Ok(rect
                .split_toroidal(size)
                .into_iter()
                .map(|p| (p.map, p.unwrapped))
                .collect())
        }
        WrapMode::Clamp => {
            if !Rect::from_size(size).contains_rect(&rect) {
                return Err(region_off(rect, size));
            }
            Ok(vec![(rect, rect)])
        }
    }
}

fn region_off(rect: Rect, map_size: UVec2) -> CacheError {
    CacheError::Core(terrain_core::CoreError::RegionOutOfBounds { rect, map_size })
}

/// Calls `f(tile, tile's rect, piece in map coordinates, the same piece unwrapped)` for every
/// level-0 tile a piece overlaps.
fn for_each_tile(
    world: &World,
    pieces: &[(Rect, Rect)],
    mut f: impl FnMut(TileId, Rect, Rect, Rect) -> Result<(), CacheError>,
) -> Result<(), CacheError> {
    let ts = world.manifest().tile_size;
    for &(map, unwrapped) in pieces {
        let first = map.min.as_uvec2() / ts;
        let last = (map.max() - IVec2::ONE).as_uvec2() / ts;
        for ty in first.y..=last.y {
            for tx in first.x..=last.x {
                let tile_rect = Rect::new((UVec2::new(tx, ty) * ts).as_ivec2(), UVec2::splat(ts));
                f(TileId::new(0, tx, ty), tile_rect, map, unwrapped)?;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::manifest::Manifest;
    use crate::store::FsStore;
    use std::sync::Arc;
    use terrain_core::HeightEncoding;

    fn world(dir: &std::path::Path, wrap: WrapMode) -> World {
        let enc = HeightEncoding::spanning::<u16>(0.0, 100.0).expect("range");
        let m = Manifest::new(UVec2::new(80, 48), 16, 1.0, enc, wrap).expect("manifest");
        World::create(Arc::new(FsStore::open(dir).expect("store")), m).expect("world")
    }

    #[test]
    fn holes_written_read_back_across_tiles_and_the_wrap() {
        let dir = crate::store::tests::temp_dir("overlays");
        let w = world(&dir, WrapMode::Repeat);
        // A rect across the world's corner: 4 pieces, 4 tiles.
        let rect = Rect::new(IVec2::new(76, 44), UVec2::new(8, 8));
        let mask =
            Grid::from_fn(8, 8, |x, y| if (x + y) % 3 == 0 { 255 } else { 0 }).expect("mask");
        assert_eq!(write_holes(&w, rect, &mask).expect("write").len(), 4);
        // Reopened: the same holes, and where nothing was written none.
        let w2 = World::open(w.store().clone()).expect("open");
        assert_eq!(read_holes(&w2, rect).expect("read"), mask);
        let at = |x, y| {
            read_holes(&w2, Rect::new(IVec2::new(x, y), UVec2::ONE))
                .expect("read")
                .as_slice()[0]
        };
        assert_eq!(at(0, 0), mask.get(4, 4).expect("cell"));
        assert_eq!(at(79, 47), mask.get(3, 3).expect("cell"));
        assert_eq!(at(40, 20), 0);
        // The same mask again changes nothing; clearing it removes every hole file.
        assert!(write_holes(&w, rect, &mask).expect("write").is_empty());
        let clear = Grid::new(8, 8, 0u8).expect("mask");
        assert_eq!(write_holes(&w, rect, &clear).expect("write").len(), 4);
        assert!(w.store().list("hole").expect("list").is_empty());
        // Paint the same way: written across the corner, read back after a reopen, cleared.
        let paint = Grid::from_fn(8, 8, |x, y| [x as u8 * 30, y as u8 * 30, 7, 0]).expect("paint");
        let written = write_paint(&w, rect, &paint).expect("write");
        // The 4 corner tiles, then their coarser ancestors: 4 at level 1, 2 at 2, 1 at 3.
        let at_level = |l| written.iter().filter(|id| id.level == l).count();
        assert_eq!([0, 1, 2, 3].map(at_level), [4, 4, 2, 1], "{written:?}");
        let w3 = World::open(w.store().clone()).expect("open");
        assert_eq!(read_paint(&w3, rect).expect("read"), paint);
        let none = Grid::new(8, 8, [0u8; 4]).expect("paint");
        assert_eq!(write_paint(&w, rect, &none).expect("write").len(), 11);
        assert!(w.store().list("material").expect("list").is_empty());
        // Colour the same way.
        assert_eq!(write_color(&w, rect, &paint).expect("write").len(), 11);
        assert_eq!(read_color(&w3, rect).expect("read"), paint);
        assert_eq!(write_color(&w, rect, &none).expect("write").len(), 11);
        assert!(w.store().list("color").expect("list").is_empty());
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn coarser_levels_hold_the_reduced_paint_and_colour() {
        let dir = crate::store::tests::temp_dir("overlays-pyramid");
        let w = world(&dir, WrapMode::Clamp);
        // All of level 0 (80 x 48: partial tiles at the right and bottom of coarser levels).
        let all = Rect::from_size(UVec2::new(80, 48));
        let paint = Grid::from_fn(80, 48, |x, y| {
            [
                ((x * 7 + y * 3) % 256) as u8,
                (x % 5 * 40) as u8,
                0,
                (y * 5) as u8,
            ]
        })
        .expect("paint");
        write_paint(&w, all, &paint).expect("write");
        let colors = Grid::from_fn(80, 48, |x, y| {
            [
                (x * 3) as u8,
                (y * 5) as u8,
                90,
                if (x / 3 + y) % 4 == 0 { 0 } else { 255 },
            ]
        })
        .expect("colours");
        write_color(&w, all, &colors).expect("write");
        let m = *w.manifest();
        for (layer, level0) in [(Layer::Material, &paint), (Layer::Color, &colors)] {
            // The CPU reference: each level from the one below, texel by texel.
            let mut below = level0.clone();
            for level in 1..m.levels {
                let size = m.level_size(level);
                let expected = Grid::from_fn(size.x, size.y, |x, y| {
                    let mut block = Vec::new();
                    for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        if let Some(t) = below.get(2 * x + dx, 2 * y + dy) {
                            block.push(t);
                        }
                    }
                    if layer == Layer::Color {
                        crate::overlay_pyramid::mean_color(&block)
                    } else {
                        crate::overlay_pyramid::mean_paint(&block)
                    }
                })
                .expect("level");
                for id in m.tiles_of(layer, level) {
                    let tile = w.load_tile(layer, id).expect("tile");
                    let cells = tile.as_rgba8().expect("rgba");
                    for y in 0..m.tile_size {
                        for x in 0..m.tile_size {
                            let (gx, gy) = (id.x * m.tile_size + x, id.y * m.tile_size + y);
                            let want = expected.get(gx, gy).unwrap_or([0; 4]);
                            assert_eq!(cells.get(x, y), Some(want), "{layer:?} {id:?} {x} {y}");
                        }
                    }
                }
                below = expected;
            }
        }
        // A coarser tile lost (a world written before paint had levels, or a failed write):
        // writing the same paint again, which changes no level-0 tile, rebuilds it.
        let lost = TileId::new(1, 0, 0);
        let key = m.tile_key(Layer::Material, lost);
        let kept = w
            .store()
            .read(&key, u64::MAX)
            .expect("read")
            .expect("a stored tile");
        w.store().remove(&key).expect("remove");
        let again = write_paint(&w, all, &read_paint(&w, all).expect("read")).expect("write");
        assert!(
            again.iter().all(|id| id.level > 0) && again.contains(&lost),
            "{again:?}"
        );
        assert_eq!(w.store().read(&key, u64::MAX).expect("read"), Some(kept));
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn bad_regions_are_refused_and_write_nothing() {
        let dir = crate::store::tests::temp_dir("overlays-bad");
        let w = world(&dir, WrapMode::Clamp);
        let mask = Grid::new(8, 8, 255u8).expect("mask");
        for rect in [
            Rect::new(IVec2::new(76, 0), UVec2::splat(8)),
            Rect::new(IVec2::new(-1, 0), UVec2::splat(8)),
            Rect::new(IVec2::ZERO, UVec2::ZERO),
        ] {
            assert!(read_holes(&w, rect).is_err(), "{rect:?}");
        }
        let wrong = Rect::new(IVec2::ZERO, UVec2::splat(4));
        assert!(write_holes(&w, wrong, &mask).is_err());
        let huge = Rect::new(IVec2::ZERO, UVec2::splat(1 << 15));
        assert!(read_holes(&w, huge).is_err());
        assert!(w.store().list("hole").expect("list").is_empty());
        // Rects at the ends of the i32 range, on a clamped and a repeating world: an error or
        // an answer, never a panic.
        let dir2 = crate::store::tests::temp_dir("overlays-extreme");
        let wrapped = world(&dir2, WrapMode::Repeat);
        for min in [
            IVec2::splat(i32::MIN),
            IVec2::splat(i32::MAX - 3),
            IVec2::new(i32::MIN, 7),
        ] {
            let rect = Rect::new(min, UVec2::splat(8));
            assert!(read_holes(&w, rect).is_err(), "{rect:?}");
            if let Ok(mask) = read_holes(&wrapped, rect) {
                assert_eq!(mask.size(), rect.size);
            }
            let _ = write_holes(&wrapped, rect, &Grid::new(8, 8, 0u8).expect("mask"));
        }
        // A rect past i32::MAX is refused on a repeating world: its last columns have no
        // place (they were written into the wrong ones). One just inside is written where its
        // cells are, across the world's edge.
        let past = Rect::new(IVec2::new(i32::MAX - 2, 0), UVec2::new(40, 8));
        let mask = Grid::from_fn(40, 8, |x, _| u8::from(x % 3 == 0) * 255).expect("mask");
        assert!(write_holes(&wrapped, past, &mask).is_err());
        assert!(read_holes(&wrapped, past).is_err());
        let inside = Rect::new(IVec2::new(i32::MAX - 40, 0), UVec2::new(40, 8));
        write_holes(&wrapped, inside, &mask).expect("write inside i32");
        assert_eq!(read_holes(&wrapped, inside).expect("read back"), mask);
        let size = wrapped.manifest().world_size;
        let at = |x: i64| x.rem_euclid(i64::from(size.x)) as i32;
        let one = Rect::new(
            IVec2::new(at(i64::from(i32::MAX) - 40), 0),
            UVec2::new(1, 8),
        );
        assert_eq!(
            read_holes(&wrapped, one).expect("first column").get(0, 0),
            Some(255)
        );
        let _ = std::fs::remove_dir_all(dir2);
        // A damaged hole file is an error naming the tile, not a panic.
        let key = w.manifest().tile_key(Layer::Hole, TileId::new(0, 0, 0));
        w.store().write(&key, b"not a tile").expect("write");
        let e = read_holes(&w, Rect::new(IVec2::ZERO, UVec2::splat(4))).unwrap_err();
        assert!(
            matches!(
                e,
                CacheError::CorruptTile {
                    layer: Layer::Hole,
                    ..
                }
            ),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(dir);
    }
}
