//! The exact stamp program: every stamp kind and blend evaluated in integer (fixed-point)
//! arithmetic, so the CPU ([`apply_stamp`](super::apply_stamp)) and the GPU pass (terrain-gpu's
//! `stamp.wgsl`, which runs this same program on 32-bit integers with 64-bit values emulated)
//! give bit-identical heights on any conforming GPU.
//!
//! Why integers: WGSL's f32 `exp` (and `sqrt`, `length`, ...) may differ between GPUs by
//! ulps, and a GPU compiler may fuse `a * b + c` into an `fma` (naga emits no `NoContraction`),
//! so no f32 expression with an inexact product is reproducible. Integer `+ - * >>` wrap or
//! floor exactly the same way everywhere. Every per-placement value (the local frame, the
//! Gaussian's falloff, the blend's scale and base) is computed once, here on the CPU, rounded to
//! integers and handed to the GPU unchanged; what depends on the placement's floats (`sin`,
//! `cos`, `ln`, `exp` of the tables) is therefore computed once, with the pure-Rust `libm`
//! crate, so every platform gets the same integers.
//!
//! The program, per texel at unwrapped coordinates `(ux, uy)`:
//! 1. Local coordinates in Q32 (`local * 2^32`): `L = l0 + i lx + j ly` (wrapping i64) with
//!    `i = ux - anchor.x`, `j = uy - anchor.y` (both `>= 0`: the anchor is the footprint's
//!    first texel). Inside the footprint iff `|L.x| <= 2^32` and `|L.y| <= 2^32`.
//! 2. The stamp value `v31` (`value * 2^31`, i64):
//!    - Gaussian, separable frame (`lx.y == 0` and `ly.x == 0`: unrotated; [`gaussian_separable`]):
//!      `exp(-beta x^2) exp(-beta y^2)` as two factors of one axis each
//!      ([`gaussian_factor31`]: `x2 = (L.x >> 8)^2 >> 18` in Q30, `t = (beta_q x2) >> 27` in
//!      Q26, `exp(-t)` from the tables as below), multiplied and rounded half up:
//!      `(fx fy + 2^30) >> 31`. X depends on the column only and Y on the row only, so the CPU
//!      computes the factors once per column and row: one product per texel.
//!    - Gaussian, any other frame: `r2 = ((L.x >> 8)^2 + (L.y >> 8)^2) >> 18` (`r^2` in Q30),
//!      `t = (beta_q r2) >> 27` (`beta r^2` in Q26, `beta_q = round(beta 2^23)`), and `exp(-t)`
//!      as the product of three table entries (Q31) for the bits of `t` (`>> 31` after each
//!      product): no `exp` on either side. `t >= 22` gives 0.
//!    - Texture: values quantised once to Q24 (`round(v 2^24)`, clamped to `+-64`); the pixel
//!      coordinate `((local + 1) n / 2 - 1/2)` in Q33; the bilinear weights in Q12; the
//!      interpolation exact in Q48, then `>> 17`.
//!    - User procedural (CPU [`Stamp::value`](super::Stamp::value), GPU WGSL): its f32 value at
//!      `local = f32(L >> 8) * 2^-24` (exact: an integer below 2^24 times a power of two),
//!      clamped to `+-64` and turned into `trunc(v 2^31)` with f32 operations that are all
//!      exact (see [`user_v31`]). The result is exact iff the user's two functions return the
//!      same f32 for the same `local`: write them with exact operations (comparisons, sums and
//!      products of few bits), not `length`, `exp` or `a * b + c` with an inexact product.
//! 3. The term in Q16 stored units: `(v31 m) >> s` (an arithmetic shift: floor), where
//!    `m 2^(15 - s)` is `intensity / encoding scale` rounded to a 24-bit mantissa `m` (the
//!    precision of an f32); a negative `s` is a left shift saturating at `+-2^62`.
//! 4. The blend: add `old + ((term + 2^15) >> 16)`; min / max
//!    `min/max(old, (base_q16 + term + 2^15) >> 16)` with `base_q16 = round(base_raw 2^16)`
//!    (a half-unit base is exact); clamped to the sample's range.

use glam::{IVec2, Vec2};
use std::sync::OnceLock;

