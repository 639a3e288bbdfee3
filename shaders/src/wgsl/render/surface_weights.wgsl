// What a fragment's material weights are computed from.
struct SurfacePoint {
    // World position (x, z) in metres.
    position: vec2<f32>,
    // Height in metres, and its fraction of the style's ramp (0 at its low end, 1 at its high).
    height: f32,
    ramp: f32,
    // Slope (metres per metre) and curvature (1/m, the heights' Laplacian).
    slope: f32,
    curvature: f32,
}

// The weights of grass, dirt, rock and snow (x, y, z, w; they need not sum to 1, the blend
// renormalises) at a point of the surface. An engine replaces this function with its own
// (TerrainRenderer::set_surface_shader); by default it is the autoshader.
// USER_SURFACE_BEGIN
fn surface_weights(p: SurfacePoint) -> vec4<f32> {
    return autoshade_weights(frame.autoshade, frame.autoshade_dirt.xy, p.ramp, p.slope, p.curvature);
}
// USER_SURFACE_END
