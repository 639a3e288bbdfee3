//! [`HillshadeOverview`]: a top-down hillshade of a map kept current as the map is deformed,
//! an engine's minimap or a server's picture of its world. Drawn once, then only the pixels
//! over the rects that changed are redrawn ([`update_hillshade_from_heights`]), so its cost
//! follows the deformations, not the map; each pixel's normal comes from the heights around
//! its texel, so no derivative map is needed. Its colour range starts as the map's and widens
//! when a deformation leaves it (the whole image is then recoloured). Cells a hole mask cuts
//! are dark.

use crate::error::CoreError;
use crate::grid::Grid;
use crate::hillshade::{
    HillshadeParams, hillshade_from_heights, hillshade_range, update_hillshade_from_heights,
};
use crate::holes::is_hole;
use crate::map::{HeightMap, HeightSample};
use crate::normals::DERIVATIVE_APRON;
use crate::rect::Rect;

/// What a cut cell shows: the dark of a shaft.
pub const HOLE_COLOUR: [u8; 4] = [16, 14, 12, 255];

/// An overview image, its parameters and the height range its colours span (module docs).
#[derive(Debug, Clone)]
pub struct HillshadeOverview {
    image: Grid<[u8; 4]>,
    params: HillshadeParams,
    range: (f64, f64),
}

impl HillshadeOverview {
    /// The overview of `map` drawn with `params`; cells `holes` (a mask of the map's size)
    /// cuts are dark.
    pub fn new<T: HeightSample>(
        map: &HeightMap<T>,
        params: HillshadeParams,
        holes: Option<&Grid<u8>>,
    ) -> Result<Self, CoreError> {
        let mut out = Self {
            image: hillshade_from_heights(map, &params)?,
            params,
            range: hillshade_range(map),
        };
        if let Some(mask) = holes {
            out.darken_holes(map.size(), mask, Rect::from_size(map.size()));
        }
        Ok(out)
    }

    /// The current image (`params.size` pixels).
    pub fn image(&self) -> &Grid<[u8; 4]> {
        &self.image
    }

    /// The stored values its colours span, lowest to highest.
    pub fn range(&self) -> (f64, f64) {
        self.range
    }

    /// Redraws what the heights changed inside `dirty` (map texels, wrapping) can change; a
    /// height outside the colour range widens it and recolours the whole image (its pixels,
    /// not the map). Cells `holes` cuts are dark.
    pub fn update<T: HeightSample>(
        &mut self,
        map: &HeightMap<T>,
        dirty: &[Rect],
        holes: Option<&Grid<u8>>,
    ) -> Result<(), CoreError> {
        let (mut lo, mut hi) = self.range;
        for rect in dirty {
            for piece in rect.split_toroidal(map.size()) {
                let (x0, x1) = (piece.map.min.x as usize, piece.map.max().x as usize);
                for y in piece.map.min.y as u32..piece.map.max().y as u32 {
                    for v in &map.grid().row(y)[x0..x1] {
                        lo = lo.min(v.to_raw_f64());
                        hi = hi.max(v.to_raw_f64());
                    }
                }
            }
        }
        let all = Rect::from_size(map.size());
        if (lo, hi) != self.range {
            self.range = (lo, hi);
            update_hillshade_from_heights(&mut self.image, map, &self.params, self.range, all)?;
            if let Some(mask) = holes {
                self.darken_holes(map.size(), mask, all);
            }
            return Ok(());
        }
        for rect in dirty {
            update_hillshade_from_heights(&mut self.image, map, &self.params, self.range, *rect)?;
            if let Some(mask) = holes {
                // The redrawn pixels reach the normals' apron beyond the rect.
                self.darken_holes(map.size(), mask, rect.expand(DERIVATIVE_APRON));
            }
        }
        Ok(())
    }

