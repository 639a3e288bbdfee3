// Clipmap surface of a coarse-map: stored heights (u32 per texel, metres = offset + scale *
// stored) and partial-derivative normals (vec2<f32> gradients, Flower 2010, eq. 3.3).

@group(0) @binding(1) var<storage, read> heights: array<u32>;
@group(0) @binding(2) var<storage, read> derivatives: array<vec2<f32>>;

fn height_at(t: vec2<i32>) -> f32 {
    return frame.height_offset + frame.height_scale * f32(heights[texel_index(t)]);
}

fn derivative_at(t: vec2<i32>) -> vec2<f32> {
    return derivatives[texel_index(t)];
}
