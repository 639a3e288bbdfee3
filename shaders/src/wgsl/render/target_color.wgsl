// Colours are computed as the bytes a capture shows (display-referred). On an sRGB target the
// hardware encodes what the shader returns, so hand it the linear value that encodes back to
// the same bytes (the sRGB transfer function, IEC 61966-2-1).
fn to_target(c: vec3<f32>, srgb_target: u32) -> vec3<f32> {
    if srgb_target == 0u {
        return c;
    }
    let low = c / 12.92;
    let high = pow((c + 0.055) / 1.055, vec3<f32>(2.4));
    return select(high, low, c <= vec3<f32>(0.04045));
}
