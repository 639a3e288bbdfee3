//! Stamps (Flower 2010, sec. 2.4.1, 3.2.1, 3.4): a pattern placed on a map by centre, rotation,
//! scale and intensity, blended into the region it covers. Texture stamps come from grayscale
//! images, the Gaussian is procedural, the shockwave ([`crate::shockwave`]) is a dynamic
//! texture, and users add their own procedural stamps by implementing [`Stamp`].
//!
//! On a repeating (toroidal) map a footprint across an edge or corner is cut into 2 or 4 rects
//! that each land where they wrap to; on a clamped map the part off the map is dropped.
//!
//! Every stamp is evaluated by one exact integer program ([`fixed`]), which the GPU pass runs
//! too: CPU and GPU heights are bit-identical for every stamp kind and blend (the user's
//! procedural stamps included when their CPU and WGSL functions agree bit for bit).
//!
//! This module holds the stamp API and the per-texel reference; `kernels` runs the program
//! row-parallel for [`apply_stamp`], `frame` finds each row's span of the footprint.

use crate::error::CoreError;
use crate::grid::{Grid, WrapMode};
use crate::map::{HeightMap, HeightSample};
use crate::rect::{DirtyRect, Rect, WrappedPiece};
use crate::sample::bilinear_taps;
use glam::{IVec2, UVec2, Vec2};

pub mod fixed;
mod frame;
mod kernels;

use fixed::{FixedBlend, FixedFrame};
use kernels::apply_prepared;

/// Where and how strongly a stamp is applied.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StampPlacement {
    /// Centre in world metres `(X, Z)`.
    pub center: Vec2,
    /// Footprint size in metres along the stamp's own axes (Flower 2010's "scale"); positive.
    pub scale: Vec2,
    /// Rotation in radians: the stamp's local +X axis turns towards +Z.
    pub rotation: f32,
    /// Metres added where the stamp's value is 1 (negative presses down).
    pub intensity: f32,
}

impl StampPlacement {
    /// An unrotated placement; fails on NaN, infinite or non-positive values.
    pub fn new(center: Vec2, scale: Vec2, intensity: f32) -> Result<Self, CoreError> {
        let p = Self {
            center,
            scale,
            rotation: 0.0,
            intensity,
        };
        p.validate()?;
        Ok(p)
    }

    /// The same placement rotated by `radians`.
    pub fn with_rotation(self, radians: f32) -> Result<Self, CoreError> {
        let p = Self {
            rotation: radians,
            ..self
        };
        p.validate()?;
        Ok(p)
    }

    /// Checks every field: all finite, scale positive.
    pub fn validate(&self) -> Result<(), CoreError> {
        let fields = [
            ("stamp centre x", self.center.x),
            ("stamp centre z", self.center.y),
            ("stamp scale x", self.scale.x),
            ("stamp scale z", self.scale.y),
            ("stamp rotation", self.rotation),
            ("stamp intensity", self.intensity),
        ];
        for (what, value) in fields {
            if !value.is_finite() {
                return Err(CoreError::NonFinite { what, value });
            }
        }
        if self.scale.min_element() <= 0.0 {
            return Err(CoreError::OutOfRange {
                what: "stamp scale",
                value: f64::from(self.scale.min_element()),
                expected: "greater than 0 metres on both axes",
            });
        }
        Ok(())
    }

    /// The stamp's local frame in texel units for a map of `texel_size` metres per texel:
    /// `(centre, 1 / half-size, sin, cos)`. A texel at unwrapped coordinates `u` has
    /// `d = u - centre` and local coordinates `(d.x cos + d.y sin, d.y cos - d.x sin) * inv_half`;
    /// stamps are evaluated from these values rounded once to integers ([`fixed_program`],
    /// computed in f64), the same integers on the CPU and the GPU.
    pub fn local_frame(&self, texel_size: f32) -> (Vec2, Vec2, f32, f32) {
        let center = self.center / texel_size;
        let inv_half = Vec2::ONE / (self.scale * 0.5 / texel_size);
        let (sin, cos) = self.rotation.sin_cos();
        (center, inv_half, sin, cos)
    }

