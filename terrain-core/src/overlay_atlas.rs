//! Paint and colour streamed like the heights: [`OverlayUploadTarget`], the upload contract of
//! a world's RGBA8 layers (its painted material weights and its colour), and [`OverlayAtlas`],
//! its CPU reference with the lookup a renderer does ([`OverlayAtlas::sample`]).
//!
//! An overlay target is a [`TileUploadTarget`](crate::TileUploadTarget) whose tiles are RGBA8
//! texels instead of heights: the same slots, the same indirection table over the same
//! [`TileLayout`], the same call order. terrain-cache's `VramPool` fills one from a RAM pool of
//! the layer with the selection and budget it fills the heights' with
//! (`VramPool::update_overlay`), so the look of far ground streams at the level its shape does
//! (Fikkan 2013, ch. 5 streams colour textures beside the heights).
//!
//! A renderer reads a layer at a level-0 position `p` (texel `i`'s value at `p = i`): it finds
//! the finest mapped level `l` of the texel under `p`, and blends the four texels of level `l`
//! around `p` bilinearly, clamped to that tile and to the level's texels (so a lookup reads one
//! tile, never its padding beyond the world; the seam this leaves at tile edges is within one
//! texel's blend). Where no level is mapped the layer is
//! transparent (zero).

use crate::error::CoreError;
use crate::grid::Grid;
use crate::tile_upload::{INVALID_SLOT, TileLayout};
use glam::{DVec2, IVec2, UVec2, Vec4};

/// Where a world's RGBA8 tiles go to be drawn: the [`TileUploadTarget`](crate::TileUploadTarget)
/// contract, with tiles of `tile_size^2` RGBA8 texels. Refusals are the implementation's
/// [`Error`](Self::Error), never a panic.
pub trait OverlayUploadTarget {
    /// What a refused call reports.
    type Error: std::error::Error + Send + Sync + 'static;

    /// The world layout the indirection table covers.
    fn layout(&self) -> &TileLayout;
    /// Tile slots, `0..slot_count()`.
    fn slot_count(&self) -> u32;
    /// Bytes one [`upload`](Self::upload) transfers.
    fn upload_bytes(&self) -> u64;
    /// Stores `texels` (`tile_size` x `tile_size`) in `slot` as tile `tile` of `level`;
    /// returns the bytes transferred.
    fn upload(
        &mut self,
        slot: u32,
        level: u32,
        tile: UVec2,
        texels: &Grid<[u8; 4]>,
    ) -> Result<u64, Self::Error>;
    /// Sets the indirection entry of tile `tile` of `level` to `slot`, or to not resident.
    fn map(&mut self, level: u32, tile: UVec2, slot: Option<u32>) -> Result<(), Self::Error>;
}

/// Most texels an [`OverlayAtlas`] holds (4 GiB), and most entries its table has: more slots
/// or tiles are refused, not allocated.
pub const MAX_OVERLAY_TEXELS: u64 = 1 << 30;

/// Slots of RGBA8 tiles and an indirection table in memory: the CPU reference of terrain-gpu's
/// `GpuOverlayAtlas`, and what tests of the VRAM pool upload into.
#[derive(Debug, Clone, PartialEq)]
pub struct OverlayAtlas {
    layout: TileLayout,
    slots: u32,
    texels: Vec<[u8; 4]>,
    table: Vec<u32>,
    uploads: u64,
}

impl OverlayAtlas {
    /// An atlas of `slots` slots over `layout`, nothing resident. Fails on a bad layout, zero
    /// slots, or more texels than this machine addresses.
    pub fn new(layout: TileLayout, slots: u32) -> Result<Self, CoreError> {
        layout.validate()?;
        if slots == 0 || slots == INVALID_SLOT {
            return Err(CoreError::OutOfRange {
                what: "overlay atlas slots",
                value: f64::from(slots),
                expected: "1 ..= 2^32 - 2",
            });
        }
        let too_large = CoreError::GridTooLarge {
            width: layout.tile_size,
            height: layout.tile_size.saturating_mul(slots),
        };
        let texels = u64::from(slots)
            .checked_mul(layout.tile_texels())
            .filter(|&n| n <= MAX_OVERLAY_TEXELS)
            .and_then(|n| usize::try_from(n).ok())
            .ok_or(too_large)?;
        let table = usize::try_from(layout.table_len())
            .ok()
            .filter(|&n| n as u64 <= MAX_OVERLAY_TEXELS)
            .ok_or(CoreError::OutOfRange {
                what: "tiles in the pyramid",
                value: layout.table_len() as f64,
                expected: "at most 2^30",
            })?;
        Ok(Self {
            layout,
            slots,
            texels: vec![[0; 4]; texels],
            table: vec![INVALID_SLOT; table],
            uploads: 0,
        })
    }