/// `1.0` in the Q32 local coordinates.
pub const LOCAL_ONE: i64 = 1 << 32;
/// Largest magnitude of a texture value (quantised values are clamped to it).
pub const VALUE_LIMIT: f32 = 64.0;
/// Fraction bits of a quantised texture value.
pub const TEXTURE_FRACTION_BITS: u32 = 24;
/// Entries of the three Gaussian tables (`exp(-k 2^-6)`, `exp(-k 2^-16)`, `exp(-k 2^-26)`),
/// laid out one after the other in [`gaussian_tables`].
pub const EXP_HI_LEN: usize = 22 * 64;
/// See [`EXP_HI_LEN`].
pub const EXP_MID_LEN: usize = 1024;
/// See [`EXP_HI_LEN`].
pub const EXP_LO_LEN: usize = 1024;
/// `beta r^2` in Q26 from which the Gaussian is 0.
pub const EXP_T_LIMIT: u64 = (EXP_HI_LEN as u64) << 20;

/// The per-placement local frame as integers (see the module docs, step 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FixedFrame {
    /// The footprint's first texel (unwrapped): `i = ux - anchor.x`, `j = uy - anchor.y`.
    pub anchor: IVec2,
    /// Local coordinates (Q32) of the anchor texel.
    pub l0: [i64; 2],
    /// Change of the local coordinates per column.
    pub lx: [i64; 2],
    /// Change of the local coordinates per row.
    pub ly: [i64; 2],
    /// Whether `|l0| + w |lx| + h |ly|` over the footprint stays below 2^62 (no wrapping, so
    /// the inside test is monotone along a row); the CPU tests each texel otherwise.
    pub monotone: bool,
}

impl FixedFrame {
    /// The frame of a footprint `anchor` / `size` (texels) for a stamp centred at `center`
    /// (texels), `inv_half` (1 / half-size in texels) and rotation `(sin, cos)`, all in f64.
    pub fn new(
        anchor: IVec2,
        size: glam::UVec2,
        center: glam::DVec2,
        inv_half: glam::DVec2,
        sin: f64,
        cos: f64,
    ) -> Self {
        let q = |v: f64, lim: f64| -> i64 {
            let v = (v * LOCAL_ONE as f64).round();
            if v.is_nan() {
                0
            } else {
                v.clamp(-lim, lim) as i64
            }
        };
        // Steps of at most 256 local units per texel (a footprint under 1/128 texel), and an
        // anchor at most 2^20 units out: far outside in both cases.
        let (step_lim, l0_lim) = (2f64.powi(40), 2f64.powi(52));
        let d = anchor.as_dvec2() - center;
        let l0 = [
            q((d.x * cos + d.y * sin) * inv_half.x, l0_lim),
            q((d.y * cos - d.x * sin) * inv_half.y, l0_lim),
        ];
        let lx = [
            q(cos * inv_half.x, step_lim),
            q(-sin * inv_half.y, step_lim),
        ];
        let ly = [q(sin * inv_half.x, step_lim), q(cos * inv_half.y, step_lim)];
        let reach = |k: usize| {
            (l0[k] as f64).abs()
                + f64::from(size.x) * (lx[k] as f64).abs()
                + f64::from(size.y) * (ly[k] as f64).abs()
        };
        let monotone = reach(0).max(reach(1)) < 2f64.powi(62);
        Self {
            anchor,
            l0,
            lx,
            ly,
            monotone,
        }
    }

    /// Local coordinates (Q32) of unwrapped texel `(ux, uy)`; wrapping, as the GPU's.
    #[inline(always)]
    pub fn local_q(&self, ux: i32, uy: i32) -> [i64; 2] {
        let i = i64::from(ux.wrapping_sub(self.anchor.x) as u32);
        let j = i64::from(uy.wrapping_sub(self.anchor.y) as u32);
        [0, 1].map(|k| {
            self.l0[k]
                .wrapping_add(i.wrapping_mul(self.lx[k]))
                .wrapping_add(j.wrapping_mul(self.ly[k]))
        })
    }
}

/// Whether Q32 local coordinates are inside the footprint (`|local| <= 1` on both axes).
#[inline(always)]
pub fn inside(l: [i64; 2]) -> bool {
    (-LOCAL_ONE..=LOCAL_ONE).contains(&l[0]) && (-LOCAL_ONE..=LOCAL_ONE).contains(&l[1])
}

