// Clipmap surface of a coarse-map: stored heights (16-bit texels packed two per u32, metres =
// offset + scale * stored) and partial-derivative normals (Flower 2010, eq. 3.3) as two 8-bit
// slope codes per texel (terrain_core::slope_code), also packed two texels per u32.

@group(0) @binding(1) var<storage, read> heights: array<u32>;
@group(0) @binding(2) var<storage, read> derivatives: array<u32>;

fn height_at(t: vec2<i32>) -> f32 {
    let c = map_texel(t);
    let stored = packed_get(heights[packed_index(c.x, c.y, frame.map_size.x, 16u)], c.x, 16u);
    return frame.height_offset + frame.height_scale * f32(stored);
}

// The slope a code stands for: tan(code * 85° / 127) (terrain_core::decode_slope).
fn decode_slope(code: u32) -> f32 {
    let c = max(f32((i32(code) << 24u) >> 24u), -127.0);
    return tan(c * radians(f32(SLOPE_CODE_MAX_DEGREES) / 127.0));
}

fn derivative_at(t: vec2<i32>) -> vec2<f32> {
    let c = map_texel(t);
    let codes = packed_get(derivatives[packed_index(c.x, c.y, frame.map_size.x, 16u)], c.x, 16u);
    return vec2<f32>(decode_slope(codes & 0xffu), decode_slope(codes >> 8u));
}
