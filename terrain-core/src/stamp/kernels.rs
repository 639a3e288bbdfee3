//! The body of [`apply_stamp`](super::apply_stamp): the exact stamp program ([`super::fixed`])
//! row by row, rows in parallel on the caller's pool, each row only over its footprint span.
//! Every texel gets the program's integer result, whatever path, thread count or instruction
//! set: the same bits as the GPU pass and as [`apply_stamp_reference`](super::apply_stamp_reference).

use super::fixed::{self, FixedBlend, FixedFrame, GaussianTables, LOCAL_ONE, QuantizedTexture};
use super::{Prepared, Stamp, StampKernel};
use crate::error::CoreError;
use crate::map::{HeightMap, HeightSample};
use crate::rect::DirtyRect;
use std::borrow::Cow;

/// How a stamp's value is evaluated, from [`Stamp::kernel`].
pub(super) enum Kernel<'a> {
    /// `round(beta 2^23)`, and whether the frame is [`fixed::gaussian_separable`].
    Gaussian(u32, bool),
    /// Quantised values (Q24): the stamp's own, or quantised for this placement.
    Texture(Cow<'a, QuantizedTexture>),
    /// [`Stamp::value`] per texel, converted by [`fixed::user_v31`].
    PerTexel,
}

impl<'a> Kernel<'a> {
    pub(super) fn of<S: Stamp + ?Sized>(stamp: &'a S, frame: &FixedFrame) -> Self {
        match stamp.kernel() {
            StampKernel::Gaussian { beta } => Kernel::Gaussian(
                fixed::gaussian_beta_q(beta),
                fixed::gaussian_separable(frame),
            ),
            StampKernel::Texture(values) if values.width() > 0 && values.height() > 0 => {
                Kernel::Texture(Cow::Owned(QuantizedTexture::new(values)))
            }
            StampKernel::Quantized(q) if q.width() > 0 && q.height() > 0 => {
                Kernel::Texture(Cow::Borrowed(q))
            }
            _ => Kernel::PerTexel,
        }
    }

    /// The value `* 2^31` at Q32 local `l` (inside the footprint), or `None` for a user value
    /// that is NaN or infinite (the texel stays unchanged).
    #[inline(always)]
    pub(super) fn v31<S: Stamp + ?Sized>(&self, stamp: &S, l: [i64; 2]) -> Option<i64> {
        match self {
            Kernel::Gaussian(beta_q, false) => Some(fixed::gaussian_v31(*beta_q, l)),
            Kernel::Gaussian(beta_q, true) => Some(fixed::gaussian_sep_v31(*beta_q, l)),
            Kernel::Texture(t) => Some(fixed::texture_v31(t.values(), t.width(), t.height(), l)),
            Kernel::PerTexel => {
                let v = stamp.value(fixed::local_f32(l));
                v.is_finite().then(|| fixed::user_v31(v))
            }
        }
    }
}

/// One texel of the program: `old` blended with the value at `l`, clamped to `T`'s range.
#[inline(always)]
pub(super) fn texel<T: HeightSample, S: Stamp + ?Sized>(
    kernel: &Kernel<'_>,
    stamp: &S,
    op: &FixedBlend,
    l: [i64; 2],
    old: T,
) -> T {
    if !fixed::inside(l) {
        return old;
    }
    match kernel.v31(stamp, l) {
        Some(v) => {
            let new = op.blend(old.to_raw_f64() as i64, v);
            T::from_raw_f64_clamped(new.clamp(0, T::MAX_RAW as i64) as f64)
        }
        None => old,
    }
}

/// Footprints of fewer texels run on the calling thread: handing them to the pool's other
/// threads costs more than it saves.
const PARALLEL_TEXELS: usize = 1 << 14;