    /// The texels whose centres the rotated footprint can cover, on a map with `texel_size`
    /// metres per texel, in unwrapped texel coordinates (not clipped to any map).
    pub fn footprint(&self, texel_size: f32) -> Result<Rect, CoreError> {
        self.validate()?;
        crate::map::check_texel_size(texel_size)?;
        // libm's `sincos`, as `fixed_program`'s: the footprint's first texel anchors the exact
        // program's frame, so it must be the same on every platform.
        let (s, c) = libm::sincos(f64::from(self.rotation));
        let h = self.scale.as_dvec2() * 0.5;
        let half = glam::DVec2::new(c.abs() * h.x + s.abs() * h.y, s.abs() * h.x + c.abs() * h.y);
        let ts = f64::from(texel_size);
        let center = self.center.as_dvec2() / ts;
        // Clamp before casting so absurd placements stay representable; callers clip to maps.
        let lim = f64::from(i32::MAX / 4);
        let lo =
            ((center - half / ts).ceil()).clamp(glam::DVec2::splat(-lim), glam::DVec2::splat(lim));
        let hi = ((center + half / ts).floor() + 1.0)
            .clamp(glam::DVec2::splat(-lim), glam::DVec2::splat(lim));
        Ok(Rect::from_min_max(lo.as_ivec2(), hi.as_ivec2()))
    }
}

/// How a stamp's heights combine with the map's.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Blend {
    /// Clamped additive blend (Flower 2010, sec. 3.2.1): `h + intensity * value`, clamped to what
    /// the encoding can store.
    #[default]
    Add,
    /// Lowers the map to the stamp's surface `base_m + intensity * value` where it is higher
    /// (a mould pressed in).
    Min {
        /// Height in metres of the stamp's zero level.
        base_m: f32,
    },
    /// Raises the map to the stamp's surface `base_m + intensity * value` where it is lower.
    Max {
        /// Height in metres of the stamp's zero level.
        base_m: f32,
    },
}

/// A pattern that can be stamped: a texture, a procedural function, a dynamic texture.
///
/// Implement it for a user-defined procedural stamp. `value` is called for every texel of the
/// footprint with `local` in `[-1, 1]^2` (the footprint's corners at ±1, after rotation), and
/// its result is multiplied by the placement's intensity. A NaN or infinite value leaves that
/// texel unchanged.
pub trait Stamp {
    /// Per-placement setup before sampling (Flower 2010, sec. 3.4.2's "pre-deform callback"), e.g.
    /// the Gaussian's falloff from the footprint size and intensity.
    fn prepare(&mut self, placement: &StampPlacement) -> Result<(), CoreError> {
        let _ = placement;
        Ok(())
    }

    /// The stamp's value at `local` in `[-1, 1]^2`.
    fn value(&self, local: Vec2) -> f32;

    /// A closed form [`apply_stamp`] may evaluate instead of calling [`Stamp::value`] per
    /// texel (after [`Stamp::prepare`]). The default, [`StampKernel::PerTexel`], is always
    /// right; return another kernel only if it describes `value` exactly.
    fn kernel(&self) -> StampKernel<'_> {
        StampKernel::PerTexel
    }
}

/// How [`apply_stamp`] evaluates a stamp (see [`Stamp::kernel`]).
#[derive(Debug, Clone, Copy)]
#[non_exhaustive]
pub enum StampKernel<'a> {
    /// `value(local) = exp(-beta |local|^2)`: evaluated by the exact program ([`fixed`]), from
    /// tables, without an `exp` per texel.
    Gaussian {
        /// The falloff in units of the normalised radius.
        beta: f32,
    },
    /// Bilinear, clamped sampling of these values with pixel centres at `(i + 0.5) / n` of
    /// the footprint, as [`TextureStamp`] samples: evaluated by the exact program ([`fixed`]:
    /// values quantised to Q24, weights to Q12), row-parallel.
    Texture(&'a Grid<f32>),
    /// As [`StampKernel::Texture`], with the values already quantised (a stamp applied often
    /// keeps them, as [`TextureStamp`] does, instead of quantising them per placement).
    Quantized(&'a fixed::QuantizedTexture),
    /// [`Stamp::value`] for every texel, on the calling thread.
    PerTexel,
}

/// A stamp from a grayscale image (Flower 2010, sec. 3.4.1), sampled bilinearly.
///
/// Which end is an impression: values run from 0 (black) to 1 (white) and are multiplied by
/// the intensity, so white is the full effect and black none. A footprint image is white where
/// the foot presses hardest and is applied with a negative intensity.
#[derive(Clone)]
pub struct TextureStamp {
    values: Grid<f32>,
    /// The values quantised for the exact program, made by the first placement.
    quantized: std::sync::OnceLock<fixed::QuantizedTexture>,
}

impl PartialEq for TextureStamp {
    fn eq(&self, other: &Self) -> bool {
        self.values == other.values
    }
}

impl std::fmt::Debug for TextureStamp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TextureStamp")
            .field("values", &self.values)
            .finish_non_exhaustive()
    }
}

