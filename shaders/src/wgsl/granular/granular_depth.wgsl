// Granular deformation (Persson 2019, sec. 4.1.2): depth of objects seen from below, as an exact
// integer rasterizer in a compute pass: the integer program of terrain_core::granular::depth
// (see its module docs), so the result is bit-identical to the CPU reference on any GPU.
//
// The CPU snaps every triangle (vertices in Q8 texels relative to a per-triangle origin, heights
// in 2^-f units above a per-triangle base) and uploads one record per triangle and 16 x 16 tile
// of the samples it may cover. One workgroup takes one record; each invocation tests samples of
// the tile with exact edge functions (top-left rule), interpolates the height exactly in
// integers and keeps the lowest with atomicMin into a u32 per column (cleared to NO_OBJECT by
// the caller). Products exceed 32 bits: 64-bit values are emulated as two u32 (two's
// complement), which wrap the same on every GPU.

struct Params {
    // Word index of this dispatch's first record in `records`.
    first: u32,
    // Records in this dispatch (one workgroup each).
    count: u32,
    // Row stride of the output: the area's width.
    area_width: u32,
    _pad: u32,
}

// Words per record (terrain-gpu's DepthRecord):
//  0..6   vertices a, b, c in Q8 texels relative to the origin (i32)
//  6..8   the origin in texels relative to the area's min (i32)
//  8..11  heights of a, b, c above base, in 2^-f units
//  11     f, the heights' fractional bits
//  12..14 base (i64: lo, hi)
//  14..16 area2, twice the Q8 area (i64: lo, hi; positive)
//  16..18 the tile's first sample, area-relative
//  18..20 the tile's end (exclusive), area-relative
const RECORD_WORDS: u32 = 20u;
const TILE: u32 = 16u;
const GROUP: u32 = 64u;
const MAX_DEPTH: u32 = 0xfffffffeu;

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> records: array<u32>;
@group(0) @binding(2) var<storage, read_write> depth: array<atomic<u32>>;

// A 64-bit integer, two's complement.
struct W64 {
    lo: u32,
    hi: u32,
}

fn w_add(a: W64, b: W64) -> W64 {
    let lo = a.lo + b.lo;
    return W64(lo, a.hi + b.hi + select(0u, 1u, lo < a.lo));
}

fn w_neg(a: W64) -> W64 {
    return w_add(W64(~a.lo, ~a.hi), W64(1u, 0u));
}

fn w_is_neg(a: W64) -> bool {
    return (a.hi >> 31u) != 0u;
}

// Unsigned a >= b.
fn w_ge(a: W64, b: W64) -> bool {
    return a.hi > b.hi || (a.hi == b.hi && a.lo >= b.lo);
}

// Unsigned 32 x 32 -> 64 bits.
fn w_mul_u32(a: u32, b: u32) -> W64 {
    let a0 = a & 0xffffu;
    let a1 = a >> 16u;
    let b0 = b & 0xffffu;
    let b1 = b >> 16u;
    let p00 = a0 * b0;
    let p01 = a0 * b1;
    let p10 = a1 * b0;
    let mid = p01 + p10;
    let mid_carry = select(0u, 0x10000u, mid < p01);
    let lo = p00 + (mid << 16u);
    let hi = a1 * b1 + (mid >> 16u) + mid_carry + select(0u, 1u, lo < p00);
    return W64(lo, hi);
}

// Signed 32 x 32 -> 64 bits (operands below 2^31 in magnitude).
fn w_mul_i32(a: i32, b: i32) -> W64 {
    let p = w_mul_u32(u32(abs(a)), u32(abs(b)));
    if (a < 0) != (b < 0) {
        return w_neg(p);
    }
    return p;
}

// The low 64 bits of a non-negative a times b.
fn w_mul_w_u32(a: W64, b: u32) -> W64 {
    let p = w_mul_u32(a.lo, b);
    return W64(p.lo, p.hi + a.hi * b);
}

// floor(n / d) for n >= 0, d > 0 below 2^62, and a quotient below 2^32 (so n >> 32 < d):
// restoring division over the low 32 bits of n.
fn w_div(n: W64, d: W64) -> u32 {
    var rem = W64(n.hi, 0u);
    var q = 0u;
    for (var i = 0u; i < 32u; i = i + 1u) {
        let bit = 31u - i;
        rem = W64((rem.lo << 1u) | ((n.lo >> bit) & 1u), (rem.hi << 1u) | (rem.lo >> 31u));
        if w_ge(rem, d) {
            rem = w_add(rem, w_neg(d));
            q = q | (1u << bit);
        }
    }
    return q;
}

// The edge function of (s, e) at p: (e - s) x (p - s).
fn edge(s: vec2<i32>, e: vec2<i32>, p: vec2<i32>) -> W64 {
    let d = e - s;
    return w_add(w_mul_i32(d.x, p.y - s.y), w_neg(w_mul_i32(d.y, p.x - s.x)));
}

// Whether an edge function value counts as inside: positive, or zero on a top-left edge.
fn inside(w: W64, s: vec2<i32>, e: vec2<i32>) -> bool {
    if w_is_neg(w) {
        return false;
    }
    if w.lo == 0u && w.hi == 0u {
        let d = e - s;
        return d.y < 0 || (d.y == 0 && d.x > 0);
    }
    return true;
}

fn vertex(r: u32, k: u32) -> vec2<i32> {
    return vec2<i32>(bitcast<i32>(records[r + 2u * k]), bitcast<i32>(records[r + 2u * k + 1u]));
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    if wg.x >= params.count {
        return;
    }
    let r = params.first + wg.x * RECORD_WORDS;
    let a = vertex(r, 0u);
    let b = vertex(r, 1u);
    let c = vertex(r, 2u);
    let origin = vec2<i32>(bitcast<i32>(records[r + 6u]), bitcast<i32>(records[r + 7u]));
    let rel = vec3<u32>(records[r + 8u], records[r + 9u], records[r + 10u]);
    let frac_bits = records[r + 11u];
    let base = W64(records[r + 12u], records[r + 13u]);
    let area2 = W64(records[r + 14u], records[r + 15u]);
    let t0 = vec2<u32>(records[r + 16u], records[r + 17u]);
    let t1 = vec2<u32>(records[r + 18u], records[r + 19u]);
    for (var k = li; k < TILE * TILE; k = k + GROUP) {
        let col = t0 + vec2<u32>(k % TILE, k / TILE);
        if col.x >= t1.x || col.y >= t1.y {
            continue;
        }
        // The sample in Q8 texels relative to the triangle's origin.
        let p = (vec2<i32>(col) - origin) * 256;
        let w0 = edge(b, c, p);
        let w1 = edge(c, a, p);
        let w2 = edge(a, b, p);
        if !(inside(w0, b, c) && inside(w1, c, a) && inside(w2, a, b)) {
            continue;
        }
        // w0 weighs a, w1 b, w2 c; the sum is non-negative and below 2^62.
        let num = w_add(w_add(w_mul_w_u32(w0, rel.x), w_mul_w_u32(w1, rel.y)), w_mul_w_u32(w2, rel.z));
        let q = w_div(num, area2) >> frac_bits;
        let sum = w_add(base, W64(q, 0u));
        var units = sum.lo;
        if w_is_neg(sum) {
            units = 0u;
        } else if sum.hi != 0u || sum.lo > MAX_DEPTH {
            units = MAX_DEPTH;
        }
        atomicMin(&depth[col.y * params.area_width + col.x], units);
    }
}
