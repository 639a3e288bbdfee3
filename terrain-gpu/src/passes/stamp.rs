//! `StampPass`: every stamp kind of terrain-core (Gaussian, texture, shockwave as a texture,
//! user procedural WGSL) applied on the GPU to the stamp's region only, in place.
//!
//! The shader runs terrain-core's exact stamp program ([`terrain_core::stamp::fixed`]) on the
//! integers [`terrain_core::stamp::fixed_program`] computes, so its heights equal
//! [`terrain_core::apply_stamp`]'s bit for bit on any conforming GPU (a user stamp's when its
//! WGSL and Rust functions agree bit for bit).

use crate::device::compute::{
    PassBindings, StorageBinding, compute_pipeline, dispatch, dispatch_size, shader_module,
    wrap_code, wrap_offset,
};
use crate::device::scope::buffer_init;
use crate::error::GpuError;
use crate::resources::detail::GpuDetailTiles;
use crate::resources::maps::{ExactInF32, GpuHeightMap, MapView};
use crate::resources::packing;
use bytemuck::{Pod, Zeroable};
use glam::UVec2;
use terrain_core::detail::{detail_encoding, tiles_of_pieces};
use terrain_core::stamp::{fixed, fixed_program};
use terrain_core::{
    Blend, DirtyRect, GaussianStamp, HeightEncoding, Rect, StampPlacement, TextureStamp, WrapMode,
    stamp_region,
};

/// The uniform block of `stamp.wgsl` (`StampParams`), byte for byte.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct StampParams {
    region_min: [i32; 2],
    region_size: [u32; 2],
    map_size: [u32; 2],
    wrap: u32,
    kind: u32,
    anchor: [i32; 2],
    l0x: [u32; 2],
    l0y: [u32; 2],
    lxx: [u32; 2],
    lxy: [u32; 2],
    lyx: [u32; 2],
    lyy: [u32; 2],
    base_q16: [u32; 2],
    blend: u32,
    m: i32,
    shift: i32,
    max_raw: u32,
    beta_q: u32,
    base: u32,
    tex_size: [u32; 2],
    wrap_offset: [i32; 2],
    texel_offset: [i32; 2],
    spill_min: [i32; 2],
    spill_width: u32,
    bits: u32,
    start_x: u32,
    pad1: u32,
}

// The WGSL struct's size (WGSL alignment rules): a mismatch fails the build, not a draw.
const _: () = assert!(std::mem::size_of::<StampParams>() == 168);

/// An i64 of the exact program as the shader's `vec2<u32>(lo, hi)`.
fn split64(v: i64) -> [u32; 2] {
    [v as u32, (v >> 32) as u32]
}

use terrain_shaders::codes::{
    BLEND_ADD, BLEND_MAX, BLEND_MIN, STAMP_GAUSSIAN, STAMP_TEXTURE, STAMP_USER,
};

// The shader's blend codes are the exact program's kinds (`FixedBlend::kind`).
const _: () = assert!(BLEND_ADD == 0 && BLEND_MIN == 1 && BLEND_MAX == 2);

/// A texture stamp's values uploaded once (the shockwave uploads its change every frame).
#[derive(Debug)]
pub struct GpuTextureStamp {
    values: wgpu::Buffer,
    size: UVec2,
}

impl GpuTextureStamp {
    /// Uploads the values of `stamp`.
    pub fn new(device: &wgpu::Device, stamp: &TextureStamp) -> Result<Self, GpuError> {
        let values = buffer_init(
            device,
            "GpuTextureStamp",
            bytemuck::cast_slice(&quantized(stamp)),
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        )?;
        Ok(Self {
            values,
            size: stamp.values().size(),
        })
    }

    /// Replaces the values with those of `stamp` (a dynamic stamp such as the shockwave, whose
    /// change is uploaded every frame). The buffer is reused while the new values fit and only
    /// grows (once) when they do not.
    pub fn update(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        stamp: &TextureStamp,
    ) -> Result<(), GpuError> {
        let values = quantized(stamp);
        let bytes = std::mem::size_of_val(values.as_slice()) as u64;
        if bytes > self.values.size() {
            *self = Self::new(device, stamp)?;
            return Ok(());
        }
        queue.write_buffer(&self.values, 0, bytemuck::cast_slice(&values));
        self.size = stamp.values().size();
        Ok(())
    }

