//! The spill rule of the detail layer: what a detail stamp pushes beyond a tile's 1 m range
//! moves into the coarse-map instead of being clipped.
//!
//! A detail stamp is evaluated unclamped; the tile keeps what its range holds and the excess
//! goes to the coarse-map by the transpose of the bilinear interpolation that carries coarse
//! heights onto the detail grid, so the volume is kept to the coarse encoding's rounding (half
//! a unit per coarse texel) and nothing is clipped. The rule and why it keeps the volume are
//! derived in the repository's `docs/derivations.md` ("The detail layer's spill").
//!
//! A coarse texel at the end of the coarse encoding's range clamps, as under any stamp.
//!
//! [`spill_into_coarse`] is the CPU reference of terrain-gpu's `SpillPass`;
//! [`crate::detail::DetailLayer::apply_stamp_spilling`] applies a stamp with this rule.
//!
//! ```
//! use glam::{IVec2, UVec2, Vec2};
//! use terrain_core::detail::{DetailLayer, DetailLayout};
//! use terrain_core::{Blend, GaussianStamp, Grid, HeightEncoding, HeightMap, StampPlacement, WrapMode};
//!
//! // A 64^2 coarse-map at 0.1 m (1 mm units) under detail tiles refined x3.
//! let enc = HeightEncoding::new(0.001, -30.0)?;
//! let mut coarse = HeightMap::new(Grid::new(64, 64, 30_000u16)?, enc, 0.1, WrapMode::Repeat)?;
//! let mut layer = DetailLayer::new(DetailLayout::new(UVec2::splat(64), 0.1, 3, 32)?)?;
//!
//! // A mark 1.5 m deep: the tile keeps -0.5 m (the bottom of its range), the coarse-map the rest.
//! let p = StampPlacement::new(Vec2::splat(3.2), Vec2::splat(0.6), -1.5)?;
//! let (_, spilled) =
//!     layer.apply_stamp_spilling(&mut coarse, &mut GaussianStamp::default(), &p, Blend::Add)?;
//! assert_eq!(layer.raw(IVec2::splat(96)), 0);
//! assert!(!spilled.is_empty());
//! assert!(coarse.grid().get(32, 32).unwrap() < 30_000 - 300);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use crate::error::CoreError;
use crate::grid::{Grid, WrapMode};
use crate::map::{HeightEncoding, HeightMap, HeightSample};
use crate::rect::{DirtyRect, Rect};
use glam::{IVec2, UVec2};

/// The raw value of 0 m in the wide window a spilling detail stamp is evaluated on: detail
/// raw `v` is wide raw `v + WIDE_SHIFT` ([`crate::detail::DETAIL_ZERO_RAW`] is 128).
pub const WIDE_ZERO_RAW: u16 = 32_768;

/// Detail raw `v` is wide raw `v + WIDE_SHIFT`.
pub const WIDE_SHIFT: i32 = WIDE_ZERO_RAW as i32 - crate::detail::DETAIL_ZERO_RAW as i32;

/// The encoding of the wide window: the detail tiles' 1/255 m units with ±128 m of range.
pub fn wide_encoding() -> HeightEncoding {
    HeightEncoding {
        scale: 1.0 / 255.0,
        offset: -f32::from(WIDE_ZERO_RAW) / 255.0,
    }
}

/// The excess of a wide raw value (detail units beyond `0..=255`; 0 inside the range), and the
/// detail raw value the tile keeps.
pub fn split_wide(wide: u16) -> (i32, u8) {
    let v = i32::from(wide) - WIDE_SHIFT;
    let kept = v.clamp(0, 255);
    (v - kept, kept as u8)
}

/// The coarse texels (unwrapped) the excess of a detail footprint `footprint` (detail texels,
/// unwrapped, not empty) can reach at refinement `refine`: exactly the coarse texels `C`
/// whose tent covers one of its detail texels `q` with a non-zero weight (`|q - r C| < r` on
/// both axes), from `floor(min / r)` to `ceil((max - 1) / r)`.
pub fn spill_rect(footprint: Rect, refine: u32) -> Rect {
    // In i64: `last` and `ceil(last / r) + 1` may leave i32 at the ends of its range.
    let r = i64::from(refine.max(1));
    let axis = |min: i32, size: u32| {
        let lo = i64::from(min).div_euclid(r);
        let last = i64::from(min) + i64::from(size.max(1)) - 1;
        // ceil(last / r), rounding towards +infinity for negative values too.
        let hi = -(-last).div_euclid(r) + 1;
        (lo, hi)
    };
    let ((x0, x1), (y0, y1)) = (
        axis(footprint.min.x, footprint.size.x),
        axis(footprint.min.y, footprint.size.y),
    );
    let size = |a: i64, b: i64| (b - a).clamp(0, i64::from(u32::MAX)) as u32;
    Rect::new(
        IVec2::new(x0 as i32, y0 as i32),
        UVec2::new(size(x0, x1), size(y0, y1)),
    )
}

