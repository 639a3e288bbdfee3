//! The top-down hillshade overview: the whole frame without a GPU, an inset with one. Drawn
//! once, then each frame only the pixels over the rects that changed are redrawn
//! (terrain-core's `update_hillshade_from_heights`), so its cost follows the deformations, not
//! the map. Each pixel's normal comes from the heights around its texel: the overview needs no
//! derivative map on the CPU (with a GPU the normals live there).

use crate::images::Image;
use anyhow::Result;
use glam::UVec2;
use terrain_core::{
    CoarseMap, DirtyRect, HillshadeParams, Rect, hillshade_from_heights, hillshade_range,
    update_hillshade_from_heights,
};

/// The overview image and the height range its colours span.
#[derive(Debug)]
pub struct Overview {
    image: Image,
    params: HillshadeParams,
    /// Stored values coloured lowest to highest: the map's first range, widened when a
    /// deformation goes beyond it.
    range: (f64, f64),
}

impl Overview {
    /// The overview of `map` at `size` pixels.
    pub fn new(map: &CoarseMap, size: UVec2) -> Result<Self> {
        let params = HillshadeParams::with_size(size);
        Ok(Self {
            image: hillshade_from_heights(map, &params)?,
            params,
            range: hillshade_range(map),
        })
    }

    /// The current image.
    pub fn image(&self) -> &Image {
        &self.image
    }

    /// Redraws what heights changed inside `dirty` (map coordinates) can change. If a new
    /// height lies outside the colour range, the range widens and the whole image (its pixels,
    /// not the map) is redrawn.
    pub fn update(&mut self, map: &CoarseMap, dirty: &[DirtyRect]) -> Result<()> {
        let (mut lo, mut hi) = self.range;
        for rect in dirty {
            for piece in rect.split_toroidal(map.size()) {
                let (x0, x1) = (piece.map.min.x as usize, piece.map.max().x as usize);
                for y in piece.map.min.y as u32..piece.map.max().y as u32 {
                    for &v in &map.grid().row(y)[x0..x1] {
                        lo = lo.min(f64::from(v));
                        hi = hi.max(f64::from(v));
                    }
                }
            }
        }
        if (lo, hi) != self.range {
            self.range = (lo, hi);
            let all = Rect::from_size(map.size());
            update_hillshade_from_heights(&mut self.image, map, &self.params, self.range, all)?;
            return Ok(());
        }
        for rect in dirty {
            update_hillshade_from_heights(&mut self.image, map, &self.params, self.range, *rect)?;
        }
        Ok(())
    }
}