impl TextureStamp {
    /// From an 8-bit image: value = pixel / 255.
    pub fn from_gray8(image: &Grid<u8>) -> Self {
        Self::new(image.map(|&v| f32::from(v) / 255.0))
    }

    /// From a 16-bit image: value = pixel / 65535.
    pub fn from_gray16(image: &Grid<u16>) -> Self {
        Self::new(image.map(|&v| f32::from(v) / 65535.0))
    }

    /// From any finite values (a dynamic texture such as the shockwave's displacement).
    pub fn from_values(values: Grid<f32>) -> Result<Self, CoreError> {
        if let Some(&bad) = values.as_slice().iter().find(|v| !v.is_finite()) {
            return Err(CoreError::NonFinite {
                what: "texture stamp value",
                value: bad,
            });
        }
        Ok(Self::new(values))
    }

    fn new(values: Grid<f32>) -> Self {
        Self {
            values,
            quantized: std::sync::OnceLock::new(),
        }
    }

    /// The stamp's values.
    pub fn values(&self) -> &Grid<f32> {
        &self.values
    }
}

impl Stamp for TextureStamp {
    fn kernel(&self) -> StampKernel<'_> {
        StampKernel::Quantized(
            self.quantized
                .get_or_init(|| fixed::QuantizedTexture::new(&self.values)),
        )
    }

    fn value(&self, local: Vec2) -> f32 {
        // Pixel i covers [i, i + 1) of the image; its centre i + 0.5 maps to local
        // (i + 0.5) / n * 2 - 1, so the image fills the footprint edge to edge.
        let size = self.values.size().as_vec2();
        let p = (local + 1.0) * 0.5 * size - 0.5;
        let (taps, [fx, fz]) = bilinear_taps(p);
        let v = taps.map(|t| self.values.get_wrapped(t, WrapMode::Clamp));
        let (fx, fz) = (fx as f32, fz as f32);
        let top = v[0] + (v[1] - v[0]) * fx;
        let bot = v[2] + (v[3] - v[2]) * fx;
        top + (bot - top) * fz
    }
}

/// The Gaussian procedural stamp of Flower 2010, eq. 3.5, `alpha exp(-beta r^2)`, with `r = 1` at
/// the middle of each footprint edge and `alpha` the placement's intensity.
///
/// The falloff is chosen per placement so the value at the edge is `epsilon_m` metres (the
/// derivation after eq. 3.5): `beta = ln(|alpha| / epsilon)`. When `|alpha|` is not above
/// `e * epsilon` the stamp is nearly flat anyway and `beta` is held at 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GaussianStamp {
    epsilon_m: f32,
    beta: f32,
}

/// Height in metres of the Gaussian stamp at its footprint edge by default.
pub const DEFAULT_GAUSSIAN_EPSILON_M: f32 = 1e-3;

impl Default for GaussianStamp {
    fn default() -> Self {
        Self {
            epsilon_m: DEFAULT_GAUSSIAN_EPSILON_M,
            beta: 1.0,
        }
    }
}

impl GaussianStamp {
    /// A Gaussian whose edge height is `epsilon_m` metres (finite, positive).
    pub fn new(epsilon_m: f32) -> Result<Self, CoreError> {
        if !epsilon_m.is_finite() || epsilon_m <= 0.0 {
            return Err(CoreError::OutOfRange {
                what: "Gaussian edge epsilon (m)",
                value: f64::from(epsilon_m),
                expected: "finite and greater than 0",
            });
        }
        Ok(Self {
            epsilon_m,
            beta: 1.0,
        })
    }

    /// The edge height in metres.
    pub fn epsilon_m(&self) -> f32 {
        self.epsilon_m
    }