/// The f32 local coordinates handed to a user stamp: `f32(L >> 8) * 2^-24`, exact for a texel
/// inside the footprint (`|L >> 8| <= 2^24`).
#[inline(always)]
pub fn local_f32(l: [i64; 2]) -> Vec2 {
    let c = |v: i64| ((v >> 8) as i32) as f32 * (1.0 / 16_777_216.0);
    Vec2::new(c(l[0]), c(l[1]))
}

/// Every Gaussian table entry, laid out as [`gaussian_tables`] returns them.
const EXP_TABLES_LEN: usize = EXP_HI_LEN + EXP_MID_LEN + EXP_LO_LEN;

/// The three Gaussian tables, Q31: `exp(-k 2^-6)` for `k < EXP_HI_LEN`, then `exp(-k 2^-16)`
/// and `exp(-k 2^-26)` for `k < 1024`. Computed once with the pure-Rust `libm` crate's `exp`
/// (the same bits on every platform, whatever its C library or instruction set), rounded to
/// nearest, and uploaded unchanged by the GPU pass.
pub fn gaussian_tables() -> &'static [u32] {
    &exp_tables()[..]
}

/// [`gaussian_tables`] as one array (so [`GaussianTables`] can split it without a check).
fn exp_tables() -> &'static [u32; EXP_TABLES_LEN] {
    static TABLES: OnceLock<Box<[u32; EXP_TABLES_LEN]>> = OnceLock::new();
    TABLES.get_or_init(|| {
        let q = |x: f64| (libm::exp(-x) * 2f64.powi(31)).round() as u32;
        let mut t = Box::new([0u32; EXP_TABLES_LEN]);
        let (hi, rest) = t.split_at_mut(EXP_HI_LEN);
        let (mid, lo) = rest.split_at_mut(EXP_MID_LEN);
        for (k, e) in hi.iter_mut().enumerate() {
            *e = q(k as f64 / 64.0);
        }
        for (k, e) in mid.iter_mut().enumerate() {
            *e = q(k as f64 / 65_536.0);
        }
        for (k, e) in lo.iter_mut().enumerate() {
            *e = q(k as f64 / 67_108_864.0);
        }
        t
    })
}

/// The three Gaussian tables as arrays of their own lengths: indices masked to a table's
/// length need no bounds check in the CPU's inner loops.
#[derive(Debug, Clone, Copy)]
pub(crate) struct GaussianTables {
    hi: &'static [u32; EXP_HI_LEN],
    mid: &'static [u32; EXP_MID_LEN],
    lo: &'static [u32; EXP_LO_LEN],
}

impl GaussianTables {
    /// The tables of [`gaussian_tables`].
    pub(crate) fn get() -> Self {
        let (hi, rest) = exp_tables()
            .split_first_chunk::<EXP_HI_LEN>()
            .expect("lengths");
        let (mid, lo) = rest.split_first_chunk::<EXP_MID_LEN>().expect("lengths");
        let lo = lo.first_chunk::<EXP_LO_LEN>().expect("lengths");
        Self { hi, mid, lo }
    }

    /// [`gaussian_v31`] at a texel inside the footprint (`|L| <= 2^32`), in 32-bit pieces
    /// where the values fit (so a vectorised loop multiplies 32 x 32 bits) and without a
    /// branch: the same integers.
    #[inline(always)]
    pub(crate) fn v31_inside(&self, beta_q: u32, l: [i64; 2]) -> i64 {
        // |L >> 8| <= 2^24 fits an i32; r2 <= 2^31 a u32.
        let sq = |v: i64| {
            let a = ((v >> 8) as i32).unsigned_abs();
            u64::from(a) * u64::from(a)
        };
        let r2 = ((sq(l[0]) + sq(l[1])) >> 18) as u32;
        let t = (u64::from(beta_q) * u64::from(r2)) >> 27;
        let tc = t.min(EXP_T_LIMIT - 1) as u32;
        let hi = self.hi[((tc >> 20) as usize).min(EXP_HI_LEN - 1)];
        let mid = self.mid[((tc >> 10) & 1023) as usize];
        let lo = self.lo[(tc & 1023) as usize];
        // Table entries are at most 2^31, so the product shifted is too.
        let p = ((u64::from(hi) * u64::from(mid)) >> 31) as u32;
        let v = ((u64::from(p) * u64::from(lo)) >> 31) as i64;
        if t >= EXP_T_LIMIT { 0 } else { v }
    }

