// SpillPass: moves the excess a detail stamp left in its spill window into the coarse-map, by
// the rule of terrain-core's `detail_spill` (the transpose of the bilinear interpolation from
// coarse to detail texels). Invocation (i, j) owns coarse texel rect_min + (i, j) and writes
// only it, so no two invocations touch the same texel.

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
}

@group(0) @binding(0) var<uniform> p: SpillParams;
@group(0) @binding(1) var<storage, read> excess: array<i32>;
@group(0) @binding(2) var<storage, read_write> heights: array<u32>;

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= p.rect_size.x || id.y >= p.rect_size.y {
        return;
    }
    let c = p.rect_min + vec2<i32>(id.xy);
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
    let delta = floor(sum * p.k + 0.5);
    if delta == 0.0 {
        return;
    }
    var x: u32;
    var y: u32;
    if p.wrap == WRAP_REPEAT {
        x = u32(c.x + p.wrap_offset.x) % p.map_size.x;
        y = u32(c.y + p.wrap_offset.y) % p.map_size.y;
    } else {
        // A clamped coarse-map keeps nothing beyond its edges.
        if c.x < 0 || c.y < 0 || c.x >= i32(p.map_size.x) || c.y >= i32(p.map_size.y) {
            return;
        }
        x = u32(c.x);
        y = u32(c.y);
    }
    let i = y * p.map_size.x + x;
    heights[i] = u32(clamp(f32(heights[i]) + delta, 0.0, p.max_raw));
}
