// CdlodRenderer: CDLOD quadrants (Cervin 2012, sec. 1.1.4) drawn with clipmap.wgsl's frame, surface
// and fragment shader; this file adds the vertex shader with Strugar's per-vertex morph. CPU
// reference: terrain_lod::cdlod::morphed_vertex.

struct CdlodLods {
    // Per LOD: morph start and end distance (metres); end < 0: no morph (the coarsest LOD).
    morph: array<vec4<f32>, 16>,
}

// Binding 6: after every surface's bindings (a tile atlas has 1-3, a detail surface 1-5).
@group(0) @binding(6) var<uniform> lods: CdlodLods;

struct CdlodIn {
    @location(0) grid: vec2<f32>,
    @location(1) origin: vec2<i32>,
    @location(2) step: u32,
    @location(3) lod: u32,
}

// Bilinear height at a texel position given relative to the camera's integer texel.
fn height_bilinear(rel: vec2<f32>) -> f32 {
    let r0 = floor(rel);
    let f = rel - r0;
    let t = frame.camera_texel + vec2<i32>(r0);
    let h00 = height_at(t);
    if f.x == 0.0 && f.y == 0.0 {
        return h00;
    }
    let h10 = height_at(t + vec2<i32>(1, 0));
    let h01 = height_at(t + vec2<i32>(0, 1));
    let h11 = height_at(t + vec2<i32>(1, 1));
    let a = h00 + (h10 - h00) * f.x;
    let b = h01 + (h11 - h01) * f.x;
    return a + (b - a) * f.y;
}

@vertex
fn vs_cdlod(in: CdlodIn) -> VsOut {
    let g = vec2<i32>(in.grid);
    let s = i32(in.step);
    let texel = in.origin + g * s;
    // Distance from the camera at the unmorphed vertex: both nodes sharing a vertex compute the
    // same, so shared edges stay shared.
    let h = height_at(texel);
    let rel0 = vec2<f32>(texel - frame.camera_texel) - frame.camera_frac;
    let world0 = vec3<f32>(rel0.x * frame.texel_size, h - frame.camera_height, rel0.y * frame.texel_size);
    let m = lods.morph[min(in.lod, 15u)];
    var k = 0.0;
    if m.y > 0.0 {
        // As 1 - (end - d) / (end - start): exactly 1 from the end on.
        k = clamp(1.0 - (m.y - length(world0)) / (m.y - m.x), 0.0, 1.0);
    }
    // Odd grid positions move towards the lower even line (quadrant origins are even).
    let odd = vec2<f32>(g & vec2<i32>(1, 1));
    let rel_int = vec2<f32>(texel - frame.camera_texel) - odd * (k * f32(s));
    let hm = height_bilinear(rel_int);
    let rel_texel = rel_int - frame.camera_frac;
    let world = vec3<f32>(rel_texel.x * frame.texel_size, hm - frame.camera_height, rel_texel.y * frame.texel_size);
    var out: VsOut;
    out.clip = frame.view_proj * vec4<f32>(world, 1.0);
    out.rel_texel = rel_texel;
    out.height = hm;
    out.view_dist = length(world);
    return out;
}
