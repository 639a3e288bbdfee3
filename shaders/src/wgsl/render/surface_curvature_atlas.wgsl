// The material shading's curvature on a tile atlas: from the cell's corner gradients, which the
// atlas surface computes as exact differences of its heights. Each atlas height read walks the
// pyramid's levels; more of them in one fragment shader made lavapipe's compiler take minutes.
fn surface_curvature(qs: vec2<f32>, d00: vec2<f32>, d10: vec2<f32>, d01: vec2<f32>, d11: vec2<f32>) -> f32 {
    return curvature_from_gradients(d00, d10, d01, d11, frame.texel_size);
}
