//! `NormalPass`: regenerates partial-derivative normals (Flower 2010, eq. 3.3) in a dirty rect plus
//! its 2-texel apron, on the GPU.

use crate::device::compute::{
    PassBindings, StorageBinding, compute_pipeline, dispatch, dispatch_size, shader_module,
    wrap_code, wrap_offset,
};
use crate::error::GpuError;
use crate::resources::maps::{ExactInF32, GpuDerivativeMap, GpuHeightMap};
use bytemuck::{Pod, Zeroable};
use terrain_core::{Rect, derivative_region};

/// The uniform block of `normals.wgsl`, byte for byte.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct NormalParams {
    region_min: [i32; 2],
    region_size: [u32; 2],
    map_size: [u32; 2],
    wrap: u32,
    k: f32,
    wrap_offset: [i32; 2],
}

// The WGSL struct's size (WGSL alignment rules): a mismatch fails the build, not a draw.
const _: () = assert!(std::mem::size_of::<NormalParams>() == 40);

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
        let k = (f64::from(map.encoding().scale) / (12.0 * f64::from(map.texel_size()))) as f32;
        let params = NormalParams {
            region_min: region.min.to_array(),
            region_size: region.size.to_array(),
            map_size: map.size().to_array(),
            wrap: wrap_code(map.wrap()),
            k,
            // Covers the region and the stencil's reach of 2 texels around any wrapped texel.
            wrap_offset: wrap_offset(
                region
                    .min
                    .min(glam::IVec2::ZERO)
                    .saturating_sub(glam::IVec2::splat(2)),
                map.size(),
            )?,
        };
        let groups = dispatch_size(device, region.size)?;
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
