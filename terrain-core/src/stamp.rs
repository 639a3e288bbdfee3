//! Stamps (seed 000 sec 2.4.1, 3.2.1, 3.4): a pattern placed on a map by centre, rotation,
//! scale and intensity, blended into the region it covers. Texture stamps come from grayscale
//! images, the Gaussian is procedural, the shockwave ([`crate::shockwave`]) is a dynamic
//! texture, and users add their own procedural stamps by implementing [`Stamp`].
//!
//! On a repeating (toroidal) map a footprint across an edge or corner is cut into 2 or 4 rects
//! that each land where they wrap to; on a clamped map the part off the map is dropped.

use crate::error::CoreError;
use crate::grid::{Grid, WrapMode};
use crate::map::{HeightMap, HeightSample};
use crate::rect::{DirtyRect, Rect, WrappedPiece};
use crate::sample::bilinear_taps;
use glam::{IVec2, UVec2, Vec2};

/// Where and how strongly a stamp is applied.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StampPlacement {
    /// Centre in world metres `(X, Z)`.
    pub center: Vec2,
    /// Footprint size in metres along the stamp's own axes (seed 000's "scale"); positive.
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
    /// the GPU pass receives exactly these values, so both compute the same coordinates.
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
        let (s, c) = f64::from(self.rotation).sin_cos();
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
    /// Clamped additive blend (seed 000 sec 3.2.1): `h + intensity * value`, clamped to what
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
    /// Per-placement setup before sampling (seed 000 sec 3.4.2's "pre-deform callback"), e.g.
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
    /// `value(local) = exp(-beta |local|^2)`: evaluated separably in map coordinates, without
    /// an `exp` per texel.
    Gaussian {
        /// The falloff in units of the normalised radius.
        beta: f32,
    },
    /// Bilinear, clamped sampling of these values with pixel centres at `(i + 0.5) / n` of
    /// the footprint, as [`TextureStamp`] samples: evaluated inline and row-parallel.
    Texture(&'a Grid<f32>),
    /// [`Stamp::value`] for every texel, on the calling thread.
    PerTexel,
}

/// A stamp from a grayscale image (seed 000 sec 3.4.1), sampled bilinearly.
///
/// Which end is an impression: values run from 0 (black) to 1 (white) and are multiplied by
/// the intensity, so white is the full effect and black none. A footprint image is white where
/// the foot presses hardest and is applied with a negative intensity.
#[derive(Debug, Clone, PartialEq)]
pub struct TextureStamp {
    values: Grid<f32>,
}

impl TextureStamp {
    /// From an 8-bit image: value = pixel / 255.
    pub fn from_gray8(image: &Grid<u8>) -> Self {
        Self {
            values: image.map(|&v| f32::from(v) / 255.0),
        }
    }

    /// From a 16-bit image: value = pixel / 65535.
    pub fn from_gray16(image: &Grid<u16>) -> Self {
        Self {
            values: image.map(|&v| f32::from(v) / 65535.0),
        }
    }

    /// From any finite values (a dynamic texture such as the shockwave's displacement).
    pub fn from_values(values: Grid<f32>) -> Result<Self, CoreError> {
        if let Some(&bad) = values.as_slice().iter().find(|v| !v.is_finite()) {
            return Err(CoreError::NonFinite {
                what: "texture stamp value",
                value: bad,
            });
        }
        Ok(Self { values })
    }

    /// The stamp's values.
    pub fn values(&self) -> &Grid<f32> {
        &self.values
    }
}

impl Stamp for TextureStamp {
    fn kernel(&self) -> StampKernel<'_> {
        StampKernel::Texture(&self.values)
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

/// The Gaussian procedural stamp of seed 000 eq. 3.5, `alpha exp(-beta r^2)`, with `r = 1` at
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

