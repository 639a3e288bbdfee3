//! `SpillPass`: a detail stamp whose excess beyond the tiles' 1 m range spills into the
//! coarse-map instead of being clipped (terrain-core's `detail_spill` rule, of which
//! [`terrain_core::detail::DetailLayer::apply_stamp_spilling`] is the CPU reference).
//!
//! The stamp pass writes each texel's excess into a window the size of the footprint (a
//! scratch buffer this pass owns, cleared first); the spill dispatch then gives every coarse
//! texel under the footprint's tents its tent-weighted share. Both are recorded into the
//! caller's encoder, so the coarse change lands with the detail change.

use crate::device::compute::{
    PassBindings, StorageBinding, compute_pipeline, dispatch, dispatch_size, shader_module,
    wrap_code, wrap_offset,
};
use crate::error::GpuError;
use crate::passes::stamp::{ExcessWindow, StampOp, StampPass};
use crate::resources::detail::GpuDetailTiles;
use crate::resources::maps::{ExactInF32, GpuHeightMap};
use crate::resources::packing;
use bytemuck::{Pod, Zeroable};
use glam::UVec2;
use terrain_core::detail_spill::{check_spill_fits, coarse_pieces, spill_factor, spill_rect};
use terrain_core::{DirtyRect, Rect, WrapMode};

/// The uniform block of `spill.wgsl` (`SpillParams`), byte for byte.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct SpillParams {
    rect_min: [i32; 2],
    rect_size: [u32; 2],
    map_size: [u32; 2],
    wrap: u32,
    refine: u32,
    window_min: [i32; 2],
    window_size: [u32; 2],
    wrap_offset: [i32; 2],
    k: f32,
    max_raw: f32,
    bits: u32,
    start_x: u32,
}

const _: () = assert!(std::mem::size_of::<SpillParams>() == 72);

/// What a spilling detail stamp covered.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SpilledStamp {
    /// The detail tiles the footprint covers, each with the rect of its texels covered (as
    /// [`StampPass::encode_detail`] returns them): the dirty detail tiles.
    pub detail: Vec<(UVec2, Rect)>,
    /// The coarse rects the excess may have changed (the spill rect, wrapped onto a repeating
    /// coarse-map or cut at a clamped one's edges): the GPU does not say whether any texel
    /// left the range, so these are dirty whenever the stamp was recorded.
    pub coarse: Vec<DirtyRect>,
}

/// What a spilling detail stamp writes: the detail layer's tiles and the coarse-map under the
/// layer, which takes the excess beyond the tiles' range.
#[derive(Debug)]
pub struct SpillTargets<'a, T: ExactInF32> {
    /// The detail tiles the stamp is applied to.
    pub tiles: &'a mut GpuDetailTiles,
    /// The coarse-map under the layer (its layout's coarse size and texel size).
    pub coarse: &'a GpuHeightMap<T>,
}

/// Detail stamps that spill their excess into the coarse-map: the excess window (built once,
/// of a fixed capacity) and the spill pipeline.
#[derive(Debug)]
pub struct SpillPass {
    pipeline: wgpu::ComputePipeline,
    bindings: PassBindings<SpillParams>,
    excess: wgpu::Buffer,
    capacity: u64,
}

impl SpillPass {
    /// Builds the pipeline and an excess window of `max_texels` texels (4 bytes each): the
    /// largest footprint a spilling stamp may cover, in detail texels.
    ///
    /// Fails on a capacity of 0 or above 16 M texels (a detail mark is fine; large marks
    /// belong to the coarse-map), or when the device refuses the buffer.
    pub fn new(device: &wgpu::Device, max_texels: u32) -> Result<Self, GpuError> {
        if !(1..=1 << 24).contains(&max_texels) {
            return Err(terrain_core::CoreError::OutOfRange {
                what: "spill window (detail texels)",
                value: f64::from(max_texels),
                expected: "1 to 16 M texels",
            }
            .into());
        }
        let bindings = PassBindings::new(
            device,
            "SpillPass",
            wgpu::ShaderStages::COMPUTE,
            &[
                StorageBinding::compute(true),
                StorageBinding::compute(false),
            ],
        );
        let module = shader_module(device, "spill.wgsl", terrain_shaders::SPILL)?;
        let pipeline = compute_pipeline(device, "SpillPass", &module, bindings.layout(), "main")?;
        let capacity = u64::from(max_texels);
        let excess = crate::device::scope::scoped(device, "SpillPass excess window", || {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("SpillPass excess window"),
                size: capacity * 4,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })?;
        Ok(Self {
            pipeline,
            bindings,
            excess,
            capacity,
        })
    }

