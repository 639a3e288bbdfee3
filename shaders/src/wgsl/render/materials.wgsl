// Material shading of the terrain renderers (terrain_gpu::GpuMaterials): four materials' albedo
// and normal images in texture arrays, blended by weights, projected from above on gentle
// ground and from the sides on steep ground (triplanar mapping), their normals perturbing the
// surface's.

@group(0) @binding(10) var material_albedo: texture_2d_array<f32>;
@group(0) @binding(11) var material_normal: texture_2d_array<f32>;
@group(0) @binding(12) var material_sampler: sampler;
// The colour layer (GpuColorLayer): one RGBA8 texel per map texel, sRGB as the image holds it
// (a texture: storage buffers per stage are few on some devices).
@group(0) @binding(13) var color_layer: texture_2d<f32>;
// The material layer (GpuMaterialLayer): painted weights of the four materials per map texel,
// their sum the paint's cover (terrain_core::material_effect).
@group(0) @binding(14) var material_layer: texture_2d<f32>;
// The hole mask (GpuHoleMask, terrain_core::holes): nonzero at the cells cut away, over the
// world cells frame.holes covers (the whole map, or a window around the camera), each cell at
// its coordinates modulo the mask's size.
@group(0) @binding(15) var hole_mask: texture_2d<f32>;
// Which layers are streamed (frame.color_layer.w's bits).
fn streamed(bit: u32) -> bool {
    return (u32(frame.color_layer.w + 0.5) & bit) != 0u;
}

// Whether the cell under `q` (texels relative to the camera's whole texel) is a hole: the cell
// whose lower corner is floor(q), as collision finds it. Cells outside the mask are ground.
fn in_hole(q: vec2<f32>) -> bool {
    let w = window_texel(frame.camera_texel + vec2<i32>(floor(q)), frame.holes);
    return w.z != 0 && textureLoad(hole_mask, w.xy, 0).r > 0.0;
}

// Where world cell `t` lies in a layer covering the cells `window` (origin xy, size zw: the
// whole map, or a window around the camera): its texel (xy) and whether it is covered (z).
// Cell `c` lies at texel `c mod size`.
fn window_texel(t: vec2<i32>, window: vec4<i32>) -> vec3<i32> {
    let cell = vec2<i32>(map_texel(t));
    let size = window.zw;
    var rel = cell - window.xy;
    if frame.wrap == WRAP_REPEAT {
        // On a repeating world the window may reach across the edge.
        let m = vec2<i32>(frame.map_size);
        rel = ((rel % m) + m) % m;
    }
    if any(rel < vec2<i32>(0, 0)) || any(rel >= size) {
        return vec3<i32>(0, 0, 0);
    }
    return vec3<i32>(((window.xy + rel) % size + size) % size, 1);
}

// `layer`'s texel at world cell `t`, the layer covering the cells `window`: nothing (zero)
// outside it. `premultiply`: its colour times its alpha (a colour layer's texels, so that
// blending them with transparent ones, and fading them, darkens nothing).
fn window_layer_texel(layer: texture_2d<f32>, window: vec4<i32>, t: vec2<i32>, premultiply: bool) -> vec4<f32> {
    let w = window_texel(t, window);
    if w.z == 0 {
        return vec4<f32>(0.0, 0.0, 0.0, 0.0);
    }
    let c = textureLoad(layer, w.xy, 0);
    if premultiply {
        return vec4<f32>(c.rgb * c.a, c.a);
    }
    return c;
}

// `layer` at `q` (texels relative to the camera's whole texel), bilinear between the four
// texels around it, the layer covering the cells `window`. A window smaller than the map fades
// out over its outer eighth, so a move of the window never pops.
fn window_layer_at(layer: texture_2d<f32>, window: vec4<i32>, q: vec2<f32>, premultiply: bool) -> vec4<f32> {
    let p0 = floor(q);
    let f = q - p0;
    let t0 = frame.camera_texel + vec2<i32>(p0);
    let c00 = window_layer_texel(layer, window, t0, premultiply);
    let c10 = window_layer_texel(layer, window, t0 + vec2<i32>(1, 0), premultiply);
    let c01 = window_layer_texel(layer, window, t0 + vec2<i32>(0, 1), premultiply);
    let c11 = window_layer_texel(layer, window, t0 + vec2<i32>(1, 1), premultiply);
    let value = mix(mix(c00, c10, f.x), mix(c01, c11, f.x), f.y);
    let size = window.zw;
    if all(size >= vec2<i32>(frame.map_size)) {
        return value;
    }
    // Distance (cells) from the fragment to the window's nearest edge.
    let rel = vec2<f32>(frame.camera_texel - window.xy) + q;
    let edge = min(min(rel.x, rel.y), min(f32(size.x) - rel.x, f32(size.y) - rel.y));
    let fade = clamp(edge / max(f32(min(size.x, size.y)) * 0.125, 1.0), 0.0, 1.0);
    return value * fade;
}

