//! Normals of the granular map by the symmetric difference (Persson 2019, eq. 4.3) with optional
//! 3x3 Gaussian blur passes (eq. 2.1), and the float copy of the heights for filtered rendering.

use glam::{IVec2, Vec3};

use super::{GranularError, check_area};
use crate::Rect;
use crate::{FixedPointMap, Grid, WrapMode};

/// Heights in metres (f32) of `area` written into `out` (a grid of the map's size): the float
/// copy used for hardware-filtered rendering (sec. 4.1.6).
pub fn float_heights(
    map: &FixedPointMap,
    area: Rect,
    out: &mut Grid<f32>,
) -> Result<(), GranularError> {
    check_area(area, map.size())?;
    same_size(map.size(), out.size())?;
    let enc = map.encoding();
    for y in area.min.y as u32..area.max().y as u32 {
        for x in area.min.x as u32..area.max().x as u32 {
            let i = map.grid().index(x, y);
            out.as_mut_slice()[i] = enc.to_metres(f64::from(map.grid().as_slice()[i]));
        }
    }
    Ok(())
}

fn same_size(expected: glam::UVec2, actual: glam::UVec2) -> Result<(), GranularError> {
    if expected != actual {
        return Err(GranularError::SizeMismatch { expected, actual });
    }
    Ok(())
}

/// Unit normals of `area` into `out` (a grid of the map's size), from the symmetric
/// differences `(h(x+1) - h(x-1)) / 2` in metres per texel (eq. 4.3, edges clamped):
/// `normalize(-dh/dx / texel, 1, -dh/dz / texel)`. A float pass: GPU results agree within
/// a tolerance, not bit for bit.
pub fn symmetric_normals(
    map: &FixedPointMap,
    area: Rect,
    out: &mut Grid<Vec3>,
) -> Result<(), GranularError> {
    check_area(area, map.size())?;
    same_size(map.size(), out.size())?;
    let g = map.grid();
    let scale = f64::from(map.encoding().scale);
    let ts = f64::from(map.texel_size());
    let at = |x: i32, y: i32| f64::from(g.get_wrapped(IVec2::new(x, y), WrapMode::Clamp));
    for y in area.min.y..area.max().y {
        for x in area.min.x..area.max().x {
            let sx = (at(x + 1, y) - at(x - 1, y)) * 0.5 * scale / ts;
            let sz = (at(x, y + 1) - at(x, y - 1)) * 0.5 * scale / ts;
            let n = Vec3::new(-sx as f32, 1.0, -sz as f32).normalize_or(Vec3::Y);
            let i = g.index(x as u32, y as u32);
            out.as_mut_slice()[i] = n;
        }
    }
    Ok(())
}

/// `iterations` passes of the 3x3 Gaussian kernel `[1 2 1; 2 4 2; 1 2 1] / 16` over `area` of
/// a normal grid (edges clamped, ping-pong, renormalised after each pass).
pub fn blur_normals(
    normals: &mut Grid<Vec3>,
    area: Rect,
    iterations: u32,
) -> Result<(), GranularError> {
    check_area(area, normals.size())?;
    // Only the area and a one-texel apron are copied (the ping-pong source).
    let apron = area.expand(1).intersect(&normals.rect()).unwrap_or(area);
    let mut src = normals.copy_rect(apron)?;
    let max = normals.size().as_ivec2() - 1;
    for _ in 0..iterations {
        for y in area.min.y..area.max().y {
            for x in area.min.x..area.max().x {
                let mut s = Vec3::ZERO;
                for dy in -1..=1i32 {
                    for dx in -1..=1i32 {
                        let w = ((2 - dx.abs()) * (2 - dy.abs())) as f32;
                        let p = IVec2::new(x + dx, y + dy).clamp(IVec2::ZERO, max) - apron.min;
                        s += src.as_slice()[src.index(p.x as u32, p.y as u32)] * w;
                    }
                }
                let i = normals.index(x as u32, y as u32);
                normals.as_mut_slice()[i] = (s / 16.0).normalize_or(Vec3::Y);
            }
        }
        src.paste(&normals.copy_rect(area)?, area.min - apron.min)?;
    }
    Ok(())
}
