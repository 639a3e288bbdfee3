// A material layer's texel with `a` (0 to 255) of `material` painted over it
// (terrain_core::paint_texel): one RGBA8 texel per u32 word, R in the low byte.

fn paint_texel(old: u32, material: u32, a: u32) -> u32 {
    var out = 0u;
    for (var ch = 0u; ch < 4u; ch++) {
        let v = (old >> (8u * ch)) & 255u;
        let target_v = select(0u, 255u, ch == material);
        out |= ((v * (255u - a) + target_v * a + 127u) / 255u) << (8u * ch);
    }
    return out;
}