    /// Size of the stamp's values in texels.
    pub fn size(&self) -> UVec2 {
        self.size
    }
}

/// A texture stamp's values as the exact program reads them (Q24 integers).
fn quantized(stamp: &TextureStamp) -> Vec<i32> {
    let v = stamp.values().as_slice();
    let mut q: Vec<i32> = v
        .iter()
        .map(|&v| fixed::quantize_texture_value(v))
        .collect();
    if q.is_empty() {
        q.push(0); // a storage buffer may not be empty
    }
    q
}

/// A user-defined procedural stamp: a WGSL function
/// `fn user_stamp_value(local: vec2<f32>) -> f32` (local coordinates in `[-1, 1]^2`, the value
/// multiplied by the intensity), compiled into its own variant of the stamp pipeline. It is the
/// GPU side of a [`terrain_core::Stamp`] implementation; keep both in step. Heights equal the
/// CPU's bit for bit when both functions return the same f32 for the same `local` (which is
/// exact on both sides): write them with exact operations (comparisons, sums and products of
/// few bits), not `length`, `sqrt`, `exp` or an `a * b + c` whose product is inexact, which a
/// GPU may evaluate to other last bits or fuse into an `fma`.
#[derive(Debug)]
pub struct GpuProceduralStamp {
    pipeline: wgpu::ComputePipeline,
}

impl GpuProceduralStamp {
    /// Compiles `wgsl_function` into the stamp shader of `pass`.
    pub fn new(
        device: &wgpu::Device,
        pass: &StampPass,
        wgsl_function: &str,
    ) -> Result<Self, GpuError> {
        let (begin, end) = terrain_shaders::USER_STAMP_MARKERS;
        let src = terrain_shaders::STAMP;
        // terrain-shaders' tests check that the markers are there, in order.
        let (a, b) = match (src.find(begin), src.find(end)) {
            (Some(a), Some(b)) if a < b => (a, b),
            _ => unreachable!("terrain_shaders::STAMP carries its user markers"),
        };
        let source = format!("{}{begin}\n{wgsl_function}\n{}", &src[..a], &src[b..]);
        let module = shader_module(device, "user procedural stamp", &source)
            .map_err(GpuError::user_shader)?;
        let pipeline = compute_pipeline(
            device,
            "user procedural stamp",
            &module,
            pass.bindings.layout(),
            "main",
        )
        .map_err(GpuError::user_shader)?;
        Ok(Self { pipeline })
    }
}

/// The stamp to apply.
#[derive(Debug, Clone, Copy)]
pub enum GpuStamp<'a> {
    /// The Gaussian of Flower 2010, eq. 3.5 with its edge epsilon.
    Gaussian(&'a GaussianStamp),
    /// An uploaded texture stamp.
    Texture(&'a GpuTextureStamp),
    /// A user procedural stamp.
    Procedural(&'a GpuProceduralStamp),
}

/// One stamp to apply: what, where, and how it combines with the map (the arguments of
/// [`terrain_core::apply_stamp`]).
#[derive(Debug, Clone, Copy)]
pub struct StampOp<'a> {
    /// The stamp.
    pub stamp: GpuStamp<'a>,
    /// Where, how large, how strong.
    pub placement: StampPlacement,
    /// How it combines with the map.
    pub blend: Blend,
}

/// Applies stamps to a [`GpuHeightMap`]: one dispatch over the stamp's footprint, wrapped on a
/// repeating map inside the shader (no split into pieces and no backup copy of the map).
#[derive(Debug)]
pub struct StampPass {
    pipeline: wgpu::ComputePipeline,
    bindings: PassBindings<StampParams>,
    empty_values: wgpu::Buffer,
    /// Bound as the excess window of stamps that do not spill (never written).
    no_excess: wgpu::Buffer,
    /// terrain-core's Gaussian tables ([`fixed::gaussian_tables`]), uploaded once.
    exp_table: wgpu::Buffer,
}

/// Where a spilling detail stamp writes its excess: a window of the footprint's texels
/// (unwrapped detail coordinates of its texel `(0, 0)`, its width) in `buffer` (i32 each).
#[derive(Debug, Clone, Copy)]
pub(crate) struct ExcessWindow<'a> {
    pub buffer: &'a wgpu::Buffer,
    pub origin: glam::IVec2,
    pub width: u32,
}

