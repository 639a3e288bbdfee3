// TessellationPass: adaptive tessellation by longest-edge bisection (Cervin 2012, sec. 2.3,
// algorithm 3.1), as compute: one invocation per level-0 triangle (two per patch) refines it
// depth first and appends the triangles it keeps to a vertex buffer, then `finish` writes the
// indirect draw arguments. CPU reference: terrain_lod::TessHierarchy::select (same decisions,
// same f32 operations in the same order).

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
    _pad1: u32,
    _pad2: u32,
}

// A grid vertex: true height (m), saturated sphere radius (m), saturated density, saturated
// error (m).
struct Vertex {
    h: f32,
    r: f32,
    d: f32,
    e: f32,
}

struct State {
    count: atomic<u32>,
    overflow: atomic<u32>,
    _pad0: u32,
    _pad1: u32,
    // draw_indirect arguments: vertex count, instance count, first vertex, first instance.
    args: array<u32, 4>,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> verts: array<Vertex>;
@group(0) @binding(2) var<storage, read> patch_bounds: array<vec2<f32>>;
@group(0) @binding(3) var<storage, read_write> out_vertices: array<f32>;
@group(0) @binding(4) var<storage, read_write> state: State;

const NEAR_M: f32 = 1e-3;
// terrain_lod::tessellation::{SPLIT_MARGIN, MAX_LEVELS}.
const SPLIT_MARGIN: f32 = 1e-4;
const MAX_LEVELS: u32 = 16u;
// A depth-first refinement holds at most 2 log2(256) + 1 = 17 triangles; 20 leaves room.
const STACK: u32 = 20u;

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

fn vindex(v: vec2<i32>) -> u32 {
    let g = vec2<i32>(params.grid);
    var w: vec2<i32>;
    if params.wrap == WRAP_REPEAT {
        w = ((v % g) + g) % g;
    } else {
        w = clamp(v, vec2<i32>(0, 0), g - vec2<i32>(1, 1));
    }
    return u32(w.y) * params.grid.x + u32(w.x);
}

fn ratio(v: vec2<i32>) -> f32 {
    let b = verts[vindex(v)];
    let ts = params.texel_size;
    let c = vec3<f32>(
        f32(v.x) * ts - params.camera.x,
        b.h - params.camera.y,
        f32(v.y) * ts - params.camera.z,
    );
    let dist = max(sqrt(c.x * c.x + c.y * c.y + c.z * c.z) - b.r, NEAR_M);
    if params.error_metric != 0u {
        return params.scale * b.e / dist;
    }
    var dens = 1.0;
    if params.use_density != 0u {
        dens = b.d;
    }
    return params.scale * b.r * dens / dist;
}

fn visible(t: Tri, pid: u32) -> bool {
    if params.cull == 0u {
        return true;
    }
    let ts = params.texel_size;
    let lo2 = vec2<f32>(min(min(t.a, t.l), t.r)) * ts;
    let hi2 = vec2<f32>(max(max(t.a, t.l), t.r)) * ts;
    let hb = patch_bounds[pid];
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
    t.ha = verts[vindex(t.a)].h;
    t.hl = verts[vindex(t.l)].h;
    t.hr = verts[vindex(t.r)].h;
    t.level = 0u;
    return t;
}

@compute @workgroup_size(64, 1, 1)
fn generate(@builtin(global_invocation_id) id: vec3<u32>) {
    let n = params.patches.x * params.patches.y;
    if id.x >= 2u * n {
        return;
    }
    let pid = id.x / 2u;
    let px = i32(pid % params.patches.x);
    let py = i32(pid / params.patches.x);
    var stack: array<Tri, STACK>;
    var top = 1u;
    stack[0] = base(px, py, id.x % 2u);
    while top > 0u {
        top -= 1u;
        let t = stack[top];
        if !visible(t, pid) {
            continue;
        }
        var split = false;
        if t.level < params.split_levels && top + 2u <= STACK {
            let v = (t.l + t.r) / 2;
            let r = ratio(v);
            // terrain_lod::tessellation::split_threshold.
            let threshold = 1.0 - f32(MAX_LEVELS - min(t.level, MAX_LEVELS)) * SPLIT_MARGIN;
            if r > threshold {
                split = true;
                let h = verts[vindex(v)].h;
                var k = 1.0;
                if params.inv_morph_range > 0.0 {
                    k = min((r - threshold) * params.inv_morph_range, 1.0);
                }
                let mid = 0.5 * (t.hl + t.hr);
                let hv = mid + (h - mid) * k;
                // The children: apex v, hypotenuses a -> l and r -> a (as Tri::children).
                stack[top] = Tri(v, t.r, t.a, hv, t.hr, t.ha, t.level + 1u);
                stack[top + 1u] = Tri(v, t.a, t.l, hv, t.ha, t.hl, t.level + 1u);
                top += 2u;
            }
        }
        if !split {
            emit(t);
        }
    }
}

@compute @workgroup_size(1, 1, 1)
fn finish() {
    let n = min(atomicLoad(&state.count), params.capacity);
    state.args[0] = n * 3u;
    state.args[1] = 1u;
    state.args[2] = 0u;
    state.args[3] = 0u;
}