    /// The falloff for a given intensity, in units of the normalised radius: the f64 `log` of
    /// the pure-Rust `libm` crate rounded to f32, the same bits on every platform (the exact
    /// program's `beta_q` comes from it).
    pub fn beta_for(&self, intensity: f32) -> f32 {
        let ratio = (intensity.abs() / self.epsilon_m).max(std::f32::consts::E);
        libm::log(f64::from(ratio)) as f32
    }

    /// The falloff set by the last [`Stamp::prepare`].
    pub fn beta(&self) -> f32 {
        self.beta
    }

    /// The exact volume in cubic metres the stamp adds with `placement` (ignoring the map's
    /// quantisation and clamping): `alpha hx hz (sqrt(pi / beta) erf(sqrt(beta)))^2` for an
    /// unrotated footprint of half-sizes `hx`, `hz` (rotation does not change it).
    pub fn volume(&self, placement: &StampPlacement) -> f64 {
        let beta = f64::from(self.beta_for(placement.intensity));
        let h = placement.scale.as_dvec2() * 0.5;
        let one_axis = (std::f64::consts::PI / beta).sqrt() * erf(beta.sqrt());
        f64::from(placement.intensity) * h.x * h.y * one_axis * one_axis
    }
}

impl Stamp for GaussianStamp {
    fn prepare(&mut self, placement: &StampPlacement) -> Result<(), CoreError> {
        self.beta = self.beta_for(placement.intensity);
        Ok(())
    }

    fn value(&self, local: Vec2) -> f32 {
        (-self.beta * local.length_squared()).exp()
    }

    fn kernel(&self) -> StampKernel<'_> {
        StampKernel::Gaussian { beta: self.beta }
    }
}

/// The error function (Abramowitz & Stegun 7.1.26; absolute error below 1.5e-7).
fn erf(x: f64) -> f64 {
    let t = 1.0 / (1.0 + 0.327_591_1 * x.abs());
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    let y = 1.0 - poly * (-x * x).exp();
    y.copysign(x)
}

/// Where a stamp lands on a map.
#[derive(Debug, Clone, PartialEq)]
pub struct StampRegion {
    /// The texels to visit in unwrapped coordinates: the whole footprint on a repeating map,
    /// the footprint clipped to the map on a clamped one.
    pub footprint: Rect,
    /// The same texels cut into pieces inside the map (1, 2 or 4 on a repeating map).
    pub pieces: Vec<WrappedPiece>,
}

/// The region a stamp at `placement` covers on a map of `map_size` texels with `wrap`, or
/// `None` when it misses a clamped map entirely.
///
/// Fails on an invalid placement or texel size, and on a footprint larger than a repeating
/// map (it would overlap itself).
pub fn stamp_region(
    map_size: UVec2,
    wrap: WrapMode,
    texel_size: f32,
    placement: &StampPlacement,
) -> Result<Option<StampRegion>, CoreError> {
    let footprint = placement.footprint(texel_size)?;
    let region = match wrap {
        WrapMode::Repeat => {
            if footprint.size.cmpgt(map_size).any() {
                return Err(CoreError::OutOfRange {
                    what: "stamp footprint (texels)",
                    value: f64::from(footprint.size.max_element()),
                    expected: "no larger than the repeating map it is applied to",
                });
            }
            StampRegion {
                footprint,
                pieces: footprint.split_toroidal(map_size),
            }
        }
        WrapMode::Clamp => match footprint.intersect(&Rect::from_size(map_size)) {
            Some(r) => StampRegion {
                footprint: r,
                pieces: vec![WrappedPiece {
                    map: r,
                    unwrapped: r,
                }],
            },
            None => return Ok(None),
        },
    };
    Ok((!region.pieces.is_empty()).then_some(region))
}

