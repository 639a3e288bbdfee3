// Clipmap surface of a granular map, straight from GranularNormalsPass's output (Persson 2019, sec.
// 4.1.6 and 4.3): per texel vec4(unit normal xyz, height in metres): the float copy of the
// fixed-point heights, so the renderer filters floats and never reads the integers.

@group(0) @binding(1) var<storage, read> surface: array<vec4<f32>>;

fn height_at(t: vec2<i32>) -> f32 {
    return frame.height_offset + surface[texel_index(t)].w;
}

// The gradient whose normal normalize(-dx, 1, -dz) is the stored normal.
fn derivative_at(t: vec2<i32>) -> vec2<f32> {
    let n = surface[texel_index(t)].xyz;
    return -n.xz / max(n.y, 1e-3);
}
