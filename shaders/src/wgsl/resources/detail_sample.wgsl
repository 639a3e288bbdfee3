// What the detail layer adds to the coarse surface at a point: its height in metres and its
// gradient (metres per metre), both already faded out with distance where drawn.
struct DetailSample {
    height: f32,
    gradient: vec2<f32>,
}

// The composite normal of Flower 2010, eq. 3.4: coarse and detail derivatives add, so no tangent
// space is needed. CPU reference: terrain_core::composite_normal.
fn composite_normal(coarse: vec2<f32>, detail: vec2<f32>) -> vec3<f32> {
    let d = coarse + detail;
    return normalize(vec3<f32>(-d.x, 1.0, -d.y));
}
