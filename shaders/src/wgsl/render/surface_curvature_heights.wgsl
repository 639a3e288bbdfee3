// The material shading's curvature on a surface with cheap height reads (coarse-map, granular
// map): the Laplacian of the heights around the fragment's nearest texel, `frame.autoshade_dirt.w`
// texels apart. Heights, not the 8-bit slope codes, whose steps would show as noise.
fn surface_curvature(qs: vec2<f32>, d00: vec2<f32>, d10: vec2<f32>, d01: vec2<f32>, d11: vec2<f32>) -> f32 {
    let step = i32(frame.autoshade_dirt.w);
    let c = frame.camera_texel + vec2<i32>(floor(qs + 0.5));
    let around = vec4<f32>(
        height_at(c - vec2<i32>(step, 0)),
        height_at(c + vec2<i32>(step, 0)),
        height_at(c - vec2<i32>(0, step)),
        height_at(c + vec2<i32>(0, step)),
    );
    return curvature_from_heights(height_at(c), around, f32(step) * frame.texel_size);
}
