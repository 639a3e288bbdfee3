// TessRenderer: the triangles TessellationPass wrote (texel x, texel y, drawn height per
// vertex), drawn with clipmap.wgsl's frame, surface and fragment shader; this file adds the
// vertex shader.

@vertex
fn vs_tess(@location(0) v: vec3<f32>) -> VsOut {
    // Relative to the camera's integer texel first, so large worlds keep their precision.
    let rel_texel = v.xy - vec2<f32>(frame.camera_texel) - frame.camera_frac;
    let world = vec3<f32>(rel_texel.x * frame.texel_size, v.z - frame.camera_height, rel_texel.y * frame.texel_size);
    var out: VsOut;
    out.clip = frame.view_proj * vec4<f32>(world, 1.0);
    out.rel_texel = rel_texel;
    out.height = v.z;
    out.view_dist = length(world);
    return out;
}