    /// The falloff for a given intensity, in units of the normalised radius.
    pub fn beta_for(&self, intensity: f32) -> f32 {
        (intensity.abs() / self.epsilon_m)
            .max(std::f32::consts::E)
            .ln()
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
/// How values are evaluated depends on [`Stamp::kernel`]. A texture stamp is sampled exactly
/// as [`TextureStamp::value`] does, inline and row-parallel: the result equals
/// [`apply_stamp_reference`] (the per-texel evaluation) bit for bit. A Gaussian is evaluated
/// separably in map coordinates, `exp(-beta (A dx^2 + 2 B dx dy + C dy^2))` as a product of a
/// column table, a row factor and (for a rotated, non-square footprint) a cross factor built
/// incrementally per row, all in f64: no `exp` per texel. It differs from the per-texel f32
/// evaluation by at most 1 stored unit, only where the exact value lies within
/// [`gaussian_rounding_bound`] of a rounding boundary (the reference's own f32 error is of
/// that size). Other stamps call [`Stamp::value`] per texel, on one thread.
///
/// Fails on an invalid placement, an error from the stamp's `prepare`, a non-finite blend
/// base, or a footprint larger than a repeating map (it would overlap itself).
pub fn apply_stamp<T: HeightSample, S: Stamp + ?Sized>(
    map: &mut HeightMap<T>,
    stamp: &mut S,
    placement: &StampPlacement,
    blend: Blend,
) -> Result<Vec<DirtyRect>, CoreError> {
    let prepared = prepare_stamp(map, stamp, placement, blend, None)?;
    apply_prepared(map, stamp, prepared)
}

/// Applies `stamp` to `map` as the window of a larger, clamped map whose texel `origin` is the
/// window's texel `(0, 0)`: texel `(x, y)` of `map` gets exactly what texel
/// `origin + (x, y)` of the larger map would get from [`apply_stamp`] with the same
/// `placement` (in the larger map's metres), whenever the window holds the stamp's whole
/// footprint (then the evaluation is the same one, texel for texel). A window cut through a
/// footprint is evaluated on its own part, within one stored unit of
/// [`apply_stamp_reference`] as [`apply_stamp`] is. `map`'s own wrap mode is ignored. Returns the covered rect in `map`'s coordinates, if any.
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
    let prepared = prepare_stamp(map, stamp, placement, blend, Some(origin))?;
    Ok(apply_prepared(map, stamp, prepared)?.into_iter().next())
}

/// A placement ready to apply: the pieces (map rect, offset to unwrapped coordinates), the
/// local frame and the blend.
type Prepared = (Vec<(Rect, IVec2)>, Frame, BlendOp);

/// The shared body of [`apply_stamp`] and [`apply_stamp_window`].
fn apply_prepared<T: HeightSample, S: Stamp + ?Sized>(
    map: &mut HeightMap<T>,
    stamp: &mut S,
    prepared: Option<Prepared>,
) -> Result<Vec<DirtyRect>, CoreError> {
    let Some((pieces, frame, op)) = prepared else {
        return Ok(Vec::new());
    };
    let footprint_x = pieces
        .iter()
        .map(|&(r, o)| (r.min.x + o.x, r.max().x + o.x))
        .fold((i32::MAX, i32::MIN), |(a, b), (lo, hi)| {
            (a.min(lo), b.max(hi))
        });
    let kernel = match stamp.kernel() {
        // A footprint too small for its texel size gives non-finite local coordinates, which
        // only the per-texel path treats exactly as the reference does.
        _ if !frame.inv_half.is_finite() => Kernel::PerTexel,
        StampKernel::Gaussian { beta } => GaussianKernel::new(&frame, beta, footprint_x, &pieces)
            .map_or(Kernel::PerTexel, Kernel::Gaussian),
        StampKernel::Texture(values) => match TextureKernel::new(values, texels(&pieces)) {
            Some(t) => Kernel::Texture(t),
            None => Kernel::PerTexel,
        },
        StampKernel::PerTexel => Kernel::PerTexel,
    };
    let width = map.size().x as usize;
    let grid = map.grid_mut();
    for &(rect, offset) in &pieces {
        let (y0, y1) = (rect.min.y as usize, rect.max().y as usize);
        let (x0, x1) = (rect.min.x, rect.max().x);
        let rows = &mut grid.as_mut_slice()[y0 * width..y1 * width];
        let run = |j: usize, row: &mut [T], eval: &RowEval<'_>| {
            let uy = (y0 + j) as i32 + offset.y;
            let (a, b) = frame.row_span(uy, x0 + offset.x, x1 + offset.x);
            let row = &mut row[(a - offset.x) as usize..(b - offset.x) as usize];
            let mut z = [0.0f64; BLOCK];
            for (k, dst) in row.chunks_mut(BLOCK).enumerate() {
                let ux = a + (k * BLOCK) as i32;
                eval(uy, ux, dst.len() as i32, &mut z[..dst.len()]);
                op.apply(dst, &z[..dst.len()]);
            }
        };
        match &kernel {
            Kernel::Gaussian(g) if SmallOp::fits::<T>(&op) => {
                let small = SmallOp::new(&op);
                crate::par::for_each_chunk(rows, width, |j, row| {
                    let uy = (y0 + j) as i32 + offset.y;
                    let (a, b) = frame.row_span(uy, x0 + offset.x, x1 + offset.x);
                    let row = &mut row[(a - offset.x) as usize..(b - offset.x) as usize];
                    let rg = g.row(uy, op.add_scale.abs());
                    gaussian_row_small(g, &rg, &small, row, a);
                });
            }
            Kernel::Gaussian(_) | Kernel::Texture(_) => {
                crate::par::for_each_chunk(rows, width, |j, row| {
                    let uy = (y0 + j) as i32 + offset.y;
                    let (a, b) = frame.row_span(uy, x0 + offset.x, x1 + offset.x);
                    let row = &mut row[(a - offset.x) as usize..(b - offset.x) as usize];
                    blend_row(&kernel, &frame, &op, uy, a, row);
                });
            }
            Kernel::PerTexel => {
                for (j, row) in rows.chunks_mut(width).enumerate() {
                    run(j, row, &|uy, ux, _, z: &mut [f64]| {
                        for (i, z) in z.iter_mut().enumerate() {
                            *z = op.z(stamp.value(frame.local(ux + i as i32, uy)));
                        }
                    })
                }
            }
        }
    }
    Ok(pieces.into_iter().map(|(r, _)| r).collect())
}