    /// [`gaussian_factor31`] with these tables. Any `l` gives some value without a panic (the
    /// CPU fills its column factors for every column of a footprint); the program's only at a
    /// texel inside.
    #[inline(always)]
    pub(crate) fn factor31(&self, beta_q: u32, l: i64) -> u32 {
        // Inside |L >> 8| <= 2^24: x2 <= 2^30.
        let a = ((l >> 8) as i32).unsigned_abs();
        let x2 = ((u64::from(a) * u64::from(a)) >> 18) as u32;
        let t = (u64::from(beta_q) * u64::from(x2)) >> 27;
        let tc = t.min(EXP_T_LIMIT - 1) as u32;
        let hi = self.hi[((tc >> 20) as usize).min(EXP_HI_LEN - 1)];
        let mid = self.mid[((tc >> 10) & 1023) as usize];
        let lo = self.lo[(tc & 1023) as usize];
        let p = ((u64::from(hi) * u64::from(mid)) >> 31) as u32;
        let v = ((u64::from(p) * u64::from(lo)) >> 31) as u32;
        if t >= EXP_T_LIMIT { 0 } else { v }
    }

    /// [`gaussian_v31`] with these tables.
    #[inline(always)]
    pub(crate) fn v31(&self, beta_q: u32, l: [i64; 2]) -> i64 {
        let sq = |v: i64| {
            let a = (v >> 8).unsigned_abs();
            a * a
        };
        // Inside the footprint |L >> 8| <= 2^24: r2 <= 2^31.
        let r2 = (sq(l[0]) + sq(l[1])) >> 18;
        let t = (u64::from(beta_q) * r2) >> 27;
        if t >= EXP_T_LIMIT {
            return 0;
        }
        let hi = u64::from(self.hi[(t >> 20) as usize]);
        let mid = u64::from(self.mid[((t >> 10) & 1023) as usize]);
        let lo = u64::from(self.lo[(t & 1023) as usize]);
        ((((hi * mid) >> 31) * lo) >> 31) as i64
    }
}

/// `round(beta 2^23)` for a Gaussian falloff (0 for NaN or negative values; `beta` from
/// [`crate::GaussianStamp::beta_for`] is at most ~192).
pub fn gaussian_beta_q(beta: f32) -> u32 {
    let b = (f64::from(beta) * 2f64.powi(23)).round();
    if b.is_nan() {
        0
    } else {
        b.clamp(0.0, f64::from(u32::MAX)) as u32
    }
}

/// `exp(-beta r^2) * 2^31` at Q32 local coordinates `l` of a frame that is not
/// [`gaussian_separable`] (module docs, step 2).
#[inline(always)]
pub fn gaussian_v31(beta_q: u32, l: [i64; 2]) -> i64 {
    GaussianTables::get().v31(beta_q, l)
}

/// Whether the frame's Gaussian is the separable program ([`gaussian_sep_v31`]): local X
/// depends on the column only and local Y on the row only (`lx.y == 0` and `ly.x == 0`, an
/// unrotated placement), decided from the integers alone, as the GPU decides.
#[inline(always)]
pub fn gaussian_separable(frame: &FixedFrame) -> bool {
    frame.lx[1] == 0 && frame.ly[0] == 0
}

/// `exp(-beta x^2) * 2^31` of one Q32 local coordinate `l` inside the footprint (`|l| <=
/// 2^32`): `x2 = (|l >> 8|^2) >> 18` (Q30), `t = (beta_q x2) >> 27` (Q26), and the three
/// tables' product as in [`gaussian_v31`]; `t >= 22` gives 0.
#[inline(always)]
pub fn gaussian_factor31(beta_q: u32, l: i64) -> u32 {
    GaussianTables::get().factor31(beta_q, l)
}

