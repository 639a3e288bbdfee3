//! Tile ids ([`TileId`]), layers ([`Layer`]) and decoded tile samples ([`TileData`]).

use bytemuck::{Pod, Zeroable};
use std::fmt;
use terrain_core::Grid;

/// One tile of the pyramid: `level` 0 is the finest, each level up halves the resolution
/// (2x2 reduction); `x` is the tile column (world X), `y` the tile row (world Z).
///
/// `#[repr(C)]` and [`Pod`] so indirection tables can carry it to the GPU as three `u32`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Default, Pod, Zeroable)]
pub struct TileId {
    /// Pyramid level, 0 = finest.
    pub level: u32,
    /// Tile column.
    pub x: u32,
    /// Tile row.
    pub y: u32,
}

impl TileId {
    /// The tile at `level`, column `x`, row `y`.
    pub const fn new(level: u32, x: u32, y: u32) -> Self {
        Self { level, x, y }
    }

    /// The tile one level coarser that covers this one, or `None` at `u32::MAX` levels.
    pub fn parent(self) -> Option<Self> {
        Some(Self::new(
            self.level.checked_add(1)?,
            self.x / 2,
            self.y / 2,
        ))
    }

    /// The four tiles one level finer (row-major: `(2x, 2y)`, `(2x+1, 2y)`, `(2x, 2y+1)`,
    /// `(2x+1, 2y+1)`), or `None` at level 0 or when the coordinates would overflow.
    pub fn children(self) -> Option<[Self; 4]> {
        let level = self.level.checked_sub(1)?;
        let x = self.x.checked_mul(2)?;
        let y = self.y.checked_mul(2)?;
        let x1 = x.checked_add(1)?;
        let y1 = y.checked_add(1)?;
        Some([
            Self::new(level, x, y),
            Self::new(level, x1, y),
            Self::new(level, x, y1),
            Self::new(level, x1, y1),
        ])
    }
}

impl fmt::Display for TileId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "L{}({:#x}, {:#x})", self.level, self.x, self.y)
    }
}

/// Which map a tile belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Layer {
    /// The u16 coarse-map pyramid (raw `.tile` files; PNG16 in version-1 worlds).
    Height,
    /// The u8 detail-map tiles (one level, LZ4 `.tile` files; PNG8 in version-1 worlds),
    /// Flower 2010, sec. 2.4.2.
    Detail,
    /// The u8 hole mask (`terrain_core::holes`) over the height pyramid's level 0: one byte
    /// per level-0 cell, 0 for ground, in tiles of the height tiles' size. Every world has the
    /// layer; a tile without a hole is not stored (the zero tile), so a world without holes
    /// has no file of it.
    Hole,
    /// The RGBA8 material layer (`terrain_core::material_effect`: painted weights of grass,
    /// dirt, rock and snow, their sum the paint's cover) over the height pyramid's level 0, in
    /// tiles of the height tiles' size. Every world has the layer; an unpainted tile (all zero:
    /// the autoshader shows) is not stored.
    Material,
    /// The RGBA8 colour layer (an orthophoto beside a DEM: sRGB, alpha its cover) over level
    /// 0, as the material layer; a transparent tile is not stored.
    Color,
}

impl Layer {
    /// Every layer, in the order of their index.
    pub const ALL: [Layer; 5] = [
        Layer::Height,
        Layer::Detail,
        Layer::Hole,
        Layer::Material,
        Layer::Color,
    ];
}

impl Layer {
    /// The folder of the layer in the store.
    pub const fn folder(self) -> &'static str {
        match self {
            Layer::Height => "height",
            Layer::Detail => "detail",
            Layer::Hole => "hole",
            Layer::Material => "material",
            Layer::Color => "color",
        }
    }

    /// Bits per stored sample: 16 for heights, 8 for detail and holes, 32 for materials and
    /// colours.
    pub const fn bits(self) -> u8 {
        match self {
            Layer::Height => 16,
            Layer::Detail | Layer::Hole => 8,
            Layer::Material | Layer::Color => 32,
        }
    }

    /// Bytes of one decoded tile of side `tile_size`.
    pub const fn tile_bytes(self, tile_size: u32) -> u64 {
        (tile_size as u64) * (tile_size as u64) * (self.bits() as u64 / 8)
    }
}

/// The decoded samples of one tile.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TileData {
    /// A height tile.
    U16(Grid<u16>),
    /// A detail or hole tile.
    U8(Grid<u8>),
    /// A material tile: four 8-bit channels per texel.
    Rgba8(Grid<[u8; 4]>),
}

impl TileData {
    /// A tile of side `size` filled with `value` (truncated to the layer's sample type).
    pub fn filled(layer: Layer, size: u32, value: u16) -> Result<Self, crate::CacheError> {
        Ok(match layer {
            Layer::Height => TileData::U16(Grid::new(size, size, value)?),
            Layer::Detail | Layer::Hole => {
                TileData::U8(Grid::new(size, size, value.min(255) as u8)?)
            }
            Layer::Material | Layer::Color => {
                TileData::Rgba8(Grid::new(size, size, [value.min(255) as u8; 4])?)
            }
        })
    }