/// One row of the u8 / u16 Gaussian path: the row's stamp magnitudes block by block, blended
/// with integer operations. Compiled for AVX2 too (the same bits on every instruction set).
#[multiversion::multiversion(targets("x86_64+avx2+fma"))]
fn gaussian_row_small<T: HeightSample>(
    g: &GaussianKernel,
    rg: &GaussianRow,
    small: &SmallOp,
    row: &mut [T],
    first: i32,
) {
    let mut w = [0.0f32; BLOCK];
    let mut cross = g.cross_at(rg, first);
    for (k, dst) in row.chunks_mut(BLOCK).enumerate() {
        let w = &mut w[..dst.len()];
        g.eval32(rg, first + (k * BLOCK) as i32, w, &mut cross);
        small.apply(dst, w);
    }
}

/// One row of the f64 paths (textures, and Gaussians on u32 maps or of huge intensity): the
/// stamp terms block by block, blended in f64 stored units exactly as the reference does.
/// Compiled for AVX-512 and AVX2 too (the same bits on every instruction set; AVX-512's
/// 8-wide f64 takes a fifth off the texture path).
#[multiversion::multiversion(targets(
    "x86_64+avx512f+avx512bw+avx512vl+avx512dq+avx2+fma",
    "x86_64+avx2+fma"
))]
fn blend_row<T: HeightSample>(
    kernel: &Kernel<'_>,
    frame: &Frame,
    op: &BlendOp,
    uy: i32,
    first: i32,
    row: &mut [T],
) {
    let mut gaussian_row = match kernel {
        Kernel::Gaussian(g) => {
            let rg = g.row(uy, op.add_scale);
            let cross = g.cross_at(&rg, first);
            Some((g, rg, cross))
        }
        _ => None,
    };
    let mut z = [0.0f64; BLOCK];
    for (k, dst) in row.chunks_mut(BLOCK).enumerate() {
        let ux = first + (k * BLOCK) as i32;
        let z = &mut z[..dst.len()];
        match (kernel, &mut gaussian_row) {
            (_, Some((g, rg, cross))) => g.eval(rg, ux, z.len() as i32, z, cross),
            (Kernel::Texture(t), _) => t.block(frame, op, ux, uy, z),
            _ => {}
        }
        op.apply(dst, z);
    }
}

/// The texels of a stamp's pieces.
fn texels(pieces: &[(Rect, IVec2)]) -> u64 {
    pieces.iter().map(|(r, _)| r.area()).sum()
}

/// Fills stamp terms for `(uy, ux, n, out)`: row, first unwrapped column, count, terms.
type RowEval<'a> = dyn Fn(i32, i32, i32, &mut [f64]) + 'a;

/// Texels a row is evaluated in at once (a stack buffer of stamp values).
const BLOCK: usize = 64;

/// The relative size of the difference between [`apply_stamp`]'s separable Gaussian and the
/// per-texel f32 evaluation of [`apply_stamp_reference`] before rounding: the two stored
/// results differ (by exactly 1 unit) only at texels whose exact unrounded new value lies
/// within `gaussian_rounding_bound(beta, placement) * |intensity / encoding scale|` of a
/// half-integer.
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
    let enc = map.encoding();
    // Local coordinates in texel units: the same arithmetic for a texel whatever piece it is
    // in, so a stamp across the wrap edge equals the same stamp on a shifted map.
    let (center, inv_half, sin, cos) = placement.local_frame(ts);
    let add_scale = f64::from(placement.intensity) / f64::from(enc.scale);
    let op = match blend {
        Blend::Add => BlendOp {
            kind: 0,
            add_scale,
            base_raw: 0.0,
        },
        // In stored units, as the GPU pass computes it: base + value * units.
        Blend::Min { base_m } => BlendOp {
            kind: 1,
            add_scale,
            base_raw: enc.to_raw(base_m),
        },
        Blend::Max { base_m } => BlendOp {
            kind: 2,
            add_scale,
            base_raw: enc.to_raw(base_m),
        },
    };
    let frame = Frame {
        center,
        inv_half,
        sin,
        cos,
    };
    Ok(Some((pieces, frame, op)))
}

/// The per-texel evaluation: [`Stamp::value`] at every texel of the footprint through the
/// trait, each result rounded on its own. This is how [`apply_stamp`] worked before its fast
/// paths, kept as the reference they are tested and benchmarked against; it is several
/// hundred times slower than a copy of the region's bytes.
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
    let grid = map.grid_mut();
    for &(rect, offset) in &pieces {
        for y in rect.min.y..rect.max().y {
            let row = grid.row_mut(y as u32);
            for x in rect.min.x..rect.max().x {
                let local = frame.local(x + offset.x, y + offset.y);
                if local.x.abs() > 1.0 || local.y.abs() > 1.0 {
                    continue;
                }
                let v = stamp.value(local);
                if !v.is_finite() {
                    continue;
                }
                let old = row[x as usize].to_raw_f64();
                let new = match op.kind {
                    0 => old + op.add_scale * f64::from(v),
                    1 => old.min(op.base_raw + op.add_scale * f64::from(v)),
                    _ => old.max(op.base_raw + op.add_scale * f64::from(v)),
                };
                row[x as usize] = T::from_raw_f64_clamped(new);
            }
        }
    }
    Ok(pieces.into_iter().map(|(r, _)| r).collect())
}

/// A placement's local frame in texel units (see [`StampPlacement::local_frame`]).
#[derive(Debug, Clone, Copy)]
struct Frame {
    center: Vec2,
    inv_half: Vec2,
    sin: f32,
    cos: f32,
}

