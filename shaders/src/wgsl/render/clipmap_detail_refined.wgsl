// The fragment hook of refined geometry (refine.wgsl): the vertices already carry the detail
// height, so the hook adds none; it shades with the detail's gradient (eq. 3.4's composite
// normal), faded out with distance as the vertices' heights are.

struct FragmentDetail {
    sample: DetailSample,
    // Where to shade, in texels relative to the camera's whole texel.
    q: vec2<f32>,
}

fn fragment_detail(q: vec2<f32>, world: vec3<f32>, view_dist: f32) -> FragmentDetail {
    let w = detail_fade(view_dist);
    if w <= 0.0 {
        return FragmentDetail(DetailSample(0.0, vec2<f32>(0.0, 0.0)), q);
    }
    let pt = detail_point(q);
    let s = detail_sample(pt.b, pt.f);
    return FragmentDetail(DetailSample(0.0, w * s.gradient), q);
}
