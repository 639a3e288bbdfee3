// MaterialEffectPass: a stamp's material effect painted over one piece of its footprint on a
// material layer (terrain_core::material_effect, its CPU reference, evaluated in the same
// order). The layer is one RGBA8 texel per u32 word (R in the low byte), rows `pitch` words
// apart (a multiple of 64, so a rect of it copies to the layer's texture as is); paint.wgsl
// paints a texel.

struct EffectParams {
    // The piece in layer texels and in the footprint's unwrapped frame.
    map_min: vec2<u32>,
    size: vec2<u32>,
    unwrapped_min: vec2<i32>,
    pitch: u32,
    material: u32,
    // The stamp's frame in texels (terrain_core::EffectFrame).
    center: vec2<f32>,
    inv_half: vec2<f32>,
    sin_cos: vec2<f32>,
    // 255 times the effect's strength.
    strength: f32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> p: EffectParams;
@group(0) @binding(1) var<storage, read_write> layer: array<u32>;

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= p.size.x || id.y >= p.size.y {
        return;
    }
    let u = p.unwrapped_min + vec2<i32>(id.xy);
    let d = vec2<f32>(f32(u.x) - p.center.x, f32(u.y) - p.center.y);
    let s = p.sin_cos.x;
    let c = p.sin_cos.y;
    let local = vec2<f32>((d.x * c + d.y * s) * p.inv_half.x, (d.y * c - d.x * s) * p.inv_half.y);
    let t2 = local.x * local.x + local.y * local.y;
    if !(t2 < 1.0) {
        return;
    }
    let f = 1.0 - t2;
    let a = min(u32(floor(p.strength * (f * f) + 0.5)), 255u);
    if a == 0u {
        return;
    }
    let i = (p.map_min.y + id.y) * p.pitch + p.map_min.x + id.x;
    layer[i] = paint_texel(layer[i], p.material, a);
}
