// The autoshader's functions (materials_common.wgsl) at a list of points, for comparison with
// the CPU reference (terrain_core::autoshade_weights, curvature_from_heights, curvature_from_gradients).

struct ProbeParams {
    // Rock slope (x, y), snow height (z, w).
    edges: vec4<f32>,
    // Dirt curvature (x, y); z: the point count (as u32 bits).
    dirt: vec4<f32>,
}

struct ProbePoint {
    // Ramp fraction, slope, curvature, spacing (m).
    a: vec4<f32>,
    // The heights around (x-, x+, z-, z+).
    b: vec4<f32>,
    // The centre height (x); the texel size of the gradients' cell (y).
    c: vec4<f32>,
    // The cell's corner gradients d00 (xy), d10 (zw), then d01, d11.
    d: vec4<f32>,
    e: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: ProbeParams;
@group(0) @binding(1) var<storage, read> points: array<ProbePoint>;
// Per point: the weights, then (curvature from heights, from gradients, 0, 0).
@group(0) @binding(2) var<storage, read_write> out: array<vec4<f32>>;

@compute @workgroup_size(64, 1, 1)
fn probe_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= bitcast<u32>(params.dirt.z) {
        return;
    }
    let p = points[id.x];
    out[2u * id.x] = autoshade_weights(params.edges, params.dirt.xy, p.a.x, p.a.y, p.a.z);
    let c = curvature_from_heights(p.c.x, p.b, p.a.w);
    let g = curvature_from_gradients(p.d.xy, p.d.zw, p.e.xy, p.e.zw, p.c.y);
    out[2u * id.x + 1u] = vec4<f32>(c, g, 0.0, 0.0);
}
