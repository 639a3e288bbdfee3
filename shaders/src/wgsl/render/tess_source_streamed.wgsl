// TessellationPass's source for a streamed world (terrain_lod::StreamedTessellation): splits
// decided from a streamed CDLOD tree's node bounds (the camera's distance to the box of a square
// of the level's reach around the vertex and its nodes' heights), heights from the tile atlas
// (tile_atlas.wgsl and tile_atlas_bind_high.wgsl, placed before this file). Placed before
// tessellate.wgsl.

struct TreeInfo {
    // Per tree LOD: nodes across, nodes down, first node in tree_nodes, node side (texels).
    lod: array<vec4<u32>, 16>,
    // Per triangle level: reach (texels), tree LOD, flat radius (f32 bits, metres), unused.
    level: array<vec4<u32>, 16>,
    // The world's size in texels (vertices past it read its clamped edge), unused, unused.
    world: vec4<u32>,
    // Height in metres = x + y * stored value; unused, unused.
    height: vec4<f32>,
}

// (lowest, highest) height of every node of every LOD, LOD by LOD, row-major.
@group(0) @binding(1) var<storage, read> tree_nodes: array<vec2<f32>>;
@group(0) @binding(2) var<storage, read> tree: TreeInfo;

// (lowest, highest) height of the nodes covering the square of `level`'s reach around v: at
// most 2 x 2 nodes (the LOD's side is at least the square's). Mirrors
// StreamedTessellation::region.
fn region(v: vec2<i32>, level: u32) -> vec2<f32> {
    let info = tree.level[min(level, 15u)];
    let lod = tree.lod[min(info.y, 15u)];
    let side = i32(max(lod.w, 1u));
    let r = i32(info.x);
    let last = vec2<i32>(lod.xy) - vec2<i32>(1, 1);
    let lo = min(max(v - vec2<i32>(r, r), vec2<i32>(0, 0)) / side, last);
    let hi = min(max(v + vec2<i32>(r, r), vec2<i32>(0, 0)) / side, last);
    var b = tree_nodes[lod.z + u32(lo.y) * lod.x + u32(lo.x)];
    for (var y = lo.y; y <= min(hi.y, lo.y + 1); y++) {
        for (var x = lo.x; x <= min(hi.x, lo.x + 1); x++) {
            let n = tree_nodes[lod.z + u32(y) * lod.x + u32(x)];
            b = vec2<f32>(min(b.x, n.x), max(b.y, n.y));
        }
    }
    return b;
}

// The level's flat radius (the triangles' size) over the camera's distance to the box
// of the square of the level's reach and the region's heights. Mirrors
// StreamedTessellation::ratio.
fn split_ratio(v: vec2<i32>, level: u32) -> f32 {
    let b = region(v, level);
    let info = tree.level[min(level, 15u)];
    let ts = params.texel_size;
    let r = f32(info.x) * ts;
    let dx = max(abs(f32(v.x) * ts - params.camera.x) - r, 0.0);
    let dz = max(abs(f32(v.y) * ts - params.camera.z) - r, 0.0);
    let dy = max(max(b.x - params.camera.y, params.camera.y - b.y), 0.0);
    let dist = max(sqrt(dx * dx + dy * dy + dz * dz), NEAR_M);
    return params.scale * bitcast<f32>(info.z) / dist;
}

fn vertex_height(v: vec2<i32>) -> f32 {
    let last = vec2<i32>(tree.world.xy) - vec2<i32>(1, 1);
    let t = vec2<u32>(clamp(v, vec2<i32>(0, 0), last));
    return tree.height.x + tree.height.y * f32(atlas_stored(t));
}

// (lowest, highest) height around patch pid: the region of its first split.
fn patch_range(pid: u32) -> vec2<f32> {
    let ps = i32(params.patch_size);
    let p = vec2<i32>(i32(pid % params.patches.x), i32(pid / params.patches.x));
    return region(p * ps + vec2<i32>(ps / 2, ps / 2), 0u);
}
