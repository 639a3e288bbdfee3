// Evening out steep slopes (Persson 2019, sec. 4.1.5), bit for bit as
// terrain_core::granular::{slope_scatter_pass, slope_amounts_pass, slope_apply_pass}.
// Scatter: `scatter` adds every column's remainder and outflow to `acc` with atomic adds, then
// `writeback` moves `acc` into the heights (leaving it zeroed). Interleaved: `amounts` writes
// (a, mask) for the columns of `g.parity`, `apply` gathers into `acc`, then `writeback`.

@group(0) @binding(0) var<uniform> g: Granular;
@group(0) @binding(1) var<storage, read_write> heights: array<u32>;
@group(0) @binding(2) var<storage, read> pen: array<Penetration>;
@group(0) @binding(3) var<storage, read_write> acc: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read_write> amounts: array<vec2<u32>>;

const OFFSETS = array<vec2<i32>, 8>(
    vec2<i32>(-1, -1), vec2<i32>(0, -1), vec2<i32>(1, -1), vec2<i32>(-1, 0),
    vec2<i32>(1, 0), vec2<i32>(-1, 1), vec2<i32>(0, 1), vec2<i32>(1, 1),
);

fn mul_q15(v: u32, q0: u32) -> u32 {
    let q = min(q0, 32768u);
    return (v >> 15u) * q + (((v & 0x7fffu) * q) >> 15u);
}

fn height(l: vec2<i32>) -> u32 {
    return heights[(g.area_min.y + u32(l.y)) * g.map_width + g.area_min.x + u32(l.x)];
}

fn inside(l: vec2<i32>) -> bool {
    return l.x >= 0 && l.y >= 0 && l.x < i32(g.area_size.x) && l.y < i32(g.area_size.y);
}

// terrain_core::granular::column_outflow: (amount per receiver, receiver mask).
fn outflow(me: vec2<i32>) -> vec2<u32> {
    let hc = height(me);
    var mask = 0u;
    var deltas = array<u32, 8>();
    var n = 0u;
    for (var k = 0u; k < 8u; k = k + 1u) {
        let o = OFFSETS[k];
        let q = me + o;
        if !inside(q) {
            continue;
        }
        if pen[u32(q.y) * g.area_size.x + u32(q.x)].kind != SEED {
            continue;
        }
        let t = select(g.threshold_orth, g.threshold_diag, o.x != 0 && o.y != 0);
        let hq = height(q);
        if hc > hq && hc - hq > t {
            mask = mask | (1u << k);
            deltas[n] = hc - hq;
            n = n + 1u;
        }
    }
    if n == 0u {
        return vec2<u32>(0u, 0u);
    }
    var quot = 0u;
    var rems = 0u;
    for (var i = 0u; i < n; i = i + 1u) {
        quot = quot + deltas[i] / n;
        rems = rems + deltas[i] % n;
    }
    let a = mul_q15(quot + rems / n, g.roughness_q15) / n;
    if a == 0u {
        return vec2<u32>(0u, 0u);
    }
    return vec2<u32>(a, mask);
}

@compute @workgroup_size(8, 8, 1)
fn scatter(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= g.area_size.x || id.y >= g.area_size.y {
        return;
    }
    let me = vec2<i32>(id.xy);
    let i = id.y * g.area_size.x + id.x;
    let out = outflow(me);
    atomicAdd(&acc[i], height(me) - out.x * countOneBits(out.y));
    if out.y == 0u {
        return;
    }
    for (var k = 0u; k < 8u; k = k + 1u) {
        if (out.y & (1u << k)) != 0u {
            let q = me + OFFSETS[k];
            atomicAdd(&acc[u32(q.y) * g.area_size.x + u32(q.x)], out.x);
        }
    }
}

@compute @workgroup_size(8, 8, 1)
fn amounts_pass(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= g.area_size.x || id.y >= g.area_size.y {
        return;
    }
    let i = id.y * g.area_size.x + id.x;
    let parity = (g.area_min.x + id.x + g.area_min.y + id.y) & 1u;
    var out = vec2<u32>(0u, 0u);
    if parity == g.parity {
        out = outflow(vec2<i32>(id.xy));
    }
    amounts[i] = out;
}

@compute @workgroup_size(8, 8, 1)
fn apply(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= g.area_size.x || id.y >= g.area_size.y {
        return;
    }
    let me = vec2<i32>(id.xy);
    let i = id.y * g.area_size.x + id.x;
    let mine = amounts[i];
    var v = height(me) - mine.x * countOneBits(mine.y);
    for (var k = 0u; k < 8u; k = k + 1u) {
        let q = me + OFFSETS[k];
        if !inside(q) {
            continue;
        }
        let other = amounts[u32(q.y) * g.area_size.x + u32(q.x)];
        if (other.y & (1u << (7u - k))) != 0u {
            v = v + other.x;
        }
    }
    atomicStore(&acc[i], v);
}

@compute @workgroup_size(8, 8, 1)
fn writeback(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= g.area_size.x || id.y >= g.area_size.y {
        return;
    }
    let i = id.y * g.area_size.x + id.x;
    heights[(g.area_min.y + id.y) * g.map_width + g.area_min.x + id.x] = atomicExchange(&acc[i], 0u);
}