/// The shared body of [`apply_stamp`](super::apply_stamp) and
/// [`apply_stamp_window`](super::apply_stamp_window).
pub(super) fn apply_prepared<T: HeightSample, S: Stamp + ?Sized>(
    map: &mut HeightMap<T>,
    stamp: &mut S,
    prepared: Option<Prepared>,
) -> Result<Vec<DirtyRect>, CoreError> {
    let Some((pieces, frame, op)) = prepared else {
        return Ok(Vec::new());
    };
    let kernel = Kernel::of(&*stamp, &frame);
    let fast = Fast::new(&kernel, &frame, &op, &pieces);
    let texels: usize = pieces.iter().map(|(r, _)| r.area() as usize).sum();
    let width = map.size().x as usize;
    let grid = map.grid_mut();
    for &(rect, offset) in &pieces {
        let (y0, y1) = (rect.min.y as usize, rect.max().y as usize);
        let rows = &mut grid.as_mut_slice()[y0 * width..y1 * width];
        let piece = Piece {
            frame: &frame,
            op: &op,
            lo: rect.min.x + offset.x,
            hi: rect.max().x + offset.x,
            offset,
            y0,
        };
        match &kernel {
            // A user stamp is only `Stamp`, not `Sync`: on the calling thread.
            Kernel::PerTexel => rows
                .chunks_mut(width)
                .enumerate()
                .for_each(|(j, r)| piece.row_texels(&kernel, &*stamp, j, r)),
            _ => {
                let run = |j: usize, row: &mut [T]| match &fast {
                    Some(f) => piece.row_fast(f, j, row),
                    None => piece.row_texels(&kernel, &NoStamp, j, row),
                };
                if texels < PARALLEL_TEXELS {
                    rows.chunks_mut(width)
                        .enumerate()
                        .for_each(|(j, r)| run(j, r));
                } else {
                    crate::par::for_each_chunk(rows, width, run);
                }
            }
        }
    }
    Ok(pieces.into_iter().map(|(r, _)| r).collect())
}

/// A placeholder stamp for the kernels that never call [`Stamp::value`] (shareable between
/// threads, unlike a user's stamp).
struct NoStamp;
impl Stamp for NoStamp {
    fn value(&self, _: glam::Vec2) -> f32 {
        0.0
    }
}

/// One piece of a placement: what each of its rows needs.
struct Piece<'a> {
    frame: &'a FixedFrame,
    op: &'a FixedBlend,
    /// The unwrapped columns `[lo, hi)` of every row.
    lo: i32,
    hi: i32,
    /// From map to unwrapped coordinates.
    offset: glam::IVec2,
    /// The map row of the piece's first row.
    y0: usize,
}

impl Piece<'_> {
    /// The unwrapped row of the piece's row `j`, and its span of the footprint as indices of
    /// the map row.
    #[inline(always)]
    fn span(&self, j: usize) -> (i32, i32, std::ops::Range<usize>) {
        let uy = (self.y0 + j) as i32 + self.offset.y;
        let (a, b) = self.frame.row_span(uy, self.lo, self.hi);
        let at = |ux: i32| (ux - self.offset.x) as usize;
        (uy, a, at(a)..at(b))
    }

    /// Row `j` texel by texel: the program as [`texel`] writes it (any frame, any blend).
    fn row_texels<T: HeightSample, S: Stamp + ?Sized>(
        &self,
        kernel: &Kernel<'_>,
        stamp: &S,
        j: usize,
        row: &mut [T],
    ) {
        let (uy, a, span) = self.span(j);
        for (ux, d) in (a..).zip(&mut row[span]) {
            *d = texel(kernel, stamp, self.op, self.frame.local_q(ux, uy), *d);
        }
    }

    /// Row `j` by [`Fast`], in blocks: the values of a block (local coordinates stepped
    /// from the span's first texel, every texel of the span inside: the frame is monotone),
    /// then its blend.
    fn row_fast<T: HeightSample>(&self, fast: &Fast<'_>, j: usize, row: &mut [T]) {
        let (uy, a, span) = self.span(j);
        let mut v = [0i64; BLOCK];
        // The separable Gaussian's row factor (local Y depends on the row only).
        let row_factor = match &fast.eval {
            Eval::GaussianSep { tables, beta_q, .. } => {
                tables.factor31(*beta_q, self.frame.local_q(a, uy)[1])
            }
            _ => 0,
        };
        for (k, dst) in row[span].chunks_mut(BLOCK).enumerate() {
            let ux = a + (k * BLOCK) as i32;
            let l = self.frame.local_q(ux, uy);
            let v = &mut v[..dst.len()];
            match &fast.eval {
                Eval::Gaussian(tables, beta_q) => {
                    gaussian_block(tables, *beta_q, l, self.frame.lx, v)
                }
                Eval::GaussianSep { cols, i0, .. } => {
                    let i = (i64::from(ux) - i64::from(self.frame.anchor.x) - i0) as usize;
                    gaussian_sep_block(&cols[i..i + v.len()], row_factor, v)
                }
                Eval::Texture(t) => texture_block(t, l, self.frame.lx, v),
            }
            blend_block(fast, dst, v);
        }
    }
}