// The colour layer at `q` over `albedo`, by its alpha (premultiplied).
fn colored_albedo(q: vec2<f32>, albedo: vec3<f32>) -> vec3<f32> {
    var c: vec4<f32>;
    if streamed(2u) {
        c = streamed_layer_at(color_slots, color_table, q, true);
    } else {
        c = window_layer_at(color_layer, frame.color_window, q, true);
    }
    return albedo * (1.0 - c.a) + c.rgb;
}

// The weights `w` (the autoshader's or an engine's) with the material layer's paint at `q`
// over them: all paint where its cover is full, none where it is zero.
fn painted_weights(q: vec2<f32>, w: vec4<f32>) -> vec4<f32> {
    var paint: vec4<f32>;
    if streamed(1u) {
        paint = streamed_layer_at(paint_slots, paint_table, q, false);
    } else {
        paint = window_layer_at(material_layer, frame.paint_window, q, false);
    }
    let cover = paint.x + paint.y + paint.z + paint.w;
    let base = max(w, vec4<f32>(0.0, 0.0, 0.0, 0.0));
    let unpainted = base / max(base.x + base.y + base.z + base.w, 1e-6);
    return unpainted * max(1.0 - cover, 0.0) + paint / max(cover, 1.0);
}

struct MaterialSurface {
    albedo: vec3<f32>,
    normal: vec3<f32>,
}

// Texture coordinates of one projection and their screen derivatives.
struct Projection {
    uv: vec2<f32>,
    ddx: vec2<f32>,
    ddy: vec2<f32>,
}

// One material's share: its albedo and normal bend weighted by `wm` and the projections'
// blend, and the weight it took (projections of negligible blend are not sampled; the
// explicit gradients make that branch legal).
struct MaterialShare {
    albedo: vec3<f32>,
    bend: vec3<f32>,
    weight: f32,
}

fn material_share(m: i32, wm: f32, blend: vec3<f32>, top: Projection, side_x: Projection, side_z: Projection) -> MaterialShare {
    var share = MaterialShare(vec3<f32>(0.0, 0.0, 0.0), vec3<f32>(0.0, 0.0, 0.0), 0.0);
    if wm <= 0.002 {
        return share;
    }
    if blend.y > 0.01 {
        let k = wm * blend.y;
        share.albedo += k * textureSampleGrad(material_albedo, material_sampler, top.uv, m, top.ddx, top.ddy).rgb;
        let t = textureSampleGrad(material_normal, material_sampler, top.uv, m, top.ddx, top.ddy).xy * 2.0 - 1.0;
        share.bend += k * vec3<f32>(t.x, 0.0, t.y);
        share.weight += k;
    }
    if blend.x > 0.01 {
        let k = wm * blend.x;
        share.albedo += k * textureSampleGrad(material_albedo, material_sampler, side_x.uv, m, side_x.ddx, side_x.ddy).rgb;
        let t = textureSampleGrad(material_normal, material_sampler, side_x.uv, m, side_x.ddx, side_x.ddy).xy * 2.0 - 1.0;
        share.bend += k * vec3<f32>(0.0, t.y, t.x);
        share.weight += k;
    }
    if blend.z > 0.01 {
        let k = wm * blend.z;
        share.albedo += k * textureSampleGrad(material_albedo, material_sampler, side_z.uv, m, side_z.ddx, side_z.ddy).rgb;
        let t = textureSampleGrad(material_normal, material_sampler, side_z.uv, m, side_z.ddx, side_z.ddy).xy * 2.0 - 1.0;
        share.bend += k * vec3<f32>(t.x, t.y, 0.0);
        share.weight += k;
    }
    return share;
}

// `w`: the materials' weights; `top`, `side_x`, `side_z`: the three projections; `n`: the
// surface normal. Written without loops: software rasterisers compile loops over texture
// samples, inlined into a surface's own loops, very slowly.
fn material_surface(weights: vec4<f32>, top: Projection, side_x: Projection, side_z: Projection, n: vec3<f32>, strength: f32) -> MaterialSurface {
    // A user's weights may not sum to 1 (or be negative): normalised here.
    let clamped = max(weights, vec4<f32>(0.0, 0.0, 0.0, 0.0));
    let w = clamped / max(clamped.x + clamped.y + clamped.z + clamped.w, 1e-6);
    var blend = pow(abs(n), vec3<f32>(4.0, 4.0, 4.0));
    blend = blend / (blend.x + blend.y + blend.z);
    let s0 = material_share(0, w.x, blend, top, side_x, side_z);
    let s1 = material_share(1, w.y, blend, top, side_x, side_z);
    let s2 = material_share(2, w.z, blend, top, side_x, side_z);
    let s3 = material_share(3, w.w, blend, top, side_x, side_z);
    let albedo = s0.albedo + s1.albedo + s2.albedo + s3.albedo;
    let bend = s0.bend + s1.bend + s2.bend + s3.bend;
    // Shares skipped leave the weights short of 1: renormalise.
    let total = s0.weight + s1.weight + s2.weight + s3.weight;
    return MaterialSurface(albedo / max(total, 1e-4), normalize(n + strength * bend));
}
