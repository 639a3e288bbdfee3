// TessellationPass: adaptive tessellation by longest-edge bisection (Cervin 2012, sec. 2.3,
// algorithm 3.1), as compute, breadth first: one dispatch per level of the triangle hierarchy.
// Cervin refines each patch in a hardware tessellator; wgpu has none, and a depth-first
// refinement per base triangle (one invocation with a private stack, as the CPU reference
// does) keeps a real GPU nearly idle: two invocations per patch, each running a long loop
// that diverges from its neighbours', with a large private array that cuts occupancy. Here
// every level runs one short invocation per triangle of that level instead, so the work
// spreads over as many invocations as there are triangles.
//
// `generate` runs level 0 (two invocations per patch, the base triangles computed from the
// invocation index) and every later level (one invocation per triangle of the level's input
// queue): a triangle that splits appends those of its two children the frustum may see to the
// next level's queue (the other half of `tri_queue`), one that does not split is appended to the
// output vertex buffer. `advance` (one invocation) runs between two levels: it steps the level,
// writes the next level's dispatch size from the queue's count (clamped to the queue's
// capacity, and over two dimensions past the device's limit per dimension) and empties the
// queue the level will fill. `finish` writes the indirect draw arguments. A full queue or
// output sets `overflow`: a child that finds no room in the queue is emitted unsplit, a
// triangle that finds no room in the output is dropped; nothing is written out of bounds, and
// the pass always ends after its fixed number of dispatches.
//
// CPU reference: terrain_lod::TessHierarchy::select, or StreamedTessellation::select for a
// streamed world (same decisions, same f32 operations in the same order; only the order of the
// emitted triangles differs).

struct Params {
    camera: vec4<f32>,
    // Frustum planes (n, d) in world metres: left, right, bottom, top, near, far.
    planes: array<vec4<f32>, 6>,
    texel_size: f32,
    // K / (FLAT_SPHERE * triangle_width_px).
    scale: f32,
    // 1 / morph_range, or 0 without the morph.
    inv_morph_range: f32,
    use_density: u32,
    // Triangles of this level and finer are not split.
    split_levels: u32,
    patch_size: u32,
    // Triangles the output holds.
    capacity: u32,
    // 1: drop triangles outside the frustum.
    cull: u32,
    patches: vec2<u32>,
    grid: vec2<u32>,
    wrap: u32,
    // 1: split by projected error (scale = K / max_error_px), 0: by edge size.
    error_metric: u32,
    // Triangles each half of `tri_queue` holds.
    queue_capacity: u32,
    // The device's max_compute_workgroups_per_dimension.
    max_groups: u32,
    // TessDecision::full_resolution: texels drawn at full resolution (corners included) when
    // `full` is 1.
    full_lo: vec2<i32>,
    full_hi: vec2<i32>,
    full: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
    // descendant_reach of each level, four to a vector.
    reach: array<vec4<u32>, 4>,
}

struct State {
    count: atomic<u32>,
    overflow: atomic<u32>,
    // The level `generate` runs (0 after the clear; `advance` steps it).
    level: u32,
    _pad0: u32,
    // draw_indirect arguments: vertex count, instance count, first vertex, first instance.
    args: array<u32, 4>,
    // Triangles appended to each half of `tri_queue` (may pass its capacity: then it is
    // full).
    queued: array<atomic<u32>, 2>,
    _pad1: u32,
    _pad2: u32,
}

