// The autoshader's functions (materials_common.wgsl) at a list of points, for comparison with
// the CPU reference (terrain_core::autoshade_weights, curvature_from_derivatives).

struct ProbeParams {
    // Rock slope (x, y), snow height (z, w).
    edges: vec4<f32>,
    // Dirt curvature (x, y); z: the point count (as u32 bits).
    dirt: vec4<f32>,
}

struct ProbePoint {
    // Ramp fraction, slope, curvature, texel size.
    a: vec4<f32>,
    // Corner gradients d00 (xy), d10 (zw).
    b: vec4<f32>,
    // Corner gradients d01 (xy), d11 (zw).
    c: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: ProbeParams;
@group(0) @binding(1) var<storage, read> points: array<ProbePoint>;
// Per point: the weights, then (curvature, 0, 0, 0).
@group(0) @binding(2) var<storage, read_write> out: array<vec4<f32>>;

@compute @workgroup_size(64, 1, 1)
fn probe_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= bitcast<u32>(params.dirt.z) {
        return;
    }
    let p = points[id.x];
    out[2u * id.x] = autoshade_weights(params.edges, params.dirt.xy, p.a.x, p.a.y, p.a.z);
    let c = curvature_from_derivatives(p.b.xy, p.b.zw, p.c.xy, p.c.zw, p.a.w);
    out[2u * id.x + 1u] = vec4<f32>(c, 0.0, 0.0, 0.0);
}
