//! A world's overview: one whole level of its pyramid as one [`CoarseMap`], the finest that
//! fits a given side (a minimap, a hillshade of the whole world, the heights a server reports).
//! Pick the level with [`Manifest::finest_level_within`] before anything is read: the memory
//! it takes is then bounded by the side asked for, where the pyramid reaches that far, and
//! [`World::read_level`] refuses a level of more than 2^28 texels whatever the pyramid.

use crate::overlays::MAX_OVERLAY_REGION_CELLS;
use crate::tile::{Layer, TileId};
use crate::world::World;
use crate::{CacheError, Manifest};
use glam::{IVec2, UVec2};
use terrain_core::{CoarseMap, Grid, Rect, WrapMode};

impl Manifest {
    /// The finest level whose longer side is at most `max_side` texels; the coarsest level
    /// when none is.
    pub fn finest_level_within(&self, max_side: u32) -> u32 {
        let levels = self.levels.max(1);
        (0..levels)
            .find(|&l| self.level_size(l).max_element() <= max_side)
            .unwrap_or(levels - 1)
    }
}

impl World {
    /// Level `level` of the heights as one coarse-map (texels `2^level` times level 0's,
    /// clamped at the edges: an overview is one picture, not a repeat). Tiles without a file
    /// read as the zero tile. Reads every tile of the level: pick it with
    /// [`Manifest::finest_level_within`] to bound what it takes. Fails on a level the world
    /// does not have, one of more than [`MAX_OVERLAY_REGION_CELLS`] texels, and a tile that
    /// does not read.
    pub fn read_level(&self, level: u32) -> Result<CoarseMap, CacheError> {
        let m = *self.manifest();
        if level >= m.levels {
            return Err(CacheError::OutOfRange {
                what: "level",
                value: f64::from(level),
                expected: "a level of the world's pyramid",
            });
        }
        let size = m.level_size(level);
        let texels = u64::from(size.x) * u64::from(size.y);
        if texels > MAX_OVERLAY_REGION_CELLS {
            return Err(CacheError::OutOfRange {
                what: "level texels",
                value: texels as f64,
                expected: "at most 2^28 (read a coarser level: Manifest::finest_level_within)",
            });
        }
        let mut grid = Grid::new(size.x, size.y, 0u16)?;
        for id in m.tiles_of(Layer::Height, level) {
            let data = self.load_tile(Layer::Height, id)?;
            let Some(tile) = data.as_u16() else {
                return Err(not_heights(id));
            };
            let origin = UVec2::new(id.x, id.y) * m.tile_size;
            let part = (size - origin).min(tile.size());
            let piece = tile.copy_rect(Rect::new(IVec2::ZERO, part))?;
            grid.paste(&piece, origin.as_ivec2())?;
        }
        let scale = (1u64 << level) as f32;
        Ok(CoarseMap::new(
            grid,
            m.encoding,
            m.texel_size * scale,
            WrapMode::Clamp,
        )?)
    }
}

fn not_heights(id: TileId) -> CacheError {
    CacheError::OutOfRange {
        what: "height tile format",
        value: f64::from(id.level),
        expected: "16-bit heights in every tile of the level",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::{MapSource, build_world};
    use crate::store::FsStore;
    use crate::store::tests::temp_dir;
    use std::sync::Arc;
    use terrain_core::HeightEncoding;

    #[test]
    fn the_overview_level_is_the_finest_that_fits() {
        let enc = HeightEncoding::spanning::<u16>(0.0, 100.0).expect("encoding");
        let mut m =
            Manifest::new(UVec2::new(1000, 600), 256, 1.0, enc, WrapMode::Clamp).expect("manifest");
        assert_eq!(m.finest_level_within(1000), 0);
        assert_eq!(m.finest_level_within(999), 1);
        assert_eq!(m.finest_level_within(250), 2);
        // Nothing fits: the coarsest.
        assert_eq!(m.finest_level_within(0), m.levels - 1);
        m.levels = 1;
        assert_eq!(m.finest_level_within(10), 0);
    }

    #[test]
    fn a_level_reads_as_the_tiles_stitched_together() {
        let dir = temp_dir("overview");
        let store: Arc<dyn crate::TileStore> = Arc::new(FsStore::open(&dir).expect("store"));
        let enc = HeightEncoding::spanning::<u16>(0.0, 100.0).expect("encoding");
        let heights =
            Grid::from_fn(300, 200, |x, y| ((x * 7 + y * 13) % 60_000) as u16).expect("grid");
        let map = CoarseMap::new(heights.clone(), enc, 0.5, WrapMode::Clamp).expect("map");
        let m = Manifest::new(map.grid().size(), 64, 0.5, enc, WrapMode::Clamp).expect("manifest");
        let source = MapSource::new(&map);
        let (world, _) = build_world(store, m, &source, &|_| true).expect("build");
        let level0 = world.read_level(0).expect("level 0");
        assert_eq!(level0.grid(), &heights);
        assert_eq!(level0.texel_size(), 0.5);
        let level1 = world.read_level(1).expect("level 1");
        assert_eq!(level1.grid().size(), UVec2::new(150, 100));
        assert_eq!(level1.texel_size(), 1.0);
        let past = world.read_level(world.manifest().levels);
        assert!(
            matches!(past, Err(CacheError::OutOfRange { .. })),
            "{past:?}"
        );
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn a_level_too_large_to_hold_is_refused_before_anything_is_read() {
        let dir = temp_dir("overview-huge");
        let store: Arc<dyn crate::TileStore> = Arc::new(FsStore::open(&dir).expect("store"));
        let enc = HeightEncoding::spanning::<u16>(0.0, 100.0).expect("encoding");
        let mut m =
            Manifest::new(UVec2::splat(1 << 20), 256, 1.0, enc, WrapMode::Clamp).expect("manifest");
        m.levels = m.max_levels();
        // Only a manifest: every tile reads as the zero tile.
        let world = World::create(store, m).expect("world");
        let level0 = world.read_level(0);
        assert!(
            matches!(level0, Err(CacheError::OutOfRange { .. })),
            "{level0:?}"
        );
        let fits = m.finest_level_within(1024);
        let overview = world.read_level(fits).expect("overview");
        assert_eq!(overview.grid().size(), UVec2::splat(1024));
        let _ = std::fs::remove_dir_all(dir);
    }
}
