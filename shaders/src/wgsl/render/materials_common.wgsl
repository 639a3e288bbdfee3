// The autoshader's formulas (CPU reference: terrain_core::material), operation for operation:
// bare rock on steep slopes, snow high up, dirt where the ground bends sharply, grass elsewhere.

// Hermite smoothstep written out, as terrain_core::material::smoothstep.
fn mat_smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = clamp((x - e0) / (e1 - e0), 0.0, 1.0);
    return t * t * (3.0 - 2.0 * t);
}

// Weights of grass, dirt, rock, snow (x, y, z, w) at ramp fraction `t`, `slope` (m/m) and
// `curvature` (1/m). `edges`: rock slope (x, y) and snow height (z, w); `dirt`: the dirt
// curvature's edges (x, y).
fn autoshade_weights(edges: vec4<f32>, dirt_edges: vec2<f32>, t: f32, slope: f32, curvature: f32) -> vec4<f32> {
    let rock = mat_smoothstep(edges.x, edges.y, slope);
    let cover = 1.0 - rock;
    let snow = mat_smoothstep(edges.z, edges.w, t) * cover;
    let open = cover - snow;
    let dirt = mat_smoothstep(dirt_edges.x, dirt_edges.y, abs(curvature)) * open;
    return vec4<f32>(open - dirt, dirt, rock, snow);
}

// The heights' Laplacian (1/m) from a centre height and its four neighbours (x-, x+, z-, z+)
// `spacing` metres away.
fn curvature_from_heights(centre: f32, around: vec4<f32>, spacing: f32) -> f32 {
    return ((around.x + around.y) + (around.z + around.w) - 4.0 * centre) / (spacing * spacing);
}

// The Laplacian (1/m) inside a texel cell from the gradients at its corners (x then z),
// `texel_size` apart: for surfaces whose gradients are exact differences of their heights.
fn curvature_from_gradients(d00: vec2<f32>, d10: vec2<f32>, d01: vec2<f32>, d11: vec2<f32>, texel_size: f32) -> f32 {
    let dxx = (d10.x - d00.x) + (d11.x - d01.x);
    let dzz = (d01.y - d00.y) + (d11.y - d10.y);
    return (dxx + dzz) / (2.0 * texel_size);
}