impl StampPass {
    /// Builds the pipeline, its bindings and uniform ring.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let bindings = PassBindings::new(
            device,
            "StampPass",
            wgpu::ShaderStages::COMPUTE,
            &[
                StorageBinding::compute(false),
                StorageBinding::compute(true),
                StorageBinding::compute(false),
                StorageBinding::compute(true),
            ],
        );
        let module = shader_module(device, "stamp.wgsl", terrain_shaders::STAMP)?;
        let pipeline = compute_pipeline(device, "StampPass", &module, bindings.layout(), "main")?;
        let empty_values = buffer_init(
            device,
            "StampPass empty texture",
            bytemuck::cast_slice(&[0.0f32; 4]),
            wgpu::BufferUsages::STORAGE,
        )?;
        let no_excess = buffer_init(
            device,
            "StampPass no excess window",
            bytemuck::cast_slice(&[0i32; 4]),
            wgpu::BufferUsages::STORAGE,
        )?;
        let exp_table = buffer_init(
            device,
            "StampPass Gaussian tables",
            bytemuck::cast_slice(fixed::gaussian_tables()),
            wgpu::BufferUsages::STORAGE,
        )?;
        Ok(Self {
            pipeline,
            bindings,
            empty_values,
            no_excess,
            exp_table,
        })
    }

    /// Frees the uniform slots of the stamps recorded so far: call it after the submit that
    /// carries them.
    pub fn recall(&mut self) {
        self.bindings.recall();
    }

    /// Records one stamp into `encoder` and returns the map rects it covers (as
    /// [`terrain_core::apply_stamp`]: 1, 2 or 4 on a repeating map, none off a clamped map).
    pub fn encode<T: ExactInF32>(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuHeightMap<T>,
        op: &StampOp<'_>,
    ) -> Result<Vec<DirtyRect>, GpuError> {
        self.encode_view(device, queue, encoder, map.view(), op)
    }

    /// Records one stamp on the tile in `tile.slot` of `atlas` (a tile of level `tile.level`) and returns the tile rects it covers. The placement is in the
    /// tile's own frame: metres from its first texel, at the level's texel size (the world's
    /// times `2^level`); the tile is a clamped map, so a stamp across a tile edge is applied to
    /// each tile it touches with the centre moved into that tile's frame, exactly as
    /// [`terrain_core::apply_stamp`] on the tile's [`terrain_core::Grid<u16>`] would.
    pub fn encode_tile(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        atlas: &crate::GpuTileAtlas,
        tile: crate::TileSlot,
        op: &StampOp<'_>,
    ) -> Result<Vec<DirtyRect>, GpuError> {
        let view = atlas.slot_view(tile)?;
        self.encode_view(device, queue, encoder, view, op)
    }

    /// Records one stamp on a detail layer's tiles ([`GpuDetailTiles`]): one dispatch per tile
    /// piece of the footprint ([`terrain_core::detail::DetailLayout::footprint_pieces`]), each
    /// in the layer's unwrapped frame, so a stamp across tile edges, corners and the map's wrap
    /// gives every texel the arithmetic the same stamp has on one large map (bit for bit). The
    /// placement is in metres on the coarse-map's plane, as for
    /// [`terrain_core::detail::DetailLayer::apply_stamp`], its CPU reference. A shared zero
    /// tile under the footprint gets a slot of its own first. Returns the tiles covered, each
    /// with the rect of its texels covered (tile coordinates), row-major: the dirty tiles.
    ///
    /// Fails, with nothing recorded or uploaded, on an invalid placement or blend, a footprint
    /// the CPU layer refuses, a tile under it that is not loaded, or too few free slots. A pass
    /// never recalled fails with [`GpuError::UniformRingFull`] once its ring is full; the zero
    /// tiles given slots for the stamp keep them then (they still read as 0 m).
    pub fn encode_detail(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        tiles: &mut GpuDetailTiles,
        op: &StampOp<'_>,
    ) -> Result<Vec<(UVec2, Rect)>, GpuError> {
        self.encode_detail_window(device, queue, encoder, tiles, op, None)
    }

    /// [`StampPass::encode_detail`], writing each texel's excess beyond the tiles' range into
    /// `spill` when given (a `SpillPass` moves it into the coarse-map).
    pub(crate) fn encode_detail_window(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        tiles: &mut GpuDetailTiles,
        op: &StampOp<'_>,
        spill: Option<ExcessWindow<'_>>,
    ) -> Result<Vec<(UVec2, Rect)>, GpuError> {
        let layout = *tiles.layout();
        let ts = layout.detail_texel_m();
        let footprint = op.placement.footprint(ts)?;
        let prepared = prepare(
            &self.pipeline,
            &self.empty_values,
            op,
            ts,
            detail_encoding(),
            255,
        )?;
        if footprint.is_empty() {
            return Ok(Vec::new());
        }
        let pieces = layout.footprint_pieces(footprint)?;
        if pieces.len() > MAX_DETAIL_PIECES {
            return Err(GpuError::Unsupported {
                what: "detail stamp",
                reason: "the footprint covers more than 4096 tile pieces (one dispatch each): use larger tiles, or stamp the coarse-map",
            });
        }
        let covered = tiles_of_pieces(&pieces);
        tiles.make_resident(queue, covered.iter().map(|t| t.0))?;
        let side = layout.tile_size();
        for piece in &pieces {
            let Some(slot) = tiles.slot_of(piece.tile) else {
                unreachable!("make_resident gave every covered tile a slot");
            };
            let params = StampParams {
                region_min: piece.unwrapped.to_array(),
                region_size: piece.local.size.to_array(),
                map_size: [side; 2],
                wrap: wrap_code(WrapMode::Clamp),
                // Below 2^32 texels in all: `GpuDetailTiles::new` checked slots x tile texels.
                base: slot * tiles.slot_words(),
                wrap_offset: [0; 2],
                texel_offset: (piece.local.min - piece.unwrapped).to_array(),
                bits: GpuDetailTiles::BITS,
                start_x: piece.local.min.x as u32,
                spill_min: spill.map_or([0; 2], |w| w.origin.to_array()),
                spill_width: spill.map_or(0, |w| w.width),
                ..prepared.params
            };
            let excess = spill.map_or(&self.no_excess, |w| w.buffer);
            record(
                &mut self.bindings,
                device,
                queue,
                encoder,
                [tiles.heights_buffer(), excess, &self.exp_table],
                &Prepared { params, ..prepared },
            )?;
        }
        Ok(covered)
    }

    fn encode_view(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        map: MapView<'_>,
        op: &StampOp<'_>,
    ) -> Result<Vec<DirtyRect>, GpuError> {
        let ts = map.texel_size;
        let prepared = prepare(
            &self.pipeline,
            &self.empty_values,
            op,
            ts,
            map.encoding,
            map.max_raw,
        )?;
        let Some(region) = stamp_region(map.size, map.wrap, ts, &op.placement)? else {
            return Ok(Vec::new());
        };
        let offset = wrap_offset(region.footprint.min, map.size)?;
        let params = StampParams {
            region_min: region.footprint.min.to_array(),
            region_size: region.footprint.size.to_array(),
            map_size: map.size.to_array(),
            wrap: wrap_code(map.wrap),
            base: map.base,
            wrap_offset: offset,
            texel_offset: [0; 2],
            bits: map.bits,
            start_x: match map.wrap {
                WrapMode::Repeat => region.footprint.min.x + offset[0],
                WrapMode::Clamp => region.footprint.min.x,
            } as u32,
            ..prepared.params
        };
        record(
            &mut self.bindings,
            device,
            queue,
            encoder,
            [map.buffer, &self.no_excess, &self.exp_table],
            &Prepared { params, ..prepared },
        )?;
        Ok(region.pieces.iter().map(|p| p.map).collect())
    }
}

