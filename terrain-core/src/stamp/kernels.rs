//! The fast paths of [`apply_stamp`](super::apply_stamp): a Gaussian evaluated separably from
//! f64 tables (no `exp` per texel), a texture sampled inline block by block, and u8 / u16
//! blends in integer operations, each row compiled for AVX2 / AVX-512 too with the same bits.
//! They are tested against the per-texel [`apply_stamp_reference`](super::apply_stamp_reference).

use super::frame::{BlendOp, Frame};
use super::{Prepared, Stamp, StampKernel};
use crate::error::CoreError;
use crate::grid::Grid;
use crate::map::{HeightMap, HeightSample};
use crate::rect::{DirtyRect, Rect};
use glam::{IVec2, Vec2};

/// The shared body of [`apply_stamp`] and [`apply_stamp_window`].
pub(super) fn apply_prepared<T: HeightSample, S: Stamp + ?Sized>(
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
}
