//! The level morph of geometry clipmaps (GPU Gems 2 ch. 2, "transition regions"): near a
//! level's outer edge its vertices blend towards the next coarser level's surface, so the edge
//! matches the coarser level exactly (no cracks) and levels do not pop. This is the CPU
//! reference of the morph in terrain-shaders' `clipmap.wgsl`.

use glam::{IVec2, Vec2};

/// Width of the transition region in level grid units: GPU Gems 2 uses `w = n / 10`.
pub fn default_morph_width(n: u32) -> f32 {
    (n as f32 / 10.0).max(1.0)
}

/// Blend factor of a vertex at `texel` on a level of `scale` texels per grid unit, with the
/// camera at `camera_texel`: 0 in the level's interior, rising over `width` grid units to 1 at
/// `(n - 1) / 2 - 1` grid units from the camera (the level's edge is at least that far, since
/// the level is snapped to the coarser grid around the camera).
pub fn morph_alpha(texel: IVec2, camera_texel: Vec2, scale: u32, n: u32, width: f32) -> f32 {
    let rel = (texel.as_vec2() - camera_texel) / scale as f32;
    let d = rel.x.abs().max(rel.y.abs());
    let half = (n as f32 - 1.0) * 0.5;
    // Written as 1 - (edge - d) / width rather than (d - (edge - width)) / width: from the edge
    // on `edge - d` is <= 0 exactly, so edge vertices get exactly 1 whatever the rounding of
    // `width` (the other form gave 0.9999998 at n = 63; found by the morph property test).
    (1.0 - ((half - 1.0) - d) / width).clamp(0.0, 1.0)
}

/// The next coarser level's surface under a vertex at `texel` of a level with `scale` texels
/// per grid unit: the vertex's own height where it is a coarser vertex too, else the mean of
/// its two coarser neighbours (odd on one axis) or of the four around it (odd on both).
///
/// Any input is answered, never a panic: as in the shader's i32 arithmetic, neighbour
/// coordinates wrap at the ends of `i32`, and a scale whose division is undefined (0, or a
/// scale above `i32::MAX` dividing `i32::MIN`) divides as WGSL's `/` does, giving the texel
/// coordinate itself. (A scale of 0 divided by zero; found by terrain-lod's fuzz target.)
pub fn coarse_height(texel: IVec2, scale: u32, height: impl Fn(IVec2) -> f32) -> f32 {
    let s = scale as i32;
    let grid = |t: i32| t.checked_div_euclid(s).unwrap_or(t);
    let odd = IVec2::new(grid(texel.x) & 1, grid(texel.y) & 1);
    // `odd` is 0 or 1 per axis, so the step is 0 or the scale: no overflow.
    let step = odd * s;
    let (x, z) = (texel.x, texel.y);
    let at = |x: i32, z: i32| height(IVec2::new(x, z));
    let (x_lo, x_hi) = (x.wrapping_sub(step.x), x.wrapping_add(step.x));
    let (z_lo, z_hi) = (z.wrapping_sub(step.y), z.wrapping_add(step.y));
    match (odd.x, odd.y) {
        (0, 0) => height(texel),
        (1, 1) => 0.25 * (at(x_lo, z_lo) + at(x_hi, z_hi) + at(x_hi, z_lo) + at(x_lo, z_hi)),
        _ => 0.5 * (at(x_lo, z_lo) + at(x_hi, z_hi)),
    }
}

/// What the morph needs to know of a vertex's level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MorphLevel {
    /// Texels per grid step of the level (`2^level`).
    pub scale: u32,
    /// Clipmap N (vertices per side).
    pub n: u32,
    /// Transition width in level grid units ([`default_morph_width`]).
    pub width: f32,
    /// Whether this is the coarsest level (which has no coarser level and is not morphed).
    pub coarsest: bool,
}

/// The morphed height: `height(texel)` blended towards [`coarse_height`] by [`morph_alpha`]
/// (the coarsest level is not morphed).
pub fn morphed_height(
    texel: IVec2,
    camera_texel: Vec2,
    level: &MorphLevel,
    height: impl Fn(IVec2) -> f32,
) -> f32 {
    let h = height(texel);
    if level.coarsest {
        return h;
    }
    let alpha = morph_alpha(texel, camera_texel, level.scale, level.n, level.width);
    if alpha <= 0.0 {
        return h;
    }
    h + (coarse_height(texel, level.scale, &height) - h) * alpha
}
