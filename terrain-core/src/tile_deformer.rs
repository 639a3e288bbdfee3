//! [`TileDeformer`]: the contract between a streamed world's stamp protocol (terrain-cache's
//! `TileStamps`, which decides where and when each tile is stamped) and what stamps a tile
//! (terrain-gpu's `AtlasDeformer` on the GPU, or the application's own), which never name each
//! other; and [`TileStamp`], the stamps every deformer of this workspace applies.

use crate::{Blend, CoarseMap, GaussianStamp, Rect, StampPlacement, TextureStamp, apply_stamp};
use std::sync::Arc;

/// What applies one kind of stamp `K` to one level-0 tile: in its VRAM slot on the GPU, or on
/// the CPU in RAM. Placements are in the tile's own frame (metres from its corner).
pub trait TileDeformer<K> {
    /// What a failed stamp reports (an application may use `anyhow::Error`).
    type Error: std::fmt::Display + std::fmt::Debug;

    /// Stamps `kind` at `placement` into the VRAM slot `slot` (level 0) and requests the
    /// changed rects back (tile texels): a ticket and rect each, the tickets unique among
    /// those in flight. `None` when no readback can be taken now (nothing stamped: the tile is
    /// tried again next frame).
    fn stamp_slot(
        &mut self,
        slot: u32,
        kind: &K,
        placement: &StampPlacement,
    ) -> Result<Option<Vec<(u64, Rect)>>, Self::Error>;

    /// Stamps `kind` at `placement` into `tile` (a clamped map of one level-0 tile, the
    /// world's encoding and texel size) and returns the rects it changed.
    fn stamp_ram(
        &mut self,
        kind: &K,
        tile: &mut CoarseMap,
        placement: &StampPlacement,
    ) -> Result<Vec<Rect>, Self::Error>;
}

/// A stamp added to a world's tiles: a Gaussian (a crater, with a negative intensity) or a
/// texture (a footprint, a shockwave's change since its last stamp).
#[derive(Debug, Clone)]
pub enum TileStamp {
    /// A Gaussian's shape.
    Gaussian(GaussianStamp),
    /// A texture's values.
    Texture(Arc<TextureStamp>),
}

impl TileStamp {
    /// Adds the stamp at `placement` to `tile` on the CPU: the reference of every GPU
    /// deformer of [`TileStamp`]s.
    pub fn apply(
        &self,
        tile: &mut CoarseMap,
        placement: &StampPlacement,
    ) -> Result<Vec<Rect>, crate::CoreError> {
        match self {
            TileStamp::Gaussian(g) => apply_stamp(tile, &mut g.clone(), placement, Blend::Add),
            TileStamp::Texture(t) => apply_stamp(tile, &mut (**t).clone(), placement, Blend::Add),
        }
    }
}

/// The deformer of a world without a GPU: every tile is stamped in RAM.
#[derive(Debug, Default, Clone, Copy)]
pub struct RamDeformer;

impl TileDeformer<TileStamp> for RamDeformer {
    type Error = crate::CoreError;

    /// No slot is ever stamped: `None`, the tile is stamped in RAM instead.
    fn stamp_slot(
        &mut self,
        _: u32,
        _: &TileStamp,
        _: &StampPlacement,
    ) -> Result<Option<Vec<(u64, Rect)>>, Self::Error> {
        Ok(None)
    }

    fn stamp_ram(
        &mut self,
        kind: &TileStamp,
        tile: &mut CoarseMap,
        placement: &StampPlacement,
    ) -> Result<Vec<Rect>, Self::Error> {
        kind.apply(tile, placement)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Grid, HeightEncoding, WrapMode};
    use glam::Vec2;

    #[test]
    fn tile_stamps_apply_as_apply_stamp_and_ram_deformers_never_take_a_slot() {
        let enc = HeightEncoding::spanning::<u16>(0.0, 100.0).unwrap();
        let tile = || {
            let grid = Grid::new(32, 32, 30_000u16).unwrap();
            CoarseMap::new(grid, enc, 0.5, WrapMode::Clamp).unwrap()
        };
        let p = StampPlacement::new(Vec2::new(8.0, 8.0), Vec2::splat(6.0), -2.0).unwrap();
        let texture =
            TextureStamp::from_gray8(&Grid::from_fn(5, 5, |x, y| (x * 40 + y) as u8).unwrap());
        let kinds = [
            TileStamp::Gaussian(GaussianStamp::default()),
            TileStamp::Texture(Arc::new(texture.clone())),
        ];
        for kind in &kinds {
            let (mut a, mut b) = (tile(), tile());
            let rects = RamDeformer.stamp_ram(kind, &mut a, &p).unwrap();
            let want = match kind {
                TileStamp::Gaussian(_) => {
                    apply_stamp(&mut b, &mut GaussianStamp::default(), &p, Blend::Add).unwrap()
                }
                TileStamp::Texture(_) => {
                    apply_stamp(&mut b, &mut texture.clone(), &p, Blend::Add).unwrap()
                }
            };
            assert_eq!(rects, want);
            assert_eq!(a.grid(), b.grid());
            assert_ne!(a.grid(), tile().grid(), "nothing stamped");
            assert_eq!(RamDeformer.stamp_slot(0, kind, &p).unwrap(), None);
        }
    }
}
