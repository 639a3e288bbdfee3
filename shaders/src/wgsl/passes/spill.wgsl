// SpillPass: moves the excess a detail stamp left in its spill window into the coarse-map, by
// the rule of terrain-core's `detail_spill` (the transpose of the bilinear interpolation from
// coarse to detail texels). Invocation (i, j) owns the i-th word of row j of the rect (the
// coarse texels packed in it, packed.wgsl) and writes only that word, so no two invocations
// touch the same texel or word.

struct SpillParams {
    // Coarse texels of the spill rect (unwrapped).
    rect_min: vec2<i32>,
    rect_size: vec2<u32>,
    // The coarse-map.
    map_size: vec2<u32>,
    wrap: u32,
    // Detail texels per coarse texel.
    refine: u32,
    // The spill window: unwrapped detail coordinates of its texel (0, 0), and its size.
    window_min: vec2<i32>,
    window_size: vec2<u32>,
    // A multiple of the map size making every unwrapped coarse coordinate non-negative.
    wrap_offset: vec2<i32>,
    // Coarse raw units per tent-weighted detail unit: detail scale / (coarse scale r^4).
    k: f32,
    max_raw: f32,
    // Bits per coarse texel (8 or 16).
    bits: u32,
    // rect_min.x made non-negative (plus wrap_offset.x on a repeating map; a clamped map's
    // rect is inside it): where the rect's word groups start.
    start_x: u32,
}

@group(0) @binding(0) var<uniform> p: SpillParams;
@group(0) @binding(1) var<storage, read> excess: array<i32>;
@group(0) @binding(2) var<storage, read_write> heights: array<u32>;

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let group = packed_group(p.start_x, id.x, p.map_size.x, p.bits);
    if id.y >= p.rect_size.y || group.first >= p.start_x + p.rect_size.x {
        return;
    }
    let cy = p.rect_min.y + i32(id.y);
    var y = u32(cy);
    if p.wrap == WRAP_REPEAT {
        y = u32(cy + p.wrap_offset.y) % p.map_size.y;
    }
    let idx = y * packed_pitch(p.map_size.x, p.bits) + group.word;
    var word = heights[idx];
    let lanes = 32u / p.bits;
    for (var lane = 0u; lane < lanes; lane++) {
        let col = group.first + lane;
        let x = group.word * lanes + lane;
        if col >= p.start_x && col < p.start_x + p.rect_size.x && x < p.map_size.x {
            let c = vec2<i32>(p.rect_min.x + i32(col - p.start_x), cy);
            let delta = spill_at(c);
            if delta != 0.0 {
                let old = f32(packed_get(word, x, p.bits));
                word = packed_set(word, x, p.bits, u32(clamp(old + delta, 0.0, p.max_raw)));
            }
        }
    }
    heights[idx] = word;
}

// The change of coarse texel c (unwrapped) in stored units.
fn spill_at(c: vec2<i32>) -> f32 {
    let r = i32(p.refine);
    let centre = c * r - p.window_min;
    var sum = 0.0;
    // Row-major over the tent, as the CPU reference sums.
    for (var dy = 1 - r; dy < r; dy++) {
        for (var dx = 1 - r; dx < r; dx++) {
            let q = centre + vec2<i32>(dx, dy);
            if q.x < 0 || q.y < 0 || q.x >= i32(p.window_size.x) || q.y >= i32(p.window_size.y) {
                continue;
            }
            let e = excess[u32(q.y) * p.window_size.x + u32(q.x)];
            if e != 0 {
                let w = (r - abs(dx)) * (r - abs(dy));
                sum += f32(w) * f32(e);
            }
        }
    }
    return floor(sum * p.k + 0.5);
}