    /// The slot holding tile `tile` of `level`, if mapped.
    pub fn slot_of(&self, level: u32, tile: UVec2) -> Option<u32> {
        let i = self.layout.table_index(level, tile)?;
        let s = *self.table.get(i as usize)?;
        (s < self.slots).then_some(s)
    }

    /// The finest mapped level covering level-0 texel `texel` (inside the world), with its slot.
    pub fn resolve(&self, texel: UVec2) -> Option<(u32, u32)> {
        let ts = self.layout.tile_size;
        (0..self.layout.levels).find_map(|level| {
            self.slot_of(level, (texel >> level) / ts)
                .map(|s| (level, s))
        })
    }

    /// Tiles uploaded since the atlas was made.
    pub fn uploads(&self) -> u64 {
        self.uploads
    }

    /// Tiles mapped now.
    pub fn mapped(&self) -> usize {
        self.table.iter().filter(|&&s| s < self.slots).count()
    }

    /// The layer at level-0 position `p` (texel `i`'s value at `p = i`; outside the world
    /// addressed by the layout's wrap mode), as a renderer reads it (see the module docs), in
    /// 0..=1 per channel; `premultiply` multiplies each texel's colour by its alpha before the
    /// blend (a colour layer). Zero where no level is mapped or `p` is not finite.
    pub fn sample(&self, p: DVec2, premultiply: bool) -> Vec4 {
        if !p.is_finite() {
            return Vec4::ZERO;
        }
        let whole = p.floor();
        // Far outside the world the position is clamped first (an i32 texel).
        let limit = f64::from(i32::MAX / 2);
        let t = self.layout.address(
            whole
                .clamp(DVec2::splat(-limit), DVec2::splat(limit))
                .as_ivec2(),
        );
        let Some((level, slot)) = self.resolve(t) else {
            return Vec4::ZERO;
        };
        let scale = f64::from(1u32 << level);
        let at = (t.as_dvec2() + (p - whole) + 0.5) / scale - 0.5;
        let i0 = at.floor();
        let f = (at - i0).as_vec2();
        let ts = self.layout.tile_size;
        let origin = ((t >> level) / ts * ts).as_ivec2();
        // The tile's last texel, or the level's where the world ends inside the tile.
        let end = ((self.layout.world_size - UVec2::ONE) >> level).as_ivec2();
        let last = (origin + IVec2::splat(ts as i32 - 1)).min(end);
        let texel = |d: IVec2| {
            let c = (i0.as_ivec2() + d).clamp(origin, last) - origin;
            let i = u64::from(slot) * self.layout.tile_texels()
                + c.y as u64 * u64::from(ts)
                + c.x as u64;
            let [r, g, b, a] = self.texels[i as usize].map(|v| f32::from(v) / 255.0);
            if premultiply {
                Vec4::new(r * a, g * a, b * a, a)
            } else {
                Vec4::new(r, g, b, a)
            }
        };
        let top = texel(IVec2::ZERO).lerp(texel(IVec2::X), f.x);
        let bottom = texel(IVec2::Y).lerp(texel(IVec2::ONE), f.x);
        top.lerp(bottom, f.y)
    }

    fn check(&self, slot: Option<u32>, level: u32, tile: UVec2) -> Result<usize, CoreError> {
        if let Some(s) = slot
            && s >= self.slots
        {
            return Err(CoreError::OutOfRange {
                what: "overlay atlas slot",
                value: f64::from(s),
                expected: "below the atlas's slot count",
            });
        }
        self.layout
            .table_index(level, tile)
            .map(|i| i as usize)
            .ok_or(CoreError::OutOfRange {
                what: "tile (level, x, y)",
                value: f64::from(level),
                expected: "a tile of the layout's pyramid",
            })
    }
}

impl OverlayUploadTarget for OverlayAtlas {
    type Error = CoreError;

    fn layout(&self) -> &TileLayout {
        &self.layout
    }

    fn slot_count(&self) -> u32 {
        self.slots
    }

    /// 4 bytes per texel.
    fn upload_bytes(&self) -> u64 {
        self.layout.tile_texels() * 4
    }

