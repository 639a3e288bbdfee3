// Displacement of intersected material to the contour (seed 001 sec 4.1.4), bit for bit as
// terrain_core::granular::{displace_closest_seed, displace_multiple_targets}: every column adds
// its contributions to `acc` with atomic adds (wrapping u32, so the order does not matter),
// then `writeback` moves `acc` into the map's heights and leaves `acc` zeroed.
// `removed` is a u64 (low, high) counter of compressed material.

struct Granular {
    area_min: vec2<u32>,
    area_size: vec2<u32>,
    map_width: u32,
    step: u32,
    pass_index: u32,
    metric: u32,
    keep_q15: u32,
    margin: u32,
    threshold_orth: u32,
    threshold_diag: u32,
    roughness_q15: u32,
    parity: u32,
    _pad0: u32,
    _pad1: u32,
}

struct Penetration {
    seed_x: u32,
    seed_y: u32,
    kind: i32,
    penetration: u32,
}

const NO_SEED: u32 = 0xffffffffu;
const SEED: i32 = -3;
const PENETRATING: i32 = -1;
// MULTI_TARGET_CHUNK and MAX_TARGETS of the CPU reference.
const CHUNK: u32 = 1000u;
const MAX_TARGETS: u32 = 64u;

@group(0) @binding(0) var<uniform> g: Granular;
@group(0) @binding(1) var<storage, read_write> heights: array<u32>;
@group(0) @binding(2) var<storage, read> pen: array<Penetration>;
@group(0) @binding(3) var<storage, read> seeds: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read_write> acc: array<atomic<u32>>;
@group(0) @binding(5) var<storage, read_write> removed: array<atomic<u32>, 2>;

// floor(v * q / 32768) for q <= 32768 without overflow (terrain_core::granular::mul_q15).
fn mul_q15(v: u32, q0: u32) -> u32 {
    let q = min(q0, 32768u);
    return (v >> 15u) * q + (((v & 0x7fffu) * q) >> 15u);
}

// Adds `v` to the u64 counter, carrying into the high word exactly.
fn count_removed(v: u32) {
    if v == 0u {
        return;
    }
    let old = atomicAdd(&removed[0], v);
    if old > 0xffffffffu - v {
        atomicAdd(&removed[1], 1u);
    }
}

// Area-local index of map column `c`, or -1 outside the area.
fn local(c: vec2<i32>) -> i32 {
    let l = c - vec2<i32>(g.area_min);
    if l.x < 0 || l.y < 0 || l.x >= i32(g.area_size.x) || l.y >= i32(g.area_size.y) {
        return -1;
    }
    return l.y * i32(g.area_size.x) + l.x;
}

struct Column {
    index: u32,
    height: u32,
    // Area-local index of the column's seed when it displaces material, else -1.
    dest: i32,
}

fn column(id: vec2<u32>) -> Column {
    let i = id.y * g.area_size.x + id.x;
    let h = heights[(g.area_min.y + id.y) * g.map_width + g.area_min.x + id.x];
    let s = seeds[i];
    var t = -1;
    if pen[i].kind == PENETRATING && s.x != NO_SEED {
        t = local(vec2<i32>(s));
    }
    return Column(i, h, t);
}

@compute @workgroup_size(8, 8, 1)
fn closest(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= g.area_size.x || id.y >= g.area_size.y {
        return;
    }
    let c = column(id.xy);
    if c.dest < 0 {
        atomicAdd(&acc[c.index], c.height);
        return;
    }
    let p = pen[c.index].penetration;
    let disp = mul_q15(p, g.keep_q15);
    count_removed(p - disp);
    atomicAdd(&acc[c.index], c.height - p);
    atomicAdd(&acc[u32(c.dest)], disp);
}

@compute @workgroup_size(8, 8, 1)
fn multiple(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= g.area_size.x || id.y >= g.area_size.y {
        return;
    }
    let c = column(id.xy);
    if c.dest < 0 {
        atomicAdd(&acc[c.index], c.height);
        return;
    }
    let p = pen[c.index].penetration;
    let disp = mul_q15(p, g.keep_q15);
    count_removed(p - disp);
    atomicAdd(&acc[c.index], c.height - p);
    let n = clamp(disp / CHUNK + select(0u, 1u, disp % CHUNK != 0u), 1u, MAX_TARGETS);
    let base = disp / n;
    let rem = disp % n;
    let s = vec2<i32>(seeds[c.index]);
    let d = s - (vec2<i32>(g.area_min) + vec2<i32>(id.xy));
    let m = max(max(abs(d.x), abs(d.y)), 1);
    var last = u32(c.dest);
    var left = disp;
    for (var i = 0u; i < n; i = i + 1u) {
        let share = base + select(0u, 1u, i < rem);
        let t = local(s + d * i32(i) / m);
        if t < 0 {
            break;
        }
        if pen[u32(t)].kind != SEED {
            break;
        }
        atomicAdd(&acc[u32(t)], share);
        left = left - share;
        last = u32(t);
    }
    atomicAdd(&acc[last], left);
}

@compute @workgroup_size(8, 8, 1)
fn writeback(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= g.area_size.x || id.y >= g.area_size.y {
        return;
    }
    let i = id.y * g.area_size.x + id.x;
    heights[(g.area_min.y + id.y) * g.map_width + g.area_min.x + id.x] = atomicExchange(&acc[i], 0u);
}