/// The factor that turns a sum of excess weighted by integer tents `w` (detail units) into
/// coarse raw units: `detail_scale / (coarse_scale r^4)`, in f32 as the GPU computes it.
pub fn spill_factor(refine: u32, coarse: HeightEncoding) -> f32 {
    let r2 = (refine as f32) * (refine as f32);
    crate::detail::detail_encoding().scale / (coarse.scale * r2 * r2)
}

/// The coarse raw change of coarse texel `c` (unwrapped) from the excess window `excess`, whose
/// texel `(0, 0)` is detail texel `origin`: `floor(S k + 0.5)` with `S` the tent-weighted sum
/// in f32 (row-major over the tent, as the GPU sums it) and `k` from [`spill_factor`].
pub fn spill_delta(excess: &Grid<i32>, origin: IVec2, refine: u32, k: f32, c: IVec2) -> f32 {
    let r = i64::from(refine);
    // In i64: `c r` may leave i32 for coarse texels near the ends of the i32 range.
    let centre = |c: i32, o: i32| i64::from(c) * r - i64::from(o);
    let (cx, cy) = (centre(c.x, origin.x), centre(c.y, origin.y));
    let mut sum = 0.0f32;
    for dy in (1 - r)..r {
        for dx in (1 - r)..r {
            let (qx, qy) = (cx + dx, cy + dy);
            let (Ok(qx), Ok(qy)) = (u32::try_from(qx), u32::try_from(qy)) else {
                continue;
            };
            let Some(e) = excess.get(qx, qy) else {
                continue;
            };
            if e != 0 {
                let w = (r - dx.abs()) * (r - dy.abs());
                sum += (w as f32) * (e as f32);
            }
        }
    }
    (sum * k + 0.5).floor()
}

/// Moves the excess of a detail stamp into `coarse` by the spill rule (module docs). `excess`
/// holds the excess of every detail texel of the footprint, its texel `(0, 0)` at detail texel
/// `origin` (unwrapped); `refine` is the layer's refinement. Returns the coarse rects it
/// changed (wrapped onto a repeating map: up to 4), empty when there was no excess.
///
/// Fails, changing nothing, on a refinement of 0 or above [`crate::detail::MAX_REFINE`], or
/// a spill rect larger than a repeating coarse-map (it would overlap itself).
pub fn spill_into_coarse<T: HeightSample>(
    coarse: &mut HeightMap<T>,
    excess: &Grid<i32>,
    origin: IVec2,
    refine: u32,
) -> Result<Vec<DirtyRect>, CoreError> {
    check_refine(refine)?;
    let footprint = Rect::new(origin, excess.size());
    let rect = spill_rect(footprint, refine);
    check_spill_fits(rect, coarse.size(), coarse.wrap())?;
    if excess.as_slice().iter().all(|&e| e == 0) {
        return Ok(Vec::new());
    }
    let k = spill_factor(refine, coarse.encoding());
    let size = coarse.size();
    let wrap = coarse.wrap();
    let mut changed = Vec::new();
    for piece in coarse_pieces(rect, size, wrap) {
        let mut any = false;
        let to_unwrapped = piece.1 - piece.0.min;
        for y in piece.0.min.y..piece.0.max().y {
            for x in piece.0.min.x..piece.0.max().x {
                let c = IVec2::new(x, y) + to_unwrapped;
                let delta = spill_delta(excess, origin, refine, k, c);
                if delta == 0.0 {
                    continue;
                }
                if let Some(v) = coarse.grid_mut().get_mut(x as u32, y as u32) {
                    let new = T::from_raw_f64_clamped(v.to_raw_f64() + f64::from(delta));
                    any |= bytemuck::bytes_of(&new) != bytemuck::bytes_of(v);
                    *v = new;
                }
            }
        }
        if any {
            changed.push(piece.0);
        }
    }
    Ok(changed)
}

