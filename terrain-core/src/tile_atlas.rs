//! [`TileAtlas`]: the CPU reference of a tile upload target (terrain-gpu's `GpuTileAtlas` is
//! its GPU mirror): tile slots of heights, the indirection table, and the lookup a renderer
//! does, the finest resident level covering a texel ([`TileAtlas::stored_at`]).
//!
//! It is also what tests of a tile pool upload into, and what a user without a GPU samples.

use crate::error::CoreError;
use crate::grid::Grid;
use crate::tile_upload::{INVALID_SLOT, TileLayout, TileUploadTarget};
use glam::{IVec2, UVec2};

/// Tile slots and an indirection table in memory, laid out as the GPU atlas lays them out
/// (one u32 per height here; the GPU packs two 16-bit heights per word): slot `s` holds
/// `tile_size^2` heights from index `s * tile_size^2`, row-major; table
/// entry [`TileLayout::table_index`] holds a slot or [`INVALID_SLOT`].
#[derive(Debug, Clone, PartialEq)]
pub struct TileAtlas {
    layout: TileLayout,
    slots: u32,
    heights: Vec<u32>,
    table: Vec<u32>,
    uploads: u64,
    uploaded_bytes: u64,
}

impl TileAtlas {
    /// An atlas of `slots` tile slots over `layout`, nothing resident.
    pub fn new(layout: TileLayout, slots: u32) -> Result<Self, CoreError> {
        layout.validate()?;
        if slots == 0 || slots == INVALID_SLOT {
            return Err(CoreError::OutOfRange {
                what: "atlas slots",
                value: f64::from(slots),
                expected: "1 ..= 2^32 - 2",
            });
        }
        let texels = u64::from(slots)
            .checked_mul(layout.tile_texels())
            .and_then(|n| usize::try_from(n).ok())
            .ok_or(CoreError::GridTooLarge {
                width: layout.tile_size,
                height: layout.tile_size.saturating_mul(slots),
            })?;
        let table_len = usize::try_from(layout.table_len()).map_err(|_| CoreError::OutOfRange {
            what: "tiles in the pyramid",
            value: layout.table_len() as f64,
            expected: "addressable on this machine",
        })?;
        Ok(Self {
            layout,
            slots,
            heights: vec![0; texels],
            table: vec![INVALID_SLOT; table_len],
            uploads: 0,
            uploaded_bytes: 0,
        })
    }

    /// The slot holding tile `tile` of `level`, if it is mapped.
    pub fn slot_of(&self, level: u32, tile: UVec2) -> Option<u32> {
        let i = self.layout.table_index(level, tile)?;
        let s = self.table[i as usize];
        (s < self.slots).then_some(s)
    }

    /// The finest level whose tile covering level-0 texel `texel` (inside the world) is mapped,
    /// with its slot; `None` when no level covers it.
    pub fn resolve(&self, texel: UVec2) -> Option<(u32, u32)> {
        let ts = self.layout.tile_size;
        (0..self.layout.levels).find_map(|level| {
            let c = texel >> level;
            self.slot_of(level, c / ts).map(|s| (level, s))
        })
    }

    /// The stored height a renderer reads at level-0 texel `t` (addressed by the layout's wrap
    /// mode): the texel `t >> l` of the finest mapped level `l`, or the layout's `fill` when no
    /// level is mapped there.
    pub fn stored_at(&self, t: IVec2) -> u32 {
        let texel = self.layout.address(t);
        match self.resolve(texel) {
            Some((level, slot)) => {
                let ts = self.layout.tile_size;
                let c = (texel >> level) % ts;
                let i = u64::from(slot) * self.layout.tile_texels()
                    + u64::from(c.y) * u64::from(ts)
                    + u64::from(c.x);
                self.heights[i as usize]
            }
            None => u32::from(self.layout.fill),
        }
    }

    /// [`stored_at`](Self::stored_at) in metres.
    pub fn height_at(&self, t: IVec2) -> f32 {
        self.layout.encoding.to_metres(f64::from(self.stored_at(t)))
    }

    /// The indirection table, level by level, row-major.
    pub fn table(&self) -> &[u32] {
        &self.table
    }

    /// Tiles uploaded since the atlas was made.
    pub fn uploads(&self) -> u64 {
        self.uploads
    }

    /// Bytes uploaded since the atlas was made.
    pub fn uploaded_bytes(&self) -> u64 {
        self.uploaded_bytes
    }

    /// Tiles mapped now.
    pub fn mapped(&self) -> usize {
        self.table.iter().filter(|&&s| s < self.slots).count()
    }

    fn check_tile(&self, level: u32, tile: UVec2) -> Result<usize, CoreError> {
        self.layout
            .table_index(level, tile)
            .map(|i| i as usize)
            .ok_or(CoreError::OutOfRange {
                what: "tile (level, x, y)",
                value: f64::from(level),
                expected: "a tile of the layout's pyramid",
            })
    }

    fn check_slot(&self, slot: u32) -> Result<(), CoreError> {
        if slot < self.slots {
            Ok(())
        } else {
            Err(CoreError::OutOfRange {
                what: "atlas slot",
                value: f64::from(slot),
                expected: "below the atlas's slot count",
            })
        }
    }
}

impl TileUploadTarget for TileAtlas {
    type Error = CoreError;

