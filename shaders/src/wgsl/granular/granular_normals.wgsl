// GranularNormalsPass: normals of the granular map by the symmetric difference (Persson 2019
// eq. 4.3, edges clamped) and 3x3 Gaussian blur passes, as
// terrain_core::granular::{symmetric_normals, blur_normals} within a float tolerance.
// Output per map texel, row-major: vec4<f32>(unit normal xyz, height in metres): the float
// copy of the heights for filtered rendering (Persson 2019, sec. 4.3).

struct NormalParams {
    area_min: vec2<u32>,
    area_size: vec2<u32>,
    map_size: vec2<u32>,
    // Height units to metres (the encoding scale) * 0.5 / texel size.
    k: f32,
    // Height units to metres (the encoding scale), for the float copy in w.
    scale: f32,
}

// `main` binds all three buffers; `blur` and `copy_back` only the first two (their pipelines
// have a layout without the heights), so a blur needs no map.
@group(0) @binding(0) var<uniform> p: NormalParams;
@group(0) @binding(1) var<storage, read_write> normals: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> scratch: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> heights: array<u32>;

fn h(x: i32, y: i32) -> u32 {
    let cx = u32(clamp(x, 0, i32(p.map_size.x) - 1));
    let cy = u32(clamp(y, 0, i32(p.map_size.y) - 1));
    return heights[cy * p.map_size.x + cx];
}

// a - b as f32 without u32 wrap-around.
fn diff(a: u32, b: u32) -> f32 {
    return select(-f32(b - a), f32(a - b), a >= b);
}

fn normalize_or_up(v: vec3<f32>) -> vec3<f32> {
    let l = length(v);
    if l > 0.0 && l < 3.0e38 {
        return v / l;
    }
    return vec3<f32>(0.0, 1.0, 0.0);
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= p.area_size.x || id.y >= p.area_size.y {
        return;
    }
    let x = i32(p.area_min.x + id.x);
    let y = i32(p.area_min.y + id.y);
    let sx = diff(h(x + 1, y), h(x - 1, y)) * p.k;
    let sz = diff(h(x, y + 1), h(x, y - 1)) * p.k;
    let metres = f32(h(x, y)) * p.scale;
    normals[u32(y) * p.map_size.x + u32(x)] = vec4<f32>(normalize_or_up(vec3<f32>(-sx, 1.0, -sz)), metres);
}

// One blur pass of the area from `normals` into `scratch`.
@compute @workgroup_size(8, 8, 1)
fn blur(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= p.area_size.x || id.y >= p.area_size.y {
        return;
    }
    let x = i32(p.area_min.x + id.x);
    let y = i32(p.area_min.y + id.y);
    let hi = vec2<i32>(p.map_size) - 1;
    var s = vec3<f32>(0.0);
    for (var dy = -1; dy <= 1; dy = dy + 1) {
        for (var dx = -1; dx <= 1; dx = dx + 1) {
            let w = f32((2 - abs(dx)) * (2 - abs(dy)));
            let q = clamp(vec2<i32>(x + dx, y + dy), vec2<i32>(0), hi);
            s = s + normals[u32(q.y) * p.map_size.x + u32(q.x)].xyz * w;
        }
    }
    // The blur smooths the normal only; the height (w) is kept.
    let here = normals[u32(y) * p.map_size.x + u32(x)].w;
    scratch[u32(y) * p.map_size.x + u32(x)] = vec4<f32>(normalize_or_up(s / 16.0), here);
}

// Copies the blurred area back from `scratch` into `normals`.
@compute @workgroup_size(8, 8, 1)
fn copy_back(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= p.area_size.x || id.y >= p.area_size.y {
        return;
    }
    let i = (p.area_min.y + id.y) * p.map_size.x + p.area_min.x + id.x;
    normals[i] = scratch[i];
}
