// DetailProbe: what the detail clipmap (detail_tiles.wgsl, detail_sample.wgsl) reads at a list
// of points: the detail height, its gradient, and the composite normal with a given coarse
// gradient, for comparison with the CPU reference (DetailLayer::height_m, gradient_m and
// terrain_core::composite_normal).

struct ProbeInfo {
    count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

struct ProbePoint {
    // Coarse texels past the camera's whole texel (DetailInfo::camera_detail).
    q: vec2<f32>,
    coarse_gradient: vec2<f32>,
}

@group(0) @binding(0) var<uniform> probe: ProbeInfo;
@group(0) @binding(6) var<storage, read> probe_points: array<ProbePoint>;
// Per point: (height, gradient x, gradient z, 0), then (composite normal, 0).
@group(0) @binding(7) var<storage, read_write> probe_out: array<vec4<f32>>;

@compute @workgroup_size(64, 1, 1)
fn probe_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= probe.count {
        return;
    }
    let p = probe_points[id.x];
    let pt = detail_point(p.q);
    let s = detail_sample(pt.b, pt.f);
    probe_out[2u * id.x] = vec4<f32>(s.height, s.gradient, 0.0);
    probe_out[2u * id.x + 1u] = vec4<f32>(composite_normal(p.coarse_gradient, s.gradient), 0.0);
}
