// Displacement of intersected material to the contour (Persson 2019, sec. 4.1.4), bit for bit as
// terrain_core::granular::{displace_closest_seed, displace_multiple_targets,
// displace_iterative}: every column adds its contributions to `acc` with atomic adds (wrapping
// u32, so the order does not matter), then `writeback` moves `acc` into the map's heights and
// leaves `acc` zeroed. `removed` is a u64 (low, high) counter of compressed material.
//
// The iterative method (listing 4.2): `iter_init` writes each column's distance to its seed
// and its number of lower neighbours to `info` and its displaced material to carried grid 0;
// `iter_pass` is one gather pass from carried grid `parity` to grid `1 - parity` (grid 1 starts
// after the area's columns); `iter_flush` adds each column's remaining height and its final
// carried material (grid `parity`) to `acc`, then `writeback`.

// MULTI_TARGET_CHUNK and MAX_TARGETS of the CPU reference.
const CHUNK: u32 = 1000u;
const MAX_TARGETS: u32 = 64u;

@group(0) @binding(0) var<uniform> g: Granular;
@group(0) @binding(1) var<storage, read_write> heights: array<u32>;
@group(0) @binding(2) var<storage, read> pen: array<Penetration>;
@group(0) @binding(3) var<storage, read> seeds: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read_write> acc: array<atomic<u32>>;
@group(0) @binding(5) var<storage, read_write> removed: array<atomic<u32>, 2>;
// Iterative method only: (distance to the seed, lower-neighbour count) per column, and the
// two carried grids.
@group(0) @binding(6) var<storage, read_write> info: array<vec2<u32>>;
@group(0) @binding(7) var<storage, read_write> carried: array<u32>;

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

fn absdiff(a: u32, b: u32) -> u32 {
    return select(b - a, a - b, a > b);
}

// terrain_core::granular::seed_distance (Euclidean squared, Manhattan, Chebyshev).
fn seed_distance(c: vec2<u32>, s: vec2<u32>) -> u32 {
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

// Area-local index of neighbour `k` (0..8, in the order of terrain_core::granular::JFA_OFFSETS:
// the 3x3 block row by row without its centre) of area-local column `id`, or -1 outside the
// area.
fn neighbour(id: vec2<u32>, k: u32) -> i32 {
    let b = k + select(0u, 1u, k >= 4u);
    let q = vec2<i32>(id) + vec2<i32>(i32(b % 3u) - 1, i32(b / 3u) - 1);
    if q.x < 0 || q.y < 0 || q.x >= i32(g.area_size.x) || q.y >= i32(g.area_size.y) {
        return -1;
    }
    return q.y * i32(g.area_size.x) + q.x;
}

// distance_grid + lower_neighbour_counts, and the initial carried grid (grid 0).
@compute @workgroup_size(8, 8, 1)
fn iter_init(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= g.area_size.x || id.y >= g.area_size.y {
        return;
    }
    let w = g.area_size.x;
    let i = id.y * w + id.x;
    let d = seed_distance(g.area_min + id.xy, seeds[i]);
    var n = 0u;
    for (var k = 0u; k < 8u; k = k + 1u) {
        let q = neighbour(id.xy, k);
        if q < 0 {
            continue;
        }
        let qu = u32(q);
        let qc = g.area_min + vec2<u32>(qu % w, qu / w);
        if seed_distance(qc, seeds[qu]) < d {
            n = n + 1u;
        }
    }
    info[i] = vec2<u32>(d, n);
    var c = 0u;
    let p = pen[i];
    if p.kind == PENETRATING {
        c = mul_q15(p.penetration, g.keep_q15);
        count_removed(p.penetration - c);
    }
    carried[i] = c;
}

// terrain_core::granular::iterative_pass: a column keeps the remainder of its carried material
// over its lower-neighbour count and gathers the share of every farther neighbour.
@compute @workgroup_size(8, 8, 1)
fn iter_pass(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= g.area_size.x || id.y >= g.area_size.y {
        return;
    }
    let cells = g.area_size.x * g.area_size.y;
    let src = g.parity * cells;
    let dst = (1u - g.parity) * cells;
    let i = id.y * g.area_size.x + id.x;
    let me = info[i];
    let c = carried[src + i];
    var v = c;
    if me.y > 0u {
        v = c % me.y;
    }
    for (var k = 0u; k < 8u; k = k + 1u) {
        let q = neighbour(id.xy, k);
        if q < 0 {
            continue;
        }
        let o = info[u32(q)];
        // A farther neighbour has this column among its lower ones, so o.y > 0.
        if o.x > me.x {
            v = v + carried[src + u32(q)] / o.y;
        }
    }
    carried[dst + i] = v;
}

// The end of terrain_core::granular::displace_iterative: the column's height (less the
// penetration where it penetrates) stays, and its carried material (grid `parity`) goes to
// itself if it is a seed or has no seed, else to its seed.
@compute @workgroup_size(8, 8, 1)
fn iter_flush(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= g.area_size.x || id.y >= g.area_size.y {
        return;
    }
    let i = id.y * g.area_size.x + id.x;
    let h = heights[(g.area_min.y + id.y) * g.map_width + g.area_min.x + id.x];
    let p = pen[i];
    var own = h;
    if p.kind == PENETRATING {
        own = h - p.penetration;
    }
    atomicAdd(&acc[i], own);
    let c = carried[g.parity * g.area_size.x * g.area_size.y + i];
    if c == 0u {
        return;
    }
    var t = i32(i);
    let s = seeds[i];
    if (p.kind == PENETRATING || p.kind == OBSTACLE) && s.x != NO_SEED {
        let l = local(vec2<i32>(s));
        if l >= 0 {
            t = l;
        }
    }
    atomicAdd(&acc[u32(t)], c);
}
