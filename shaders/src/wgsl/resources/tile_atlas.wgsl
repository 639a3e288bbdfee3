// Tile atlas lookup (Fikkan 2013, sec. 4.2, 5.6): tile slots of 16-bit heights (packed two per
// u32 word) and an indirection
// table over every tile of every level of the world (a slot, or INVALID_SLOT). A level-0 texel
// t reads the finest level l whose tile covering t >> l is resident, so a missing tile shows as
// a coarser one, never as a hole. CPU reference: terrain_core::TileAtlas::stored_at.

struct AtlasInfo {
    world_size: vec2<u32>,
    // log2 of the tile side.
    tile_shift: u32,
    levels: u32,
    // Stored value where no level is resident.
    fill: u32,
    slot_count: u32,
    _pad0: u32,
    _pad1: u32,
    // Per level: tiles across, tiles down, first table entry, unused.
    level: array<vec4<u32>, 32>,
}

// `atlas`, `atlas_heights` and `atlas_table` are bound by tile_atlas_bind.wgsl (1 to 3) or,
// beside a detail layer's 3 to 5, by tile_atlas_bind_high.wgsl (20 to 22).

// The stored height at level-0 texel `t`, which lies inside the world. Every invocation walks
// every level (`found` keeps the finest resident one) rather than returning from inside the
// loop: llvmpipe's GL driver gave the fill value to some invocations whose neighbours had left
// such a loop early in an earlier call (the atlas tests failed on WGPU_BACKEND=gl).
fn atlas_stored(t: vec2<u32>) -> u32 {
    let shift = atlas.tile_shift;
    let mask = (1u << shift) - 1u;
    var stored = atlas.fill;
    var found = false;
    for (var l = 0u; l < atlas.levels; l = l + 1u) {
        let c = t >> vec2<u32>(l, l);
        let tile = c >> vec2<u32>(shift, shift);
        let info = atlas.level[l];
        if !found && tile.x < info.x && tile.y < info.y {
            let slot = atlas_table[info.z + tile.y * info.x + tile.x];
            // INVALID_SLOT (and anything else out of range) is not resident.
            if slot < atlas.slot_count {
                let w = c & vec2<u32>(mask, mask);
                // Slots of rows of 16-bit texels packed two per word (packed.wgsl).
                let side = 1u << shift;
                let words = packed_pitch(side, 16u) * side;
                let word = atlas_heights[slot * words + packed_index(w.x, w.y, side, 16u)];
                stored = packed_get(word, w.x, 16u);
                found = true;
            }
        }
    }
    return stored;
}