/// The most tile pieces (dispatches) one detail stamp records: a fine mark covers a few tiles.
const MAX_DETAIL_PIECES: usize = 4096;

/// Binds `prepared` over `[heights, excess window]` and records one dispatch over its region.
fn record(
    bindings: &mut PassBindings<StampParams>,
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    encoder: &mut wgpu::CommandEncoder,
    [heights, excess, exp_table]: [&wgpu::Buffer; 3],
    prepared: &Prepared<'_>,
) -> Result<(), GpuError> {
    let p = &prepared.params;
    let words = packing::word_groups(p.start_x, p.region_size[0], p.map_size[0], p.bits);
    let groups = dispatch_size(device, UVec2::new(words, p.region_size[1]))?;
    let (group, offset) = bindings.bind(
        device,
        queue,
        &prepared.params,
        &[heights, prepared.values, excess, exp_table],
    )?;
    dispatch(
        encoder,
        "StampPass",
        groups,
        &[(prepared.pipeline, &group, offset)],
    );
    Ok(())
}

/// A stamp's parameters (its map and region filled in per dispatch), with the buffers and
/// pipeline it needs.
#[derive(Clone, Copy)]
struct Prepared<'a> {
    params: StampParams,
    values: &'a wgpu::Buffer,
    pipeline: &'a wgpu::ComputePipeline,
}