impl Frame {
    /// Local coordinates of the texel at unwrapped coordinates `(ux, uy)`, in f32 exactly as
    /// the GPU pass computes them.
    #[inline(always)]
    fn local(&self, ux: i32, uy: i32) -> Vec2 {
        let dx = ux as f32 - self.center.x;
        let dy = uy as f32 - self.center.y;
        Vec2::new(dx * self.cos + dy * self.sin, dy * self.cos - dx * self.sin) * self.inv_half
    }

    /// The texels `[a, b)` of row `uy` within `[lo, hi)` that are inside the footprint
    /// (`!(|local.x| > 1 || |local.y| > 1)`, the per-texel test). Each of the four half-tests
    /// is monotone along a row (an f32 affine function of x, every rounding monotone), so each
    /// holds on a prefix or a suffix, found by bisection: `O(log(hi - lo))` evaluations.
    fn row_span(&self, uy: i32, lo: i32, hi: i32) -> (i32, i32) {
        // `!(v > 1)` rather than `v <= 1`: NaN passes, as in the per-texel test.
        use std::cmp::Ordering::Greater;
        use std::cmp::Ordering::Less;
        let tests: [&dyn Fn(i32) -> bool; 4] = [
            &|x| self.local(x, uy).x.partial_cmp(&1.0) != Some(Greater),
            &|x| self.local(x, uy).x.partial_cmp(&-1.0) != Some(Less),
            &|x| self.local(x, uy).y.partial_cmp(&1.0) != Some(Greater),
            &|x| self.local(x, uy).y.partial_cmp(&-1.0) != Some(Less),
        ];
        let (mut a, mut b) = (lo, hi);
        for t in tests {
            let (ta, tb) = monotone_span(lo, hi, t);
            a = a.max(ta);
            b = b.min(tb);
        }
        if a >= b { (lo, lo) } else { (a, b) }
    }
}

/// Where a predicate that is monotone over `[lo, hi)` holds: a prefix or a suffix (or all,
/// or nothing), by bisection.
fn monotone_span(lo: i32, hi: i32, p: &dyn Fn(i32) -> bool) -> (i32, i32) {
    if lo >= hi {
        return (lo, lo);
    }
    match (p(lo), p(hi - 1)) {
        (true, true) => (lo, hi),
        (false, false) => (lo, lo),
        (first, _) => {
            // p(l) == first and p(h) != first; bisect to adjacent l, h.
            let (mut l, mut h) = (lo, hi - 1);
            while h - l > 1 {
                let m = l + (h - l) / 2;
                if p(m) == first { l = m } else { h = m }
            }
            if first { (lo, h) } else { (h, hi) }
        }
    }
}

/// The blend of one stamp value into a stored height, in f64 stored units.
#[derive(Debug, Clone, Copy)]
struct BlendOp {
    /// 0 add, 1 min, 2 max.
    kind: u8,
    add_scale: f64,
    base_raw: f64,
}

impl BlendOp {
    /// The stored-unit term of value `v`, or the value that leaves a texel unchanged when `v`
    /// is NaN or infinite (0 for add, +inf for min, -inf for max).
    #[inline(always)]
    fn z(&self, v: f32) -> f64 {
        if v.is_finite() {
            self.add_scale * f64::from(v)
        } else {
            [0.0, f64::INFINITY, f64::NEG_INFINITY][usize::from(self.kind)]
        }
    }

    /// Blends the terms `z` into `dst`: `round(old + z)`, `round(min(old, base + z))` or
    /// `round(max(old, base + z))`, rounded half up and clamped to the sample's range.
    #[inline(always)]
    fn apply<T: HeightSample>(&self, dst: &mut [T], z: &[f64]) {
        let base = self.base_raw;
        match self.kind {
            0 => {
                for (d, &z) in dst.iter_mut().zip(z) {
                    *d = T::from_raw_f64_floor_clamped(d.to_raw_f64() + z + 0.5);
                }
            }
            1 => {
                for (d, &z) in dst.iter_mut().zip(z) {
                    *d = T::from_raw_f64_floor_clamped(d.to_raw_f64().min(base + z) + 0.5);
                }
            }
            _ => {
                for (d, &z) in dst.iter_mut().zip(z) {
                    *d = T::from_raw_f64_floor_clamped(d.to_raw_f64().max(base + z) + 0.5);
                }
            }
        }
    }
}

/// The blend of non-negative f32 magnitudes `w` (the stamp term is `+w` or `-w` stored units)
/// into u8 or u16 samples with integer SIMD-friendly operations: `old +/- floor(w + 1/2)`
/// saturating, or `min` / `max` with `floor(base + z + 1/2)` computed as the integer part of
/// the base plus `floor(frac(base) + 1/2 + z)` in f32.
///
/// Magnitudes are clamped to `TERM_LIMIT` and bases are at most `BASE_LIMIT` from 0 (else the
/// f64 path runs), so a clamped magnitude leaves `base + z` outside the sample range on the
/// same side as the exact one: clamping changes no result.
#[derive(Debug, Clone, Copy)]
struct SmallOp {
    kind: u8,
    negative: bool,
    base_int: i32,
    base_frac_half: f32,
}

/// The largest stored-unit magnitude a min / max blend of the u8 / u16 path takes (2^21;
/// `floor_small` needs `|y| < 2^22`).
const TERM_LIMIT: f32 = 2_097_152.0;
/// The farthest a min / max base may lie from 0 on the u8 / u16 path, in stored units (2^20):
/// `TERM_LIMIT - BASE_LIMIT` is far above any sample's range.
const BASE_LIMIT: f64 = 1_048_576.0;

