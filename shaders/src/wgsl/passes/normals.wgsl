// NormalPass: partial-derivative normals by the 4th-order difference of Flower 2010, eq. 3.3,
// h'(x) = (h(x-2) - 8 h(x-1) + 8 h(x+1) - h(x+2)) / (12 xi), over a region only.

struct NormalParams {
    // Region in unwrapped texel coordinates (wrapped into the map on a repeating map).
    region_min: vec2<i32>,
    region_size: vec2<u32>,
    map_size: vec2<u32>,
    // 0: repeat, 1: clamp.
    wrap: u32,
    // Encoding scale / (12 * texel size): stored units to metres per metre.
    k: f32,
    // A multiple of the map size that makes every coordinate the stencil reads non-negative:
    // `%` of negative integers is undefined in GLSL, so wrap only non-negatives.
    wrap_offset: vec2<i32>,
}

@group(0) @binding(0) var<uniform> p: NormalParams;
@group(0) @binding(1) var<storage, read> heights: array<u32>;
@group(0) @binding(2) var<storage, read_write> derivatives: array<vec2<f32>>;

fn resolve(v: i32, n: u32, offset: i32) -> u32 {
    if p.wrap == WRAP_REPEAT {
        return u32(v + offset) % n;
    }
    return u32(clamp(v, 0, i32(n) - 1));
}

fn h(x: i32, y: i32) -> i32 {
    let row = resolve(y, p.map_size.y, p.wrap_offset.y);
    return i32(heights[row * p.map_size.x + resolve(x, p.map_size.x, p.wrap_offset.x)]);
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= p.region_size.x || id.y >= p.region_size.y {
        return;
    }
    let u = p.region_min + vec2<i32>(id.xy);
    let x = i32(resolve(u.x, p.map_size.x, p.wrap_offset.x));
    let y = i32(resolve(u.y, p.map_size.y, p.wrap_offset.y));
    // Integer stencils are exact (|sum| < 2^24), so only the final scale rounds.
    let dx = h(x - 2, y) - 8 * h(x - 1, y) + 8 * h(x + 1, y) - h(x + 2, y);
    let dz = h(x, y - 2) - 8 * h(x, y - 1) + 8 * h(x, y + 1) - h(x, y + 2);
    derivatives[u32(y) * p.map_size.x + u32(x)] = vec2<f32>(f32(dx), f32(dz)) * p.k;
}
