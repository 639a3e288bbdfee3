// StampPass: applies one stamp to a height buffer (texels packed into u32 words, packed.wgsl),
// in place. Each invocation reads and writes only its own word, so no backup copy of the map is
// needed (Flower 2010 measured its backup copy as the deformation bottleneck).
//
// Exact: this is terrain-core's exact stamp program (terrain_core::stamp::fixed), step for step,
// in 32-bit integers with its 64-bit values emulated as vec2<u32> (lo, hi), two's complement.
// Integer `+ - * << >>` wrap and floor identically on every conforming GPU and on the CPU, so
// the heights are bit-identical to terrain-core's. The only f32 arithmetic left is
//  - the local coordinates handed to a user stamp: f32(i32 below 2^24) * 2^-24, both exact;
//  - the user value's conversion (`user_v31`): |v| * 128, floor, s - floor(s), r * 2^24,
//    floor: each exact (products by powers of two, floor, and the fraction of a non-negative
//    float), so neither rounding nor a fused multiply-add can change them;
//  - the user's own function, which the caller must write exactly (see the Rust docs).
// No `exp`, no `a * b + c` with an inexact product, no division.

struct StampParams {
    // Footprint in unwrapped texel coordinates: row j of invocations handles its row
    // region_min.y + j, invocation i the i-th word of that row it touches (packed_group).
    region_min: vec2<i32>,
    region_size: vec2<u32>,
    map_size: vec2<u32>,
    // 0: repeat (toroidal), 1: clamp (the region is already clipped to the map).
    wrap: u32,
    // 0: Gaussian, 1: texture, 2: user procedural.
    kind: u32,
    // The frame: texel (ux, uy) has Q32 local coordinates l0 + i lx + j ly with
    // i = ux - anchor.x, j = uy - anchor.y (i64 values as (lo, hi)).
    anchor: vec2<i32>,
    l0x: vec2<u32>,
    l0y: vec2<u32>,
    lxx: vec2<u32>,
    lxy: vec2<u32>,
    lyx: vec2<u32>,
    lyy: vec2<u32>,
    // The min / max base in Q16 stored units.
    base_q16: vec2<u32>,
    // 0: add, 1: min, 2: max.
    blend: u32,
    // intensity / encoding scale as m 2^(15 - shift) (Q16 term = v31 m >> shift).
    m: i32,
    shift: i32,
    // Largest stored value (255 or 65535).
    max_raw: u32,
    // Gaussian falloff, round(beta 2^23).
    beta_q: u32,
    // Word of `heights` where the map starts (a tile slot of an atlas; 0 for a whole map).
    base: u32,
    // Size of the texture stamp's values.
    tex_size: vec2<u32>,
    // A multiple of the map size that makes every unwrapped coordinate of the region
    // non-negative: `%` of negative integers is undefined in GLSL, so wrap only non-negatives.
    wrap_offset: vec2<i32>,
    // Added to an unwrapped coordinate of a clamped map to give the texel it writes: 0 for a
    // whole map, minus the tile's origin for a detail tile stamped in its layer's frame.
    texel_offset: vec2<i32>,
    // The spill window (a detail stamp whose excess spills into the coarse-map): unwrapped
    // coordinates of its texel (0, 0) and its width; width 0 writes no excess.
    spill_min: vec2<i32>,
    spill_width: u32,
    // Bits per stored texel (8 or 16; packed.wgsl).
    bits: u32,
    // The region's first column made non-negative (region_min.x plus wrap_offset.x on a
    // repeating map, plus texel_offset.x on a clamped one): where its word groups start.
    start_x: u32,
    pad1: u32,
}

@group(0) @binding(0) var<uniform> p: StampParams;
@group(0) @binding(1) var<storage, read_write> heights: array<u32>;
// A texture stamp's values quantised to Q24 (terrain-core's quantize_texture_value).
@group(0) @binding(2) var<storage, read> tex: array<i32>;
// The excess beyond the clamped range per texel of the spill window, in stored units
// (terrain-core's `detail_spill`): read by SpillPass. A 1-element dummy when not spilling.
@group(0) @binding(3) var<storage, read_write> excess: array<i32>;
// The Gaussian tables (terrain-core's gaussian_tables): exp(-k 2^-6), exp(-k 2^-16),
// exp(-k 2^-26) in Q31, EXP_HI_LEN + 1024 + 1024 entries.
@group(0) @binding(4) var<storage, read> exp_table: array<u32>;

