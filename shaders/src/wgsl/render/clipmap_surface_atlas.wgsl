// Clipmap surface of a tile atlas (GpuTileAtlas): heights from the finest resident level of the
// tile pyramid (tile_atlas.wgsl, placed before this file), addressed like the world (clamped to
// its edges, or wrapped), normals by central differences of those heights.

// The level-0 texel a grid texel reads.
fn atlas_texel(t: vec2<i32>) -> vec2<u32> {
    if frame.wrap == WRAP_REPEAT {
        return vec2<u32>(t + frame.wrap_offset) % frame.map_size;
    }
    return vec2<u32>(clamp(t, vec2<i32>(0, 0), vec2<i32>(frame.map_size) - vec2<i32>(1, 1)));
}

fn height_at(t: vec2<i32>) -> f32 {
    return frame.height_offset + frame.height_scale * f32(atlas_stored(atlas_texel(t)));
}

// Gradient (dh/dX, dh/dZ) in metres per metre by central differences.
fn derivative_at(t: vec2<i32>) -> vec2<f32> {
    let dx = height_at(t + vec2<i32>(1, 0)) - height_at(t - vec2<i32>(1, 0));
    let dz = height_at(t + vec2<i32>(0, 1)) - height_at(t - vec2<i32>(0, 1));
    return vec2<f32>(dx, dz) / (2.0 * frame.texel_size);
}
