// StampPass: applies one stamp to a height buffer (one u32 per texel), in place.
// Each invocation reads and writes only its own texel, so no backup copy of the map is needed
// (Flower 2010 measured its backup copy as the deformation bottleneck).

struct StampParams {
    // Footprint in unwrapped texel coordinates: invocation (i, j) handles region_min + (i, j).
    region_min: vec2<i32>,
    region_size: vec2<u32>,
    map_size: vec2<u32>,
    // 0: repeat (toroidal), 1: clamp (the region is already clipped to the map).
    wrap: u32,
    // 0: Gaussian, 1: texture, 2: user procedural.
    kind: u32,
    // Stamp centre in texels, 1 / half-size in texels, (cos, sin) of the rotation.
    center: vec2<f32>,
    inv_half: vec2<f32>,
    cos_sin: vec2<f32>,
    // 0: add, 1: min, 2: max.
    blend: u32,
    // Stored units per unit stamp value (intensity / encoding scale).
    raw_per_value: f32,
    // Stored value of the min / max blend's base height.
    base_raw: f32,
    // Largest stored value (255 or 65535).
    max_raw: f32,
    // Gaussian falloff in units of the normalised radius.
    beta: f32,
    // Element of `heights` where the map starts (a tile slot of an atlas; 0 for a whole map).
    base: u32,
    // Size of the texture stamp's values.
    tex_size: vec2<u32>,
    // A multiple of the map size that makes every unwrapped coordinate of the region
    // non-negative: `%` of negative integers is undefined in GLSL, so wrap only non-negatives.
    wrap_offset: vec2<i32>,
    // Added to an unwrapped coordinate of a clamped map to give the texel it writes: 0 for a
    // whole map, minus the tile's origin for a detail tile stamped in its layer's frame.
    texel_offset: vec2<i32>,
    // The spill window (a detail stamp whose excess spills into the coarse-map): unwrapped
    // coordinates of its texel (0, 0) and its width; width 0 writes no excess.
    spill_min: vec2<i32>,
    spill_width: u32,
    pad0: u32,
    pad1: vec2<u32>,
}

@group(0) @binding(0) var<uniform> p: StampParams;
@group(0) @binding(1) var<storage, read_write> heights: array<u32>;
@group(0) @binding(2) var<storage, read> tex: array<f32>;
// The excess beyond the clamped range per texel of the spill window, in stored units
// (terrain-core's `detail_spill`): read by SpillPass. A 1-element dummy when not spilling.
@group(0) @binding(3) var<storage, read_write> excess: array<i32>;

// The wide window of terrain-core's spill rule keeps WIDE_SHIFT units below a detail tile's
// range and as many above it (raw 0 of the tile is raw 32 640 of the window's u16).
const WIDE_SHIFT: f32 = 32640.0;

// USER_STAMP_BEGIN
fn user_stamp_value(local: vec2<f32>) -> f32 {
    return 0.0;
}
// USER_STAMP_END

fn tex_at(x: i32, y: i32) -> f32 {
    let cx = u32(clamp(x, 0, i32(p.tex_size.x) - 1));
    let cy = u32(clamp(y, 0, i32(p.tex_size.y) - 1));
    return tex[cy * p.tex_size.x + cx];
}

// Bilinear, clamped, with pixel centres at (i + 0.5) / n of the footprint (as terrain-core).
fn texture_value(local: vec2<f32>) -> f32 {
    let q = (local + 1.0) * 0.5 * vec2<f32>(p.tex_size) - 0.5;
    let f0 = floor(q);
    let f = q - f0;
    let x0 = i32(f0.x);
    let y0 = i32(f0.y);
    let top = tex_at(x0, y0) + (tex_at(x0 + 1, y0) - tex_at(x0, y0)) * f.x;
    let bot = tex_at(x0, y0 + 1) + (tex_at(x0 + 1, y0 + 1) - tex_at(x0, y0 + 1)) * f.x;
    return top + (bot - top) * f.y;
}

fn stamp_value(local: vec2<f32>) -> f32 {
    switch p.kind {
        case STAMP_GAUSSIAN: { return exp(-p.beta * dot(local, local)); }
        case STAMP_TEXTURE: { return texture_value(local); }
        default: { return user_stamp_value(local); }
    }
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= p.region_size.x || id.y >= p.region_size.y {
        return;
    }
    let u = p.region_min + vec2<i32>(id.xy);
    let d = vec2<f32>(u) - p.center;
    let local = vec2<f32>(d.x * p.cos_sin.x + d.y * p.cos_sin.y, d.y * p.cos_sin.x - d.x * p.cos_sin.y) * p.inv_half;
    if abs(local.x) > 1.0 || abs(local.y) > 1.0 {
        return;
    }
    let v = stamp_value(local);
    // NaN or infinite values leave the texel unchanged (as the CPU reference).
    if !(abs(v) <= 3.0e38) {
        return;
    }
    var x = u32(u.x + p.texel_offset.x);
    var y = u32(u.y + p.texel_offset.y);
    if p.wrap == WRAP_REPEAT {
        x = u32(u.x + p.wrap_offset.x) % p.map_size.x;
        y = u32(u.y + p.wrap_offset.y) % p.map_size.y;
    }
    let i = p.base + y * p.map_size.x + x;
    let old = f32(heights[i]);
    var new_raw: f32;
    switch p.blend {
        // Clamped additive blend, rounded half up like the CPU reference.
        case BLEND_ADD: { new_raw = old + floor(p.raw_per_value * v + 0.5); }
        case BLEND_MIN: { new_raw = floor(min(old, p.base_raw + p.raw_per_value * v) + 0.5); }
        default: { new_raw = floor(max(old, p.base_raw + p.raw_per_value * v) + 0.5); }
    }
    let kept = clamp(new_raw, 0.0, p.max_raw);
    heights[i] = u32(kept);
    if p.spill_width != 0u {
        let w = vec2<u32>(u - p.spill_min);
        let wide = clamp(new_raw, -WIDE_SHIFT, p.max_raw + WIDE_SHIFT);
        excess[w.y * p.spill_width + w.x] = i32(wide - kept);
    }
}
