//! Deformation that changes what the ground shows: a material layer painted by stamps, the CPU
//! reference of terrain-gpu's `MaterialEffectPass`.
//!
//! A material layer (a splat map) holds one RGBA8 texel per map texel: the painted weight of
//! each material, in [`crate::MATERIALS`] order, 0 to 255. Their sum is the texel's cover: where
//! it is 0 the autoshader's weights show, where it is 255 only the paint, and in between the
//! two mix (the renderers' `painted_weights`). A new layer is all zero, the autoshader
//! everywhere; a splat map painted in full is 255 everywhere.
//!
//! A [`MaterialEffect`] paints one material over a stamp's footprint, fading from its centre:
//! the amount is `a = round(255 * strength * (1 - t^2)^2)`, `t` the distance from the centre
//! in the stamp's local frame (1 at the footprint's edge, so the paint follows its rotation and
//! aspect), and every channel `c` becomes `(c (255 - a) + target a + 127) / 255`, `target` 255
//! for the effect's material and 0 for the others. After the one f32 amount the arithmetic is
//! integer; the GPU runs the same operations, so its amounts differ by at most one step where a
//! conforming GPU fuses a multiply and an add (WGSL allows it) and a product lands on a
//! rounding boundary.
//!
//! A granular trail paints the same way where an object presses the material down
//! ([`apply_trail_effect`]): the whole amount on every pressed column, integers only.

use crate::error::CoreError;
use crate::granular::{ColumnKind, Penetration};
use crate::grid::{Grid, WrapMode};
use crate::material::MATERIALS;
use crate::rect::{DirtyRect, Rect};
use crate::stamp::{StampPlacement, stamp_region};
use glam::{IVec2, Vec2};

/// A material painted by a stamp: which one, and how strongly at the footprint's centre.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct MaterialEffect {
    /// The material's index ([`crate::material::MATERIAL_NAMES`]: 0 grass, 1 dirt, 2 rock, 3 snow).
    pub material: u32,
    /// How much of the material covers the centre after one stamp, 0 to 1 (1: all of it).
    pub strength: f32,
}

impl MaterialEffect {
    /// An effect; fails where [`MaterialEffect::validate`] does.
    pub fn new(material: u32, strength: f32) -> Result<Self, CoreError> {
        let effect = Self { material, strength };
        effect.validate()?;
        Ok(effect)
    }

    /// Fails on a material index of 4 or more and on a strength outside [0, 1] (NaN too).
    pub fn validate(&self) -> Result<(), CoreError> {
        if self.material as usize >= MATERIALS {
            return Err(CoreError::OutOfRange {
                what: "material effect's material",
                value: f64::from(self.material),
                expected: "a material index below 4 (grass, dirt, rock, snow)",
            });
        }
        if !(0.0..=1.0).contains(&self.strength) {
            return Err(CoreError::OutOfRange {
                what: "material effect's strength",
                value: f64::from(self.strength),
                expected: "0 to 1",
            });
        }
        Ok(())
    }
}

/// The amount (0 to 255) an effect of `strength` paints at `local`, the texel's place in the
/// stamp's frame (the footprint's edge at distance 1).
pub fn effect_amount(local: Vec2, strength: f32) -> u32 {
    let t2 = local.x * local.x + local.y * local.y;
    // NaN (a texel the frame cannot place) paints nothing, as beyond the edge.
    if t2.is_nan() || t2 >= 1.0 {
        return 0;
    }
    let f = 1.0 - t2;
    // `255 * strength` is one f32 the GPU receives as is; the rest is evaluated there in this
    // order.
    let a = (255.0 * strength) * (f * f) + 0.5;
    (a.floor() as u32).min(255)
}

/// `texel` with `amount` (0 to 255) of `material` painted over it.
pub fn paint_texel(texel: [u8; 4], material: u32, amount: u32) -> [u8; 4] {
    let a = amount.min(255);
    let mut out = texel;
    for (c, v) in out.iter_mut().enumerate() {
        let target = if c as u32 == material { 255 } else { 0 };
        *v = ((u32::from(*v) * (255 - a) + target * a + 127) / 255) as u8;
    }
    out
}

