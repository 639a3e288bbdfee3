// DensityPass: the density map of Cervin 2012, ch. 3 (CPU reference: terrain_lod::density).
// `raw`: a curvature filter at every texel of a sample's 6 x 6 window (the max-downsampling by
// 4 with the one-sample overlap), normalised by the spacing. `finish`: the preprocessing max
// filter (a wider window on tile borders, eq. 3.8), gain and exponent, quantised to u8.
// `reduce`: one pyramid level from the one below: 3 x 3 maxima inside tiles, point samples on
// tile borders.

struct DensityParams {
    // The samples this dispatch writes (inside the level it writes).
    rect_min: vec2<i32>,
    rect_size: vec2<u32>,
    // Heights: size in texels, wrap code, metres per stored unit, metres per texel, filter, and
    // a multiple of the size that makes the coordinates read non-negative before `%`.
    map_size: vec2<u32>,
    wrap: u32,
    scale: f32,
    spacing: f32,
    filter_code: u32,
    map_offset: vec2<i32>,
    // Level 0 (`raw`, `finish`) or the child level (`reduce`): size and first element.
    src_size: vec2<u32>,
    src_base: u32,
    // `finish`: window radii and tile side; `reduce`: tile side; and the level written.
    radius: u32,
    border_radius: u32,
    tile: u32,
    dst_w: u32,
    dst_base: u32,
    // gain / full_density_bend, and the curvature exponent.
    density_scale: f32,
    exponent: f32,
    // `finish`: the multiple of the level-0 size that makes its reads non-negative.
    src_offset: vec2<i32>,
    // Bits per height texel (8 or 16; packed.wgsl).
    bits: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> p: DensityParams;
@group(0) @binding(1) var<storage, read> heights: array<u32>;
@group(0) @binding(2) var<storage, read_write> raw_values: array<f32>;
@group(0) @binding(3) var<storage, read_write> levels: array<u32>;

fn resolve(v: i32, n: u32, offset: i32) -> u32 {
    if p.wrap == WRAP_REPEAT {
        return u32(v + offset) % n;
    }
    return u32(clamp(v, 0, i32(n) - 1));
}

fn h(x: i32, y: i32) -> f32 {
    let row = resolve(y, p.map_size.y, p.map_offset.y);
    let col = resolve(x, p.map_size.x, p.map_offset.x);
    return f32(packed_get(heights[packed_index(col, row, p.map_size.x, p.bits)], col, p.bits));
}

fn cot(a: vec3<f32>, b: vec3<f32>) -> f32 {
    let c = length(cross(a, b));
    if c > 0.0 {
        return dot(a, b) / c;
    }
    return 0.0;
}

// |H| by the cotangent formula over the one-ring E, SE, S, W, NW, N (diagonals from (x, y) to
// (x + 1, y + 1)), divided by a third of the triangle area or by the Voronoi area (eq. 2.32).
fn laplace_beltrami(d: array<f32, 8>, s: f32, voronoi: bool) -> f32 {
    var v = array<vec3<f32>, 6>(
        vec3<f32>(s, d[1], 0.0),
        vec3<f32>(s, d[7], s),
        vec3<f32>(0.0, d[3], s),
        vec3<f32>(-s, d[0], 0.0),
        vec3<f32>(-s, d[4], -s),
        vec3<f32>(0.0, d[2], -s),
    );
    var sum = vec3<f32>(0.0);
    var area = 0.0;
    for (var j = 0u; j < 6u; j++) {
        let prev = v[(j + 5u) % 6u];
        let next = v[(j + 1u) % 6u];
        let vj = v[j];
        let w = cot(-prev, vj - prev) + cot(-next, vj - next);
        sum += w * vj;
        if voronoi {
            area += w * dot(vj, vj) / 8.0;
        } else {
            area += length(cross(vj, next)) / 6.0;
        }
    }
    if area <= 0.0 {
        return 0.0;
    }
    return 0.5 * length(sum) / (2.0 * area);
}

// The curvature magnitude (1 / m) of the chosen filter from the differences W, E, N, S, NW,
// NE, SW, SE to the centre, in metres (terrain_lod::density::curvature).
fn curvature(d: array<f32, 8>) -> f32 {
    let s = p.spacing;
    var v = 0.0;
    if p.filter_code == 0u {
        let inv2 = 1.0 / (s * s);
        v = ((d[1] + d[0]) + (d[3] + d[2])) * inv2;
    } else if p.filter_code <= 2u {
        let inv = 1.0 / s;
        let inv2 = inv * inv;
        let hx = (d[1] - d[0]) * (0.5 * inv);
        let hy = (d[3] - d[2]) * (0.5 * inv);
        let hxx = (d[1] + d[0]) * inv2;
        let hyy = (d[3] + d[2]) * inv2;
        let hxy = ((d[7] - d[5]) - (d[6] - d[4])) * (0.25 * inv2);
        let g = 1.0 + hx * hx + hy * hy;
        if p.filter_code == 1u {
            v = sqrt(abs((hxx * hyy - hxy * hxy) / (g * g)));
        } else {
            v = (hxx * (1.0 + hy * hy) - 2.0 * hxy * hx * hy + hyy * (1.0 + hx * hx))
                / (2.0 * g * sqrt(g));
        }
    } else {
        v = laplace_beltrami(d, s, p.filter_code == 4u);
    }
    v = abs(v);
    // Not finite (an overflow of absurd heights): no curvature, as on the CPU.
    if !(v <= 3.4028235e38) {
        return 0.0;
    }
    return v;
}

@compute @workgroup_size(8, 8, 1)
fn raw_density(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= p.rect_size.x || id.y >= p.rect_size.y {
        return;
    }
    let i = p.rect_min.x + i32(id.x);
    let j = p.rect_min.y + i32(id.y);
    var m = 0.0;
    for (var ty = 4 * j - 1; ty <= 4 * j + 4; ty++) {
        for (var tx = 4 * i - 1; tx <= 4 * i + 4; tx++) {
            let c = h(tx, ty);
            // Differences of stored integers are exact; only the scale to metres rounds.
            let d = array<f32, 8>(
                (h(tx - 1, ty) - c) * p.scale,
                (h(tx + 1, ty) - c) * p.scale,
                (h(tx, ty - 1) - c) * p.scale,
                (h(tx, ty + 1) - c) * p.scale,
                (h(tx - 1, ty - 1) - c) * p.scale,
                (h(tx + 1, ty - 1) - c) * p.scale,
                (h(tx - 1, ty + 1) - c) * p.scale,
                (h(tx + 1, ty + 1) - c) * p.scale,
            );
            m = max(m, curvature(d));
        }
    }
    raw_values[u32(j) * p.src_size.x + u32(i)] = m * p.spacing;
}

fn raw_at(x: i32, y: i32) -> f32 {
    var xx: u32;
    var yy: u32;
    if p.wrap == WRAP_REPEAT {
        xx = u32(x + p.src_offset.x) % p.src_size.x;
        yy = u32(y + p.src_offset.y) % p.src_size.y;
    } else {
        xx = u32(clamp(x, 0, i32(p.src_size.x) - 1));
        yy = u32(clamp(y, 0, i32(p.src_size.y) - 1));
    }
    return raw_values[yy * p.src_size.x + xx];
}

@compute @workgroup_size(8, 8, 1)
fn finish_density(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= p.rect_size.x || id.y >= p.rect_size.y {
        return;
    }
    let i = p.rect_min.x + i32(id.x);
    let j = p.rect_min.y + i32(id.y);
    var r = i32(p.radius);
    if u32(i) % p.tile == 0u || u32(j) % p.tile == 0u {
        r = i32(p.border_radius);
    }
    var m = 0.0;
    for (var y = j - r; y <= j + r; y++) {
        for (var x = i - r; x <= i + r; x++) {
            m = max(m, raw_at(x, y));
        }
    }
    var v = clamp(m * p.density_scale, 0.0, 1.0);
    if p.exponent != 1.0 {
        v = pow(v, p.exponent);
    }
    levels[p.dst_base + u32(j) * p.dst_w + u32(i)] = u32(v * 255.0 + 0.5);
}

@compute @workgroup_size(8, 8, 1)
fn reduce_density(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= p.rect_size.x || id.y >= p.rect_size.y {
        return;
    }
    let i = u32(p.rect_min.x) + id.x;
    let j = u32(p.rect_min.y) + id.y;
    let cx = min(2u * i, p.src_size.x - 1u);
    let cy = min(2u * j, p.src_size.y - 1u);
    var m = 0u;
    if i % p.tile == 0u || j % p.tile == 0u {
        m = levels[p.src_base + cy * p.src_size.x + cx];
    } else {
        for (var y = max(cy, 1u) - 1u; y <= min(cy + 1u, p.src_size.y - 1u); y++) {
            for (var x = max(cx, 1u) - 1u; x <= min(cx + 1u, p.src_size.x - 1u); x++) {
                m = max(m, levels[p.src_base + y * p.src_size.x + x]);
            }
        }
    }
    levels[p.dst_base + j * p.dst_w + i] = m;
}
