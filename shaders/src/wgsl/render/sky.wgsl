// SkyPass: a full-screen triangle drawn first, coloured by the elevation of the view ray
// between a horizon and a zenith colour.

struct SkyParams {
    inv_view_proj: mat4x4<f32>,
    horizon: vec4<f32>,
    zenith: vec4<f32>,
    // x: 1 when the colour target is sRGB (see to_target); y: 1 when depth falls with
    // distance (reverse-Z).
    flags: vec4<u32>,
}

@group(0) @binding(0) var<uniform> sky: SkyParams;

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) ndc: vec2<f32>,
}

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> VsOut {
    let xy = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u)) * 2.0 - 1.0;
    var out: VsOut;
    out.clip = vec4<f32>(xy, 0.0, 1.0);
    out.ndc = xy;
    return out;
}

@fragment
fn fs_main(in: VsOut) -> @location(0) vec4<f32> {
    // Two depths strictly inside the view volume: with an infinite far plane, depth 1 (or 0
    // under reverse-Z) is a point at infinity, whose w is 0.
    let a = sky.inv_view_proj * vec4<f32>(in.ndc, 0.25, 1.0);
    let b = sky.inv_view_proj * vec4<f32>(in.ndc, 0.75, 1.0);
    let away = select(1.0, -1.0, sky.flags.y == 1u);
    let dir = normalize(b.xyz / b.w - a.xyz / a.w) * away;
    let t = clamp(dir.y * 2.5, 0.0, 1.0);
    return vec4<f32>(to_target(mix(sky.horizon.rgb, sky.zenith.rgb, sqrt(t)), sky.flags.x), 1.0);
}
