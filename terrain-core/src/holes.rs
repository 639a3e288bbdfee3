//! Holes in the terrain: a per-cell mask that removes ground (cave mouths, tunnels, the nodata
//! of a DEM) without touching the heights.
//!
//! A hole mask is a `Grid<u8>` of the map's size: 0 is ground, any other value a hole. Mask
//! texel `(x, y)` stands for the map cell `[x, x + 1] x [y, y + 1]` (texel units) whose lower
//! corner is texel `(x, y)`, the cell the renderers' fragments and the collision queries both
//! find with `floor`, so what is drawn and what collides remove the same ground. On a
//! repeating map the mask repeats with the heights; the last column's and row's cells reach
//! across the wrap.
//!
//! Why a mask beside the heights and not a reserved height: the heights stay integers whose
//! volume the granular passes conserve exactly, and a hole closed again gets its ground back.
//!
//! The mask is authored on the CPU ([`apply_hole_stamp`], [`holes_from_nodata`]) and uploaded
//! to the GPU (terrain-gpu's `GpuHoleMask`) and to collision (terrain-physics's
//! `HeightField::with_holes`): both need it, it is one byte per cell and it changes rarely, so
//! an upload of the changed rect costs less than a readback would.

use crate::error::CoreError;
use crate::grid::{Grid, WrapMode};
use crate::material_effect::for_each_in_footprint;
use crate::rect::DirtyRect;
use crate::stamp::StampPlacement;

/// A mask value of ground.
pub const GROUND: u8 = 0;
/// The mask value [`apply_hole_stamp`] and [`holes_from_nodata`] write for a hole (any value
/// but [`GROUND`] is a hole).
pub const HOLE: u8 = 255;

/// What a hole stamp does to the cells of its footprint.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum HoleOp {
    /// Removes the ground.
    Cut,
    /// Gives the ground back.
    Fill,
}

/// Whether mask value `v` is a hole.
#[inline]
pub fn is_hole(v: u8) -> bool {
    v != GROUND
}

/// Cuts (or fills) the cells inside a stamp's footprint at `placement` on `mask`, the hole
/// mask of a map of `texel_size` metres per texel with `wrap`: every cell whose corner texel
/// lies strictly inside the footprint's ellipse (its local distance below 1, in the stamp's
/// rotated frame, as a material effect measures it). Returns the rects it covered in mask
/// coordinates (1, 2 or 4 on a repeating mask, none for a footprint wholly off a clamped one).
///
/// Fails, with the mask unchanged, on an invalid placement or texel size and on a footprint
/// larger than a repeating mask.
pub fn apply_hole_stamp(
    mask: &mut Grid<u8>,
    wrap: WrapMode,
    texel_size: f32,
    placement: &StampPlacement,
    op: HoleOp,
) -> Result<Vec<DirtyRect>, CoreError> {
    let value = match op {
        HoleOp::Cut => HOLE,
        HoleOp::Fill => GROUND,
    };
    for_each_in_footprint(mask, wrap, texel_size, placement, |cell, local| {
        // NaN compares false: a texel the frame cannot place is outside.
        if local.length_squared() < 1.0 {
            *cell = value;
        }
    })
}

/// The hole mask of a DEM's nodata: a hole at every cell whose corner sample is nodata (NaN,
/// infinite, or a magnitude of at least [`crate::dem::HUGE_FLOAT_NODATA`]; the GeoTIFF reader
/// has already turned the GDAL nodata value into NaN). Take it from the heights as read, before
/// the nodata is filled: [`crate::dem::read_dem`] keeps it in [`crate::dem::Dem::holes`].
pub fn holes_from_nodata(heights: &Grid<f32>) -> Grid<u8> {
    heights.map(|&h| {
        if crate::dem::is_nodata(h) {
            HOLE
        } else {
            GROUND
        }
    })
}

/// Number of hole cells in `mask`.
pub fn count_holes(mask: &Grid<u8>) -> u64 {
    mask.as_slice().iter().filter(|&&v| is_hole(v)).count() as u64
}

/// Where a window of a streamed world's holes is drawn (terrain-gpu's hole mask window): a
/// square of cells that terrain-cache's `HoleWindow` places around the camera and keeps
/// current.
///
/// Contract for implementers:
/// - `place` makes the window cover the cells `origin .. origin + mask.size()` (world cells;
///   on a repeating world they may cross its edges) and hold `mask`, their hole mask,
///   row-major; every later call keeps that size.
/// - `update` rewrites the cells of `rect` that lie in the placed window with `mask`, their
///   hole mask (of `rect`'s size); cells outside the window are left out.
/// - Failures are the implementation's own [`HoleWindowTarget::Error`], never a panic.
pub trait HoleWindowTarget {
    /// Why an upload failed.
    type Error;

