//! The lowest and highest level-0 height under any rect of a streamed world, without the
//! rect's texels in memory: exact from the level-0 tiles resident in a RAM pool, else from the
//! world's per-tile bounds (`bounds.bin` of level 0, written by the build and kept current by
//! write-back), else the whole range. What a LOD quadtree over the world (CDLOD's
//! `CdlodTree::from_leaf_bounds` in terrain-lod) is built and updated from (Strugar 2010 keeps
//! min / max per node; Flower 2010, sec. 3.3 streams the tiles they come from).

use crate::error::CacheError;
use crate::manifest::Manifest;
use crate::pool::RamPool;
use crate::tile::{TileData, TileId};
use crate::world::{LevelBounds, World};
use glam::{IVec2, UVec2};
use terrain_core::Rect;

/// Per-tile bounds of a world's level 0, kept current with its RAM pool's changes.
#[derive(Debug, Clone)]
pub struct RegionBounds {
    manifest: Manifest,
    tiles: LevelBounds,
}

impl RegionBounds {
    /// The bounds of `world`'s level 0 as its `bounds.bin` holds them (tiles it does not
    /// list, or all of them without the file, span the whole u16 range).
    pub fn open(world: &World) -> Result<Self, CacheError> {
        let manifest = *world.manifest();
        let count = manifest.tiles_at(0);
        let mut tiles = world
            .bounds(0)?
            .unwrap_or_else(|| LevelBounds::empty(count));
        // An empty entry ([MAX, 0]: the build never saw the tile) bounds nothing: the whole
        // range stands in for it.
        for b in &mut tiles.min_max {
            if b[0] > b[1] {
                *b = [0, u16::MAX];
            }
        }
        Ok(Self { manifest, tiles })
    }

    /// `[min, max]` stored heights of the level-0 texels of `rect` (clipped to the world;
    /// `None` when nothing of it is inside): each tile's part exactly where `pool` holds the
    /// tile, else the tile's own bounds (which cover the part).
    pub fn of(&self, pool: &RamPool, rect: Rect) -> Option<[u16; 2]> {
        let rect = rect.intersect(&Rect::from_size(self.manifest.world_size))?;
        let ts = self.manifest.tile_size;
        let lo = rect.min.as_uvec2() / ts;
        let hi = (rect.max().as_uvec2() - UVec2::ONE) / ts;
        let (mut min, mut max) = (u16::MAX, 0u16);
        for ty in lo.y..=hi.y {
            for tx in lo.x..=hi.x {
                let [a, b] = match pool.tile(TileId::new(0, tx, ty)) {
                    Some(TileData::U16(grid)) => {
                        let origin = IVec2::new(tx as i32, ty as i32) * ts as i32;
                        let tile = Rect::new(origin, UVec2::splat(ts));
                        let Some(part) = rect.intersect(&tile) else {
                            continue;
                        };
                        part_bounds(grid, Rect::new(part.min - origin, part.size))
                    }
                    _ => self.tiles.get(tx, ty).unwrap_or([0, u16::MAX]),
                };
                min = min.min(a);
                max = max.max(b);
            }
        }
        Some([min, max])
    }

    /// [`RegionBounds::of`] in metres (the world's encoding), the whole stored range where
    /// nothing of `rect` is inside: what a quadtree's leaves are built and updated from
    /// (`CdlodTree::from_leaf_bounds` and `update_leaf_bounds` in terrain-lod).
    pub fn metres(&self, pool: &RamPool, rect: Rect) -> (f32, f32) {
        let [lo, hi] = self.of(pool, rect).unwrap_or([0, u16::MAX]);
        let enc = self.manifest.encoding;
        (enc.to_metres(f64::from(lo)), enc.to_metres(f64::from(hi)))
    }

    /// Recomputes the bounds of the level-0 tiles `changed` (world texels) touches from their
    /// resident data in `pool` (a tile not resident keeps its bounds): after a deformation,
    /// so the tile's bounds hold once it is evicted.
    pub fn update(&mut self, pool: &RamPool, changed: Rect) {
        let Some(rect) = changed.intersect(&Rect::from_size(self.manifest.world_size)) else {
            return;
        };
        let ts = self.manifest.tile_size;
        let lo = rect.min.as_uvec2() / ts;
        let hi = (rect.max().as_uvec2() - UVec2::ONE) / ts;
        for ty in lo.y..=hi.y {
            for tx in lo.x..=hi.x {
                if let Some(TileData::U16(grid)) = pool.tile(TileId::new(0, tx, ty)) {
                    let i = ty as usize * self.tiles.tiles.x as usize + tx as usize;
                    // The tile's texels inside the world (a last partial tile's rest is fill).
                    let origin = UVec2::new(tx, ty) * ts;
                    let inside = (self.manifest.world_size - origin).min(UVec2::splat(ts));
                    let b = part_bounds(grid, Rect::from_size(inside));
                    if let Some(slot) = self.tiles.min_max.get_mut(i) {
                        *slot = b;
                    }
                }
            }
        }
    }
}

/// `[min, max]` of `rect` (inside `grid`).
fn part_bounds(grid: &terrain_core::Grid<u16>, rect: Rect) -> [u16; 2] {
    let (mut min, mut max) = (u16::MAX, 0u16);
    let (x0, x1) = (rect.min.x as usize, rect.max().x as usize);
    for y in rect.min.y..rect.max().y {
        for &v in &grid.row(y as u32)[x0..x1] {
            min = min.min(v);
            max = max.max(v);
        }
    }
    [min, max]
}
