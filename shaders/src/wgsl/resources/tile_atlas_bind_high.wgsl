// tile_atlas.wgsl's buffers at bindings 20 to 22, clear of a detail layer's 3 to 5, for a
// streamed world drawn with detail tiles.
@group(0) @binding(20) var<storage, read> atlas: AtlasInfo;
@group(0) @binding(21) var<storage, read> atlas_heights: array<u32>;
@group(0) @binding(22) var<storage, read> atlas_table: array<u32>;