/// The pieces of `rect` (unwrapped coarse texels) on a coarse-map of `size`: (map rect,
/// unwrapped min) — split across the wrap on a repeating map, cut at the edges of a clamped one.
pub fn coarse_pieces(rect: Rect, size: UVec2, wrap: WrapMode) -> Vec<(Rect, IVec2)> {
    match wrap {
        WrapMode::Repeat => rect
            .split_toroidal(size)
            .into_iter()
            .map(|p| (p.map, p.unwrapped.min))
            .collect(),
        WrapMode::Clamp => Rect::new(IVec2::ZERO, size)
            .intersect(&rect)
            .map(|r| vec![(r, r.min)])
            .unwrap_or_default(),
    }
}

/// Fails on a refinement the detail layer refuses.
pub(crate) fn check_refine(refine: u32) -> Result<(), CoreError> {
    if (1..=crate::detail::MAX_REFINE).contains(&refine) {
        return Ok(());
    }
    Err(CoreError::OutOfRange {
        what: "detail refinement (detail texels per coarse texel)",
        value: f64::from(refine),
        expected: "1 to 16",
    })
}

/// Fails where the spill rect would overlap itself on a repeating coarse-map.
pub fn check_spill_fits(rect: Rect, size: UVec2, wrap: WrapMode) -> Result<(), CoreError> {
    if wrap == WrapMode::Repeat && rect.size.cmpgt(size).any() {
        return Err(CoreError::OutOfRange {
            what: "detail stamp spill (coarse texels it may reach)",
            value: rect.area() as f64,
            expected: "within the coarse-map (a mark this large belongs to the coarse-map)",
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn coarse(size: u32, wrap: WrapMode) -> HeightMap<u16> {
        let enc = HeightEncoding::new(0.001, -30.0).unwrap();
        HeightMap::new(Grid::new(size, size, 30_000u16).unwrap(), enc, 0.3, wrap).unwrap()
    }

    #[test]
    fn split_wide_keeps_the_range_and_returns_the_rest() {
        assert_eq!(split_wide(WIDE_ZERO_RAW), (0, 128));
        assert_eq!(split_wide((WIDE_SHIFT + 255) as u16), (0, 255));
        assert_eq!(split_wide((WIDE_SHIFT + 260) as u16), (5, 255));
        assert_eq!(split_wide(WIDE_SHIFT as u16), (0, 0));
        assert_eq!(split_wide((WIDE_SHIFT - 7) as u16), (-7, 0));
        assert_eq!(split_wide(0), (-WIDE_SHIFT, 0));
    }

    #[test]
    fn wide_encoding_agrees_with_the_detail_encoding() {
        let d = crate::detail::detail_encoding();
        for v in [0u8, 100, 128, 255] {
            let m = d.to_metres(f64::from(v));
            let w = wide_encoding().to_metres(f64::from(i32::from(v) + WIDE_SHIFT));
            assert!((m - w).abs() < 1e-5, "{v}: {m} vs {w}");
        }
    }

    #[test]
    fn spill_rect_is_exactly_the_tents_that_weigh_a_texel() {
        for r in 1..=5u32 {
            let ri = r as i32;
            for min in -13..13 {
                for len in 1..12u32 {
                    let fp = Rect::new(IVec2::new(min, 2 - min), UVec2::new(len, len + 1));
                    let rect = spill_rect(fp, r);
                    // Brute force, per axis: the coarse texels with a detail texel in reach.
                    let reach = |lo: i32, n: u32| -> Vec<i32> {
                        (-40..40)
                            .filter(|c| (lo..lo + n as i32).any(|q| (q - c * ri).abs() < ri))
                            .collect()
                    };
                    let (xs, ys) = (reach(fp.min.x, fp.size.x), reach(fp.min.y, fp.size.y));
                    let got_x: Vec<i32> = (rect.min.x..rect.max().x).collect();
                    let got_y: Vec<i32> = (rect.min.y..rect.max().y).collect();
                    assert_eq!(got_x, xs, "r {r} min {min} len {len}");
                    assert_eq!(got_y, ys, "r {r} min {min} len {len}");
                }
            }
        }
    }

    #[test]
    fn the_volume_moved_is_the_excess_volume() {
        // Excess over an odd-shaped window, some texels positive, some negative.
        let r = 3u32;
        let mut excess = Grid::new(11, 7, 0i32).unwrap();
        for (i, v) in excess.as_mut_slice().iter_mut().enumerate() {
            *v = match i % 5 {
                0 => 40 + i as i32,
                1 => -(i as i32) * 3,
                _ => 0,
            };
        }
        let mut map = coarse(32, WrapMode::Repeat);
        let before = map.raw_sum() as f64;
        let rects = spill_into_coarse(&mut map, &excess, IVec2::new(-4, 5), r).unwrap();
        assert!(!rects.is_empty());
        let moved = (map.raw_sum() as f64 - before) * 0.001 * 0.3 * 0.3;
        let ts_d = 0.1;
        let excess_m3: f64 =
            excess.as_slice().iter().map(|&e| f64::from(e)).sum::<f64>() / 255.0 * ts_d * ts_d;
        let texels = spill_rect(Rect::new(IVec2::new(-4, 5), excess.size()), r).area() as f64;
        let bound = texels * 0.5 * 0.001 * 0.3 * 0.3;
        assert!(
            (moved - excess_m3).abs() <= bound,
            "moved {moved} m^3, excess {excess_m3} m^3, bound {bound}"
        );
    }

    #[test]
    fn a_single_texel_on_a_coarse_texel_goes_to_it_alone() {
        let mut excess = Grid::new(1, 1, 0i32).unwrap();
        excess.as_mut_slice()[0] = 90; // 90 / 255 m on one detail texel of a 3x3 cell
        let mut map = coarse(8, WrapMode::Repeat);
        let rects = spill_into_coarse(&mut map, &excess, IVec2::new(6, 9), 3).unwrap();
        assert_eq!(rects, vec![Rect::new(IVec2::new(2, 3), UVec2::new(1, 1))]);
        // 90 units * 9 / 9 / 255 m = 0.3529 m over a coarse texel's area / 9: 39.2 mm.
        let want = (90.0f64 / 255.0 / 9.0 / 0.001 + 0.5).floor() as u16;
        assert_eq!(map.grid().get(2, 3), Some(30_000 + want));
        assert_eq!(map.grid().get(3, 3), Some(30_000));
        assert_eq!(map.grid().get(2, 4), Some(30_000));
    }

    #[test]
    fn across_the_wrap_and_off_a_clamped_edge() {
        let mut excess = Grid::new(4, 4, 0i32).unwrap();
        excess.as_mut_slice().fill(-200);
        let origin = IVec2::new(-2, -2);
        let mut wrapped = coarse(8, WrapMode::Repeat);
        let rects = spill_into_coarse(&mut wrapped, &excess, origin, 2).unwrap();
        assert_eq!(rects.len(), 4, "{rects:?}");
        assert!(wrapped.grid().get(7, 7).unwrap() < 30_000);
        assert!(wrapped.grid().get(0, 0).unwrap() < 30_000);
        let mut clamped = coarse(8, WrapMode::Clamp);
        let rects = spill_into_coarse(&mut clamped, &excess, origin, 2).unwrap();
        assert_eq!(rects.len(), 1);
        assert_eq!(clamped.grid().get(7, 7), Some(30_000));
        assert!(clamped.grid().get(0, 0).unwrap() < 30_000);
    }

    #[test]
    fn no_excess_changes_nothing_and_bad_input_is_refused() {
        let excess = Grid::new(5, 5, 0i32).unwrap();
        let mut map = coarse(8, WrapMode::Repeat);
        let before = map.clone();
        assert!(
            spill_into_coarse(&mut map, &excess, IVec2::ZERO, 3)
                .unwrap()
                .is_empty()
        );
        assert_eq!(map, before);
        let mut ones = Grid::new(5, 5, 1i32).unwrap();
        assert!(spill_into_coarse(&mut map, &ones, IVec2::ZERO, 0).is_err());
        assert!(spill_into_coarse(&mut map, &ones, IVec2::ZERO, 17).is_err());
        ones = Grid::new(30, 30, 1i32).unwrap();
        assert!(spill_into_coarse(&mut map, &ones, IVec2::ZERO, 3).is_err());
        assert_eq!(map, before);
        // Extreme origins stay bounded (the rect is computed without overflow).
        let far = Grid::new(2, 2, 1i32).unwrap();
        spill_into_coarse(&mut map, &far, IVec2::new(i32::MAX - 8, i32::MIN), 3).unwrap();
        let one = Grid::new(1, 1, 300i32).unwrap();
        for (o, r) in [
            (IVec2::new(i32::MIN, i32::MAX), 1),
            (IVec2::new(i32::MAX, i32::MIN), 1),
            (IVec2::splat(i32::MIN), 16),
        ] {
            spill_into_coarse(&mut map, &one, o, r).unwrap();
            let rect = spill_rect(Rect::new(o, UVec2::ONE), r);
            assert_eq!(rect.size, UVec2::ONE, "{o} r {r}");
        }
    }
}
