// tile_atlas.wgsl's buffers at bindings 1 to 3 (GpuTileAtlas's info, heights and table).
@group(0) @binding(1) var<storage, read> atlas: AtlasInfo;
@group(0) @binding(2) var<storage, read> atlas_heights: array<u32>;
@group(0) @binding(3) var<storage, read> atlas_table: array<u32>;