impl SmallOp {
    /// Whether this path applies: u8 or u16 samples, `|add_scale| <= 1e9` (so every product
    /// stays far inside f32's range) and, for min and max, a base within `BASE_LIMIT`.
    fn fits<T: HeightSample>(op: &BlendOp) -> bool {
        use std::any::TypeId;
        let t = TypeId::of::<T>();
        (t == TypeId::of::<u16>() || t == TypeId::of::<u8>())
            && op.add_scale.abs() <= 1e9
            && (op.kind == 0 || op.base_raw.abs() <= BASE_LIMIT)
    }

    fn new(op: &BlendOp) -> Self {
        let b = op.base_raw.floor();
        Self {
            kind: op.kind,
            negative: op.add_scale < 0.0,
            // `fits` keeps min / max bases within the limit; an add ignores the base.
            base_int: b.clamp(-BASE_LIMIT, BASE_LIMIT) as i32,
            base_frac_half: (op.base_raw - b + 0.5) as f32,
        }
    }

    #[inline(always)]
    fn apply<T: HeightSample>(&self, dst: &mut [T], w: &[f32]) {
        use std::any::TypeId;
        let t = TypeId::of::<T>();
        if t == TypeId::of::<u16>()
            && let Ok(d) = bytemuck::try_cast_slice_mut::<T, u16>(dst)
        {
            apply_small_u16(self, d, w);
        } else if t == TypeId::of::<u8>()
            && let Ok(d) = bytemuck::try_cast_slice_mut::<T, u8>(dst)
        {
            apply_small_u8(self, d, w);
        }
    }
}

/// `floor(y)` for `|y| < 2^22`, with f32 adds, a compare and a bit cast only (SSE2 has no
/// vector `floor`, and a saturating cast does not vectorise): adding `1.5 * 2^23` rounds to an
/// integer and leaves it in the low mantissa bits.
#[inline(always)]
fn floor_small(y: f32) -> i32 {
    const M: f32 = 12_582_912.0; // 1.5 * 2^23
    let r = (y + M) - M;
    let f = if r > y { r - 1.0 } else { r };
    (f + M).to_bits() as i32 - 0x4B40_0000
}

macro_rules! apply_small {
    ($name:ident, $t:ty) => {
        #[inline(always)]
        fn $name(op: &SmallOp, dst: &mut [$t], w: &[f32]) {
            const MAX: f32 = <$t>::MAX as f32;
            let (bi, bfh) = (op.base_int, op.base_frac_half);
            match (op.kind, op.negative) {
                (0, false) => {
                    for (d, &w) in dst.iter_mut().zip(w) {
                        *d = d.saturating_add(floor_small(w.min(MAX) + 0.5) as $t);
                    }
                }
                (0, true) => {
                    for (d, &w) in dst.iter_mut().zip(w) {
                        *d = d.saturating_sub(floor_small(w.min(MAX) + 0.5) as $t);
                    }
                }
                (kind, negative) => {
                    let sign = if negative { -1.0f32 } else { 1.0 };
                    for (d, &w) in dst.iter_mut().zip(w) {
                        let y = bfh + sign * w.min(TERM_LIMIT);
                        let t = floor_small(y);
                        let level = (bi + t).clamp(0, <$t>::MAX as i32) as $t;
                        *d = if kind == 1 {
                            (*d).min(level)
                        } else {
                            (*d).max(level)
                        };
                    }
                }
            }
        }
    };
}
apply_small!(apply_small_u16, u16);
apply_small!(apply_small_u8, u8);

/// The evaluation [`apply_stamp`] chose.
enum Kernel<'a> {
    Gaussian(GaussianKernel),
    Texture(TextureKernel<'a>),
    PerTexel,
}

/// The Gaussian `exp(-beta |local|^2)` in texel offsets `(dx, dy)` from the centre: with
/// `local = ((c dx + s dy) a, (c dy - s dx) b)`, `|local|^2 = A dx^2 + 2 B dx dy + C dy^2`
/// where `A = a^2 c^2 + b^2 s^2`, `C = a^2 s^2 + b^2 c^2`, `B = c s (a^2 - b^2)` (zero for a
/// square or unrotated footprint). Evaluated in f64 as `ex[x] * ey(y) * cross(x, y)`.
struct GaussianKernel {
    /// `exp(-beta A dx^2)` for unwrapped columns `x0..`.
    ex: Vec<f64>,
    /// `ex` rounded to f32.
    ex32: Vec<f32>,
    x0: i32,
    /// `exp(-beta C dy^2)` for unwrapped rows `y0..`.
    ey: Vec<f64>,
    y0: i32,
    cx: f64,
    cy: f64,
    /// `beta * B`; 0 when the form is separable.
    beta_b: f64,
}

/// Per-row state of [`GaussianKernel`].
struct GaussianRow {
    /// `add_scale * exp(-beta C dy^2)`.
    scale: f64,
    dy: f64,
    /// `exp(-2 beta B dy)^k` for `k < BLOCK` (empty when separable).
    pow: [f64; BLOCK],
    /// `exp(-2 beta B dy BLOCK)`: the cross factor's step from one block to the next.
    block_step: f64,
}

