// The streamed layer lookup (overlay_atlas.wgsl) at a list of points, for comparison with its
// CPU reference, terrain_core::OverlayAtlas::sample. Declares the frame fields and the
// `map_texel` that lookup reads, as clipmap.wgsl does for the renderers.

struct Frame {
    camera_texel: vec2<i32>,
    map_size: vec2<u32>,
    wrap_offset: vec2<i32>,
    wrap: u32,
    count: u32,
    premultiply: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> frame: Frame;
// Positions relative to the camera's whole texel.
@group(0) @binding(1) var<storage, read> points: array<vec2<f32>>;
@group(0) @binding(2) var<storage, read_write> out: array<vec4<f32>>;

fn map_texel(t: vec2<i32>) -> vec2<u32> {
    if frame.wrap == WRAP_REPEAT {
        return vec2<u32>(t + frame.wrap_offset) % frame.map_size;
    }
    return vec2<u32>(clamp(t, vec2<i32>(0, 0), vec2<i32>(frame.map_size) - vec2<i32>(1, 1)));
}

@compute @workgroup_size(64, 1, 1)
fn probe_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= frame.count {
        return;
    }
    out[id.x] = streamed_layer_at(paint_slots, paint_table, points[id.x], frame.premultiply != 0u);
}