// The wide window of terrain-core's spill rule keeps WIDE_SHIFT units below a detail tile's
// range and as many above it (raw 0 of the tile is raw 32 640 of the window's u16).
const WIDE_SHIFT: i32 = 32640;
const EXP_HI_LEN: u32 = 1408u;
const EXP_T_LIMIT: u32 = 1476395008u; // EXP_HI_LEN << 20

// USER_STAMP_BEGIN
fn user_stamp_value(local: vec2<f32>) -> f32 {
    return 0.0;
}
// USER_STAMP_END

// ---- 64-bit integers as vec2<u32>(lo, hi), two's complement, wrapping ----
fn add64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let lo = a.x + b.x;
    return vec2<u32>(lo, a.y + b.y + select(0u, 1u, lo < a.x));
}
fn neg64(a: vec2<u32>) -> vec2<u32> {
    return add64(~a, vec2<u32>(1u, 0u));
}
fn from_i32(v: i32) -> vec2<u32> {
    return vec2<u32>(u32(v), select(0u, 0xffffffffu, v < 0));
}
fn is_neg64(a: vec2<u32>) -> bool {
    return i32(a.y) < 0;
}
// a < b, signed.
fn lt64(a: vec2<u32>, b: vec2<u32>) -> bool {
    if a.y != b.y {
        return i32(a.y) < i32(b.y);
    }
    return a.x < b.x;
}
// The full 64-bit product of two u32.
fn mul32(a: u32, b: u32) -> vec2<u32> {
    let a0 = a & 0xffffu;
    let a1 = a >> 16u;
    let b0 = b & 0xffffu;
    let b1 = b >> 16u;
    let p00 = a0 * b0;
    let p01 = a0 * b1;
    let p10 = a1 * b0;
    let p11 = a1 * b1;
    let mid = p01 + p10;
    let mid_carry = select(0u, 0x10000u, mid < p01);
    let lo = p00 + (mid << 16u);
    let c = select(0u, 1u, lo < p00);
    return vec2<u32>(lo, p11 + (mid >> 16u) + mid_carry + c);
}
// a * b modulo 2^64 (a signed or not, b unsigned): Rust's i64::wrapping_mul by a u32.
fn mul64(a: vec2<u32>, b: u32) -> vec2<u32> {
    let q = mul32(a.x, b);
    return vec2<u32>(q.x, q.y + a.y * b);
}
// Arithmetic shift right by s in [0, 63] (floor of a / 2^s).
fn sar64(a: vec2<u32>, s: u32) -> vec2<u32> {
    if s == 0u {
        return a;
    }
    if s < 32u {
        return vec2<u32>((a.x >> s) | (a.y << (32u - s)), u32(i32(a.y) >> s));
    }
    return vec2<u32>(u32(i32(a.y) >> (s - 32u)), u32(i32(a.y) >> 31u));
}
// Logical shift right by s in [0, 63].
fn shr64(a: vec2<u32>, s: u32) -> vec2<u32> {
    if s == 0u {
        return a;
    }
    if s < 32u {
        return vec2<u32>((a.x >> s) | (a.y << (32u - s)), a.y >> s);
    }
    return vec2<u32>(a.y >> (s - 32u), 0u);
}
// Shift left by s in [1, 62].
fn shl64(a: vec2<u32>, s: u32) -> vec2<u32> {
    if s < 32u {
        return vec2<u32>(a.x << s, (a.y << s) | (a.x >> (32u - s)));
    }
    return vec2<u32>(0u, a.x << (s - 32u));
}
// clamp(a, lo, hi) as an i32.
fn clamp64(a: vec2<u32>, lo: i32, hi: i32) -> i32 {
    if lt64(a, from_i32(lo)) {
        return lo;
    }
    if lt64(from_i32(hi), a) {
        return hi;
    }
    return i32(a.x);
}

// ---- the program (terrain_core::stamp::fixed) ----

// -2^32 <= L <= 2^32.
fn inside1(l: vec2<u32>) -> bool {
    let hi = i32(l.y);
    return hi >= -1 && (hi < 1 || (hi == 1 && l.x == 0u));
}