/// Texels per block of [`Piece::row_fast`].
const BLOCK: usize = 64;

/// `fixed::gaussian_v31` of `out.len()` texels inside the footprint from local `l`, `step`
/// apart (modulo 2^64 the same integers as `FixedFrame::local_q`'s). Compiled for AVX-512 and
/// AVX2 too (integer operations: the same bits on every instruction set).
#[multiversion::multiversion(targets(
    "x86_64+avx512f+avx512bw+avx512vl+avx512dq+avx2+fma",
    "x86_64+avx2+fma"
))]
fn gaussian_block(
    tables: &GaussianTables,
    beta_q: u32,
    l: [i64; 2],
    step: [i64; 2],
    out: &mut [i64],
) {
    for (i, o) in out.iter_mut().enumerate() {
        let i = i as i64;
        let l = [
            l[0].wrapping_add(i.wrapping_mul(step[0])),
            l[1].wrapping_add(i.wrapping_mul(step[1])),
        ];
        *o = tables.v31_inside(beta_q, l);
    }
}

/// `fixed::gaussian_sep_v31` of texels whose column factors are `cols` and row factor `row`;
/// compiled as [`gaussian_block`] is.
#[multiversion::multiversion(targets(
    "x86_64+avx512f+avx512bw+avx512vl+avx512dq+avx2+fma",
    "x86_64+avx2+fma"
))]
fn gaussian_sep_block(cols: &[u32], row: u32, out: &mut [i64]) {
    for (o, &c) in out.iter_mut().zip(cols) {
        *o = fixed::sep_product(c, row);
    }
}

/// `fixed::texture_v31` of `out.len()` texels inside the footprint from local `l`, `step`
/// apart; compiled as [`gaussian_block`] is.
#[multiversion::multiversion(targets(
    "x86_64+avx512f+avx512bw+avx512vl+avx512dq+avx2+fma",
    "x86_64+avx2+fma"
))]
fn texture_block(t: &PaddedTexture<'_>, l: [i64; 2], step: [i64; 2], out: &mut [i64]) {
    // The pixel coordinates (Q33) of `fixed::texture_v31`, stepped: the same integers modulo
    // 2^64 (`(L + i lx + 1) n - 1 = (L + 1) n - 1 + i lx n`).
    let pix = |l: i64, n: u32| {
        l.wrapping_add(LOCAL_ONE)
            .wrapping_mul(i64::from(n))
            .wrapping_sub(LOCAL_ONE)
    };
    let (px, pz) = (pix(l[0], t.w), pix(l[1], t.h));
    let (dx, dz) = (
        step[0].wrapping_mul(i64::from(t.w)),
        step[1].wrapping_mul(i64::from(t.h)),
    );
    for (i, o) in out.iter_mut().enumerate() {
        let i = i as i64;
        *o = texture_tap(
            t.values,
            t.stride,
            px.wrapping_add(i.wrapping_mul(dx)),
            pz.wrapping_add(i.wrapping_mul(dz)),
        );
    }
}