    fn layout(&self) -> &TileLayout {
        &self.layout
    }

    fn slot_count(&self) -> u32 {
        self.slots
    }

    /// 2 bytes per texel, as on the GPU (16-bit texels packed two per u32 word, rows of
    /// whole words).
    fn upload_bytes(&self) -> u64 {
        u64::from(self.layout.tile_size.div_ceil(2)) * u64::from(self.layout.tile_size) * 4
    }

    fn upload(
        &mut self,
        slot: u32,
        level: u32,
        tile: UVec2,
        heights: &Grid<u16>,
    ) -> Result<u64, CoreError> {
        self.check_slot(slot)?;
        self.check_tile(level, tile)?;
        let ts = self.layout.tile_size;
        if heights.size() != UVec2::splat(ts) {
            return Err(CoreError::SizeMismatch {
                expected: UVec2::splat(ts),
                actual: heights.size(),
            });
        }
        let n = self.layout.tile_texels() as usize;
        let start = slot as usize * n;
        for (d, &s) in self.heights[start..start + n]
            .iter_mut()
            .zip(heights.as_slice())
        {
            *d = u32::from(s);
        }
        let bytes = self.upload_bytes();
        self.uploads += 1;
        self.uploaded_bytes += bytes;
        Ok(bytes)
    }

    fn map(&mut self, level: u32, tile: UVec2, slot: Option<u32>) -> Result<(), CoreError> {
        let i = self.check_tile(level, tile)?;
        if let Some(s) = slot {
            self.check_slot(s)?;
        }
        self.table[i] = slot.unwrap_or(INVALID_SLOT);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::WrapMode;
    use crate::map::HeightEncoding;

    fn layout() -> TileLayout {
        TileLayout {
            world_size: UVec2::new(40, 24),
            tile_size: 8,
            levels: 4,
            texel_size: 0.5,
            encoding: HeightEncoding::new(0.1, -2.0).unwrap(),
            wrap: WrapMode::Clamp,
            fill: 7,
        }
    }

    /// The tile of `level` whose texel `c` holds `level * 10000 + c.y * 100 + c.x`.
    fn tile(level: u32, t: UVec2) -> Grid<u16> {
        Grid::from_fn(8, 8, |x, y| {
            (level * 10_000 + (t.y * 8 + y) * 100 + t.x * 8 + x) as u16
        })
        .unwrap()
    }

    #[test]
    fn lookups_take_the_finest_mapped_level_and_the_fill_where_none_is() {
        let l = layout();
        let mut a = TileAtlas::new(l, 4).unwrap();
        assert_eq!(a.stored_at(IVec2::new(3, 3)), 7);
        assert!((a.height_at(IVec2::new(3, 3)) - (-2.0 + 0.7)).abs() < 1e-6);
        // Level 3 (5 x 3 texels): one tile covers the whole world.
        a.upload(0, 3, UVec2::ZERO, &tile(3, UVec2::ZERO)).unwrap();
        a.map(3, UVec2::ZERO, Some(0)).unwrap();
        assert_eq!(a.stored_at(IVec2::new(17, 9)), 30_000 + 100 + 2);
        // Level 0 tile (2, 1) covers texels 16..24 x 8..16.
        a.upload(1, 0, UVec2::new(2, 1), &tile(0, UVec2::new(2, 1)))
            .unwrap();
        a.map(0, UVec2::new(2, 1), Some(1)).unwrap();
        assert_eq!(a.stored_at(IVec2::new(17, 9)), 9 * 100 + 17);
        assert_eq!(a.resolve(UVec2::new(17, 9)), Some((0, 1)));
        assert_eq!(a.stored_at(IVec2::new(15, 9)), 30_000 + 100 + 1);
        // Clamped addressing: far off the world reads the edge texel's finest level.
        assert_eq!(a.stored_at(IVec2::new(i32::MAX, -40)), 30_000 + 4);
        // Unmapped again: the coarser tile answers.
        a.map(0, UVec2::new(2, 1), None).unwrap();
        assert_eq!(a.stored_at(IVec2::new(17, 9)), 30_102);
        assert_eq!(a.uploads(), 2);
        assert_eq!(a.uploaded_bytes(), 2 * 64 * 2);
        assert_eq!(a.mapped(), 1);
    }

    #[test]
    fn out_of_range_calls_are_errors() {
        let mut a = TileAtlas::new(layout(), 2).unwrap();
        let t = tile(0, UVec2::ZERO);
        assert!(a.upload(2, 0, UVec2::ZERO, &t).is_err());
        assert!(a.upload(0, 4, UVec2::ZERO, &t).is_err());
        assert!(a.upload(0, 0, UVec2::new(5, 0), &t).is_err());
        assert!(
            a.upload(0, 0, UVec2::ZERO, &Grid::new(4, 4, 0).unwrap())
                .is_err()
        );
        assert!(a.map(0, UVec2::new(0, 3), Some(0)).is_err());
        assert!(a.map(0, UVec2::ZERO, Some(2)).is_err());
        assert!(a.map(0, UVec2::ZERO, Some(INVALID_SLOT)).is_err());
        assert!(TileAtlas::new(layout(), 0).is_err());
        assert_eq!(a.uploads(), 0);
    }
}
