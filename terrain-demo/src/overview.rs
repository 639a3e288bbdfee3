//! The top-down hillshade overview: the whole frame without a GPU, an inset with one. Drawn
//! once, then each frame only the pixels over the rects that changed are redrawn
//! (terrain-core's `update_hillshade_from_heights`), so its cost follows the deformations, not
//! the map. Each pixel's normal comes from the heights around its texel: the overview needs no
//! derivative map on the CPU (with a GPU the normals live there). With materials shading it is
//! coloured by the autoshader's materials (their colours from afar), as the frames are.

use crate::images::Image;
use anyhow::Result;
use glam::UVec2;
use terrain_core::{
    AutoshadeParams, CoarseMap, DirtyRect, Grid, HillshadeMaterials, HillshadeParams,
    MaterialTextures, Rect, hillshade_from_heights, hillshade_range, update_hillshade_from_heights,
};

/// What a cut cell shows: the dark of a shaft.
const HOLE_COLOUR: [u8; 4] = [16, 14, 12, 255];

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
    /// The overview of `map` at `size` pixels, coloured by the height ramp or, with
    /// `materials`, by the autoshader's placement of the project's procedural materials.
    /// Cells `holes` cuts are dark.
    pub fn new(
        map: &CoarseMap,
        size: UVec2,
        materials: bool,
        holes: Option<&Grid<u8>>,
    ) -> Result<Self> {
        let materials = match materials {
            // A small set: only the images' mean colours are used.
            true => Some(HillshadeMaterials::new(
                &MaterialTextures::procedural(16)?,
                AutoshadeParams::default(),
            )?),
            false => None,
        };
        let params = HillshadeParams {
            materials,
            ..HillshadeParams::with_size(size)
        };
        let mut out = Self {
            image: hillshade_from_heights(map, &params)?,
            params,
            range: hillshade_range(map),
        };
        if let Some(mask) = holes {
            out.darken_holes(map, mask, Rect::from_size(map.size()));
        }
        Ok(out)
    }

    /// Darkens the pixels over `rect` (map coordinates, wrapping) whose texel `mask` cuts.
    fn darken_holes(&mut self, map: &CoarseMap, mask: &Grid<u8>, rect: Rect) {
        if mask.size() != map.size() {
            return;
        }
        let (size, out) = (map.size(), self.params.size);
        let rect = if rect.size.cmpgt(size).any() {
            Rect::from_size(size)
        } else {
            rect
        };
        for piece in rect.split_toroidal(size) {
            // Pixel `p` shows texel `p * size / out` (as the hillshade draws it).
            let px = |t: i32, n: u32, o: u32| {
                (u64::from(t as u32) * u64::from(o)).div_ceil(u64::from(n)) as u32
            };
            let (lo, hi) = (piece.map.min, piece.map.max());
            for py in px(lo.y, size.y, out.y)..px(hi.y, size.y, out.y) {
                let ty = (u64::from(py) * u64::from(size.y) / u64::from(out.y)) as u32;
                for pxx in px(lo.x, size.x, out.x)..px(hi.x, size.x, out.x) {
                    let tx = (u64::from(pxx) * u64::from(size.x) / u64::from(out.x)) as u32;
                    if mask.get(tx, ty).is_some_and(terrain_core::is_hole)
                        && let Some(p) = self.image.get_mut(pxx, py)
                    {
                        *p = HOLE_COLOUR;
                    }
                }
            }
        }
    }

    /// The current image.
    pub fn image(&self) -> &Image {
        &self.image
    }

    /// Redraws what heights changed inside `dirty` (map coordinates) can change. If a new
    /// height lies outside the colour range, the range widens and the whole image (its pixels,
    /// not the map) is redrawn.
    /// Cells `holes` cuts are dark.
    pub fn update(
        &mut self,
        map: &CoarseMap,
        dirty: &[DirtyRect],
        holes: Option<&Grid<u8>>,
    ) -> Result<()> {
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
            if let Some(mask) = holes {
                self.darken_holes(map, mask, all);
            }
            return Ok(());
        }
        for rect in dirty {
            update_hillshade_from_heights(&mut self.image, map, &self.params, self.range, *rect)?;
            if let Some(mask) = holes {
                // The redrawn pixels reach the normals' apron beyond the rect.
                self.darken_holes(map, mask, rect.expand(terrain_core::DERIVATIVE_APRON));
            }
        }
        Ok(())
    }
}