/// [`FixedBlend::blend`] of `dst` with values `v` for a right shift, then the clamp of
/// [`texel`]; compiled as [`gaussian_block`] is.
#[multiversion::multiversion(targets(
    "x86_64+avx512f+avx512bw+avx512vl+avx512dq+avx2+fma",
    "x86_64+avx2+fma"
))]
fn blend_block<T: HeightSample>(fast: &Fast<'_>, dst: &mut [T], v: &[i64]) {
    let (m, shift, base) = (fast.m, fast.shift, fast.base);
    let max = T::MAX_RAW as i64;
    let v = &v[..dst.len()];
    // |v31 m| < 2^61 (`FixedBlend::term_q16`).
    let term = |v: i64| (v * m) >> shift;
    match fast.kind {
        0 => {
            for (d, &v) in dst.iter_mut().zip(v) {
                *d = store(load(*d) + ((term(v) + (1 << 15)) >> 16), max);
            }
        }
        1 => {
            for (d, &v) in dst.iter_mut().zip(v) {
                *d = store(load(*d).min((base + term(v)) >> 16), max);
            }
        }
        _ => {
            for (d, &v) in dst.iter_mut().zip(v) {
                *d = store(load(*d).max((base + term(v)) >> 16), max);
            }
        }
    }
}

/// A stored value as an integer: a plain widening for the workspace's u8, u16 and u32.
#[inline(always)]
fn load<T: HeightSample>(d: T) -> i64 {
    use std::any::TypeId;
    if TypeId::of::<T>() == TypeId::of::<u16>() {
        i64::from(bytemuck::cast::<T, u16>(d))
    } else if TypeId::of::<T>() == TypeId::of::<u8>() {
        i64::from(bytemuck::cast::<T, u8>(d))
    } else if TypeId::of::<T>() == TypeId::of::<u32>() {
        i64::from(bytemuck::cast::<T, u32>(d))
    } else {
        d.to_raw_f64() as i64
    }
}

/// `v` clamped to `0..=max` (`T::MAX_RAW`) as a stored value, as [`texel`] converts it.
#[inline(always)]
fn store<T: HeightSample>(v: i64, max: i64) -> T {
    use std::any::TypeId;
    let v = v.clamp(0, max);
    if TypeId::of::<T>() == TypeId::of::<u16>() {
        bytemuck::cast(v as u16)
    } else if TypeId::of::<T>() == TypeId::of::<u8>() {
        bytemuck::cast(v as u8)
    } else if TypeId::of::<T>() == TypeId::of::<u32>() {
        bytemuck::cast(v as u32)
    } else {
        T::from_raw_f64_clamped(v as f64)
    }
}

/// The CPU's fast form of the program, for a monotone frame (every texel of a row span is
/// inside: no per-texel test) and a term that is a right shift (every finite placement whose
/// intensity is below ~2^22 encoding units per unit value); other placements run
/// [`Piece::row_texels`]. The same integers as [`texel`], bit for bit.
struct Fast<'a> {
    eval: Eval<'a>,
    kind: u32,
    /// The term's mantissa and right shift (at most 62).
    m: i64,
    shift: u32,
    /// The min / max base in Q16 plus one half (round half up).
    base: i64,
}

/// The value of a [`Fast`] kernel.
enum Eval<'a> {
    Gaussian(GaussianTables, u32),
    /// The separable Gaussian: the factor of every column `i0 + k` (`i` counted from the
    /// frame's anchor) of the pieces; each row's factor is computed per row.
    GaussianSep {
        tables: GaussianTables,
        beta_q: u32,
        cols: Vec<u32>,
        i0: i64,
    },
    Texture(PaddedTexture<'a>),
}

