// AtlasProbe: what the atlas clipmap surface (clipmap_surface_atlas.wgsl and tile_atlas.wgsl,
// joined with this file) reads at a list of level-0 texels: the stored height, the height in
// metres and the gradient, for comparison with the CPU reference and for height queries.

// The fields of the clipmap's Frame that the surface reads, under the same names.
struct Frame {
    map_size: vec2<u32>,
    // A multiple of the world size making every texel non-negative before `%`.
    wrap_offset: vec2<i32>,
    wrap: u32,
    count: u32,
    height_scale: f32,
    height_offset: f32,
    texel_size: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(4) var<storage, read> probe_texels: array<vec2<i32>>;
// Per texel: stored height, then the bits of height_at, derivative_at.x and derivative_at.y.
@group(0) @binding(5) var<storage, read_write> probe_out: array<vec4<u32>>;

@compute @workgroup_size(64, 1, 1)
fn probe_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= frame.count {
        return;
    }
    let t = probe_texels[id.x];
    let d = derivative_at(t);
    probe_out[id.x] = vec4<u32>(
        atlas_stored(atlas_texel(t)),
        bitcast<u32>(height_at(t)),
        bitcast<u32>(d.x),
        bitcast<u32>(d.y),
    );
}