/// Paints `effect` over the footprint of a stamp at `placement` on `layer`, a material layer
/// over a map of `texel_size` metres per texel with `wrap`, and returns the rects it covered
/// in layer coordinates (as [`crate::apply_stamp`]: 1, 2 or 4 on a repeating layer, none for a
/// footprint wholly off a clamped one). Call it with the placement of the height change it goes
/// with.
///
/// Fails, with the layer unchanged, on an invalid effect, placement or texel size, and on a
/// footprint larger than a repeating layer.
pub fn apply_material_effect(
    layer: &mut Grid<[u8; 4]>,
    wrap: WrapMode,
    texel_size: f32,
    placement: &StampPlacement,
    effect: &MaterialEffect,
) -> Result<Vec<DirtyRect>, CoreError> {
    effect.validate()?;
    for_each_in_footprint(layer, wrap, texel_size, placement, |texel, local| {
        let amount = effect_amount(local, effect.strength);
        if amount > 0 {
            *texel = paint_texel(*texel, effect.material, amount);
        }
    })
}

/// Calls `f(texel, local)` for every texel of `grid` (a layer over a map of `texel_size`
/// metres per texel with `wrap`) under the footprint of a stamp at `placement`, `local` the
/// texel's place in the stamp's frame ([`EffectFrame::local`]), and returns the rects it
/// covered in grid coordinates: 1, 2 or 4 on a repeating grid, none for a footprint wholly off
/// a clamped one. Fails, with nothing called, on an invalid placement or texel size and on a
/// footprint larger than a repeating grid. What the material effects and the hole stamps
/// share.
pub(crate) fn for_each_in_footprint<T: Copy>(
    grid: &mut Grid<T>,
    wrap: WrapMode,
    texel_size: f32,
    placement: &StampPlacement,
    mut f: impl FnMut(&mut T, Vec2),
) -> Result<Vec<DirtyRect>, CoreError> {
    let Some(region) = stamp_region(grid.size(), wrap, texel_size, placement)? else {
        return Ok(Vec::new());
    };
    let frame = EffectFrame::new(placement, texel_size);
    for piece in &region.pieces {
        let (map, unwrapped) = (piece.map, piece.unwrapped);
        for dy in 0..map.size.y {
            let row = grid.row_mut((map.min.y + dy as i32) as u32);
            let start = map.min.x as usize;
            let texels = &mut row[start..start + map.size.x as usize];
            for (dx, texel) in texels.iter_mut().enumerate() {
                let u = unwrapped.min + IVec2::new(dx as i32, dy as i32);
                f(texel, frame.local(u));
            }
        }
    }
    Ok(region.pieces.iter().map(|p| p.map).collect())
}

/// Paints `effect` under a granular trail: every column a granular step presses down (a
/// `Penetrating` column of `penetration`, the step's penetration texture over `area` of the
/// map, as [`crate::granular::penetration_texture`] computes it before the step moves any
/// material) gets the effect's full amount, `effect_amount(0, strength)`. An object resting in
/// its hollow presses nothing more, so a trail is painted once, as the object moves on. The
/// CPU reference of terrain-gpu's `TrailEffectPass`; integer arithmetic only, so the two agree
/// bit for bit.
///
/// Returns `area` if a column was painted. Fails, with the layer unchanged, on an invalid
/// effect, an area not inside the layer, and a penetration texture of another size.
pub fn apply_trail_effect(
    layer: &mut Grid<[u8; 4]>,
    penetration: &Grid<Penetration>,
    area: Rect,
    effect: &MaterialEffect,
) -> Result<Option<DirtyRect>, CoreError> {
    effect.validate()?;
    if area.is_empty() || !Rect::from_size(layer.size()).contains_rect(&area) {
        return Err(CoreError::RegionOutOfBounds {
            rect: area,
            map_size: layer.size(),
        });
    }
    if penetration.size() != area.size {
        return Err(CoreError::SizeMismatch {
            expected: area.size,
            actual: penetration.size(),
        });
    }
    let amount = effect_amount(Vec2::ZERO, effect.strength);
    let pressed = ColumnKind::Penetrating as i32;
    let mut painted = false;
    let x0 = area.min.x as usize;
    for j in 0..area.size.y {
        let row = layer.row_mut(area.min.y as u32 + j);
        let texels = &mut row[x0..x0 + area.size.x as usize];
        for (texel, column) in texels.iter_mut().zip(penetration.row(j)) {
            if column.kind == pressed && amount > 0 {
                *texel = paint_texel(*texel, effect.material, amount);
                painted = true;
            }
        }
    }
    Ok(painted.then_some(area))
}

/// A stamp's local frame in texels, as the GPU receives it: the centre, the inverse half-size
/// and the rotation's sine and cosine (all f32).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EffectFrame {
    /// Centre in texels.
    pub center: Vec2,
    /// One over the footprint's half-size in texels, per local axis.
    pub inv_half: Vec2,
    /// Sine of the rotation.
    pub sin: f32,
    /// Cosine of the rotation.
    pub cos: f32,
}

