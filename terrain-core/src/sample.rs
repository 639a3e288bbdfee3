//! Bilinear height lookup with the semantics of Flower 2010, listing 3.2, with wrap or clamp.

use crate::error::CoreError;
use crate::grid::{Grid, WrapMode};
use crate::map::{HeightMap, HeightSample};
use glam::{IVec2, Vec2};

/// Height in metres at world position `pos = (X, Z)` in metres, interpolated bilinearly
/// between the four surrounding texels (Flower 2010, listing 3.2: `x0 = floor(p.x)`,
/// `fx = p.x - x0`, and `x1 = x0 + 1` wrapped on a repeating map or clamped on a clamped one).
///
/// Fails only for a NaN or infinite position.
pub fn bilinear<T: HeightSample>(map: &HeightMap<T>, pos: Vec2) -> Result<f32, CoreError> {
    check_position(pos)?;
    let p = pos / map.texel_size();
    let grid = map.grid();
    let raw = bilinear_with(p, |q| grid.get_wrapped(q, map.wrap()).to_raw_f64());
    Ok(map.encoding().to_metres(raw))
}

/// Bilinear lookup in a float grid at texel coordinates `p` (texel `(x, y)` at `p = (x, y)`).
pub fn bilinear_grid(grid: &Grid<f32>, p: Vec2, wrap: WrapMode) -> Result<f32, CoreError> {
    check_position(p)?;
    Ok(bilinear_with(p, |q| f64::from(grid.get_wrapped(q, wrap))) as f32)
}

/// The interpolation itself, in f64 so large raw values keep precision; `fetch` applies the
/// wrap mode, so `x1 = x0 + 1` wraps or clamps as listing 3.2 does.
#[inline]
fn bilinear_with(p: Vec2, fetch: impl Fn(IVec2) -> f64) -> f64 {
    let (taps, [fx, fz]) = bilinear_taps(p);
    let top = (1.0 - fx) * fetch(taps[0]) + fx * fetch(taps[1]);
    let bot = (1.0 - fx) * fetch(taps[2]) + fx * fetch(taps[3]);
    (1.0 - fz) * top + fz * bot
}

/// The four texels around `p` (x0z0, x1z0, x0z1, x1z1; not yet wrapped) and the fractions
/// `(fx, fz)`. Saturating casts keep absurd positions finite; the caller's fetch wraps them.
#[inline]
pub(crate) fn bilinear_taps(p: Vec2) -> ([IVec2; 4], [f64; 2]) {
    let fx0 = p.x.floor();
    let fz0 = p.y.floor();
    let fx = f64::from(p.x - fx0);
    let fz = f64::from(p.y - fz0);
    let (x0, z0) = (fx0 as i64, fz0 as i64);
    let (x0, x1) = (clamp_i32(x0), clamp_i32(x0.saturating_add(1)));
    let (z0, z1) = (clamp_i32(z0), clamp_i32(z0.saturating_add(1)));
    let taps = [
        IVec2::new(x0, z0),
        IVec2::new(x1, z0),
        IVec2::new(x0, z1),
        IVec2::new(x1, z1),
    ];
    (taps, [fx, fz])
}

fn clamp_i32(v: i64) -> i32 {
    v.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
}

pub(crate) fn check_position(p: Vec2) -> Result<(), CoreError> {
    for v in [p.x, p.y] {
        if !v.is_finite() {
            return Err(CoreError::NonFinite {
                what: "sample position",
                value: v,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::{CoarseMap, HeightEncoding};

    fn ramp_map() -> CoarseMap {
        // Heights 0, 10, 20, 30 along X, identical rows; 1 stored unit = 1 m, 2 m per texel.
        let g = Grid::from_fn(4, 3, |x, _| (x * 10) as u16).unwrap();
        CoarseMap::coarse(g, HeightEncoding::new(1.0, 0.0).unwrap(), 2.0).unwrap()
    }

    #[test]
    fn interpolates_between_texels_in_world_units() {
        let m = ramp_map();
        assert_eq!(bilinear(&m, Vec2::new(0.0, 0.0)).unwrap(), 0.0);
        assert_eq!(bilinear(&m, Vec2::new(2.0, 0.0)).unwrap(), 10.0);
        assert!((bilinear(&m, Vec2::new(3.0, 1.0)).unwrap() - 15.0).abs() < 1e-5);
    }

    #[test]
    fn wraps_past_the_last_texel_like_listing_3_2() {
        let m = ramp_map();
        // Between texel 3 (30 m) and texel 0 (wrapped, 0 m).
        assert!((bilinear(&m, Vec2::new(7.0, 0.0)).unwrap() - 15.0).abs() < 1e-5);
        // A whole period away gives the same height.
        let a = bilinear(&m, Vec2::new(1.3, 2.1)).unwrap();
        let b = bilinear(&m, Vec2::new(1.3 + 8.0, 2.1 - 6.0)).unwrap();
        assert!((a - b).abs() < 1e-4);
    }

    #[test]
    fn clamps_on_clamped_maps() {
        let g = Grid::from_fn(4, 3, |x, _| (x * 10) as u16).unwrap();
        let e = HeightEncoding::new(1.0, 0.0).unwrap();
        let m = HeightMap::new(g, e, 2.0, WrapMode::Clamp).unwrap();
        assert_eq!(bilinear(&m, Vec2::new(7.0, 0.0)).unwrap(), 30.0);
        assert_eq!(bilinear(&m, Vec2::new(-5.0, 100.0)).unwrap(), 0.0);
    }

    #[test]
    fn float_grids_interpolate_wrap_and_clamp_in_texels() {
        // 0, 1, 2, 3 along X, 10 more per row.
        let g = Grid::from_fn(4, 3, |x, y| x as f32 + 10.0 * y as f32).unwrap();
        let at = |p: Vec2, wrap| bilinear_grid(&g, p, wrap).unwrap();
        assert_eq!(at(Vec2::new(2.0, 1.0), WrapMode::Repeat), 12.0);
        assert!((at(Vec2::new(1.25, 0.5), WrapMode::Repeat) - 6.25).abs() < 1e-6);
        // Past the last column: towards column 0 when wrapping, held at column 3 when clamped.
        assert!((at(Vec2::new(3.5, 0.0), WrapMode::Repeat) - 1.5).abs() < 1e-6);
        assert_eq!(at(Vec2::new(3.5, 0.0), WrapMode::Clamp), 3.0);
        assert_eq!(at(Vec2::new(-2.0, -4.0), WrapMode::Clamp), 0.0);
        assert!(bilinear_grid(&g, Vec2::new(f32::NAN, 0.0), WrapMode::Repeat).is_err());
    }

    #[test]
    fn nan_and_absurd_positions() {
        let m = ramp_map();
        assert!(bilinear(&m, Vec2::new(f32::NAN, 0.0)).is_err());
        assert!(bilinear(&m, Vec2::new(0.0, f32::INFINITY)).is_err());
        assert!(bilinear(&m, Vec2::new(1e30, -1e30)).unwrap().is_finite());
    }
}
