//! The tile upload contract shared by the crate that holds tiles on the GPU (terrain-gpu's
//! `GpuTileAtlas`) and the one that decides which tiles to hold (terrain-cache's `VramPool`):
//! [`TileUploadTarget`], the world layout it indexes ([`TileLayout`]) and the sentinel of an
//! empty indirection entry ([`INVALID_SLOT`]).
//!
//! A target is a fixed number of tile *slots* plus an *indirection table* with one entry per
//! tile of every level of the world: the slot holding that tile, or [`INVALID_SLOT`]. A reader
//! (the renderer, or [`crate::tile_atlas::TileAtlas::stored_at`] on the CPU) looks up a level-0
//! texel `t` from level 0 upwards: at level `l` the texel is `t >> l`, in tile
//! `(t >> l) / tile_size`; the first level whose tile is mapped answers. So a missing tile only
//! ever shows as a coarser one, never as a hole.
//!
//! Only the contract lives here; the consumer decides what to upload and when, the target
//! only stores what it is given.

use crate::error::CoreError;
use crate::grid::{Grid, WrapMode};
use crate::map::HeightEncoding;
use glam::{IVec2, UVec2};

/// Indirection entry of a tile that is not resident.
pub const INVALID_SLOT: u32 = u32::MAX;

/// Most levels a [`TileLayout`] may have (level `l` halves the world `l` times; 32 levels
/// reach a single texel from any `u32` world size).
pub const MAX_TILE_LEVELS: u32 = 32;

/// Largest tile side a [`TileLayout`] accepts (a power of two).
pub const MAX_LAYOUT_TILE_SIZE: u32 = 1 << 15;

/// The layout of a tiled world pyramid, as a tile upload target indexes it.
///
/// Level 0 is the finest and has `world_size` texels; level `l` has `ceil(world_size / 2^l)`
/// texels (each texel the 2x2 reduction of the level below), cut into square tiles of
/// `tile_size` texels, edge tiles padded. terrain-cache's `Manifest::tile_layout` gives the
/// layout of a world on disk.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TileLayout {
    /// Level-0 size in texels.
    pub world_size: UVec2,
    /// Tile side in texels, a power of two in `1..=MAX_LAYOUT_TILE_SIZE`.
    pub tile_size: u32,
    /// Levels in the pyramid, `1..=MAX_TILE_LEVELS`.
    pub levels: u32,
    /// Metres per texel at level 0.
    pub texel_size: f32,
    /// Stored value to metres.
    pub encoding: HeightEncoding,
    /// How level-0 texels outside the world are addressed: `Clamp` extends the edges (a
    /// non-repeating world), `Repeat` wraps.
    pub wrap: WrapMode,
    /// The stored value read where no level holds a texel (nothing resident at all).
    pub fill: u16,
}

impl TileLayout {
    /// Checks every field; targets call it before building anything.
    pub fn validate(&self) -> Result<(), CoreError> {
        if self.world_size.min_element() == 0 {
            return Err(CoreError::EmptyGrid {
                width: self.world_size.x,
                height: self.world_size.y,
            });
        }
        if !self.tile_size.is_power_of_two() || self.tile_size > MAX_LAYOUT_TILE_SIZE {
            return Err(CoreError::OutOfRange {
                what: "tile size (texels)",
                value: f64::from(self.tile_size),
                expected: "a power of two, at most 32768",
            });
        }
        if self.levels == 0 || self.levels > MAX_TILE_LEVELS {
            return Err(CoreError::OutOfRange {
                what: "tile levels",
                value: f64::from(self.levels),
                expected: "1 ..= 32",
            });
        }
        if !self.texel_size.is_finite() {
            return Err(CoreError::NonFinite {
                what: "texel size",
                value: self.texel_size,
            });
        }
        if self.texel_size <= 0.0 {
            return Err(CoreError::OutOfRange {
                what: "texel size",
                value: f64::from(self.texel_size),
                expected: "greater than 0",
            });
        }
        HeightEncoding::new(self.encoding.scale, self.encoding.offset)?;
        if self.table_len() > u64::from(u32::MAX) {
            return Err(CoreError::OutOfRange {
                what: "tiles in the pyramid",
                value: self.table_len() as f64,
                expected: "fewer than 2^32",
            });
        }
        Ok(())
    }

    /// Texels of `level`: `ceil(world_size / 2^level)`, at least 1.
    pub fn level_size(&self, level: u32) -> UVec2 {
        let s = level.min(MAX_TILE_LEVELS - 1);
        let ceil_shift = |v: u32| ((u64::from(v) + (1u64 << s) - 1) >> s).max(1) as u32;
        UVec2::new(ceil_shift(self.world_size.x), ceil_shift(self.world_size.y))
    }

    /// Tiles across and down `level` (zero beyond the last level).
    pub fn tiles_at(&self, level: u32) -> UVec2 {
        if level >= self.levels {
            return UVec2::ZERO;
        }
        let t = self.tile_size.max(1);
        let s = self.level_size(level);
        UVec2::new(s.x.div_ceil(t), s.y.div_ceil(t))
    }

    /// Entries of the indirection table: the tiles of every level (saturating: a layout whose
    /// table would not fit `u64` fails [`validate`](Self::validate) anyway).
    pub fn table_len(&self) -> u64 {
        self.level_offset(self.levels)
    }

    /// Index of the first entry of `level` in the indirection table (levels in order, each
    /// row-major; saturating).
    pub fn level_offset(&self, level: u32) -> u64 {
        (0..level.min(self.levels).min(MAX_TILE_LEVELS))
            .map(|l| {
                let t = self.tiles_at(l);
                u64::from(t.x) * u64::from(t.y)
            })
            .fold(0u64, u64::saturating_add)
    }

