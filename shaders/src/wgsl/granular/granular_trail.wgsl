// TrailEffectPass: a granular trail painted on a material layer, bit for bit as its CPU
// reference terrain_core::apply_trail_effect: the effect's whole amount on every column of the
// active area that the step presses down (PENETRATING in the penetration texture).

struct TrailParams {
    // Active area in map texels (the layer covers the map).
    area_min: vec2<u32>,
    area_size: vec2<u32>,
    // Layer row pitch in texels, material index, amount 0 to 255.
    pitch: u32,
    material: u32,
    amount: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> t: TrailParams;
@group(0) @binding(1) var<storage, read> pen: array<Penetration>;
@group(0) @binding(2) var<storage, read_write> layer: array<u32>;

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= t.area_size.x || id.y >= t.area_size.y {
        return;
    }
    if pen[id.y * t.area_size.x + id.x].kind != PENETRATING {
        return;
    }
    let i = (t.area_min.y + id.y) * t.pitch + t.area_min.x + id.x;
    layer[i] = paint_texel(layer[i], t.material, t.amount);
}