    /// Darkens the pixels over `rect` (map texels, wrapping) whose texel `mask` cuts; a mask
    /// of another size than the map's is left out.
    fn darken_holes(&mut self, size: glam::UVec2, mask: &Grid<u8>, rect: Rect) {
        if mask.size() != size {
            return;
        }
        let out = self.params.size;
        let rect = if rect.size.cmpgt(size).any() {
            Rect::from_size(size)
        } else {
            rect
        };
        // Pixel `p` shows texel `p * size / out` (as the hillshade draws it).
        let first_pixel =
            |t: i32, n: u32, o: u32| (u64::from(t as u32) * u64::from(o)).div_ceil(u64::from(n));
        let texel = |p: u32, n: u32, o: u32| (u64::from(p) * u64::from(n) / u64::from(o)) as u32;
        for piece in rect.split_toroidal(size) {
            let (lo, hi) = (piece.map.min, piece.map.max());
            let rows = first_pixel(lo.y, size.y, out.y)..first_pixel(hi.y, size.y, out.y);
            for py in rows.map(|p| p as u32) {
                let ty = texel(py, size.y, out.y);
                let cols = first_pixel(lo.x, size.x, out.x)..first_pixel(hi.x, size.x, out.x);
                for px in cols.map(|p| p as u32) {
                    let tx = texel(px, size.x, out.x);
                    if mask.get(tx, ty).is_some_and(is_hole)
                        && let Some(p) = self.image.get_mut(px, py)
                    {
                        *p = HOLE_COLOUR;
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{
        Blend, CoarseMap, GaussianStamp, HeightEncoding, StampPlacement, WrapMode, apply_stamp,
    };
    use glam::{UVec2, Vec2};

    fn map() -> CoarseMap {
        let grid = Grid::from_fn(64, 48, |x, y| (20_000 + x * 37 + y * 53) as u16).unwrap();
        CoarseMap::new(
            grid,
            HeightEncoding::new(0.01, 0.0).unwrap(),
            1.0,
            WrapMode::Repeat,
        )
        .unwrap()
    }

    #[test]
    fn updated_in_place_it_equals_one_drawn_anew() {
        let mut m = map();
        let params = HillshadeParams::with_size(UVec2::new(40, 30));
        let mut holes = Grid::new(64, 48, 0u8).unwrap();
        // A 2 x 2 cut: at 1.6 texels a pixel, a single texel may be shown by no pixel.
        for (x, y) in [(10, 10), (11, 10), (10, 11), (11, 11)] {
            *holes.get_mut(x, y).unwrap() = 255;
        }
        let mut overview = HillshadeOverview::new(&m, params, Some(&holes)).unwrap();
        assert!(overview.image().as_slice().contains(&HOLE_COLOUR));
        // A bump inside the range: only its pixels are redrawn, and they match a fresh image.
        let at = StampPlacement::new(Vec2::new(60.0, 20.0), Vec2::splat(12.0), 2.0).unwrap();
        let dirty = apply_stamp(&mut m, &mut GaussianStamp::default(), &at, Blend::Add).unwrap();
        let range = overview.range();
        overview.update(&m, &dirty, Some(&holes)).unwrap();
        assert_eq!(overview.range(), range);
        let fresh = HillshadeOverview::new(&m, params, Some(&holes)).unwrap();
        assert_eq!(fresh.range(), range, "the bump left the colour range");
        assert!(overview.image() == fresh.image());
        // A peak beyond it widens the range and recolours everything.
        let at = StampPlacement::new(Vec2::new(60.0, 20.0), Vec2::splat(12.0), 200.0).unwrap();
        let dirty = apply_stamp(&mut m, &mut GaussianStamp::default(), &at, Blend::Add).unwrap();
        overview.update(&m, &dirty, Some(&holes)).unwrap();
        assert!(overview.range().1 > range.1);
        let fresh = HillshadeOverview::new(&m, params, Some(&holes)).unwrap();
        assert_eq!(overview.range(), fresh.range());
        assert!(overview.image() == fresh.image());
    }
}
