// Granular deformation (Persson 2019, sec. 4.1.2): depth of objects seen from below.
//
// An orthographic view looking up (+Y) over the active area. The CPU uploads every triangle in
// area-relative texel units (u, v) = (X / texel_size - area.min.x, Z / texel_size - area.min.y),
// so column (i, j) of the area is sampled at (u, v) = (i, j). The vertex shader puts that point
// on the centre of pixel (i - tile.x, j - tile.y) of the current tile's viewport, with framebuffer
// y growing with v, so the rasterizer's top-left rule is the CPU reference's top-left rule.
//
// Heights travel as fixed-point units relative to a per-triangle base: `base` (flat, u32) is
// floor of the lowest vertex's units clamped to 0 ..= NO_OBJECT - 1, `rel` (f32) the vertex's
// units minus base, so the interpolated value keeps f32 precision over the triangle's own span
// rather than over the absolute height. The fragment shader floors, clamps and keeps the lowest
// surface with atomicMin into a u32 per column (cleared to NO_OBJECT by the caller).

struct Tile {
    // Tile origin in area texels, as float (vertex stage) ...
    origin_f: vec2<f32>,
    // ... tile size in pixels ...
    size_f: vec2<f32>,
    // ... and the origin as integers (fragment stage).
    origin: vec2<u32>,
    // Row stride of the output: the area's width.
    area_width: u32,
    _pad: u32,
}

const MAX_DEPTH: u32 = 0xfffffffeu;
// The largest f32 below 2^32: any larger increment saturates.
const MAX_ADD_F: f32 = 4294967040.0;

@group(0) @binding(0) var<uniform> tile: Tile;
@group(0) @binding(1) var<storage, read_write> depth: array<atomic<u32>>;

struct VsOut {
    @builtin(position) position: vec4<f32>,
    @location(0) rel: f32,
    @location(1) @interpolate(flat) base: u32,
}

@vertex
fn vs_main(@location(0) uvh: vec3<f32>, @location(1) base: u32) -> VsOut {
    // Pixel centre (k + 0.5) of the tile stands at area texel origin + k.
    let pixel = uvh.xy - tile.origin_f + vec2<f32>(0.5, 0.5);
    let ndc = vec2<f32>(pixel.x / tile.size_f.x * 2.0 - 1.0, 1.0 - pixel.y / tile.size_f.y * 2.0);
    var out: VsOut;
    out.position = vec4<f32>(ndc, 0.5, 1.0);
    out.rel = uvh.z;
    out.base = base;
    return out;
}

@fragment
fn fs_main(in: VsOut) -> @location(0) vec4<f32> {
    let add = max(floor(in.rel), 0.0);
    var units = MAX_DEPTH;
    if add < MAX_ADD_F {
        let sum = in.base + u32(add);
        // u32 addition wraps: a sum below base overflowed.
        if sum >= in.base && sum <= MAX_DEPTH {
            units = sum;
        }
    }
    let pixel = vec2<u32>(in.position.xy);
    let column = tile.origin + pixel;
    atomicMin(&depth[column.y * tile.area_width + column.x], units);
    return vec4<f32>(1.0, 0.0, 0.0, 1.0);
}