    /// Places the window (see the trait docs).
    fn place(&mut self, origin: glam::IVec2, mask: &Grid<u8>) -> Result<(), Self::Error>;

    /// Rewrites the cells of `rect` in the window (see the trait docs).
    fn update(&mut self, rect: crate::Rect, mask: &Grid<u8>) -> Result<(), Self::Error>;
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{UVec2, Vec2};

    fn placement(center: Vec2, size: Vec2, rotation: f32) -> StampPlacement {
        StampPlacement::new(center, size, -1.0)
            .unwrap()
            .with_rotation(rotation)
            .unwrap()
    }

    #[test]
    fn a_cut_removes_the_cells_inside_the_ellipse_only() {
        let mut mask = Grid::new(32, 32, GROUND).unwrap();
        let p = placement(Vec2::new(16.0, 16.0), Vec2::splat(8.0), 0.0);
        let dirty = apply_hole_stamp(&mut mask, WrapMode::Clamp, 1.0, &p, HoleOp::Cut).unwrap();
        assert_eq!(dirty.len(), 1);
        assert!(is_hole(mask.get(16, 16).unwrap()));
        assert!(is_hole(mask.get(19, 16).unwrap()));
        // (4, 0) from the centre is on the edge: not inside.
        assert!(!is_hole(mask.get(20, 16).unwrap()));
        assert!(!is_hole(mask.get(19, 19).unwrap()));
        // A disc of radius 4 holds 45 lattice points strictly inside (x^2 + y^2 < 16).
        assert_eq!(count_holes(&mask), 45);
        // Filling with a smaller stamp gives the middle back.
        let small = placement(Vec2::new(16.0, 16.0), Vec2::splat(4.0), 0.0);
        apply_hole_stamp(&mut mask, WrapMode::Clamp, 1.0, &small, HoleOp::Fill).unwrap();
        assert!(!is_hole(mask.get(16, 16).unwrap()));
        assert_eq!(count_holes(&mask), 45 - 9);
    }

    #[test]
    fn a_cut_follows_rotation_and_wraps() {
        let mut mask = Grid::new(16, 16, GROUND).unwrap();
        // A 12 x 2 m slot turned a quarter: it runs along Z.
        let p = placement(
            Vec2::new(0.0, 0.0),
            Vec2::new(12.0, 2.0),
            std::f32::consts::FRAC_PI_2,
        );
        let dirty = apply_hole_stamp(&mut mask, WrapMode::Repeat, 1.0, &p, HoleOp::Cut).unwrap();
        assert_eq!(dirty.len(), 4);
        assert!(is_hole(mask.get(0, 5).unwrap()));
        assert!(is_hole(mask.get(0, 11).unwrap()), "wraps to the far side");
        assert!(!is_hole(mask.get(5, 0).unwrap()), "not across");
    }

    #[test]
    fn bad_stamps_are_refused_and_change_nothing() {
        let mut mask = Grid::new(8, 8, GROUND).unwrap();
        let big = placement(Vec2::ZERO, Vec2::splat(20.0), 0.0);
        assert!(apply_hole_stamp(&mut mask, WrapMode::Repeat, 1.0, &big, HoleOp::Cut).is_err());
        let p = placement(Vec2::splat(4.0), Vec2::splat(4.0), 0.0);
        for ts in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            assert!(apply_hole_stamp(&mut mask, WrapMode::Clamp, ts, &p, HoleOp::Cut).is_err());
        }
        assert_eq!(count_holes(&mask), 0);
        // Wholly off a clamped mask: nothing to do.
        let off = placement(Vec2::splat(-100.0), Vec2::splat(4.0), 0.0);
        let dirty = apply_hole_stamp(&mut mask, WrapMode::Clamp, 1.0, &off, HoleOp::Cut).unwrap();
        assert!(dirty.is_empty());
        assert_eq!(mask.size(), UVec2::splat(8));
    }

    #[test]
    fn nodata_becomes_holes() {
        let h = Grid::from_vec(
            6,
            1,
            vec![1.0, f32::NAN, -9999.0, f32::INFINITY, -2e30, 3.0],
        )
        .unwrap();
        assert_eq!(holes_from_nodata(&h).as_slice(), &[0, 255, 0, 255, 255, 0]);
    }
}
