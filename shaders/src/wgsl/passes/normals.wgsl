// NormalPass: partial-derivative normals by the 4th-order difference of Flower 2010, eq. 3.3,
// h'(x) = (h(x-2) - 8 h(x-1) + 8 h(x+1) - h(x+2)) / (12 xi), over a region only, stored as
// 8-bit slope codes (terrain_core::slope_code) so a texel's normal takes 2 bytes.

struct NormalParams {
    // Region in unwrapped texel coordinates (wrapped into the map on a repeating map).
    region_min: vec2<i32>,
    region_size: vec2<u32>,
    map_size: vec2<u32>,
    // 0: repeat, 1: clamp.
    wrap: u32,
    // Bits per height texel (8 or 16).
    bits: u32,
    // A multiple of the map size that makes every coordinate the stencil reads non-negative:
    // `%` of negative integers is undefined in GLSL, so wrap only non-negatives.
    wrap_offset: vec2<i32>,
    // The region's first column made non-negative (region_min.x plus wrap_offset.x on a
    // repeating map), where its word groups start (packed_group).
    start_x: u32,
    _pad: u32,
    // terrain_core::SlopeCodec's thresholds, 4 per vec4 (the 128th is u32::MAX).
    thresholds: array<vec4<u32>, 32>,
}

@group(0) @binding(0) var<uniform> p: NormalParams;
@group(0) @binding(1) var<storage, read> heights: array<u32>;
// Two 8-bit slope codes per texel (dX low byte, dZ high byte), 16-bit texels packed.
@group(0) @binding(2) var<storage, read_write> derivatives: array<u32>;

fn resolve(v: i32, n: u32, offset: i32) -> u32 {
    if p.wrap == WRAP_REPEAT {
        return u32(v + offset) % n;
    }
    return u32(clamp(v, 0, i32(n) - 1));
}

fn h(x: i32, y: i32) -> i32 {
    let row = resolve(y, p.map_size.y, p.wrap_offset.y);
    let col = resolve(x, p.map_size.x, p.wrap_offset.x);
    return i32(packed_get(heights[packed_index(col, row, p.map_size.x, p.bits)], col, p.bits));
}

// terrain_core::SlopeCodec::encode: how many thresholds lie at or below |s|, with s's sign, as
// the code's byte. Integer comparisons only, so every device gives the CPU's code.
fn encode(s: i32) -> u32 {
    let a = u32(abs(s));
    var lo = 0u;
    var hi = 127u;
    while lo < hi {
        let mid = (lo + hi + 1u) / 2u;
        if p.thresholds[(mid - 1u) / 4u][(mid - 1u) % 4u] <= a {
            lo = mid;
        } else {
            hi = mid - 1u;
        }
    }
    return u32(select(i32(lo), -i32(lo), s < 0)) & 0xffu;
}

// One invocation per word of the derivative map the region touches (two texels): it writes the
// word's texels inside the region and keeps the others, so no two invocations share a word.
@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let groups = packed_group(p.start_x, id.x, p.map_size.x, 16u);
    if id.y >= p.region_size.y || groups.first >= p.start_x + p.region_size.x {
        return;
    }
    let y = i32(resolve(p.region_min.y + i32(id.y), p.map_size.y, p.wrap_offset.y));
    let index = u32(y) * packed_pitch(p.map_size.x, 16u) + groups.word;
    var word = derivatives[index];
    for (var lane = 0u; lane < 2u; lane++) {
        let c = groups.first + lane;
        let x = groups.word * 2u + lane;
        if c < p.start_x || c >= p.start_x + p.region_size.x || x >= p.map_size.x {
            continue;
        }
        // Integer stencils are exact (|s| < 18 * 2^16); the code is decided by integers too.
        let xi = i32(x);
        let dx = h(xi - 2, y) - 8 * h(xi - 1, y) + 8 * h(xi + 1, y) - h(xi + 2, y);
        let dz = h(xi, y - 2) - 8 * h(xi, y - 1) + 8 * h(xi, y + 1) - h(xi, y + 2);
        word = packed_set(word, x, 16u, encode(dx) | (encode(dz) << 8u));
    }
    derivatives[index] = word;
}
