// TessellationPass's source for a map (TessHierarchy): the saturated bounds of every grid
// vertex and the patches' height ranges. Placed before tessellate.wgsl.

// A grid vertex: true height (m), saturated sphere radius (m), saturated density, saturated
// error (m).
struct Vertex {
    h: f32,
    r: f32,
    d: f32,
    e: f32,
}

@group(0) @binding(1) var<storage, read> verts: array<Vertex>;
@group(0) @binding(2) var<storage, read> patch_bounds: array<vec2<f32>>;

fn vindex(v: vec2<i32>) -> u32 {
    let g = vec2<i32>(params.grid);
    var w: vec2<i32>;
    if params.wrap == WRAP_REPEAT {
        w = ((v % g) + g) % g;
    } else {
        w = clamp(v, vec2<i32>(0, 0), g - vec2<i32>(1, 1));
    }
    return u32(w.y) * params.grid.x + u32(w.x);
}

// The split ratio of vertex v (its level is implied by its position in the hierarchy).
fn split_ratio(v: vec2<i32>, level: u32) -> f32 {
    let b = verts[vindex(v)];
    let ts = params.texel_size;
    let c = vec3<f32>(
        f32(v.x) * ts - params.camera.x,
        b.h - params.camera.y,
        f32(v.y) * ts - params.camera.z,
    );
    let dist = max(sqrt(c.x * c.x + c.y * c.y + c.z * c.z) - b.r, NEAR_M);
    if params.error_metric != 0u {
        return params.scale * b.e / dist;
    }
    var dens = 1.0;
    if params.use_density != 0u {
        dens = b.d;
    }
    return params.scale * b.r * dens / dist;
}

fn vertex_height(v: vec2<i32>) -> f32 {
    return verts[vindex(v)].h;
}

// (lowest, highest) height over patch pid.
fn patch_range(pid: u32) -> vec2<f32> {
    return patch_bounds[pid];
}
