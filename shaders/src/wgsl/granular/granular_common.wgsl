// Shared by the granular passes; terrain-shaders joins it in front of each of them (WGSL has
// no includes). The uniform block `Granular` is `GranularUniform` in terrain-gpu; the
// penetration texel and the column kinds are those of terrain_core::granular (table 4.1).

struct Granular {
    // Active area in map texels.
    area_min: vec2<u32>,
    area_size: vec2<u32>,
    map_width: u32,
    // Jump flooding step and pass index.
    step: u32,
    pass_index: u32,
    // 0: Euclidean squared, 1: Manhattan, 2: Chebyshev.
    metric: u32,
    keep_q15: u32,
    // Obstacle margin in height units.
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

