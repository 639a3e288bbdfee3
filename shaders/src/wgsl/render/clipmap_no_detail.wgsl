// The fragment hook of a surface without a detail layer: nothing added, nothing moved.

struct FragmentDetail {
    sample: DetailSample,
    // Where to shade, in texels relative to the camera's whole texel.
    q: vec2<f32>,
}

fn fragment_detail(q: vec2<f32>, world: vec3<f32>, view_dist: f32) -> FragmentDetail {
    return FragmentDetail(DetailSample(0.0, vec2<f32>(0.0, 0.0)), q);
}