impl EffectFrame {
    /// The frame of `placement` on a map of `texel_size` metres per texel.
    pub fn new(placement: &StampPlacement, texel_size: f32) -> Self {
        let (center, inv_half, sin, cos) = placement.local_frame(texel_size);
        Self {
            center,
            inv_half,
            sin,
            cos,
        }
    }

    /// The place of the texel at unwrapped coordinates `u` in the frame (the operations the
    /// GPU runs, in the same order).
    pub fn local(&self, u: IVec2) -> Vec2 {
        let d = Vec2::new(u.x as f32 - self.center.x, u.y as f32 - self.center.y);
        Vec2::new(
            (d.x * self.cos + d.y * self.sin) * self.inv_half.x,
            (d.y * self.cos - d.x * self.sin) * self.inv_half.y,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::UVec2;

    fn placement(center: Vec2, size: f32) -> StampPlacement {
        StampPlacement::new(center, Vec2::splat(size), -1.0).unwrap()
    }

    #[test]
    fn amount_is_full_at_the_centre_and_zero_at_the_edge() {
        assert_eq!(effect_amount(Vec2::ZERO, 1.0), 255);
        assert_eq!(effect_amount(Vec2::ZERO, 0.5), 128);
        assert_eq!(effect_amount(Vec2::new(1.0, 0.0), 1.0), 0);
        assert_eq!(effect_amount(Vec2::new(0.7, 0.7), 1.0), 0);
        assert_eq!(effect_amount(Vec2::new(f32::NAN, 0.0), 1.0), 0);
        // (1 - 0.25)^2 = 0.5625 of 255 = 143.4.
        assert_eq!(effect_amount(Vec2::new(0.5, 0.0), 1.0), 143);
        assert_eq!(effect_amount(Vec2::ZERO, 0.0), 0);
    }

    #[test]
    fn painting_moves_every_channel_towards_the_material() {
        assert_eq!(paint_texel([0; 4], 1, 255), [0, 255, 0, 0]);
        assert_eq!(paint_texel([0; 4], 1, 0), [0; 4]);
        assert_eq!(paint_texel([255, 0, 0, 0], 3, 128), [127, 0, 0, 128]);
        // A full cover stays a full cover (to rounding) whatever is painted.
        let t = paint_texel([100, 55, 50, 50], 2, 77);
        let sum: u32 = t.iter().map(|&v| u32::from(v)).sum();
        assert!((254..=256).contains(&sum), "{t:?}");
        assert!(t[2] > 50 && t[0] < 100);
    }

    #[test]
    fn an_effect_paints_its_footprint_only_and_wraps() {
        let mut layer = Grid::new(32, 32, [0u8; 4]).unwrap();
        let effect = MaterialEffect::new(1, 1.0).unwrap();
        // A 6 m footprint at texel (0, 0) of a 1 m grid: across the corner of a repeating layer.
        let dirty = apply_material_effect(
            &mut layer,
            WrapMode::Repeat,
            1.0,
            &placement(Vec2::ZERO, 6.0),
            &effect,
        )
        .unwrap();
        assert_eq!(dirty.len(), 4);
        assert_eq!(layer.get(0, 0), Some([0, 255, 0, 0]));
        assert!(layer.get(31, 31).unwrap()[1] > 0);
        assert!(layer.get(1, 30).unwrap()[1] > 0);
        assert_eq!(layer.get(16, 16), Some([0; 4]));
        assert_eq!(layer.get(3, 0), Some([0; 4]), "t = 1 at the edge");
        let painted = layer.as_slice().iter().filter(|t| t[1] > 0).count();
        assert!(
            (20..=32).contains(&painted),
            "{painted} texels, about pi 3^2"
        );
        // Clamped: only the part on the layer, none for a footprint off it.
        let mut clamped = Grid::new(32, 32, [0u8; 4]).unwrap();
        let dirty = apply_material_effect(
            &mut clamped,
            WrapMode::Clamp,
            1.0,
            &placement(Vec2::ZERO, 6.0),
            &effect,
        )
        .unwrap();
        assert_eq!(dirty.len(), 1);
        assert_eq!(clamped.get(31, 31), Some([0; 4]));
        let far = placement(Vec2::splat(-100.0), 6.0);
        let dirty =
            apply_material_effect(&mut clamped, WrapMode::Clamp, 1.0, &far, &effect).unwrap();
        assert!(dirty.is_empty());
    }

    #[test]
    fn the_paint_follows_the_footprints_rotation_and_aspect() {
        let mut layer = Grid::new(64, 64, [0u8; 4]).unwrap();
        let effect = MaterialEffect::new(2, 1.0).unwrap();
        let long = StampPlacement::new(Vec2::splat(32.0), Vec2::new(30.0, 4.0), 1.0)
            .unwrap()
            .with_rotation(std::f32::consts::FRAC_PI_2)
            .unwrap();
        apply_material_effect(&mut layer, WrapMode::Clamp, 1.0, &long, &effect).unwrap();
        // Turned a quarter: long along Z, narrow along X.
        assert!(layer.get(32, 44).unwrap()[2] > 0);
        assert_eq!(layer.get(44, 32).unwrap()[2], 0);
    }

    #[test]
    fn bad_effects_and_placements_are_refused_and_change_nothing() {
        let mut layer = Grid::new(16, 16, [7u8; 4]).unwrap();
        let p = placement(Vec2::splat(8.0), 4.0);
        for effect in [
            MaterialEffect {
                material: 4,
                strength: 1.0,
            },
            MaterialEffect {
                material: 0,
                strength: f32::NAN,
            },
            MaterialEffect {
                material: 0,
                strength: 1.5,
            },
            MaterialEffect {
                material: 0,
                strength: -0.1,
            },
        ] {
            assert!(apply_material_effect(&mut layer, WrapMode::Clamp, 1.0, &p, &effect).is_err());
        }
        let ok = MaterialEffect::new(0, 1.0).unwrap();
        assert!(apply_material_effect(&mut layer, WrapMode::Clamp, f32::NAN, &p, &ok).is_err());
        assert!(apply_material_effect(&mut layer, WrapMode::Clamp, 0.0, &p, &ok).is_err());
        let mut huge = p;
        huge.scale = Vec2::splat(1e9);
        assert!(apply_material_effect(&mut layer, WrapMode::Repeat, 1.0, &huge, &ok).is_err());
        // Absurd but finite placements answer at once: clipped to the layer.
        let mut far = p;
        far.center = Vec2::splat(3e38);
        assert!(
            apply_material_effect(&mut layer, WrapMode::Clamp, 1.0, &far, &ok)
                .unwrap()
                .is_empty()
        );
        assert!(layer.as_slice().iter().all(|t| *t == [7; 4]));
        assert_eq!(layer.size(), UVec2::splat(16));
    }

    #[test]
    fn a_trail_paints_the_pressed_columns_only() {
        let mut layer = Grid::new(8, 6, [0u8, 0, 0, 255]).unwrap();
        let seed = Penetration {
            seed_x: 0,
            seed_y: 0,
            kind: ColumnKind::Seed as i32,
            penetration: 0,
        };
        let mut pen = Grid::new(4, 3, seed).unwrap();
        let pressed = Penetration {
            kind: ColumnKind::Penetrating as i32,
            penetration: 5,
            ..seed
        };
        *pen.get_mut(1, 2).unwrap() = pressed;
        *pen.get_mut(3, 0).unwrap() = Penetration {
            kind: ColumnKind::Obstacle as i32,
            ..seed
        };
        let area = Rect::new(IVec2::new(2, 1), UVec2::new(4, 3));
        let effect = MaterialEffect::new(1, 0.5).unwrap();
        let dirty = apply_trail_effect(&mut layer, &pen, area, &effect).unwrap();
        assert_eq!(dirty, Some(area));
        // Column (1, 2) of the area is texel (3, 3): half dirt over full snow.
        assert_eq!(layer.get(3, 3), Some(paint_texel([0, 0, 0, 255], 1, 128)));
        let changed = layer.as_slice().iter().filter(|t| **t != [0, 0, 0, 255]);
        assert_eq!(changed.count(), 1, "obstacles and seeds keep their paint");
        // Nothing pressed: nothing painted, no rect.
        let none = Grid::new(4, 3, seed).unwrap();
        assert_eq!(
            apply_trail_effect(&mut layer, &none, area, &effect).unwrap(),
            None
        );
        // Areas off the layer, textures of another size and bad effects change nothing.
        let before = layer.clone();
        let off = Rect::new(IVec2::new(6, 4), UVec2::new(4, 3));
        assert!(apply_trail_effect(&mut layer, &pen, off, &effect).is_err());
        let small = Rect::new(IVec2::new(0, 0), UVec2::new(3, 3));
        assert!(apply_trail_effect(&mut layer, &pen, small, &effect).is_err());
        let bad = MaterialEffect {
            material: 9,
            strength: 1.0,
        };
        assert!(apply_trail_effect(&mut layer, &pen, area, &bad).is_err());
        assert_eq!(layer, before);
    }
}