    /// Bits per sample.
    pub fn bits(&self) -> u8 {
        match self {
            TileData::U16(_) => 16,
            TileData::U8(_) => 8,
            TileData::Rgba8(_) => 32,
        }
    }

    /// Width and height in samples.
    pub fn size(&self) -> glam::UVec2 {
        match self {
            TileData::U16(g) => g.size(),
            TileData::U8(g) => g.size(),
            TileData::Rgba8(g) => g.size(),
        }
    }

    /// Bytes of the samples.
    pub fn byte_len(&self) -> u64 {
        match self {
            TileData::U16(g) => g.as_slice().len() as u64 * 2,
            TileData::U8(g) => g.as_slice().len() as u64,
            TileData::Rgba8(g) => g.as_slice().len() as u64 * 4,
        }
    }

    /// The samples as bytes (native endian), e.g. for a GPU upload.
    pub fn as_bytes(&self) -> &[u8] {
        match self {
            TileData::U16(g) => bytemuck::cast_slice(g.as_slice()),
            TileData::U8(g) => g.as_slice(),
            TileData::Rgba8(g) => bytemuck::cast_slice(g.as_slice()),
        }
    }

    /// The height samples, if this is a height tile.
    pub fn as_u16(&self) -> Option<&Grid<u16>> {
        match self {
            TileData::U16(g) => Some(g),
            _ => None,
        }
    }

    /// The height samples, mutable, if this is a height tile.
    pub fn as_u16_mut(&mut self) -> Option<&mut Grid<u16>> {
        match self {
            TileData::U16(g) => Some(g),
            _ => None,
        }
    }

    /// The detail (or hole) samples, if this is such a tile.
    pub fn as_u8(&self) -> Option<&Grid<u8>> {
        match self {
            TileData::U8(g) => Some(g),
            _ => None,
        }
    }

    /// The detail (or hole) samples, mutable, if this is such a tile.
    pub fn as_u8_mut(&mut self) -> Option<&mut Grid<u8>> {
        match self {
            TileData::U8(g) => Some(g),
            _ => None,
        }
    }

    /// The material texels, if this is a material tile.
    pub fn as_rgba8(&self) -> Option<&Grid<[u8; 4]>> {
        match self {
            TileData::Rgba8(g) => Some(g),
            _ => None,
        }
    }

    /// The material texels, mutable, if this is a material tile.
    pub fn as_rgba8_mut(&mut self) -> Option<&mut Grid<[u8; 4]>> {
        match self {
            TileData::Rgba8(g) => Some(g),
            _ => None,
        }
    }

    /// The smallest and largest sample, widened to u16 (of a material tile: of its bytes).
    pub fn min_max(&self) -> (u16, u16) {
        fn mm<T: Copy + Ord + Into<u16>>(s: &[T]) -> (u16, u16) {
            let mut lo = u16::MAX;
            let mut hi = 0u16;
            for &v in s {
                let v: u16 = v.into();
                lo = lo.min(v);
                hi = hi.max(v);
            }
            (lo, hi)
        }
        match self {
            TileData::U16(g) => mm(g.as_slice()),
            TileData::U8(g) => mm(g.as_slice()),
            TileData::Rgba8(g) => mm(bytemuck::cast_slice::<[u8; 4], u8>(g.as_slice())),
        }
    }

    /// `Some(v)` if every sample equals `v` (of a material tile: every byte).
    pub fn uniform_value(&self) -> Option<u16> {
        fn uni<T: Copy + PartialEq + Into<u16>>(s: &[T]) -> Option<u16> {
            let first = *s.first()?;
            s.iter().all(|&v| v == first).then(|| first.into())
        }
        match self {
            TileData::U16(g) => uni(g.as_slice()),
            TileData::U8(g) => uni(g.as_slice()),
            TileData::Rgba8(g) => uni(bytemuck::cast_slice::<[u8; 4], u8>(g.as_slice())),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parent_and_children_are_inverse() {
        let t = TileId::new(2, 5, 7);
        for c in t.children().unwrap() {
            assert_eq!(c.parent(), Some(t));
        }
        assert_eq!(TileId::new(0, 1, 1).children(), None);
        assert_eq!(TileId::new(u32::MAX, 1, 1).parent(), None);
        assert_eq!(TileId::new(1, u32::MAX, 0).children(), None);
        assert_eq!(format!("{t}"), "L2(0x5, 0x7)");
    }

    #[test]
    fn tile_data_helpers() {
        let d = TileData::filled(Layer::Detail, 4, 300).unwrap();
        assert_eq!(d.uniform_value(), Some(255));
        assert_eq!(d.byte_len(), 16);
        let mut h = TileData::filled(Layer::Height, 4, 7).unwrap();
        h.as_u16_mut().unwrap().as_mut_slice()[3] = 9;
        assert_eq!(h.min_max(), (7, 9));
        assert_eq!(h.uniform_value(), None);
        assert_eq!(h.as_bytes().len(), 32);
        assert_eq!(Layer::Height.tile_bytes(256), 131072);
    }
}