/// Applies `stamp` to `map` at `placement` with `blend`, and returns the rects it covered in
/// map coordinates: one for a footprint inside the map, 2 or 4 across a repeating map's edge
/// or corner, none for a footprint wholly off a clamped map.
///
/// Every texel gets the exact integer program of [`fixed`], which terrain-gpu's stamp pass runs
/// too: the result equals the GPU's and [`apply_stamp_reference`]'s bit for bit, for every
/// thread count. Texture and Gaussian stamps ([`Stamp::kernel`]) run row-parallel; other
/// stamps call [`Stamp::value`] per texel, on one thread, and their f32 value is converted
/// exactly ([`fixed::user_v31`]).
///
/// Fails on an invalid placement, an error from the stamp's `prepare`, a non-finite blend
/// base, or a footprint larger than a repeating map (it would overlap itself).
pub fn apply_stamp<T: HeightSample, S: Stamp + ?Sized>(
    map: &mut HeightMap<T>,
    stamp: &mut S,
    placement: &StampPlacement,
    blend: Blend,
) -> Result<Vec<DirtyRect>, CoreError> {
    #[cfg(feature = "cpu-work")]
    crate::cpu_work::count(|w| w.stamps += 1);
    let prepared = prepare_stamp(map, stamp, placement, blend, None)?;
    apply_prepared(map, stamp, prepared)
}

/// Applies `stamp` to `map` as the window of a larger, clamped map whose texel `origin` is the
/// window's texel `(0, 0)`: texel `(x, y)` of `map` gets exactly what texel
/// `origin + (x, y)` of the larger map would get from [`apply_stamp`] with the same
/// `placement` (in the larger map's metres), whenever the window holds the stamp's whole
/// footprint (then the evaluation is the same one, texel for texel). A window cut through a
/// footprint gets the same too (the program's frame is anchored at the whole footprint's
/// first texel, not the window's). `map`'s own wrap mode is ignored. Returns
/// the covered rect in `map`'s coordinates, if any.
///
/// This is how a stamp lands on tiles of a larger grid (the detail layer gathers the
/// footprint into one window, stamps it, and scatters it back).
pub fn apply_stamp_window<T: HeightSample, S: Stamp + ?Sized>(
    map: &mut HeightMap<T>,
    origin: IVec2,
    stamp: &mut S,
    placement: &StampPlacement,
    blend: Blend,
) -> Result<Option<DirtyRect>, CoreError> {
    #[cfg(feature = "cpu-work")]
    crate::cpu_work::count(|w| w.stamps += 1);
    let prepared = prepare_stamp(map, stamp, placement, blend, Some(origin))?;
    Ok(apply_prepared(map, stamp, prepared)?.into_iter().next())
}

/// A placement ready to apply: the pieces (map rect, offset to unwrapped coordinates), the
/// local frame and the blend.
type Prepared = (Vec<(Rect, IVec2)>, FixedFrame, FixedBlend);

/// The integers of the exact stamp program ([`fixed`]) for `placement` on a map of `texel_size`
/// metres per texel and encoding `enc`, with `blend`: what [`apply_stamp`] evaluates and what
/// the GPU pass uploads. The frame's anchor is the placement's whole footprint's first texel,
/// so a texel's arithmetic is the same in every piece, window and tile.
///
/// Fails on an invalid placement or texel size, or a non-finite blend base.
pub fn fixed_program(
    placement: &StampPlacement,
    texel_size: f32,
    enc: crate::map::HeightEncoding,
    blend: Blend,
) -> Result<(FixedFrame, FixedBlend), CoreError> {
    check_blend(blend)?;
    let footprint = placement.footprint(texel_size)?;
    let ts = f64::from(texel_size);
    let center = placement.center.as_dvec2() / ts;
    let inv_half = glam::DVec2::ONE / (placement.scale.as_dvec2() * 0.5 / ts);
    // The pure-Rust libm, not the platform's: the frame's integers are the same everywhere.
    let (sin, cos) = libm::sincos(f64::from(placement.rotation));
    let frame = FixedFrame::new(footprint.min, footprint.size, center, inv_half, sin, cos);
    let add_scale = f64::from(placement.intensity) / f64::from(enc.scale);
    let op = match blend {
        Blend::Add => FixedBlend::new(0, add_scale, 0.0),
        // In stored units: base + value * units.
        Blend::Min { base_m } => FixedBlend::new(1, add_scale, enc.to_raw(base_m)),
        Blend::Max { base_m } => FixedBlend::new(2, add_scale, enc.to_raw(base_m)),
    };
    Ok((frame, op))
}

