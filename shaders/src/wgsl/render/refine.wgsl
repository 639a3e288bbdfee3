// RefinePass and RefineRenderer (Flower 2010, sec. 2.4.3, eq. 2.2, fig. 2.7): the coarse cells
// around the camera as two triangles each, every triangle split by the refinement pattern of
// its vertices' flags into sub-triangles displaced by coarse + detail height, appended to a
// vertex buffer with the indirect draw arguments; then drawn with clipmap.wgsl's frame,
// surface and fragment shader (the hook of clipmap_detail_refined.wgsl). CPU reference:
// terrain_lod::refine (same region, flags and patterns).

struct RefineParams {
    // The region is the cells -half_cells .. half_cells around the camera's whole texel.
    half_cells: u32,
    // Triangles the output holds.
    capacity: u32,
    // Vertices closer than this (metres, horizontally) may be refined; the detail displaces
    // them fully up to fade_start_m from the eye, not at all from radius_m on.
    radius_m: f32,
    fade_start_m: f32,
}

struct RefineState {
    count: atomic<u32>,
    overflow: atomic<u32>,
    _pad0: u32,
    _pad1: u32,
    // draw_indirect's arguments.
    vertex_count: u32,
    instance_count: u32,
    first_vertex: u32,
    first_instance: u32,
}

@group(0) @binding(6) var<uniform> refine: RefineParams;
// Three vertices per triangle of (x, z texels relative to the camera's whole texel, height m).
@group(0) @binding(7) var<storage, read_write> refined: array<f32>;
@group(0) @binding(8) var<storage, read_write> refine_state: RefineState;

// terrain_lod::refine's patterns, barycentric weights in thirds per sub-triangle vertex: the
// whole triangle (0), side v0-v1 split (1..4, rho 3), side v2-v0 (4..7, rho 5), side v1-v2
// (7..10, rho 6), nine sub-triangles (10..19, rho 7).
var<private> PATTERNS: array<vec3<u32>, 57> = array<vec3<u32>, 57>(
    vec3<u32>(3u, 0u, 0u), vec3<u32>(0u, 3u, 0u), vec3<u32>(0u, 0u, 3u),
    vec3<u32>(3u, 0u, 0u), vec3<u32>(2u, 1u, 0u), vec3<u32>(0u, 0u, 3u),
    vec3<u32>(2u, 1u, 0u), vec3<u32>(1u, 2u, 0u), vec3<u32>(0u, 0u, 3u),
    vec3<u32>(1u, 2u, 0u), vec3<u32>(0u, 3u, 0u), vec3<u32>(0u, 0u, 3u),
    vec3<u32>(0u, 0u, 3u), vec3<u32>(1u, 0u, 2u), vec3<u32>(0u, 3u, 0u),
    vec3<u32>(1u, 0u, 2u), vec3<u32>(2u, 0u, 1u), vec3<u32>(0u, 3u, 0u),
    vec3<u32>(2u, 0u, 1u), vec3<u32>(3u, 0u, 0u), vec3<u32>(0u, 3u, 0u),
    vec3<u32>(0u, 3u, 0u), vec3<u32>(0u, 2u, 1u), vec3<u32>(3u, 0u, 0u),
    vec3<u32>(0u, 2u, 1u), vec3<u32>(0u, 1u, 2u), vec3<u32>(3u, 0u, 0u),
    vec3<u32>(0u, 1u, 2u), vec3<u32>(0u, 0u, 3u), vec3<u32>(3u, 0u, 0u),
    vec3<u32>(3u, 0u, 0u), vec3<u32>(2u, 1u, 0u), vec3<u32>(2u, 0u, 1u),
    vec3<u32>(2u, 1u, 0u), vec3<u32>(1u, 2u, 0u), vec3<u32>(1u, 1u, 1u),
    vec3<u32>(2u, 0u, 1u), vec3<u32>(1u, 1u, 1u), vec3<u32>(1u, 0u, 2u),
    vec3<u32>(1u, 2u, 0u), vec3<u32>(0u, 3u, 0u), vec3<u32>(0u, 2u, 1u),
    vec3<u32>(1u, 1u, 1u), vec3<u32>(0u, 2u, 1u), vec3<u32>(0u, 1u, 2u),
    vec3<u32>(1u, 0u, 2u), vec3<u32>(0u, 1u, 2u), vec3<u32>(0u, 0u, 3u),
    vec3<u32>(0u, 1u, 2u), vec3<u32>(1u, 0u, 2u), vec3<u32>(1u, 1u, 1u),
    vec3<u32>(1u, 1u, 1u), vec3<u32>(2u, 0u, 1u), vec3<u32>(2u, 1u, 0u),
    vec3<u32>(0u, 2u, 1u), vec3<u32>(1u, 1u, 1u), vec3<u32>(1u, 2u, 0u),
);