    /// The largest footprint (detail texels) a spilling stamp may cover.
    pub fn max_texels(&self) -> u64 {
        self.capacity
    }

    /// Frees the uniform slots recorded so far: call it after the submit that carries them.
    pub fn recall(&mut self) {
        self.bindings.recall();
    }

    /// Records `op` on `targets.tiles`, as [`StampPass::encode_detail`] does, and the spill of
    /// what it pushes beyond the tiles' range into `targets.coarse`, the coarse-map under the
    /// layer (terrain-core's `detail_spill` rule). Returns the dirty detail tiles and coarse
    /// rects.
    ///
    /// Fails, with no stamp recorded, where [`StampPass::encode_detail`] fails, on a coarse-map
    /// of another size or texel size than the layer's layout, on a footprint larger than this
    /// pass's window, or on a mark whose spill would reach around a repeating coarse-map (a
    /// clear of this pass's own window may have been recorded then; it changes nothing else).
    pub fn encode<T: ExactInF32>(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        stamps: &mut StampPass,
        targets: SpillTargets<'_, T>,
        op: &StampOp<'_>,
    ) -> Result<SpilledStamp, GpuError> {
        let SpillTargets { tiles, coarse } = targets;
        let layout = *tiles.layout();
        if coarse.size() != layout.coarse_size() {
            return Err(GpuError::SizeMismatch {
                expected: layout.coarse_size(),
                actual: coarse.size(),
            });
        }
        if coarse.texel_size() != layout.coarse_texel_m() {
            return Err(GpuError::Unsupported {
                what: "SpillPass",
                reason: "the coarse-map's texel size differs from the detail layout's",
            });
        }
        let footprint = op.placement.footprint(layout.detail_texel_m())?;
        if footprint.is_empty() {
            let detail = stamps.encode_detail(device, queue, encoder, tiles, op)?;
            return Ok(SpilledStamp {
                detail,
                coarse: Vec::new(),
            });
        }
        if footprint.area() > self.capacity {
            return Err(terrain_core::CoreError::OutOfRange {
                what: "spilling detail stamp footprint (texels)",
                value: footprint.area() as f64,
                expected: "within the SpillPass window (SpillPass::max_texels)",
            }
            .into());
        }
        let rect = spill_rect(footprint, layout.refine());
        check_spill_fits(rect, coarse.size(), coarse.wrap())?;
        // A clamped coarse-map keeps nothing beyond its edges: only its texels are dispatched.
        let (dispatched, offset, start_x) = match coarse.wrap() {
            WrapMode::Repeat => {
                let offset = wrap_offset(rect.min, coarse.size())?;
                (rect, offset, (rect.min.x + offset[0]) as u32)
            }
            WrapMode::Clamp => {
                let inside = rect.intersect(&Rect::from_size(coarse.size()));
                let inside = inside.unwrap_or(Rect::new(glam::IVec2::ZERO, UVec2::ZERO));
                (inside, [0; 2], inside.min.x as u32)
            }
        };
        let params = SpillParams {
            rect_min: dispatched.min.to_array(),
            rect_size: dispatched.size.to_array(),
            map_size: coarse.size().to_array(),
            wrap: wrap_code(coarse.wrap()),
            refine: layout.refine(),
            window_min: footprint.min.to_array(),
            window_size: footprint.size.to_array(),
            wrap_offset: offset,
            k: spill_factor(layout.refine(), coarse.encoding()),
            max_raw: coarse.max_raw() as f32,
            bits: GpuHeightMap::<T>::BITS,
            start_x,
        };
        let words = packing::word_groups(start_x, dispatched.size.x, coarse.size().x, params.bits);
        let groups = dispatch_size(device, UVec2::new(words, dispatched.size.y))?;
        encoder.clear_buffer(&self.excess, 0, Some(footprint.area() * 4));
        let window = ExcessWindow {
            buffer: &self.excess,
            origin: footprint.min,
            width: footprint.size.x,
        };
        let detail =
            stamps.encode_detail_window(device, queue, encoder, tiles, op, Some(window))?;
        let (group, offset) =
            self.bindings
                .bind(device, queue, &params, &[&self.excess, coarse.buffer()])?;
        dispatch(
            encoder,
            "SpillPass",
            groups,
            &[(&self.pipeline, &group, offset)],
        );
        let coarse = coarse_pieces(rect, coarse.size(), coarse.wrap())
            .into_iter()
            .map(|(r, _)| r)
            .collect();
        Ok(SpilledStamp { detail, coarse })
    }
}
