// JumpFloodPass: jump flooding of the closest seed over an active area (Persson 2019, sec. 2.3.1,
// 4.1.4) with the hashed neighbour order of terrain_core::granular::jfa_neighbour_order,
// bit for bit as terrain_core::granular::jfa_pass. `init` copies the seeds of the penetration
// texture (jfa_init); `main` is one pass reading `src` and writing `dst` (ping-pong).

@group(0) @binding(0) var<uniform> g: Granular;
@group(0) @binding(1) var<storage, read> pen: array<Penetration>;
@group(0) @binding(2) var<storage, read> src: array<vec2<u32>>;
@group(0) @binding(3) var<storage, read_write> dst: array<vec2<u32>>;

// The PCG hash (Jarzynski and Olano 2020); u32 arithmetic wraps in WGSL.
fn pcg(v: u32) -> u32 {
    let s = v * 747796405u + 2891336453u;
    let w = ((s >> ((s >> 28u) + 4u)) ^ s) * 277803737u;
    return (w >> 22u) ^ w;
}

fn absdiff(a: u32, b: u32) -> u32 {
    return select(b - a, a - b, a > b);
}

fn distance(c: vec2<u32>, s: vec2<u32>) -> u32 {
    if s.x == NO_SEED {
        return 0xffffffffu;
    }
    let dx = absdiff(c.x, s.x);
    let dy = absdiff(c.y, s.y);
    if g.metric == METRIC_MANHATTAN {
        return dx + dy;
    }
    if g.metric == METRIC_CHEBYSHEV {
        return max(dx, dy);
    }
    return dx * dx + dy * dy;
}

@compute @workgroup_size(8, 8, 1)
fn init(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= g.area_size.x || id.y >= g.area_size.y {
        return;
    }
    let i = id.y * g.area_size.x + id.x;
    dst[i] = vec2<u32>(pen[i].seed_x, pen[i].seed_y);
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= g.area_size.x || id.y >= g.area_size.y {
        return;
    }
    // The 8 neighbour offsets in the order of JFA_OFFSETS.
    var offsets = array<vec2<i32>, 8>(
        vec2<i32>(-1, -1), vec2<i32>(0, -1), vec2<i32>(1, -1), vec2<i32>(-1, 0),
        vec2<i32>(1, 0), vec2<i32>(-1, 1), vec2<i32>(0, 1), vec2<i32>(1, 1),
    );
    let w = g.area_size.x;
    let col = g.area_min + id.xy;
    // Fisher-Yates shuffle of 0..8 driven by pcg(x + pcg(y + pcg(pass))).
    var order = array<u32, 8>(0u, 1u, 2u, 3u, 4u, 5u, 6u, 7u);
    var h = pcg(col.x + pcg(col.y + pcg(g.pass_index)));
    for (var i = 7u; i >= 1u; i = i - 1u) {
        let j = h % (i + 1u);
        let t = order[i];
        order[i] = order[j];
        order[j] = t;
        h = pcg(h);
    }
    var best = src[id.y * w + id.x];
    var best_d = distance(col, best);
    let k = i32(g.step);
    let size = vec2<i32>(g.area_size);
    for (var n = 0u; n < 8u; n = n + 1u) {
        let q = vec2<i32>(id.xy) + offsets[order[n]] * k;
        if q.x < 0 || q.y < 0 || q.x >= size.x || q.y >= size.y {
            continue;
        }
        let cand = src[u32(q.y) * w + u32(q.x)];
        let d = distance(col, cand);
        if d < best_d {
            best = cand;
            best_d = d;
        }
    }
    dst[id.y * w + id.x] = best;
}