// Whether vertex `v` (texels from the camera's whole texel) is refined: within the radius (the
// f32 operations of RefineView::within) and with a detail tile in a slot within one coarse
// texel and the differences' reach (DetailLayout::box_may_touch).
fn refine_flag(v: vec2<i32>) -> bool {
    let dx = (f32(v.x) - frame.camera_frac.x) * frame.texel_size;
    let dz = (f32(v.y) - frame.camera_frac.y) * frame.texel_size;
    if !(dx * dx + dz * dz < refine.radius_m * refine.radius_m) {
        return false;
    }
    return !detail_box_is_zero(vec2<f32>(v - vec2<i32>(1, 1)), vec2<f32>(v + vec2<i32>(1, 1)));
}

// floor(v / 3) on integers of either sign.
fn floor_div3(v: vec2<i32>) -> vec2<i32> {
    let q = v / 3;
    return q - select(vec2<i32>(0, 0), vec2<i32>(1, 1), v - q * 3 < vec2<i32>(0, 0));
}

// The drawn vertex at `p3` (thirds of a texel from the camera's whole texel): the bilinear
// coarse height (the stored height itself on whole texels, as the clipmap draws it) plus the
// detail height, faded out by the region's edge (vertices there are the coarse surface). A function of `p3` alone, so both triangles of a side agree bit for bit.
fn refined_vertex(p3: vec2<i32>) -> vec3<f32> {
    let b = floor_div3(p3);
    let f = vec2<f32>(p3 - 3 * b) / 3.0;
    let t = frame.camera_texel + b;
    let h00 = height_at(t);
    let h10 = height_at(t + vec2<i32>(1, 0));
    let h01 = height_at(t + vec2<i32>(0, 1));
    let h11 = height_at(t + vec2<i32>(1, 1));
    let top = h00 + (h10 - h00) * f.x;
    let bot = h01 + (h11 - h01) * f.x;
    let coarse = top + (bot - top) * f.y;
    let q = vec2<f32>(p3) / 3.0;
    let rel = q - frame.camera_frac;
    let world = vec3<f32>(rel.x * frame.texel_size, coarse - frame.camera_height, rel.y * frame.texel_size);
    let w = 1.0 - smoothstep(refine.fade_start_m, refine.radius_m, length(world));
    var h = coarse;
    if w > 0.0 {
        let d = p3 * i32(detail.refine);
        let db = floor_div3(d);
        let df = vec2<f32>(d - 3 * db) / 3.0;
        h = coarse + w * detail_height(detail.camera_detail + db, df);
    }
    return vec3<f32>(q, h);
}

@compute @workgroup_size(64)
fn refine_triangles(@builtin(global_invocation_id) id: vec3<u32>) {
    let side = 2u * refine.half_cells;
    let index = id.x;
    if index >= 2u * side * side {
        return;
    }
    // RefineView::base_triangle: v0 v1 the clipmap's diagonal of the cell, counter-clockwise
    // from above.
    let cell = index / 2u;
    let a = vec2<i32>(-i32(refine.half_cells)) + vec2<i32>(i32(cell % side), i32(cell / side));
    var v = array<vec2<i32>, 3>(a + vec2<i32>(0, 1), a + vec2<i32>(1, 0), a);
    if index % 2u == 1u {
        v = array<vec2<i32>, 3>(a + vec2<i32>(1, 0), a + vec2<i32>(0, 1), a + vec2<i32>(1, 1));
    }
    let rho = u32(refine_flag(v[0])) | (u32(refine_flag(v[1])) << 1u) | (u32(refine_flag(v[2])) << 2u);
    var first = 0u;
    var count = 1u;
    switch rho {
        case 3u: { first = 1u; count = 3u; }
        case 5u: { first = 4u; count = 3u; }
        case 6u: { first = 7u; count = 3u; }
        case 7u: { first = 10u; count = 9u; }
        default: {}
    }
    let at = atomicAdd(&refine_state.count, count);
    for (var i = 0u; i < count; i = i + 1u) {
        if at + i >= refine.capacity {
            atomicStore(&refine_state.overflow, 1u);
            return;
        }
        for (var j = 0u; j < 3u; j = j + 1u) {
            let w = vec3<i32>(PATTERNS[(first + i) * 3u + j]);
            let r = refined_vertex(v[0] * w.x + v[1] * w.y + v[2] * w.z);
            let o = ((at + i) * 3u + j) * 3u;
            refined[o] = r.x;
            refined[o + 1u] = r.y;
            refined[o + 2u] = r.z;
        }
    }
}

@compute @workgroup_size(1)
fn refine_finish() {
    refine_state.vertex_count = 3u * min(atomicLoad(&refine_state.count), refine.capacity);
    refine_state.instance_count = 1u;
    refine_state.first_vertex = 0u;
    refine_state.first_instance = 0u;
}

@vertex
fn vs_refined(@location(0) v: vec3<f32>) -> VsOut {
    let rel_texel = v.xy - frame.camera_frac;
    let world = vec3<f32>(rel_texel.x * frame.texel_size, v.z - frame.camera_height, rel_texel.y * frame.texel_size);
    var out: VsOut;
    out.clip = frame.view_proj * vec4<f32>(world, 1.0);
    out.rel_texel = rel_texel;
    out.height = v.z;
    out.view_dist = length(world);
    return out;
}