impl GaussianKernel {
    /// `None` (use the per-texel path) when a cross factor could overflow f64.
    fn new(frame: &Frame, beta: f32, xs: (i32, i32), pieces: &[(Rect, IVec2)]) -> Option<Self> {
        let (a, b) = (f64::from(frame.inv_half.x), f64::from(frame.inv_half.y));
        let (s, c) = (f64::from(frame.sin), f64::from(frame.cos));
        let (a2, b2) = (a * a, b * b);
        let coef_a = a2 * c * c + b2 * s * s;
        let coef_b = c * s * (a2 - b2);
        let coef_c = a2 * s * s + b2 * c * c;
        let beta = f64::from(beta);
        let (cx, cy) = (f64::from(frame.center.x), f64::from(frame.center.y));
        if !beta.is_finite() {
            return None;
        }
        let ys = pieces
            .iter()
            .map(|&(r, o)| (r.min.y + o.y, r.max().y + o.y))
            .fold((i32::MAX, i32::MIN), |(p, q), (lo, hi)| {
                (p.min(lo), q.max(hi))
            });
        if coef_b != 0.0 {
            let mx = (f64::from(xs.0) - cx)
                .abs()
                .max((f64::from(xs.1) - cx).abs())
                + 1.0;
            let my = (f64::from(ys.0) - cy)
                .abs()
                .max((f64::from(ys.1) - cy).abs())
                + 1.0;
            // The cross factor at any texel and the row's power table (k < BLOCK).
            let worst = (2.0 * beta * coef_b * my * (mx + BLOCK as f64)).abs();
            if worst.is_nan() || worst >= 600.0 {
                return None;
            }
        }
        let ex = gaussian_table(xs, cx, beta * coef_a);
        Some(Self {
            ex32: ex.iter().map(|&e| e as f32).collect(),
            ex,
            x0: xs.0,
            ey: gaussian_table(ys, cy, beta * coef_c),
            y0: ys.0,
            cx,
            cy,
            beta_b: beta * coef_b,
        })
    }

    fn row(&self, uy: i32, add_scale: f64) -> GaussianRow {
        let dy = f64::from(uy) - self.cy;
        let mut pow = [1.0; BLOCK];
        if self.beta_b != 0.0 {
            let r = (-2.0 * self.beta_b * dy).exp();
            for k in 1..BLOCK {
                pow[k] = pow[k - 1] * r;
            }
        }
        let ey = self.ey.get((uy - self.y0) as usize).copied().unwrap_or(0.0);
        GaussianRow {
            scale: add_scale * ey,
            dy,
            pow,
            block_step: (-2.0 * self.beta_b * dy * BLOCK as f64).exp(),
        }
    }

    /// The cross factor `exp(-2 beta B dx dy)` at unwrapped column `ux` of `row` (1 when
    /// separable): where a row's first block starts; [`GaussianKernel::eval`] steps it on.
    fn cross_at(&self, row: &GaussianRow, ux: i32) -> f64 {
        if self.beta_b == 0.0 {
            return 1.0;
        }
        (-2.0 * self.beta_b * (f64::from(ux) - self.cx) * row.dy).exp()
    }

    /// [`GaussianKernel::eval`] in f32 (the row built with `|add_scale|`).
    #[inline(always)]
    fn eval32(&self, row: &GaussianRow, ux: i32, w: &mut [f32], cross: &mut f64) {
        let i0 = (ux - self.x0) as usize;
        if self.beta_b == 0.0 {
            let s = row.scale as f32;
            let n = w.len();
            for (w, &e) in w.iter_mut().zip(&self.ex32[i0..i0 + n]) {
                *w = s * e;
            }
        } else {
            let mut z = [0.0f64; BLOCK];
            let z = &mut z[..w.len()];
            self.eval(row, ux, w.len() as i32, z, cross);
            for (w, &z) in w.iter_mut().zip(z.iter()) {
                *w = z as f32;
            }
        }
    }

    /// Stored-unit terms of `n` texels of a row from unwrapped column `ux`, the start of a
    /// block; `cross` is the cross factor there ([`GaussianKernel::cross_at`] for a row's
    /// first block) and is stepped on to the next block's start: one product a block instead
    /// of an `exp`, its rounding growing by 2^-53 a block (a row of 32 768 texels: 2^-44).
    #[inline(always)]
    fn eval(&self, row: &GaussianRow, ux: i32, n: i32, z: &mut [f64], cross: &mut f64) {
        let i0 = (ux - self.x0) as usize;
        let ex = &self.ex[i0..i0 + n as usize];
        if self.beta_b == 0.0 {
            for (z, &e) in z.iter_mut().zip(ex) {
                *z = row.scale * e;
            }
        } else {
            let s = row.scale * *cross;
            *cross *= row.block_step;
            for ((z, &e), &p) in z.iter_mut().zip(ex).zip(&row.pow) {
                *z = s * e * p;
            }
        }
    }
}

