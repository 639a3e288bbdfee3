// A streamed world's paint and colour (terrain_gpu::GpuOverlayAtlas), read by the renderers'
// material shading (materials.wgsl) and by the overlay probe. Needs `frame.camera_texel` and
// `map_texel` (clipmap.wgsl's, or the probe's own).
//
// Tile slots in a 2D array and a table
// texture describing the pyramid and holding each tile's slot. Drawn instead of the windows
// at 13 and 14 when frame.color_layer.w says so (bit 1: paint, bit 2: colour).
@group(0) @binding(16) var paint_slots: texture_2d_array<f32>;
@group(0) @binding(17) var paint_table: texture_2d<u32>;
@group(0) @binding(18) var color_slots: texture_2d_array<f32>;
@group(0) @binding(19) var color_table: texture_2d<u32>;

// Entry `i` of an overlay table (rows of 1024, overlay_atlas.rs's TABLE_WIDTH).
fn table_entry(table: texture_2d<u32>, i: u32) -> u32 {
    return textureLoad(table, vec2<u32>(i % 1024u, i / 1024u), 0).r;
}

// A streamed layer at `q` (texels relative to the camera's whole texel): the finest level whose
// tile over the texel is resident, its four texels around `q` blended, clamped to the tile.
// CPU reference: terrain_core::OverlayAtlas::sample. Every invocation walks every level (as
// tile_atlas.wgsl's lookup does, for llvmpipe's GL driver). Zero where nothing is resident.
fn streamed_layer_at(slots: texture_2d_array<f32>, table: texture_2d<u32>, q: vec2<f32>, premultiply: bool) -> vec4<f32> {
    let levels = table_entry(table, 0u);
    let shift = table_entry(table, 1u);
    let cols = max(table_entry(table, 2u), 1u);
    let slot_count = table_entry(table, 3u);
    let p0 = floor(q);
    let t = map_texel(frame.camera_texel + vec2<i32>(p0));
    var level = 0u;
    var slot = 0u;
    var found = false;
    for (var l = 0u; l < min(levels, 32u); l = l + 1u) {
        let tile = (t >> vec2<u32>(l, l)) >> vec2<u32>(shift, shift);
        let tiles = vec2<u32>(table_entry(table, 4u + 3u * l), table_entry(table, 5u + 3u * l));
        if !found && tile.x < tiles.x && tile.y < tiles.y {
            let first = table_entry(table, 6u + 3u * l);
            let s = table_entry(table, 128u + first + tile.y * tiles.x + tile.x);
            if s < slot_count {
                found = true;
                level = l;
                slot = s;
            }
        }
    }
    if !found {
        return vec4<f32>(0.0, 0.0, 0.0, 0.0);
    }
    let scale = f32(1u << level);
    let at = (vec2<f32>(t) + (q - p0) + 0.5) / scale - 0.5;
    let i0 = floor(at);
    let f = at - i0;
    let side = i32(1u << shift);
    let origin = vec2<i32>(((t >> vec2<u32>(level, level)) >> vec2<u32>(shift, shift)) << vec2<u32>(shift, shift));
    let per_layer = cols * cols;
    let within = slot % per_layer;
    let base = vec2<i32>(i32(within % cols), i32(within / cols)) * side;
    let layer = i32(slot / per_layer);
    var c: array<vec4<f32>, 4>;
    for (var k = 0; k < 4; k = k + 1) {
        let d = vec2<i32>(k & 1, k >> 1u);
        let local = clamp(vec2<i32>(i0) + d - origin, vec2<i32>(0, 0), vec2<i32>(side - 1, side - 1));
        let v = textureLoad(slots, base + local, layer, 0);
        if premultiply {
            c[k] = vec4<f32>(v.rgb * v.a, v.a);
        } else {
            c[k] = v;
        }
    }
    return mix(mix(c[0], c[1], f.x), mix(c[2], c[3], f.x), f.y);
}