// exp(-t) 2^31 from the three tables, t = beta x^2 in Q26 as (lo, hi); 0 from EXP_T_LIMIT.
fn exp_q31(t64: vec2<u32>) -> u32 {
    if t64.y != 0u || t64.x >= EXP_T_LIMIT {
        return 0u;
    }
    let t = t64.x;
    let hi = exp_table[t >> 20u];
    let mid = exp_table[EXP_HI_LEN + ((t >> 10u) & 1023u)];
    let lo = exp_table[EXP_HI_LEN + 1024u + (t & 1023u)];
    let hm = shr64(mul32(hi, mid), 31u).x;
    return shr64(mul32(hm, lo), 31u).x;
}

// One axis's factor of the separable Gaussian (terrain-core's gaussian_factor31).
fn gaussian_factor31(l: vec2<u32>) -> u32 {
    let a = u32(abs(i32(sar64(l, 8u).x)));
    let x2 = shr64(mul32(a, a), 18u).x;
    return exp_q31(shr64(mul32(p.beta_q, x2), 27u));
}

// The separable Gaussian (an unrotated frame: lxy == 0 and lyx == 0): (fx fy + 2^30) >> 31.
fn gaussian_sep_v31(lx: vec2<u32>, ly: vec2<u32>) -> vec2<u32> {
    let prod = add64(mul32(gaussian_factor31(lx), gaussian_factor31(ly)), vec2<u32>(0x40000000u, 0u));
    return shr64(prod, 31u);
}

fn gaussian_v31(lx: vec2<u32>, ly: vec2<u32>) -> vec2<u32> {
    let ax = u32(abs(i32(sar64(lx, 8u).x)));
    let ay = u32(abs(i32(sar64(ly, 8u).x)));
    let r2 = shr64(add64(mul32(ax, ax), mul32(ay, ay)), 18u).x;
    return vec2<u32>(exp_q31(shr64(mul32(p.beta_q, r2), 27u)), 0u);
}

fn tex_at(x: i32, y: i32) -> vec2<u32> {
    let cx = u32(clamp(x, 0, i32(p.tex_size.x) - 1));
    let cy = u32(clamp(y, 0, i32(p.tex_size.y) - 1));
    return from_i32(tex[cy * p.tex_size.x + cx]);
}

fn texture_v31(lx: vec2<u32>, ly: vec2<u32>) -> vec2<u32> {
    // Pixel coordinates in Q33: (L + 2^32) n - 2^32.
    let px = add64(mul64(add64(lx, vec2<u32>(0u, 1u)), p.tex_size.x), vec2<u32>(0u, 0xffffffffu));
    let pz = add64(mul64(add64(ly, vec2<u32>(0u, 1u)), p.tex_size.y), vec2<u32>(0u, 0xffffffffu));
    let x0 = i32(px.y) >> 1u;
    let z0 = i32(pz.y) >> 1u;
    let fx = shr64(px, 21u).x & 4095u;
    let fz = shr64(pz, 21u).x & 4095u;
    let top = add64(mul64(tex_at(x0, z0), 4096u - fx), mul64(tex_at(x0 + 1, z0), fx));
    let bot = add64(mul64(tex_at(x0, z0 + 1), 4096u - fx), mul64(tex_at(x0 + 1, z0 + 1), fx));
    return sar64(add64(mul64(top, 4096u - fz), mul64(bot, fz)), 17u);
}

// trunc(v 2^31) of a finite user value, each f32 step exact (module comment).
fn user_v31(value: f32) -> vec2<u32> {
    var v = clamp(value, -64.0, 64.0);
    if abs(v) < 1.17549435e-38 {
        v = 0.0;
    }
    let s = abs(v) * 128.0;
    let a = floor(s);
    let r = s - a;
    let mag = add64(mul32(u32(a), 16777216u), vec2<u32>(u32(floor(r * 16777216.0)), 0u));
    return select(mag, neg64(mag), v < 0.0);
}