impl<'a> Fast<'a> {
    fn new(
        kernel: &'a Kernel<'_>,
        frame: &FixedFrame,
        op: &FixedBlend,
        pieces: &[(crate::rect::Rect, glam::IVec2)],
    ) -> Option<Self> {
        if !frame.monotone || op.shift < 0 {
            return None;
        }
        let eval = match kernel {
            Kernel::Gaussian(beta_q, false) => Eval::Gaussian(GaussianTables::get(), *beta_q),
            Kernel::Gaussian(beta_q, true) => {
                // Columns i = ux - anchor.x of every piece (unwrapped `[lo, hi)`).
                let cols = |r: &(crate::rect::Rect, glam::IVec2)| {
                    let lo = i64::from(r.0.min.x + r.1.x) - i64::from(frame.anchor.x);
                    (lo, lo + i64::from(r.0.size.x))
                };
                let i0 = pieces.iter().map(|r| cols(r).0).min()?;
                let i1 = pieces.iter().map(|r| cols(r).1).max()?;
                let tables = GaussianTables::get();
                let cols = (i0..i1)
                    .map(|i| {
                        let l = frame.l0[0].wrapping_add(i.wrapping_mul(frame.lx[0]));
                        tables.factor31(*beta_q, l)
                    })
                    .collect();
                Eval::GaussianSep {
                    tables,
                    beta_q: *beta_q,
                    cols,
                    i0,
                }
            }
            Kernel::Texture(t) => Eval::Texture(PaddedTexture {
                values: t.padded(),
                w: t.width(),
                h: t.height(),
                stride: t.width() as usize + 2,
            }),
            Kernel::PerTexel => return None,
        };
        Some(Self {
            eval,
            kind: op.kind,
            m: i64::from(op.m),
            shift: op.shift.min(62) as u32,
            base: op.base_q16 + (1 << 15),
        })
    }
}

/// Quantised texture values with a border of one copied pixel on every side
/// ([`QuantizedTexture`]'s): the clamped lookups of `fixed::texture_v31` without a clamp
/// (inside the footprint a pixel index is within `[-1, n]`).
struct PaddedTexture<'a> {
    values: &'a [i32],
    w: u32,
    h: u32,
    /// Row length of `values` (`w + 2`).
    stride: usize,
}

/// `fixed::texture_v31` at the pixel coordinates (Q33) `px`, `pz` of a texel inside.
#[inline(always)]
fn texture_tap(values: &[i32], stride: usize, px: i64, pz: i64) -> i64 {
    // Inside: px, pz >= -2^32, so the padded indices (px >> 33) + 1 are >= 0, and the four
    // taps are within the padded values.
    let x = ((px >> 33) + 1) as usize;
    let z = ((pz >> 33) + 1) as usize;
    let (fx, fz) = ((px >> 21) & 4095, (pz >> 21) & 4095);
    let i = z * stride + x;
    let at = |k: usize| i64::from(values[k]);
    let top = at(i) * (4096 - fx) + at(i + 1) * fx;
    let bot = at(i + stride) * (4096 - fx) + at(i + stride + 1) * fx;
    (top * (4096 - fz) + bot * fz) >> 17
}

#[cfg(test)]
mod tests {
    use super::super::{
        Blend, GaussianStamp, StampPlacement, TextureStamp, apply_stamp, apply_stamp_reference,
    };
    use crate::grid::{Grid, WrapMode};
    use crate::map::{HeightEncoding, HeightMap, HeightSample};
    use glam::Vec2;