    /// The indirection table index of tile `tile` of `level`, or `None` outside the pyramid.
    pub fn table_index(&self, level: u32, tile: UVec2) -> Option<u64> {
        let t = self.tiles_at(level);
        (tile.x < t.x && tile.y < t.y).then(|| {
            self.level_offset(level)
                .saturating_add(u64::from(tile.y) * u64::from(t.x) + u64::from(tile.x))
        })
    }

    /// The level-0 texel a possibly out-of-world texel reads: clamped to the edges or wrapped,
    /// as `wrap` says.
    pub fn address(&self, t: IVec2) -> UVec2 {
        UVec2::new(
            self.wrap.resolve(i64::from(t.x), self.world_size.x.max(1)),
            self.wrap.resolve(i64::from(t.y), self.world_size.y.max(1)),
        )
    }

    /// Samples in one tile.
    pub fn tile_texels(&self) -> u64 {
        u64::from(self.tile_size) * u64::from(self.tile_size)
    }
}

/// Where tiles go to be drawn: a fixed number of slots and an indirection table over every
/// tile of a [`TileLayout`].
///
/// Contract for implementers:
/// - `upload` stores a whole tile's heights in a slot, replacing what the slot held; it does
///   not touch the indirection table. It returns the bytes it transferred, which the caller
///   counts against its per-frame budget; that is never more than
///   [`upload_bytes`](Self::upload_bytes).
/// - `map` sets one table entry: `Some(slot)` makes the tile resident, `None` removes it. A
///   reader resolves each texel to the finest mapped level covering it (see the module docs).
/// - The caller orders the calls: it unmaps a tile before uploading another into its slot and
///   maps a tile only after its upload, so a reader never sees a slot under the wrong tile.
///   Calls take effect in order, all before the next frame is drawn.
/// - Out-of-range slots, levels, tiles or wrongly sized grids are refused with the
///   implementation's own [`TileUploadTarget::Error`], never a panic.
pub trait TileUploadTarget {
    /// What a refused call reports.
    type Error: std::error::Error + Send + Sync + 'static;

    /// The world layout the indirection table covers (tile size, levels, tiles per level).
    fn layout(&self) -> &TileLayout;
    /// Tile slots, `0..slot_count()`.
    fn slot_count(&self) -> u32;
    /// Bytes one [`upload`](Self::upload) transfers.
    fn upload_bytes(&self) -> u64;
    /// Stores `heights` (`tile_size` x `tile_size` stored values) in `slot` as tile `tile` of
    /// `level`; returns the bytes transferred.
    fn upload(
        &mut self,
        slot: u32,
        level: u32,
        tile: UVec2,
        heights: &Grid<u16>,
    ) -> Result<u64, Self::Error>;
    /// Sets the indirection entry of tile `tile` of `level` to `slot`, or to not resident.
    fn map(&mut self, level: u32, tile: UVec2, slot: Option<u32>) -> Result<(), Self::Error>;
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn layout(world: u32, tile: u32, levels: u32) -> TileLayout {
        TileLayout {
            world_size: UVec2::splat(world),
            tile_size: tile,
            levels,
            texel_size: 1.0,
            encoding: HeightEncoding::new(0.01, 0.0).unwrap(),
            wrap: WrapMode::Clamp,
            fill: 0,
        }
    }

    #[test]
    fn levels_tiles_and_table_indices_follow_the_pyramid() {
        // 100 texels in 16-texel tiles: 7, 4 (50 texels), 2 (25), 1 (13) tiles per side.
        let l = layout(100, 16, 4);
        l.validate().unwrap();
        assert_eq!(l.level_size(1), UVec2::splat(50));
        assert_eq!(l.level_size(3), UVec2::splat(13));
        let tiles: Vec<u32> = (0..5).map(|i| l.tiles_at(i).x).collect();
        assert_eq!(tiles, [7, 4, 2, 1, 0]);
        assert_eq!(l.table_len(), 49 + 16 + 4 + 1);
        assert_eq!(l.table_index(0, UVec2::new(6, 6)), Some(48));
        assert_eq!(l.table_index(1, UVec2::ZERO), Some(49));
        assert_eq!(l.table_index(3, UVec2::ZERO), Some(69));
        assert_eq!(l.table_index(3, UVec2::new(1, 0)), None);
        assert_eq!(l.table_index(4, UVec2::ZERO), None);
        // The last level-0 texel lies in the last tile of every level.
        for lv in 0..4 {
            let c = UVec2::splat(99) >> lv;
            assert_eq!(c / 16, l.tiles_at(lv) - 1, "level {lv}");
        }
    }

    #[test]
    fn bad_layouts_are_errors_and_addressing_clamps_or_wraps() {
        assert!(layout(0, 16, 1).validate().is_err());
        assert!(layout(64, 24, 1).validate().is_err());
        assert!(layout(64, 16, 0).validate().is_err());
        assert!(layout(64, 16, 33).validate().is_err());
        let mut l = layout(64, 16, 3);
        l.texel_size = f32::NAN;
        assert!(l.validate().is_err());
        let mut l = layout(64, 16, 3);
        assert_eq!(l.address(IVec2::new(-5, 70)), UVec2::new(0, 63));
        assert_eq!(l.address(IVec2::new(i32::MIN, i32::MAX)), UVec2::new(0, 63));
        l.wrap = WrapMode::Repeat;
        assert_eq!(l.address(IVec2::new(-1, 65)), UVec2::new(63, 1));
        // Large worlds validate as long as the table stays addressable.
        assert!(layout(1 << 24, 1 << 15, 32).validate().is_ok());
        assert!(layout(u32::MAX, 1, 32).validate().is_err());
    }
}
