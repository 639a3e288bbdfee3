//! The coarser levels of a world's paint ([`Layer::Material`]) and colour ([`Layer::Color`]):
//! each texel of level `l + 1` from the 2x2 texels below it, as the heights' pyramid is built,
//! so that the VRAM pool streams far ground's look at the level it streams its heights
//! (Fikkan 2013, ch. 5 streams colour beside the heights the same way).
//!
//! - **Paint** is weights and their cover, linear quantities: the rounded mean of each channel.
//! - **Colour** is averaged premultiplied by its alpha, so a half-transparent border does not
//!   darken the colour beside it: `rgb = round(sum(rgb * a) / sum(a))`, `a = round(mean(a))`.
//!
//! Only texels inside the level below count (a world whose side is not a multiple of the
//! tile's has partial tiles at its far edges); a coarser texel with none is transparent.
//! Like the level-0 tiles, a coarser tile that is all zero has no file.

use crate::error::CacheError;
use crate::tile::{Layer, TileData, TileId};
use crate::world::World;
use glam::UVec2;
use terrain_core::Grid;

/// Rewrites the coarser tiles of `layer` (paint or colour) above the level-0 tiles `changed`,
/// level by level, and returns them (sorted per level, coarsest last). Tiles outside the
/// layer's pyramid are refused before anything is written.
pub(crate) fn rebuild_overlay_ancestors(
    world: &World,
    layer: Layer,
    changed: &[TileId],
) -> Result<Vec<TileId>, CacheError> {
    let m = *world.manifest();
    if !matches!(layer, Layer::Material | Layer::Color) {
        return Err(CacheError::NoSuchLayer { layer });
    }
    for &id in changed {
        m.check_tile(layer, id)?;
    }
    let levels = m.layer_levels(layer);
    let ts = m.tile_size;
    let mut rewritten = Vec::new();
    let mut below: Vec<TileId> = changed.to_vec();
    while !below.is_empty() {
        let mut parents: Vec<TileId> = below
            .iter()
            .filter_map(|id| id.parent())
            .filter(|p| p.level < levels)
            .collect();
        parents.sort();
        parents.dedup();
        for &p in &parents {
            let Some(kids) = p.children() else {
                continue;
            };
            let child_level = m.level_size(p.level - 1);
            let mut quads: [Option<(std::sync::Arc<TileData>, UVec2)>; 4] = Default::default();
            for (q, k) in quads.iter_mut().zip(kids) {
                let origin = UVec2::new(k.x, k.y) * ts;
                if origin.x >= child_level.x || origin.y >= child_level.y {
                    continue;
                }
                let valid = (child_level - origin).min(UVec2::splat(ts));
                *q = Some((world.load_tile(layer, k)?, valid));
            }
            let mut out = Grid::new(ts, ts, [0u8; 4])?;
            for (q, quad) in quads.iter().enumerate() {
                let Some((data, valid)) = quad else { continue };
                let cells = data.as_rgba8().ok_or(CacheError::NoSuchLayer { layer })?;
                let corner = UVec2::new(q as u32 % 2, q as u32 / 2) * (ts / 2);
                reduce_into(layer, cells, *valid, &mut out, corner);
            }
            world.write_tile(layer, p, &TileData::Rgba8(out))?;
            rewritten.push(p);
        }
        below = parents;
    }
    Ok(rewritten)
}

/// Reduces the child tile `cells` (its texels inside `valid` count) into the quadrant of
/// `out` at `corner`.
fn reduce_into(
    layer: Layer,
    cells: &Grid<[u8; 4]>,
    valid: UVec2,
    out: &mut Grid<[u8; 4]>,
    corner: UVec2,
) {
    let half = UVec2::new(valid.x.div_ceil(2), valid.y.div_ceil(2));
    for j in 0..half.y.min(out.height() - corner.y) {
        let rows = [2 * j, (2 * j + 1).min(valid.y - 1)];
        let dst = out.row_mut(corner.y + j);
        for i in 0..half.x.min(dst.len() as u32 - corner.x) {
            let cols = [2 * i, (2 * i + 1).min(valid.x - 1)];
            let mut block = [[0u8; 4]; 4];
            let mut n = 0usize;
            for (a, &y) in rows.iter().enumerate() {
                for (b, &x) in cols.iter().enumerate() {
                    // A clamped duplicate (odd valid side) is counted once.
                    if (a == 1 && rows[1] == rows[0]) || (b == 1 && cols[1] == cols[0]) {
                        continue;
                    }
                    block[n] = cells.row(y)[x as usize];
                    n += 1;
                }
            }
            dst[(corner.x + i) as usize] = match layer {
                Layer::Color => mean_color(&block[..n]),
                _ => mean_paint(&block[..n]),
            };
        }
    }
}

/// The rounded mean of each channel: how a coarser texel of paint comes from those below it.
pub(crate) fn mean_paint(texels: &[[u8; 4]]) -> [u8; 4] {
    let n = texels.len().max(1) as u32;
    let mut out = [0u8; 4];
    for (c, o) in out.iter_mut().enumerate() {
        let s: u32 = texels.iter().map(|t| u32::from(t[c])).sum();
        *o = ((s + n / 2) / n) as u8;
    }
    out
}

/// The mean of colours premultiplied by their alpha: a coarser texel of colour.
pub(crate) fn mean_color(texels: &[[u8; 4]]) -> [u8; 4] {
    let n = texels.len().max(1) as u32;
    let alpha: u32 = texels.iter().map(|t| u32::from(t[3])).sum();
    let mut out = [0u8; 4];
    // Fully transparent texels give no colour (and no division by zero).
    if let Some(alpha_nz) = std::num::NonZeroU32::new(alpha) {
        for (c, o) in out.iter_mut().take(3).enumerate() {
            let s: u32 = texels
                .iter()
                .map(|t| u32::from(t[c]) * u32::from(t[3]))
                .sum();
            *o = ((s + alpha / 2) / alpha_nz) as u8;
        }
    }
    out[3] = ((alpha + n / 2) / n) as u8;
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paint_is_the_rounded_mean_and_colour_is_premultiplied() {
        assert_eq!(mean_paint(&[[0, 255, 1, 2]; 4]), [0, 255, 1, 2]);
        assert_eq!(
            mean_paint(&[[0; 4], [0; 4], [255, 0, 0, 0], [255, 0, 0, 0]]),
            [128, 0, 0, 0]
        );
        assert_eq!(
            mean_paint(&[[1, 0, 0, 0], [0; 4], [0; 4], [0; 4]]),
            [0, 0, 0, 0]
        );
        assert_eq!(
            mean_paint(&[[2, 0, 0, 0], [0; 4], [0; 4], [0; 4]]),
            [1, 0, 0, 0]
        );
        // A red texel beside three transparent ones stays red, a quarter covered.
        assert_eq!(
            mean_color(&[[200, 0, 0, 255], [0; 4], [0; 4], [0; 4]]),
            [200, 0, 0, 64]
        );
        assert_eq!(
            mean_color(&[[200, 0, 0, 255], [0, 100, 0, 85], [0; 4], [0; 4]]),
            [150, 25, 0, 85]
        );
        assert_eq!(mean_color(&[[0; 4]; 4]), [0; 4]);
        assert_eq!(mean_color(&[[10, 20, 30, 255]]), [10, 20, 30, 255]);
    }
}