// A triangle of a queue (24 bytes): right-angle apex a, the drawn heights of a, l and r, and
// its patch (code >> 4) with the direction of l from a (code & 15: (sx + 1) + 3 (sy + 1) for
// the signs of l - a); l and r follow from the level (see `generate`).
struct Queued {
    a: vec2<i32>,
    ha: f32,
    hl: f32,
    hr: f32,
    code: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
// Bindings 1 and 2 (what the splits are decided from) and the functions `split_ratio`,
// `vertex_height` and `patch_range` come from the source placed before this file:
// tess_source_hierarchy.wgsl (a map's hierarchy) or tess_source_streamed.wgsl (a streamed
// world's tree and tile atlas).
@group(0) @binding(3) var<storage, read_write> out_vertices: array<f32>;
@group(0) @binding(4) var<storage, read_write> state: State;
// Two halves of queue_capacity triangles: level L reads half L % 2 and fills the other.
@group(0) @binding(5) var<storage, read_write> tri_queue: array<Queued>;
// `advance` only (its bind group; `generate` reads it as its indirect arguments): the
// dispatch_workgroups_indirect arguments of level L at 4 L.
@group(0) @binding(6) var<storage, read_write> dispatch_args: array<u32>;

const NEAR_M: f32 = 1e-3;
// terrain_lod::tessellation::{SPLIT_MARGIN, MAX_LEVELS}.
const SPLIT_MARGIN: f32 = 1e-4;
const MAX_LEVELS: u32 = 16u;
const GROUP: u32 = 64u;

// Right-angle apex a, hypotenuse l -> r ((l, r, a) counter-clockwise seen from above), drawn
// heights, level.
struct Tri {
    a: vec2<i32>,
    l: vec2<i32>,
    r: vec2<i32>,
    ha: f32,
    hl: f32,
    hr: f32,
    level: u32,
}

fn visible(t: Tri, pid: u32) -> bool {
    if params.cull == 0u {
        return true;
    }
    let ts = params.texel_size;
    let lo2 = vec2<f32>(min(min(t.a, t.l), t.r)) * ts;
    let hi2 = vec2<f32>(max(max(t.a, t.l), t.r)) * ts;
    let hb = patch_range(pid);
    let lo = vec3<f32>(lo2.x, hb.x, lo2.y);
    let hi = vec3<f32>(hi2.x, hb.y, hi2.y);
    for (var i = 0u; i < 6u; i++) {
        let p = params.planes[i];
        let far = select(lo, hi, p.xyz >= vec3<f32>(0.0));
        let d = p.x * far.x + p.y * far.y + p.z * far.z + p.w;
        if d < 0.0 {
            return false;
        }
    }
    return true;
}

fn emit(t: Tri) {
    let i = atomicAdd(&state.count, 1u);
    if i >= params.capacity {
        atomicStore(&state.overflow, 1u);
        return;
    }
    let o = i * 9u;
    out_vertices[o] = f32(t.l.x);
    out_vertices[o + 1u] = f32(t.l.y);
    out_vertices[o + 2u] = t.hl;
    out_vertices[o + 3u] = f32(t.r.x);
    out_vertices[o + 4u] = f32(t.r.y);
    out_vertices[o + 5u] = t.hr;
    out_vertices[o + 6u] = f32(t.a.x);
    out_vertices[o + 7u] = f32(t.a.y);
    out_vertices[o + 8u] = t.ha;
}

// Stores `t` in entry `j` (reserved) of half `qi` of the queue for the next level; emits it
// unsplit where that is past the queue's end.
fn push(t: Tri, pid: u32, qi: u32, j: u32) {
    if j >= params.queue_capacity {
        atomicStore(&state.overflow, 1u);
        emit(t);
        return;
    }
    let s = sign(t.l - t.a) + vec2<i32>(1, 1);
    let code = (pid << 4u) | u32(s.x + 3 * s.y);
    tri_queue[qi * params.queue_capacity + j] = Queued(t.a, t.ha, t.hl, t.hr, code);
}

fn base(px: i32, py: i32, which: u32) -> Tri {
    let ps = i32(params.patch_size);
    let o = vec2<i32>(px * ps, py * ps);
    let c00 = o;
    let c10 = o + vec2<i32>(ps, 0);
    let c01 = o + vec2<i32>(0, ps);
    let c11 = o + vec2<i32>(ps, ps);
    var e0 = c00;
    var e1 = c11;
    var a = c10;
    if which == 1u {
        a = c01;
    }
    if ((px + py) & 1) != 0 {
        e0 = c10;
        e1 = c01;
        a = c00;
        if which == 1u {
            a = c11;
        }
    }
    let u = e1 - e0;
    let w = a - e0;
    var t: Tri;
    t.a = a;
    if u.x * w.y - u.y * w.x < 0 {
        t.l = e0;
        t.r = e1;
    } else {
        t.l = e1;
        t.r = e0;
    }
    t.ha = vertex_height(t.a);
    t.hl = vertex_height(t.l);
    t.hr = vertex_height(t.r);
    t.level = 0u;
    return t;
}

// terrain_lod::tessellation::FORCED_RATIO.
const FORCED_RATIO: f32 = 1e30;

// Whether TessDecision::full_resolution forces v (split in by triangles of `level`): the square
// of its descendants meets the rect. Mirrors TessDecision::forces.
fn forced(v: vec2<i32>, level: u32) -> bool {
    if params.full == 0u {
        return false;
    }
    let l = min(level, 15u);
    let r = i32(params.reach[l / 4u][l % 4u]);
    return all(v - vec2<i32>(r, r) <= params.full_hi) && all(v + vec2<i32>(r, r) >= params.full_lo);
}

// A visible triangle of this level: emitted, or its visible children queued for the next.
fn refine(t: Tri, pid: u32) {
    if t.level < params.split_levels {
        let v = (t.l + t.r) / 2;
        var r = split_ratio(v, t.level);
        if forced(v, t.level) {
            r = FORCED_RATIO;
        }
        // terrain_lod::tessellation::split_threshold.
        let threshold = 1.0 - f32(MAX_LEVELS - min(t.level, MAX_LEVELS)) * SPLIT_MARGIN;
        if r > threshold {
            let h = vertex_height(v);
            var k = 1.0;
            if params.inv_morph_range > 0.0 {
                k = min((r - threshold) * params.inv_morph_range, 1.0);
            }
            let mid = 0.5 * (t.hl + t.hr);
            let hv = mid + (h - mid) * k;
            // The children: apex v, hypotenuses a -> l and r -> a (as Tri::children), culled
            // here rather than by the next level, so the queue holds only visible triangles.
            let qi = (t.level + 1u) & 1u;
            let c0 = Tri(v, t.a, t.l, hv, t.ha, t.hl, t.level + 1u);
            let c1 = Tri(v, t.r, t.a, hv, t.hr, t.ha, t.level + 1u);
            let v0 = visible(c0, pid);
            let v1 = visible(c1, pid);
            let kept = u32(v0) + u32(v1);
            if kept > 0u {
                // One atomic per split triangle.
                let j = atomicAdd(&state.queued[qi], kept);
                if v0 {
                    push(c0, pid, qi, j);
                }
                if v1 {
                    push(c1, pid, qi, j + u32(v0));
                }
            }
            return;
        }
    }
    emit(t);
}

@compute @workgroup_size(64, 1, 1)
fn generate(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lane: u32,
) {
    let i = (wg.y * groups.x + wg.x) * GROUP + lane;
    let level = state.level;
    if level == 0u {
        let n = params.patches.x * params.patches.y;
        if i >= 2u * n {
            return;
        }
        let pid = i / 2u;
        let t = base(i32(pid % params.patches.x), i32(pid / params.patches.x), i % 2u);
        if visible(t, pid) {
            refine(t, pid);
        }
        return;
    }
    let qi = level & 1u;
    if i >= min(atomicLoad(&state.queued[qi]), params.queue_capacity) {
        return;
    }
    // A leg of a level-L triangle runs along an axis for even L (patch_size / 2^(L / 2)
    // texels), diagonally for odd L (patch_size / 2^((L + 1) / 2) along each axis). Every
    // triangle is counter-clockwise with its right angle at a, so r - a is l - a turned by
    // -90 degrees (the sign base() picks: (r - l) x (a - l) < 0).
    let q = tri_queue[qi * params.queue_capacity + i];
    let c = q.code & 15u;
    let leg = i32(params.patch_size >> ((level + 1u) / 2u));
    let d = (vec2<i32>(i32(c % 3u), i32(c / 3u)) - vec2<i32>(1, 1)) * leg;
    let l = q.a + d;
    refine(Tri(q.a, l, q.a + vec2<i32>(d.y, -d.x), q.ha, q.hl, q.hr, level), q.code >> 4u);
}

@compute @workgroup_size(1, 1, 1)
fn advance() {
    let level = state.level + 1u;
    state.level = level;
    let qi = level & 1u;
    // The queue this level fills starts empty.
    atomicStore(&state.queued[1u - qi], 0u);
    let n = min(atomicLoad(&state.queued[qi]), params.queue_capacity);
    let total = (n + GROUP - 1u) / GROUP;
    let x = min(total, params.max_groups);
    var y = 0u;
    if x > 0u {
        y = min((total + x - 1u) / x, params.max_groups);
    }
    let o = 4u * level;
    dispatch_args[o] = x;
    dispatch_args[o + 1u] = y;
    dispatch_args[o + 2u] = 1u;
    dispatch_args[o + 3u] = 0u;
}

@compute @workgroup_size(1, 1, 1)
fn finish() {
    let n = min(atomicLoad(&state.count), params.capacity);
    state.args[0] = n * 3u;
    state.args[1] = 1u;
    state.args[2] = 0u;
    state.args[3] = 0u;
}