/// The relative rounding error of a per-texel f32 Gaussian `exp(-beta |local|^2)` (as
/// [`GaussianStamp::value`] computes it), before rounding to stored units. [`apply_stamp`] no
/// longer evaluates it (it runs the exact program of [`fixed`], whose own error against the
/// exact Gaussian is below 2^-26 relative); kept as the bound of f32 evaluations.
///
/// The bound is the reference's own f32 error, with a factor 2 of margin: local coordinates
/// rounded in 3 operations each, whose cancellation grows with the footprint's aspect ratio
/// `k = max(sx / sz, sz / sx)` (`|d local| <= 3 eps (1 + k)`), the squared radius
/// (`|d r^2| <= 4 |d local| + 2 eps r^2`, `r^2 <= 2`), `beta` times it and `exp` (2 eps):
/// `2 eps (beta (12 (1 + k) + 6) + 2)`; plus 4 eps for the u8 and u16 path, which multiplies
/// and rounds in f32 (min and max blends add the base's fraction in f32 too, a further
/// `2^-22` stored units at most, which the bound does not scale).
pub fn gaussian_rounding_bound(beta: f32, placement: &StampPlacement) -> f64 {
    let eps = f64::from(f32::EPSILON) * 0.5;
    let s = placement.scale.as_dvec2().abs();
    let k = (s.x / s.y).max(s.y / s.x);
    let k = if k.is_finite() { k } else { f64::MAX };
    2.0 * eps * (f64::from(beta.abs()) * (12.0 * (1.0 + k) + 6.0) + 2.0) + 4.0 * eps
}

/// Refuses a min / max blend whose base is not finite.
pub(crate) fn check_blend(blend: Blend) -> Result<(), CoreError> {
    match blend {
        Blend::Min { base_m } | Blend::Max { base_m } if !base_m.is_finite() => {
            Err(CoreError::NonFinite {
                what: "blend base height",
                value: base_m,
            })
        }
        _ => Ok(()),
    }
}

/// Per-placement state shared by every path of [`apply_stamp`] and [`apply_stamp_reference`]:
/// validates, cuts the footprint into pieces and prepares the stamp. With `window`, the map is
/// the window at that origin of a larger clamped map: one piece, the footprint clipped to it.
fn prepare_stamp<T: HeightSample, S: Stamp + ?Sized>(
    map: &HeightMap<T>,
    stamp: &mut S,
    placement: &StampPlacement,
    blend: Blend,
    window: Option<IVec2>,
) -> Result<Option<Prepared>, CoreError> {
    let ts = map.texel_size();
    check_blend(blend)?;
    // (map rect, offset from map to unwrapped coordinates) for every piece.
    let pieces: Vec<(Rect, IVec2)> = match window {
        Some(origin) => {
            let footprint = placement.footprint(ts)?;
            let Some(inside) = footprint.intersect(&Rect::new(origin, map.size())) else {
                return Ok(None);
            };
            vec![(Rect::new(inside.min - origin, inside.size), origin)]
        }
        None => {
            let Some(region) = stamp_region(map.size(), map.wrap(), ts, placement)? else {
                return Ok(None);
            };
            region
                .pieces
                .iter()
                .map(|p| (p.map, p.unwrapped.min - p.map.min))
                .collect()
        }
    };
    stamp.prepare(placement)?;
    let (frame, op) = fixed_program(placement, ts, map.encoding(), blend)?;
    Ok(Some((pieces, frame, op)))
}

