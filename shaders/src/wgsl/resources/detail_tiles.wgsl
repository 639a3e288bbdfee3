// GpuDetailTiles as shaders read them (Flower 2010, sec. 2.3.1): the tile-slot table and the slots
// of raw u8 detail values (packed four per u32 word), with bilinear heights and eq. 3.3 gradients across
// tile edges and the layer's wrap. CPU reference: terrain_core::detail::DetailLayer's
// height_m and gradient_m.

struct DetailInfo {
    // Detail texels over the whole coarse-map (the layer's period).
    size: vec2<u32>,
    // A multiple of `size` added before `%` so every texel read is non-negative.
    wrap_offset: vec2<i32>,
    // The detail texel of the camera's whole coarse texel, wrapped onto the layer: points are
    // addressed relative to it, so far-away cameras keep their precision.
    camera_detail: vec2<i32>,
    tiles_x: u32,
    tile_size: u32,
    // Slots in all: a table entry at or above it (the zero tile, a tile not loaded) reads 0 m.
    slots: u32,
    // Detail texels per coarse texel.
    refine: u32,
    // Metres = offset + scale * raw.
    scale: f32,
    offset: f32,
    // scale / (12 detail texel spacing): eq. 3.3's factor.
    gradient_k: f32,
    // The detail is drawn fully up to fade_start metres from the camera, not from fade_end.
    fade_start: f32,
    fade_end: f32,
    // Linear search steps of the parallax march (0: no parallax, composite normals only).
    parallax_steps: u32,
    // The farthest (coarse texels) the parallax march moves a fragment.
    max_reach: f32,
    // 1 when the layer's size is a whole number of tiles on both axes (the zero-tile test of
    // the parallax hook needs it), else 0.
    even_tiles: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(3) var<uniform> detail: DetailInfo;
@group(0) @binding(4) var<storage, read> detail_table: array<u32>;
@group(0) @binding(5) var<storage, read> detail_heights: array<u32>;

// The raw value of detail texel `p` (detail coordinates, wrapped onto the layer).
fn detail_raw(p: vec2<i32>) -> f32 {
    let q = vec2<u32>(p + detail.wrap_offset) % detail.size;
    let tile = q / detail.tile_size;
    let slot = detail_table[tile.y * detail.tiles_x + tile.x];
    if slot >= detail.slots {
        return f32(DETAIL_ZERO_RAW);
    }
    let local = q % detail.tile_size;
    // Slots of rows of 8-bit texels packed four per word (packed.wgsl).
    let slot_words = packed_pitch(detail.tile_size, 8u) * detail.tile_size;
    let word = detail_heights[slot * slot_words + packed_index(local.x, local.y, detail.tile_size, 8u)];
    return f32(packed_get(word, local.x, 8u));
}

// Whether the tile of detail texel `p` has no slot (the zero tile, or not loaded: 0 m).
fn detail_tile_is_zero(p: vec2<i32>) -> bool {
    let q = vec2<u32>(p + detail.wrap_offset) % detail.size;
    let tile = q / detail.tile_size;
    return detail_table[tile.y * detail.tiles_x + tile.x] >= detail.slots;
}

// Eq. 3.3 at detail texel `p`, in metres per metre.
fn detail_gradient_at(p: vec2<i32>) -> vec2<f32> {
    let x = vec2<i32>(1, 0);
    let z = vec2<i32>(0, 1);
    let dx = (detail_raw(p - 2 * x) - detail_raw(p + 2 * x)) + 8.0 * (detail_raw(p + x) - detail_raw(p - x));
    let dz = (detail_raw(p - 2 * z) - detail_raw(p + 2 * z)) + 8.0 * (detail_raw(p + z) - detail_raw(p - z));
    return vec2<f32>(dx, dz) * detail.gradient_k;
}

// Bilinear detail height (metres) at detail texel `b` plus fraction `f` in [0, 1).
fn detail_height(b: vec2<i32>, f: vec2<f32>) -> f32 {
    let h00 = detail.offset + detail.scale * detail_raw(b);
    let h10 = detail.offset + detail.scale * detail_raw(b + vec2<i32>(1, 0));
    let h01 = detail.offset + detail.scale * detail_raw(b + vec2<i32>(0, 1));
    let h11 = detail.offset + detail.scale * detail_raw(b + vec2<i32>(1, 1));
    let top = h00 + (h10 - h00) * f.x;
    let bot = h01 + (h11 - h01) * f.x;
    return top + (bot - top) * f.y;
}

// Height and gradient at detail texel `b` plus fraction `f`, unfaded.
fn detail_sample(b: vec2<i32>, f: vec2<f32>) -> DetailSample {
    let g00 = detail_gradient_at(b);
    let g10 = detail_gradient_at(b + vec2<i32>(1, 0));
    let g01 = detail_gradient_at(b + vec2<i32>(0, 1));
    let g11 = detail_gradient_at(b + vec2<i32>(1, 1));
    let top = g00 + (g10 - g00) * f.x;
    let bot = g01 + (g11 - g01) * f.x;
    return DetailSample(detail_height(b, f), top + (bot - top) * f.y);
}

// The detail texel and fraction of a point `q` coarse texels past the camera's whole coarse
// texel (integer parts kept as integers).
struct DetailPoint {
    b: vec2<i32>,
    f: vec2<f32>,
}

fn detail_point(q: vec2<f32>) -> DetailPoint {
    let d = q * f32(detail.refine);
    let whole = floor(d);
    return DetailPoint(detail.camera_detail + vec2<i32>(whole), d - whole);
}

// 1 up to fade_start metres from the camera, 0 from fade_end, smooth in between.
fn detail_fade(view_dist: f32) -> f32 {
    return 1.0 - smoothstep(detail.fade_start, detail.fade_end, view_dist);
}

// Whether every detail texel the march and sample between `a` and `b` (coarse texels from the
// camera's whole texel) can read lies in a tile without a slot: then the detail is 0 m there
// and nothing needs reading. The box of the reads (3 texels of margin for the differences and
// the bilinear) is narrower than a tile, so its corners' tiles are all the tiles it touches
// when the layer is a whole number of tiles; otherwise it answers false.
fn detail_box_is_zero(a: vec2<f32>, b: vec2<f32>) -> bool {
    let k = f32(detail.refine);
    let lo = detail.camera_detail + vec2<i32>(floor(min(a, b) * k)) - vec2<i32>(3, 3);
    let hi = detail.camera_detail + vec2<i32>(floor(max(a, b) * k)) + vec2<i32>(3, 3);
    let side = i32(detail.tile_size);
    if detail.even_tiles == 0u || hi.x - lo.x >= side || hi.y - lo.y >= side {
        return false;
    }
    return detail_tile_is_zero(lo) && detail_tile_is_zero(hi)
        && detail_tile_is_zero(vec2<i32>(lo.x, hi.y)) && detail_tile_is_zero(vec2<i32>(hi.x, lo.y));
}