/// Checks the blend and fills in the stamp, its local frame and blend for a map of texel size
/// `ts`, `enc` and largest stored value `max_raw`.
fn prepare<'a>(
    pipeline: &'a wgpu::ComputePipeline,
    empty_values: &'a wgpu::Buffer,
    op: &StampOp<'a>,
    ts: f32,
    enc: HeightEncoding,
    max_raw: u32,
) -> Result<Prepared<'a>, GpuError> {
    let StampOp {
        stamp,
        ref placement,
        blend,
    } = *op;
    // Checks the placement, texel size and blend; the integers of the exact program.
    let (frame, op) = fixed_program(placement, ts, enc, blend)?;
    let (kind, beta_q, values, tex_size, pipeline) = match stamp {
        GpuStamp::Gaussian(g) => (
            STAMP_GAUSSIAN,
            fixed::gaussian_beta_q(g.beta_for(placement.intensity)),
            empty_values,
            UVec2::ONE,
            pipeline,
        ),
        GpuStamp::Texture(t) => (STAMP_TEXTURE, 0, &t.values, t.size, pipeline),
        GpuStamp::Procedural(p) => (STAMP_USER, 0, empty_values, UVec2::ONE, &p.pipeline),
    };
    let params = StampParams {
        region_min: [0; 2],
        region_size: [0; 2],
        map_size: [0; 2],
        wrap: 0,
        kind,
        anchor: frame.anchor.to_array(),
        l0x: split64(frame.l0[0]),
        l0y: split64(frame.l0[1]),
        lxx: split64(frame.lx[0]),
        lxy: split64(frame.lx[1]),
        lyx: split64(frame.ly[0]),
        lyy: split64(frame.ly[1]),
        base_q16: split64(op.base_q16),
        blend: op.kind,
        m: op.m,
        shift: op.shift,
        max_raw,
        beta_q,
        base: 0,
        tex_size: tex_size.to_array(),
        wrap_offset: [0; 2],
        texel_offset: [0; 2],
        spill_min: [0; 2],
        spill_width: 0,
        bits: 32,
        start_x: 0,
        pad1: 0,
    };
    Ok(Prepared {
        params,
        values,
        pipeline,
    })
}