    fn upload(
        &mut self,
        slot: u32,
        level: u32,
        tile: UVec2,
        texels: &Grid<[u8; 4]>,
    ) -> Result<u64, CoreError> {
        self.check(Some(slot), level, tile)?;
        let ts = self.layout.tile_size;
        if texels.size() != UVec2::splat(ts) {
            return Err(CoreError::SizeMismatch {
                expected: UVec2::splat(ts),
                actual: texels.size(),
            });
        }
        let n = self.layout.tile_texels() as usize;
        self.texels[slot as usize * n..][..n].copy_from_slice(texels.as_slice());
        self.uploads += 1;
        Ok(self.upload_bytes())
    }

    fn map(&mut self, level: u32, tile: UVec2, slot: Option<u32>) -> Result<(), CoreError> {
        let i = self.check(slot, level, tile)?;
        self.table[i] = slot.unwrap_or(INVALID_SLOT);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{HeightEncoding, WrapMode};

    fn layout() -> TileLayout {
        TileLayout {
            world_size: UVec2::new(16, 8),
            tile_size: 4,
            levels: 3,
            texel_size: 1.0,
            encoding: HeightEncoding::spanning::<u16>(0.0, 1.0).expect("encoding"),
            wrap: WrapMode::Clamp,
            fill: 0,
        }
    }

    #[test]
    fn the_finest_mapped_level_answers_blended_within_its_tile() {
        let mut atlas = OverlayAtlas::new(layout(), 2).expect("atlas");
        assert_eq!(atlas.sample(DVec2::new(1.0, 1.0), false), Vec4::ZERO);
        // Level 1's tile (0, 0) (level-0 texels 0..8 x 0..8): red rising with x.
        let red = Grid::from_fn(4, 4, |x, _| [x as u8 * 60, 0, 0, 255]).expect("tile");
        atlas.upload(0, 1, UVec2::ZERO, &red).expect("upload");
        atlas.map(1, UVec2::ZERO, Some(0)).expect("map");
        // Level-0 texel 2 lies between level-1 texels 0 and 1 (centres at 0.5 and 2.5 in
        // level-0 units): three quarters of the way, 45 of 60.
        let v = atlas.sample(DVec2::new(2.0, 2.0), false);
        assert!((v.x - 45.0 / 255.0).abs() < 1e-6, "{v}");
        // At the tile's edge the blend clamps to its last texel.
        assert!((atlas.sample(DVec2::new(7.9, 0.0), false).x - 180.0 / 255.0).abs() < 1e-6);
        // Off the clamped world's edge: its edge texel.
        assert_eq!(
            atlas.sample(DVec2::new(-50.0, 0.2), false),
            atlas.sample(DVec2::new(0.0, 0.2), false)
        );
        // Level 0 mapped over part of it answers there, level 1 elsewhere.
        let blue = Grid::new(4, 4, [0, 0, 255, 128]).expect("tile");
        atlas.upload(1, 0, UVec2::new(1, 0), &blue).expect("upload");
        atlas.map(0, UVec2::new(1, 0), Some(1)).expect("map");
        let v = atlas.sample(DVec2::new(5.0, 1.0), true);
        assert!((v - Vec4::new(0.0, 0.0, 128.0 / 255.0, 128.0 / 255.0)).length() < 1e-6);
        assert_eq!(atlas.resolve(UVec2::new(1, 1)), Some((1, 0)));
        assert_eq!(atlas.sample(DVec2::new(f64::NAN, 0.0), false), Vec4::ZERO);
        assert_eq!(atlas.mapped(), 2);
        // Refusals.
        assert!(atlas.upload(2, 0, UVec2::ZERO, &blue).is_err());
        assert!(atlas.upload(0, 3, UVec2::ZERO, &blue).is_err());
        assert!(atlas.map(0, UVec2::new(4, 0), Some(0)).is_err());
        let small = Grid::new(2, 2, [0; 4]).expect("tile");
        assert!(atlas.upload(0, 0, UVec2::ZERO, &small).is_err());
        // A world ending inside a tile: the blend stops at its last texel, not the padding.
        let narrow = TileLayout {
            world_size: UVec2::new(10, 8),
            ..layout()
        };
        let mut edge = OverlayAtlas::new(narrow, 1).expect("atlas");
        let tile =
            Grid::from_fn(4, 4, |x, _| [if x == 1 { 255 } else { 0 }, 0, 0, 0]).expect("tile");
        edge.upload(0, 0, UVec2::new(2, 0), &tile).expect("upload");
        edge.map(0, UVec2::new(2, 0), Some(0)).expect("map");
        assert_eq!(edge.sample(DVec2::new(9.5, 1.0), false).x, 1.0);
        assert!(OverlayAtlas::new(layout(), 0).is_err());
        assert!(OverlayAtlas::new(layout(), u32::MAX - 1).is_err());
    }
}
