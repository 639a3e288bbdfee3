// A streamed world's paint and colour (terrain_gpu::GpuOverlayAtlas), read by the renderers'
// material shading (materials.wgsl) and by the overlay probe. Needs `frame.camera_texel` and
// `map_texel` (clipmap.wgsl's, or the probe's own).
//
// Tile slots in a 2D array, and a table texture: row 0 holds log2 of the tile side and the
// slots across and down an array layer; from row 1, per level-0 tile, the finest resident level
// covering it and its slot (`level << 27 | slot`), or INVALID_SLOT. Drawn instead of the
// windows at 13 and 14 when frame.color_layer.w says so (bit 1: paint, bit 2: colour).
@group(0) @binding(16) var paint_slots: texture_2d_array<f32>;
@group(0) @binding(17) var paint_table: texture_2d<u32>;
@group(0) @binding(18) var color_slots: texture_2d_array<f32>;
@group(0) @binding(19) var color_table: texture_2d<u32>;

// A streamed layer at `q` (texels relative to the camera's whole texel): the finest level whose
// tile over the texel is resident, its four texels around `q` blended, clamped to the tile.
// CPU reference: terrain_core::OverlayAtlas::sample. Zero where nothing is resident.
fn streamed_layer_at(slots: texture_2d_array<f32>, table: texture_2d<u32>, q: vec2<f32>, premultiply: bool) -> vec4<f32> {
    let shift = textureLoad(table, vec2<u32>(0u, 0u), 0).r;
    let cols = max(textureLoad(table, vec2<u32>(1u, 0u), 0).r, 1u);
    let rows = max(textureLoad(table, vec2<u32>(2u, 0u), 0).r, 1u);
    let p0 = floor(q);
    let t = map_texel(frame.camera_texel + vec2<i32>(p0));
    let tile0 = t >> vec2<u32>(shift, shift);
    let entry = textureLoad(table, vec2<u32>(tile0.x, tile0.y + 1u), 0).r;
    if entry == 0xffffffffu {
        return vec4<f32>(0.0, 0.0, 0.0, 0.0);
    }
    let level = entry >> 27u;
    let slot = entry & 0x7ffffffu;
    let scale = f32(1u << level);
    let at = (vec2<f32>(t) + (q - p0) + 0.5) / scale - 0.5;
    let i0 = floor(at);
    let f = at - i0;
    let side = i32(1u << shift);
    let origin = vec2<i32>(((t >> vec2<u32>(level, level)) >> vec2<u32>(shift, shift)) << vec2<u32>(shift, shift));
    let per_layer = cols * rows;
    let within = slot % per_layer;
    let base = vec2<i32>(i32(within % cols), i32(within / cols)) * side;
    let layer = i32(slot / per_layer);
    // The four texels, clamped to the tile, written out: a local array filled in a loop took
    // lavapipe's and llvmpipe's compilers minutes.
    let a = vec2<i32>(i0) - origin;
    // The tile's last texel, or the level's where the world ends inside the tile.
    let end = vec2<i32>((frame.map_size - vec2<u32>(1u, 1u)) >> vec2<u32>(level, level)) - origin;
    let last = min(vec2<i32>(side - 1, side - 1), end);
    let lo = clamp(a, vec2<i32>(0, 0), last);
    let hi = clamp(a + vec2<i32>(1, 1), vec2<i32>(0, 0), last);
    var c00 = textureLoad(slots, base + lo, layer, 0);
    var c10 = textureLoad(slots, base + vec2<i32>(hi.x, lo.y), layer, 0);
    var c01 = textureLoad(slots, base + vec2<i32>(lo.x, hi.y), layer, 0);
    var c11 = textureLoad(slots, base + hi, layer, 0);
    if premultiply {
        c00 = vec4<f32>(c00.rgb * c00.a, c00.a);
        c10 = vec4<f32>(c10.rgb * c10.a, c10.a);
        c01 = vec4<f32>(c01.rgb * c01.a, c01.a);
        c11 = vec4<f32>(c11.rgb * c11.a, c11.a);
    }
    return mix(mix(c00, c10, f.x), mix(c01, c11, f.x), f.y);
}