// The term in Q16 stored units: v31 m >> shift, saturating at +-2^62 on a left shift.
fn term_q16(v31: vec2<u32>) -> vec2<u32> {
    let neg = is_neg64(v31) != (p.m < 0);
    let mag = mul64(select(v31, neg64(v31), is_neg64(v31)), u32(abs(p.m)));
    let prod = select(mag, neg64(mag), neg);
    if p.shift >= 0 {
        return sar64(prod, u32(min(p.shift, 62)));
    }
    let ls = u32(-p.shift);
    if mag.x == 0u && mag.y == 0u {
        return vec2<u32>(0u, 0u);
    }
    if ls >= 62u || any(shr64(mag, 62u - ls) != vec2<u32>(0u, 0u)) {
        return select(vec2<u32>(0u, 0x40000000u), vec2<u32>(0u, 0xc0000000u), neg);
    }
    return shl64(prod, ls);
}

// One invocation per word of the map that the region touches (32 / bits texels of one row):
// it stamps the word's texels inside the region and writes the word back, so no two
// invocations share a word and packing needs no atomics (packed.wgsl).
@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let group = packed_group(p.start_x, id.x, p.map_size.x, p.bits);
    if id.y >= p.region_size.y || group.first >= p.start_x + p.region_size.x {
        return;
    }
    let uy = p.region_min.y + i32(id.y);
    var y = u32(uy + p.texel_offset.y);
    if p.wrap == WRAP_REPEAT {
        y = u32(uy + p.wrap_offset.y) % p.map_size.y;
    }
    let idx = p.base + y * packed_pitch(p.map_size.x, p.bits) + group.word;
    var word = heights[idx];
    let lanes = 32u / p.bits;
    for (var lane = 0u; lane < lanes; lane++) {
        let c = group.first + lane;
        let x = group.word * lanes + lane;
        if c >= p.start_x && c < p.start_x + p.region_size.x && x < p.map_size.x {
            let ux = p.region_min.x + i32(c - p.start_x);
            word = stamp_texel(vec2<i32>(ux, uy), x, word);
        }
    }
    heights[idx] = word;
}

// The stamp at unwrapped texel u, which is texel x of the row in `word`: the word with that
// texel's new height (unchanged where the stamp does not reach).
fn stamp_texel(u: vec2<i32>, x: u32, word: u32) -> u32 {
    let i = u32(u.x - p.anchor.x);
    let j = u32(u.y - p.anchor.y);
    let lx = add64(add64(p.l0x, mul64(p.lxx, i)), mul64(p.lyx, j));
    let ly = add64(add64(p.l0y, mul64(p.lxy, i)), mul64(p.lyy, j));
    if !(inside1(lx) && inside1(ly)) {
        return word;
    }
    var v31: vec2<u32>;
    switch p.kind {
        case STAMP_GAUSSIAN: {
            // terrain-core's gaussian_separable, from the frame's integers.
            if all(p.lxy == vec2<u32>(0u, 0u)) && all(p.lyx == vec2<u32>(0u, 0u)) {
                v31 = gaussian_sep_v31(lx, ly);
            } else {
                v31 = gaussian_v31(lx, ly);
            }
        }
        case STAMP_TEXTURE: { v31 = texture_v31(lx, ly); }
        default: {
            let scale = 1.0 / 16777216.0;
            let local = vec2<f32>(f32(i32(sar64(lx, 8u).x)), f32(i32(sar64(ly, 8u).x))) * scale;
            let v = user_stamp_value(local);
            // NaN or infinite values leave the texel unchanged (as the CPU).
            if !(abs(v) <= 0x1.fffffep+127f) {
                return word;
            }
            v31 = user_v31(v);
        }
    }
    let old = from_i32(i32(packed_get(word, x, p.bits)));
    let t = term_q16(v31);
    var new_raw: vec2<u32>;
    switch p.blend {
        case BLEND_ADD: { new_raw = add64(old, sar64(add64(t, vec2<u32>(32768u, 0u)), 16u)); }
        default: {
            let level = sar64(add64(add64(p.base_q16, t), vec2<u32>(32768u, 0u)), 16u);
            let lower = lt64(level, old);
            if p.blend == BLEND_MIN {
                new_raw = select(old, level, lower);
            } else {
                new_raw = select(level, old, lower);
            }
        }
    }
    let kept = clamp64(new_raw, 0, i32(p.max_raw));
    if p.spill_width != 0u {
        let w = vec2<u32>(u - p.spill_min);
        let wide = clamp64(new_raw, -WIDE_SHIFT, i32(p.max_raw) + WIDE_SHIFT);
        excess[w.y * p.spill_width + w.x] = wide - kept;
    }
    return packed_set(word, x, p.bits, u32(kept));
}