/// The separable Gaussian at Q32 local `l` inside the footprint: the product of the two axes'
/// factors ([`gaussian_factor31`]), rounded half up to Q31: `(fx fy + 2^30) >> 31`.
#[inline(always)]
pub fn gaussian_sep_v31(beta_q: u32, l: [i64; 2]) -> i64 {
    let t = GaussianTables::get();
    sep_product(t.factor31(beta_q, l[0]), t.factor31(beta_q, l[1]))
}

/// `(fx fy + 2^30) >> 31`: both at most 2^31, so the sum fits a u64.
#[inline(always)]
pub(crate) fn sep_product(fx: u32, fy: u32) -> i64 {
    ((u64::from(fx) * u64::from(fy) + (1 << 30)) >> 31) as i64
}

/// A texture value quantised to Q24, clamped to `+-VALUE_LIMIT` (what the GPU pass uploads).
pub fn quantize_texture_value(v: f32) -> i32 {
    let lim = f64::from(VALUE_LIMIT) * 2f64.powi(TEXTURE_FRACTION_BITS as i32);
    // `round` (half away from zero) of the clamped value without a call to `round` (a library
    // call without SSE4.1; a texture is quantised once per stamp): the clamp's bounds are
    // integers, so clamping first changes nothing; `as` truncates exactly (NaN gives 0) and
    // the fraction `x - trunc(x)` is exact below 2^52.
    let x = (f64::from(v) * 2f64.powi(TEXTURE_FRACTION_BITS as i32)).clamp(-lim, lim);
    let t = x as i32;
    let frac = x - f64::from(t);
    if frac >= 0.5 {
        t + 1
    } else if frac <= -0.5 {
        t - 1
    } else {
        t
    }
}

/// A texture's values quantised to Q24 ([`quantize_texture_value`]): what the exact program
/// samples, computed once per texture (a [`TextureStamp`](super::TextureStamp) keeps its own),
/// with a copy bordered by one repeated pixel on every side (the CPU's clamped lookups without
/// a clamp).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct QuantizedTexture {
    values: Vec<i32>,
    padded: Vec<i32>,
    w: u32,
    h: u32,
}

impl QuantizedTexture {
    /// Quantises `values` (each as [`quantize_texture_value`]).
    pub fn new(values: &crate::grid::Grid<f32>) -> Self {
        let (w, h) = (values.width(), values.height());
        let q: Vec<i32> = values
            .as_slice()
            .iter()
            .map(|&v| quantize_texture_value(v))
            .collect();
        let mut padded = Vec::new();
        if w > 0 && h > 0 {
            padded.reserve((w as usize + 2) * (h as usize + 2));
            for z in -1..=i64::from(h) {
                let row = &q[z.clamp(0, i64::from(h) - 1) as usize * w as usize..][..w as usize];
                padded.push(row[0]);
                padded.extend_from_slice(row);
                padded.push(row[w as usize - 1]);
            }
        }
        Self {
            values: q,
            padded,
            w,
            h,
        }
    }

    /// The Q24 values, row-major (what the GPU pass uploads).
    pub fn values(&self) -> &[i32] {
        &self.values
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.w
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.h
    }

    /// The values with their one-pixel border, rows of `width + 2`.
    pub(crate) fn padded(&self) -> &[i32] {
        &self.padded
    }
}

/// The bilinear value `* 2^31` of quantised texture `values` (`w` x `h`, row-major, pixel
/// centres at `(i + 0.5) / n` of the footprint, clamped at the edges) at Q32 local `l` inside
/// the footprint (module docs, step 2).
#[inline(always)]
pub fn texture_v31(values: &[i32], w: u32, h: u32, l: [i64; 2]) -> i64 {
    // Pixel coordinate `(local + 1) n / 2 - 1/2` in Q33: `(L + 2^32) n - 2^32`.
    let pix = |l: i64, n: u32| (l + LOCAL_ONE).wrapping_mul(i64::from(n)) - LOCAL_ONE;
    let (px, pz) = (pix(l[0], w), pix(l[1], h));
    let (x0, z0) = ((px >> 33) as i32, (pz >> 33) as i32);
    let (fx, fz) = (((px >> 21) & 4095), ((pz >> 21) & 4095));
    let at = |x: i32, z: i32| {
        let x = x.clamp(0, w as i32 - 1) as usize;
        let z = z.clamp(0, h as i32 - 1) as usize;
        i64::from(values[z * w as usize + x])
    };
    let top = at(x0, z0) * (4096 - fx) + at(x0 + 1, z0) * fx;
    let bot = at(x0, z0 + 1) * (4096 - fx) + at(x0 + 1, z0 + 1) * fx;
    (top * (4096 - fz) + bot * fz) >> 17
}