/// `exp(-a (x - c)^2)` for the integers `x` of `lo..hi` (`a >= 0`), with two `exp` calls per
/// 64 entries instead of one per entry: outward from the entry nearest `c`, each entry is the
/// previous times `exp(-a (2 |x - c| - 1))`, a ratio that itself steps by `exp(-2a)`; both
/// products shrink (no overflow) and start afresh from `exp` every 64 entries, so their f64
/// rounding stays below 64^2 * 2^-53 of the value, far inside `gaussian_rounding_bound`.
fn gaussian_table((lo, hi): (i32, i32), c: f64, a: f64) -> Vec<f64> {
    const ANCHOR: usize = 64;
    let n = (hi - lo).max(0) as usize;
    let mut out = vec![0.0; n];
    if n == 0 {
        return out;
    }
    let at = |i: usize| f64::from(lo) + i as f64 - c;
    let mid = (c - f64::from(lo)).round().clamp(0.0, (n - 1) as f64) as usize;
    let step = (-2.0 * a).exp();
    let exact = |i: usize| (-a * at(i) * at(i)).exp();
    // Right of `mid`: e(x + 1) = e(x) exp(-a (2 (x - c) + 1)).
    let (mut e, mut r) = (0.0, 0.0);
    for (k, i) in (mid..n).enumerate() {
        if k % ANCHOR == 0 {
            e = exact(i);
            r = (-a * (2.0 * at(i) + 1.0)).exp();
        } else {
            e *= r;
            r *= step;
        }
        out[i] = e;
    }
    // Left of `mid`: e(x - 1) = e(x) exp(-a (1 - 2 (x - c))).
    for (k, i) in (0..mid).rev().enumerate() {
        if k % ANCHOR == 0 {
            e = exact(i);
            r = (-a * (1.0 - 2.0 * at(i))).exp();
        } else {
            e *= r;
            r *= step;
        }
        out[i] = e;
    }
    out
}

/// A texture stamp sampled inline, with the arithmetic of [`TextureStamp::value`].
struct TextureKernel<'a> {
    values: &'a [f32],
    /// For footprints much larger than the image: the four pixels every bilinear cell reads,
    /// side by side, for cells `(x0, z0)` from `(-1, -1)` to `(w - 1, h - 1)` (row-major over
    /// `(x0 + 1, z0 + 1)`, clamped at the edges as the lookups are), so a texel costs one
    /// 16-byte load instead of four scattered ones.
    quads: Vec<[f32; 4]>,
    w: i32,
    h: i32,
    size: Vec2,
}

impl<'a> TextureKernel<'a> {
    /// `None` for an image too large for the exact floor below (2^22 pixels a side) or for
    /// 32-bit pixel indices (2^31 pixels).
    /// The quad table is built when the footprint has at least four texels per cell.
    fn new(values: &'a Grid<f32>, texels: u64) -> Option<Self> {
        let size = values.size();
        let cells = (u64::from(size.x) + 1) * (u64::from(size.y) + 1);
        let fits = size.max_element() < 1 << 22 && cells < 1 << 31;
        if !fits || size.min_element() == 0 {
            return None;
        }
        let (w, h) = (size.x as i32, size.y as i32);
        let v = values.as_slice();
        let at = |x: i32, z: i32| v[(z.clamp(0, h - 1) * w + x.clamp(0, w - 1)) as usize];
        let quads = if texels >= 4 * cells {
            (-1..h)
                .flat_map(|z| (-1..w).map(move |x| (x, z)))
                .map(|(x, z)| [at(x, z), at(x + 1, z), at(x, z + 1), at(x + 1, z + 1)])
                .collect()
        } else {
            Vec::new()
        };
        Some(Self {
            values: v,
            quads,
            w,
            h,
            size: size.as_vec2(),
        })
    }