/// The per-texel evaluation of the exact program ([`fixed`]): every texel of the footprint's
/// pieces in turn, on one thread, without the row spans or threads of [`apply_stamp`]; the
/// reference [`apply_stamp`] is tested and benchmarked against (they are equal bit for bit).
///
/// Fails as [`apply_stamp`] does.
pub fn apply_stamp_reference<T: HeightSample, S: Stamp + ?Sized>(
    map: &mut HeightMap<T>,
    stamp: &mut S,
    placement: &StampPlacement,
    blend: Blend,
) -> Result<Vec<DirtyRect>, CoreError> {
    let Some((pieces, frame, op)) = prepare_stamp(map, stamp, placement, blend, None)? else {
        return Ok(Vec::new());
    };
    let kernel = kernels::Kernel::of(stamp, &frame);
    let grid = map.grid_mut();
    for &(rect, offset) in &pieces {
        for y in rect.min.y..rect.max().y {
            let row = grid.row_mut(y as u32);
            for x in rect.min.x..rect.max().x {
                let l = frame.local_q(x + offset.x, y + offset.y);
                let d = &mut row[x as usize];
                *d = kernels::texel(&kernel, &*stamp, &op, l, *d);
            }
        }
    }
    Ok(pieces.into_iter().map(|(r, _)| r).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::{CoarseMap, HeightEncoding};

    /// FNV-1a (64-bit) of the Gaussian tables' little-endian bytes, computed once.
    const TABLES_FNV1A: u64 = 2_089_011_250_706_007_205;

    fn flat(size: u32, raw: u16, ts: f32) -> CoarseMap {
        let g = Grid::new(size, size, raw).unwrap();
        CoarseMap::coarse(g, HeightEncoding::new(0.01, 0.0).unwrap(), ts).unwrap()
    }

    #[test]
    fn placement_rejects_bad_values() {
        assert!(StampPlacement::new(Vec2::new(f32::NAN, 0.0), Vec2::ONE, 1.0).is_err());
        assert!(StampPlacement::new(Vec2::ZERO, Vec2::new(0.0, 1.0), 1.0).is_err());
        assert!(StampPlacement::new(Vec2::ZERO, Vec2::ONE, f32::INFINITY).is_err());
        let p = StampPlacement::new(Vec2::ZERO, Vec2::ONE, 1.0).unwrap();
        assert!(p.with_rotation(f32::NAN).is_err());
        assert!(GaussianStamp::new(0.0).is_err());
    }

    #[test]
    fn clamps_at_the_encoding_limits() {
        let mut m = flat(16, 65_000, 1.0);
        let p = StampPlacement::new(Vec2::splat(8.0), Vec2::splat(8.0), 100.0).unwrap();
        let mut box_stamp = TextureStamp::from_gray8(&Grid::new(2, 2, 255).unwrap());
        apply_stamp(&mut m, &mut box_stamp, &p, Blend::Add).unwrap();
        assert_eq!(m.grid().get(8, 8), Some(u16::MAX));
        assert_eq!(m.grid().get(0, 0), Some(65_000));
        let mut m = flat(16, 300, 1.0);
        let p = StampPlacement::new(Vec2::splat(8.0), Vec2::splat(8.0), -100.0).unwrap();
        apply_stamp(&mut m, &mut box_stamp, &p, Blend::Add).unwrap();
        assert_eq!(m.grid().get(8, 8), Some(0));
    }

    #[test]
    fn min_and_max_blends_mould_the_surface() {
        let mut m = flat(16, 500, 1.0); // 5 m
        let mut box_stamp = TextureStamp::from_gray8(&Grid::new(2, 2, 255).unwrap());
        let p = StampPlacement::new(Vec2::splat(8.0), Vec2::splat(4.0), 1.0).unwrap();
        apply_stamp(&mut m, &mut box_stamp, &p, Blend::Min { base_m: 2.0 }).unwrap();
        assert_eq!(m.grid().get(8, 8), Some(300));
        apply_stamp(&mut m, &mut box_stamp, &p, Blend::Max { base_m: 6.0 }).unwrap();
        assert_eq!(m.grid().get(8, 8), Some(700));
        assert_eq!(m.grid().get(1, 1), Some(500));
        assert!(apply_stamp(&mut m, &mut box_stamp, &p, Blend::Max { base_m: f32::NAN }).is_err());
    }

    #[test]
    fn off_a_clamped_map_is_a_no_op_and_oversized_on_a_repeating_map_is_an_error() {
        let g = Grid::new(16, 16, 100u16).unwrap();
        let e = HeightEncoding::new(0.01, 0.0).unwrap();
        let mut m = HeightMap::new(g, e, 1.0, WrapMode::Clamp).unwrap();
        let before = m.clone();
        let p = StampPlacement::new(Vec2::new(-50.0, 8.0), Vec2::splat(4.0), 1.0).unwrap();
        let dirty = apply_stamp(&mut m, &mut GaussianStamp::default(), &p, Blend::Add).unwrap();
        assert!(dirty.is_empty());
        assert_eq!(m, before);
        let mut r = flat(16, 100, 1.0);
        let huge = StampPlacement::new(Vec2::ZERO, Vec2::splat(40.0), 1.0).unwrap();
        assert!(apply_stamp(&mut r, &mut GaussianStamp::default(), &huge, Blend::Add).is_err());
        let absurd = StampPlacement::new(Vec2::splat(1e30), Vec2::splat(1e30), 1.0).unwrap();
        assert!(apply_stamp(&mut m, &mut GaussianStamp::default(), &absurd, Blend::Add).is_ok());
    }

    #[test]
    fn gaussian_edge_value_is_epsilon() {
        let mut g = GaussianStamp::new(0.01).unwrap();
        let p = StampPlacement::new(Vec2::ZERO, Vec2::splat(10.0), 2.0).unwrap();
        g.prepare(&p).unwrap();
        let edge = p.intensity * g.value(Vec2::new(1.0, 0.0));
        assert!((edge - 0.01).abs() < 1e-5, "edge height {edge}");
        assert!((erf(1.0) - 0.842_700_79).abs() < 2e-7);
    }

    /// The integers the exact program is built from are pinned to values computed once: the
    /// tables (libm's `exp`), a rotated frame (libm's `sincos`), the falloff (libm's `log`)
    /// and the blend's mantissa (an exact exponent). A platform whose own functions differ
    /// gives these same integers; a change of libm or of the arithmetic fails here.
    #[test]
    fn program_integers_are_the_same_on_every_platform() {
        let t = fixed::gaussian_tables();
        let pins = [
            (0, 1u32 << 31),
            (1, 2_114_190_000),
            (100, 450_137_026),
            (777, 11_464),
            (1407, 1),
            (1409, 2_147_450_880),
            (1963, 2_129_374_197),
            (2431, 2_114_222_260),
            (2433, 2_147_483_616),
            (3455, 2_147_450_912),
        ];
        for (k, want) in pins {
            assert_eq!(t[k], want, "table entry {k}");
        }
        // FNV-1a over every entry.
        let hash = t.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &v| {
            v.to_le_bytes()
                .iter()
                .fold(h, |h, &b| (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3))
        });
        assert_eq!(hash, TABLES_FNV1A, "the tables changed");
        let p = StampPlacement::new(Vec2::new(123.37, 45.81), Vec2::new(17.3, 9.1), -1.7)
            .unwrap()
            .with_rotation(0.7)
            .unwrap();
        let enc = HeightEncoding::new(0.01, -20.0).unwrap();
        let (f, b) = fixed_program(&p, 0.25, enc, Blend::Max { base_m: 3.3 }).unwrap();
        assert_eq!(f.anchor, IVec2::new(456, 148));
        assert_eq!(f.l0, [-6_376_478_589, -662_594_842]);
        assert_eq!(f.lx, [94_941_398, -152_027_129]);
        assert_eq!(f.ly, [79_968_034, 180_492_971]);
        assert!(f.monotone);
        assert_eq!(
            (b.kind, b.m, b.shift, b.base_q16),
            (2, -11_141_121, 31, 152_698_883)
        );
        let g = GaussianStamp::default();
        for (intensity, bits, beta_q) in [
            (-1.7f32, 1_089_341_245u32, 62_397_684u32),
            (0.05, 1_081_761_430, 32_816_428),
            (3.0, 1_090_525_717, 67_162_280),
            (250.0, 1_095_163_410, 104_263_824),
        ] {
            let beta = g.beta_for(intensity);
            assert_eq!(beta.to_bits(), bits, "beta for {intensity}");
            assert_eq!(
                fixed::gaussian_beta_q(beta),
                beta_q,
                "beta_q for {intensity}"
            );
        }
    }

    #[test]
    fn rotation_moves_an_asymmetric_stamp() {
        // A bar along local X: rotated by 90 degrees it lies along Z.
        let bar = Grid::from_fn(8, 8, |_, y| if (3..5).contains(&y) { 255u8 } else { 0 }).unwrap();
        let mut s = TextureStamp::from_gray8(&bar);
        let mut m = flat(32, 0, 1.0);
        let p = StampPlacement::new(Vec2::splat(16.0), Vec2::splat(16.0), 1.0)
            .unwrap()
            .with_rotation(std::f32::consts::FRAC_PI_2)
            .unwrap();
        apply_stamp(&mut m, &mut s, &p, Blend::Add).unwrap();
        assert!(m.grid().get(16, 10).unwrap() > 50);
        assert_eq!(m.grid().get(10, 16), Some(0));
    }
}