/// `trunc(v 2^31)` of a user stamp's finite f32 value clamped to `+-VALUE_LIMIT`, through f32
/// operations that are each exact (so the GPU, which computes the same steps, cannot round or
/// fuse them differently): with `s = |v| 2^7` (a product by a power of two: exact),
/// `a = floor(s)` (exact), `r = s - a` (exact: the bits of `s` below the unit, representable
/// since `s` is non-negative), the magnitude is `a 2^24 + floor(r 2^24)`.
/// Subnormal values count as 0 (a GPU may flush them).
pub fn user_v31(v: f32) -> i64 {
    let v = v.clamp(-VALUE_LIMIT, VALUE_LIMIT);
    let v = if v.abs() < f32::MIN_POSITIVE { 0.0 } else { v };
    let s = v.abs() * 128.0;
    let a = s.floor();
    let r = s - a;
    let mag = i64::from(a as i32) * (1 << 24) + i64::from((r * 16_777_216.0).floor() as i32);
    if v < 0.0 { -mag } else { mag }
}

/// The blend as integers (module docs, steps 3 and 4).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FixedBlend {
    /// 0 add, 1 min, 2 max.
    pub kind: u32,
    /// Signed 24-bit mantissa of `intensity / encoding scale`.
    pub m: i32,
    /// Right shift of `v31 m` to Q16 stored units (negative: saturating left shift).
    pub shift: i32,
    /// The min / max base in Q16 stored units (0 for add).
    pub base_q16: i64,
}

/// Largest magnitude of a term or base (Q16) before the sum.
const SATURATE: i64 = 1 << 62;

impl FixedBlend {
    /// From the f64 stored units per unit value and the base in stored units.
    pub fn new(kind: u32, add_scale: f64, base_raw: f64) -> Self {
        let (m, shift) = if add_scale == 0.0 || !add_scale.is_finite() {
            (0, 0)
        } else {
            // |add_scale| = mant 2^(e - 23) with mant in [2^23, 2^24]: the exponent read
            // exactly from the bits (`frexp`, not a platform's `log2`), the scaling by a power
            // of two exact (`scalbn`), so the integers are the same on every platform.
            let (_, ex) = libm::frexp(add_scale.abs());
            let mut e = ex - 1;
            let mut mant = libm::scalbn(add_scale.abs(), 23 - e).round();
            if mant >= 16_777_216.0 {
                mant = 8_388_608.0;
                e += 1;
            }
            // term_q16 = v31 2^-31 mant 2^(e - 23) 2^16 = v31 mant >> (38 - e).
            let m = mant as i32 * if add_scale < 0.0 { -1 } else { 1 };
            (m, (38 - e).clamp(-64, 64))
        };
        let b = (base_raw * 65_536.0).round();
        let lim = (1i64 << 61) as f64;
        Self {
            kind,
            m,
            shift,
            base_q16: if kind == 0 || b.is_nan() {
                0
            } else {
                b.clamp(-lim, lim) as i64
            },
        }
    }

    /// The term in Q16 stored units of a value `v31` (`|v31| <= 2^37`), within `+-2^62`.
    #[inline(always)]
    pub fn term_q16(&self, v31: i64) -> i64 {
        let p = v31 * i64::from(self.m); // |p| < 2^61
        if self.shift >= 0 {
            if self.shift > 62 {
                p >> 62
            } else {
                p >> self.shift
            }
        } else {
            let ls = (-self.shift) as u32;
            if p == 0 {
                0
            } else if ls >= 62 || p.unsigned_abs() >= (1u64 << (62 - ls)) {
                p.signum() * SATURATE
            } else {
                p << ls
            }
        }
    }