    /// The stored-unit terms `op.z(value(local))` of `z.len()` texels of row `uy` from
    /// unwrapped column `ux`, every one inside the footprint (or with a NaN local coordinate):
    /// [`TextureStamp::value`]'s f32 arithmetic in loops over the block (pixel coordinates,
    /// indices and fractions; lookups; interpolation and terms), all but the lookups
    /// vectorised by the compiler. `floor_small` is exact here (`|p| < 2^22`); for a NaN
    /// coordinate it gives some index, clamped like any other, and the fraction (NaN minus
    /// anything) makes the value NaN, as in the reference.
    #[inline(always)]
    fn block(&self, frame: &Frame, op: &BlendOp, ux: i32, uy: i32, z: &mut [f64]) {
        let n = z.len().min(BLOCK);
        let pixel = |i: usize| {
            let l = frame.local(ux + i as i32, uy);
            (
                (l.x + 1.0) * 0.5 * self.size.x - 0.5,
                (l.y + 1.0) * 0.5 * self.size.y - 0.5,
            )
        };
        // The lookups alone (a load and a store per texel) fill `q`; the interpolation and
        // the stored-unit terms then run over the whole block, which the compiler vectorises
        // (interleaved with the lookups, neither did).
        let (mut fx, mut fz) = ([0.0f32; BLOCK], [0.0f32; BLOCK]);
        let mut q = [[0.0f32; 4]; BLOCK];
        let (w, h) = (self.w, self.h);
        if !self.quads.is_empty() {
            let mut cell = [0u32; BLOCK];
            for i in 0..n {
                let (px, py) = pixel(i);
                let (x0, z0) = (floor_small(px), floor_small(py));
                fx[i] = px - x0 as f32;
                fz[i] = py - z0 as f32;
                let (cx, cz) = (
                    x0.wrapping_add(1).clamp(0, w),
                    z0.wrapping_add(1).clamp(0, h),
                );
                cell[i] = (cz * (w + 1) + cx) as u32;
            }
            let last = self.quads.len() - 1;
            for i in 0..n {
                q[i] = self.quads[(cell[i] as usize).min(last)];
            }
        } else {
            let mut idx = [[0u32; 4]; BLOCK];
            for i in 0..n {
                let (px, py) = pixel(i);
                let (x0, z0) = (floor_small(px), floor_small(py));
                fx[i] = px - x0 as f32;
                fz[i] = py - z0 as f32;
                let xa = x0.clamp(0, w - 1);
                let xb = x0.wrapping_add(1).clamp(0, w - 1);
                let ra = z0.clamp(0, h - 1) * w;
                let rb = z0.wrapping_add(1).clamp(0, h - 1) * w;
                idx[i] = [ra + xa, ra + xb, rb + xa, rb + xb].map(|k| k as u32);
            }
            let v = self.values;
            let last = v.len() - 1;
            for i in 0..n {
                q[i] = idx[i].map(|k| v[(k as usize).min(last)]);
            }
        }
        let mut v = [0.0f32; BLOCK];
        for i in 0..n {
            let [v0, v1, v2, v3] = q[i];
            let top = v0 + (v1 - v0) * fx[i];
            let bot = v2 + (v3 - v2) * fx[i];
            v[i] = top + (bot - top) * fz[i];
        }
        // `op.z` with its non-finite case as a select.
        let (scale, neutral) = (op.add_scale, op.z(f32::NAN));
        for i in 0..n {
            let t = scale * f64::from(v[i]);
            z[i] = if v[i].is_finite() { t } else { neutral };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::{CoarseMap, HeightEncoding};

    /// `monotone_span` finds the prefix or suffix where a monotone predicate holds, as a scan
    /// does, and asks the predicate only inside `[lo, hi)` (its contract says nothing of
    /// the values outside).
    #[test]
    fn monotone_span_equals_a_scan_and_stays_inside_the_range() {
        for lo in [-37, -1, 0, 3, 250] {
            for len in 0..40 {
                let hi = lo + len;
                for t in lo - 2..=hi + 2 {
                    for prefix in [true, false] {
                        let asked = std::cell::RefCell::new(Vec::new());
                        let p = |x: i32| {
                            let mut a = asked.borrow_mut();
                            assert!(a.len() < 64, "a bisection that does not end");
                            a.push(x);
                            if prefix { x < t } else { x >= t }
                        };
                        let got = monotone_span(lo, hi, &p);
                        let held: Vec<i32> = (lo..hi)
                            .filter(|&x| if prefix { x < t } else { x >= t })
                            .collect();
                        let want = match (held.first(), held.last()) {
                            (Some(&a), Some(&b)) => (a, b + 1),
                            _ => (lo, lo),
                        };
                        assert_eq!(got, want, "[{lo}, {hi}) t {t} prefix {prefix}");
                        let asked = asked.borrow();
                        assert!(
                            asked.iter().all(|x| (lo..hi).contains(x)),
                            "[{lo}, {hi}): asked {asked:?}"
                        );
                        // Bisection: a logarithmic number of questions.
                        assert!(asked.len() <= 2 + 7, "{} questions", asked.len());
                    }
                }
            }
        }
    }

    /// The Gaussian table has one entry per integer of `lo..hi`, each within the documented
    /// relative rounding of `exp(-a (x - c)^2)`, centres inside and outside the range.
    #[test]
    fn gaussian_table_entries_equal_exp() {
        for (lo, hi) in [(0, 0), (5, 6), (-20, 180), (-300, -10)] {
            for c in [-25.3, 0.0, 41.7, 179.5, 400.0] {
                for a in [0.0, 1e-4, 0.01, 0.3] {
                    let t = gaussian_table((lo, hi), c, a);
                    assert_eq!(t.len(), (hi - lo) as usize);
                    for (i, v) in t.iter().enumerate() {
                        let x = f64::from(lo) + i as f64;
                        let want = (-a * (x - c) * (x - c)).exp();
                        assert!(
                            (v - want).abs() <= 64.0 * 64.0 * f64::EPSILON * want,
                            "[{lo}, {hi}) c {c} a {a} x {x}: {v} vs {want}"
                        );
                    }
                }
            }
        }
    }

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
    fn gaussian_table_matches_exp_within_its_bound() {
        // Centres inside, between, left and right of the range; flat, typical and steep.
        let cases = [
            ((0, 40_000), 20_000.3, 1e-8),
            ((-7, 500), 3.5, 2.5e-5),
            ((10, 300), -40.25, 1e-4),
            ((10, 300), 900.75, 1e-4),
            ((0, 64), 31.0, 0.0),
            ((0, 200), 100.6, 3.0),
            ((5, 5), 0.0, 1.0),
        ];
        for ((lo, hi), c, a) in cases {
            let t = gaussian_table((lo, hi), c, a);
            assert_eq!(t.len(), (hi - lo) as usize);
            for (i, &v) in t.iter().enumerate() {
                let d = f64::from(lo) + i as f64 - c;
                let exact = (-a * d * d).exp();
                let tol = 64.0 * 64.0 * f64::EPSILON * exact + f64::MIN_POSITIVE;
                assert!(
                    (v - exact).abs() <= tol,
                    "{lo}..{hi} c {c} a {a} at {i}: {v} vs {exact}"
                );
            }
        }
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