    /// A small deterministic generator (the test needs no crate for it).
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f32 {
            self.0 = self
                .0
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (self.0 >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    fn map<T: HeightSample>(w: u32, h: u32, scale: f32, wrap: WrapMode) -> HeightMap<T> {
        let g = Grid::from_fn(w, h, |x, y| {
            let v = (x.wrapping_mul(2_654_435_761) ^ y.wrapping_mul(40_503)) % 1000;
            T::from_raw_f64_clamped(T::MAX_RAW * 0.3 + f64::from(v) * T::MAX_RAW * 4e-4)
        })
        .unwrap();
        let e = HeightEncoding::new(scale, 0.0).unwrap();
        HeightMap::new(g, e, 0.5, wrap).unwrap()
    }

    /// `apply_stamp` (on 1 and 3 threads) equals `apply_stamp_reference` texel for texel.
    fn check<T: HeightSample + PartialEq + std::fmt::Debug>(
        m: &HeightMap<T>,
        gaussian: bool,
        p: &StampPlacement,
        b: Blend,
    ) {
        let tex = Grid::from_fn(13, 9, |x, y| ((x * 37 + y * 101) % 256) as u8).unwrap();
        let run = |reference: bool, threads: usize| {
            let mut m = m.clone();
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let r = match (gaussian, reference) {
                    (true, false) => apply_stamp(&mut m, &mut GaussianStamp::default(), p, b),
                    (true, true) => {
                        apply_stamp_reference(&mut m, &mut GaussianStamp::default(), p, b)
                    }
                    (false, false) => {
                        apply_stamp(&mut m, &mut TextureStamp::from_gray8(&tex), p, b)
                    }
                    (false, true) => {
                        apply_stamp_reference(&mut m, &mut TextureStamp::from_gray8(&tex), p, b)
                    }
                };
                r.map(|_| m)
            })
        };
        let want = run(true, 1);
        for threads in [1, 3] {
            let got = run(false, threads);
            match (&got, &want) {
                (Ok(g), Ok(w)) => {
                    let bad = g
                        .grid()
                        .as_slice()
                        .iter()
                        .zip(w.grid().as_slice())
                        .position(|(a, b)| a != b);
                    assert!(
                        bad.is_none(),
                        "{p:?} {b:?} gaussian {gaussian}, {threads} threads: texel {bad:?}"
                    );
                }
                _ => assert_eq!(got.is_ok(), want.is_ok(), "{p:?} {b:?}"),
            }
        }
    }

    /// The blocked rows (Gaussian and texture, every blend, u8 / u16 / u32, both wraps,
    /// footprints small and large enough to run in parallel, rotated or not, intensities that
    /// make the term a left shift) equal the per-texel reference bit for bit.
    #[test]
    fn blocked_rows_equal_the_per_texel_reference() {
        let mut r = Lcg(7);
        for case in 0..120 {
            let big = case % 4 == 0;
            let side = if big {
                90.0 + 60.0 * r.next()
            } else {
                1.0 + 25.0 * r.next()
            };
            let aspect = if case % 3 == 0 { 1.0 } else { 0.3 + r.next() };
            let rotation = match case % 5 {
                0 => 0.0,
                1 => std::f32::consts::FRAC_PI_2,
                _ => 7.0 * r.next() - 3.5,
            };
            let intensity = match case % 7 {
                0 => 1e9 * (r.next() - 0.5),
                1 => 1e-6,
                _ => 40.0 * (r.next() - 0.5),
            };
            let centre = Vec2::new(r.next() * 110.0 - 5.0, r.next() * 100.0 - 5.0);
            let p = StampPlacement::new(centre, Vec2::new(side, side * aspect), intensity)
                .unwrap()
                .with_rotation(rotation)
                .unwrap();
            let base = 60.0 * r.next();
            let b = [
                Blend::Add,
                Blend::Min { base_m: base },
                Blend::Max { base_m: base },
            ][case % 3];
            let wrap = if case % 2 == 0 {
                WrapMode::Repeat
            } else {
                WrapMode::Clamp
            };
            let gaussian = case % 4 < 2;
            match case % 3 {
                0 => check(&map::<u16>(210, 190, 0.01, wrap), gaussian, &p, b),
                1 => check(&map::<u8>(210, 190, 0.4, wrap), gaussian, &p, b),
                _ => check(&map::<u32>(210, 190, 1e-4, wrap), gaussian, &p, b),
            }
        }
    }
}
