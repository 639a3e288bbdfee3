// PenetrationPass: the penetration texture of an active area (Persson 2019, sec. 4.1.3, table 4.1),
// bit for bit as terrain_core::granular::penetration_texture.

// The uniform block shared by the granular integer passes (GranularUniform in Rust).

@group(0) @binding(0) var<uniform> g: Granular;
@group(0) @binding(1) var<storage, read> heights: array<u32>;
// Depth from below of the area (area-local, row-major), NO_OBJECT where nothing is above.
@group(0) @binding(2) var<storage, read> depth: array<u32>;
@group(0) @binding(3) var<storage, read_write> pen: array<Penetration>;

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= g.area_size.x || id.y >= g.area_size.y {
        return;
    }
    let i = id.y * g.area_size.x + id.x;
    let gx = g.area_min.x + id.x;
    let gy = g.area_min.y + id.y;
    let h = heights[gy * g.map_width + gx];
    let d = depth[i];
    let p = h - min(h, d);
    var out: Penetration;
    if p > 0u {
        out = Penetration(NO_SEED, NO_SEED, PENETRATING, p);
    } else if d != NO_OBJECT && d - h <= g.margin {
        out = Penetration(NO_SEED, NO_SEED, OBSTACLE, 0u);
    } else {
        out = Penetration(gx, gy, SEED, 0u);
    }
    pen[i] = out;
}
