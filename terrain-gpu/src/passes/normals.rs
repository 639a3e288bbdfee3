//! `NormalPass`: regenerates partial-derivative normals (Flower 2010, eq. 3.3) in a dirty rect plus
//! its 2-texel apron, on the GPU, as 8-bit slope codes ([`terrain_core::SlopeCodec`]).

use crate::device::compute::{
    PassBindings, StorageBinding, compute_pipeline, dispatch, dispatch_size, shader_module,
    wrap_code, wrap_offset,
};
use crate::error::GpuError;
use crate::resources::maps::{ExactInF32, GpuDerivativeMap, GpuHeightMap};
use crate::resources::packing;
use bytemuck::{Pod, Zeroable};
use terrain_core::{Rect, SlopeCodec, WrapMode, derivative_region};

/// The uniform block of `normals.wgsl`, byte for byte.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct NormalParams {
    region_min: [i32; 2],
    region_size: [u32; 2],
    map_size: [u32; 2],
    wrap: u32,
    bits: u32,
    wrap_offset: [i32; 2],
    start_x: u32,
    _pad: u32,
    thresholds: [u32; 128],
}

// The WGSL struct's size (WGSL alignment rules): a mismatch fails the build, not a draw.
const _: () = assert!(std::mem::size_of::<NormalParams>() == 560);

/// Computes derivatives from a [`GpuHeightMap`] into a [`GpuDerivativeMap`] over a region.
#[derive(Debug)]
pub struct NormalPass {
    pipeline: wgpu::ComputePipeline,
    bindings: PassBindings<NormalParams>,
}

impl NormalPass {
    /// Builds the pipeline, its bindings and uniform ring.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let bindings = PassBindings::new(
            device,
            "NormalPass",
            wgpu::ShaderStages::COMPUTE,
            &[
                StorageBinding::compute(true),
                StorageBinding::compute(false),
            ],
        );
        let module = shader_module(device, "normals.wgsl", terrain_shaders::NORMALS)?;
        let pipeline = compute_pipeline(device, "NormalPass", &module, bindings.layout(), "main")?;
        Ok(Self { pipeline, bindings })
    }

    /// Frees the uniform slots of the regions recorded so far: call it after the submit that
    /// carries them.
    pub fn recall(&mut self) {
        self.bindings.recall();
    }

    /// Records the regeneration of the derivatives that heights changed inside `dirty` can
    /// affect (the same region as [`terrain_core::DerivativeMap::update_rect`]).
    pub fn encode<T: ExactInF32>(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuHeightMap<T>,
        out: &GpuDerivativeMap,
        dirty: Rect,
    ) -> Result<(), GpuError> {
        if out.size() != map.size() {
            return Err(GpuError::SizeMismatch {
                expected: map.size(),
                actual: out.size(),
            });
        }
        let Some(region) = derivative_region(map.size(), map.wrap(), dirty)? else {
            return Ok(());
        };
        let codec = SlopeCodec::new(map.encoding().scale, map.texel_size())?;
        let mut thresholds = [u32::MAX; 128];
        thresholds[..127].copy_from_slice(codec.thresholds());
        // Covers the region and the stencil's reach of 2 texels around any wrapped texel.
        let offset = wrap_offset(
            region
                .min
                .min(glam::IVec2::ZERO)
                .saturating_sub(glam::IVec2::splat(2)),
            map.size(),
        )?;
        let start_x = match map.wrap() {
            WrapMode::Repeat => region.min.x + offset[0],
            WrapMode::Clamp => region.min.x,
        } as u32;
        let params = NormalParams {
            region_min: region.min.to_array(),
            region_size: region.size.to_array(),
            map_size: map.size().to_array(),
            wrap: wrap_code(map.wrap()),
            bits: GpuHeightMap::<T>::BITS,
            wrap_offset: offset,
            start_x,
            _pad: 0,
            thresholds,
        };
        let words = packing::word_groups(start_x, region.size.x, map.size().x, 16);
        let groups = dispatch_size(device, glam::UVec2::new(words, region.size.y))?;
        let (group, offset) =
            self.bindings
                .bind(device, queue, &params, &[map.buffer(), out.buffer()])?;
        dispatch(
            encoder,
            "NormalPass",
            groups,
            &[(&self.pipeline, &group, offset)],
        );
        Ok(())
    }

    /// Records the derivatives of the whole map.
    pub fn encode_full<T: ExactInF32>(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuHeightMap<T>,
        out: &GpuDerivativeMap,
    ) -> Result<(), GpuError> {
        let whole = Rect::from_size(map.size());
        self.encode(device, queue, encoder, map, out, whole)
    }
}