    /// The new stored value of a texel holding `old`, not yet clamped to the sample's range.
    #[inline(always)]
    pub fn blend(&self, old: i64, v31: i64) -> i64 {
        let t = self.term_q16(v31);
        match self.kind {
            0 => old + ((t + (1 << 15)) >> 16),
            1 => old.min((self.base_q16 + t + (1 << 15)) >> 16),
            _ => old.max((self.base_q16 + t + (1 << 15)) >> 16),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaussian_equals_exp_closely() {
        let beta_q = gaussian_beta_q(4.6);
        for (x, y) in [(0.0, 0.0), (0.3, -0.2), (1.0, 1.0), (-0.7, 0.05)] {
            let l = [(x * 2f64.powi(32)) as i64, (y * 2f64.powi(32)) as i64];
            let got = gaussian_v31(beta_q, l) as f64 / 2f64.powi(31);
            let want = (-4.6f64 * (x * x + y * y)).exp();
            assert!((got - want).abs() < 1e-7, "({x}, {y}): {got} vs {want}");
        }
        assert_eq!(gaussian_v31(beta_q, [0, 0]), 1 << 31);
    }

    #[test]
    fn separable_gaussian_equals_exp_closely() {
        let beta_q = gaussian_beta_q(4.6);
        for (x, y) in [
            (0.0, 0.0),
            (0.3, -0.2),
            (1.0, 1.0),
            (-0.7, 0.05),
            (1.0, 0.0),
        ] {
            let l = [(x * 2f64.powi(32)) as i64, (y * 2f64.powi(32)) as i64];
            let got = gaussian_sep_v31(beta_q, l) as f64 / 2f64.powi(31);
            let want = (-4.6f64 * (x * x + y * y)).exp();
            assert!((got - want).abs() < 1e-7, "({x}, {y}): {got} vs {want}");
            let radial = gaussian_v31(beta_q, l);
            assert!(
                (gaussian_sep_v31(beta_q, l) - radial).abs() <= 64,
                "({x}, {y})"
            );
        }
        assert_eq!(gaussian_sep_v31(beta_q, [0, 0]), 1 << 31);
        assert_eq!(gaussian_factor31(beta_q, 0), 1 << 31);
    }

    #[test]
    fn blend_terms_round_half_up_and_half_unit_bases_are_exact() {
        // 1 stored unit per unit value, base 32767.5: max(0, base + 0) rounds half up.
        let b = FixedBlend::new(2, 1.0, 32_767.5);
        assert_eq!(b.base_q16, 32_767 * 65_536 + 32_768);
        assert_eq!(b.blend(0, 0), 32_768);
        let b = FixedBlend::new(0, 200.000_000_3, 0.0);
        assert_eq!(b.blend(5, 1 << 31), 205);
        let b = FixedBlend::new(0, -3.0, 0.0);
        assert_eq!(b.blend(10, 1 << 30), 9); // 10 - 1.5 rounds half up to 9
        let far = FixedBlend::new(1, -1e5, 1e5);
        assert_eq!(far.blend(500, 1 << 31), 0);
    }

    #[test]
    fn texture_values_round_as_f64_round() {
        let mut v = [
            0.0f32,
            0.5,
            -0.5,
            1.0,
            64.0,
            -64.0,
            65.0,
            -1e9,
            f32::NAN,
            f32::INFINITY,
        ]
        .to_vec();
        // Halves of the Q24 step, both signs, and values around them.
        for k in [1i32, 3, 5, 1 << 20, (1 << 30) - 1] {
            let h = (k as f32) * 2f32.powi(-25);
            v.extend([
                h,
                -h,
                h.next_up(),
                h.next_down(),
                -h.next_up(),
                -h.next_down(),
            ]);
        }
        for v in v {
            let lim = 64.0 * 2f64.powi(24);
            let q = (f64::from(v) * 2f64.powi(24)).round();
            let want = if q.is_nan() {
                0
            } else {
                q.clamp(-lim, lim) as i32
            };
            assert_eq!(quantize_texture_value(v), want, "{v}");
        }
    }

    #[test]
    fn user_values_floor_exactly() {
        for v in [
            0.0f32, 1.0, -1.0, 0.3, -0.3, 1e-30, -1e-30, 63.9, -64.0, 1e-7, -1e-7, 100.0,
        ] {
            let want = (f64::from(v.clamp(-64.0, 64.0)) * 2f64.powi(31)).trunc() as i64;
            assert_eq!(user_v31(v), want, "{v}");
        }
    }
}
