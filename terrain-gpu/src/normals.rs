//! `NormalPass`: regenerates partial-derivative normals (seed 000 eq. 3.3) in a dirty rect plus
//! its 2-texel apron, on the GPU.

use crate::compute::{bind_buffers, buffer_entry, compute_pipeline, dispatch_size, wrap_offset};
use crate::error::GpuError;
use crate::maps::{GpuDerivativeMap, GpuHeightMap};
use bytemuck::{Pod, Zeroable};
use terrain_core::{Rect, WrapMode, derivative_region};
use wgpu::util::DeviceExt;

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
    layout: wgpu::BindGroupLayout,
}

impl NormalPass {
    /// Builds the pipeline.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        use wgpu::BufferBindingType as B;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("NormalPass"),
            entries: &[
                buffer_entry(0, B::Uniform),
                buffer_entry(1, B::Storage { read_only: true }),
                buffer_entry(2, B::Storage { read_only: false }),
            ],
        });
        let pipeline = compute_pipeline(device, "NormalPass", terrain_shaders::NORMALS, &layout)?;
        Ok(Self { pipeline, layout })
    }

    /// Records the regeneration of the derivatives that heights changed inside `dirty` can
    /// affect (the same region as [`terrain_core::DerivativeMap::update_rect`]).
    pub fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuHeightMap,
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
            wrap: match map.wrap() {
                WrapMode::Repeat => 0,
                WrapMode::Clamp => 1,
            },
            k,
            // Covers the region and the stencil's reach of 2 texels around any wrapped texel.
            wrap_offset: wrap_offset(region.min.min(glam::IVec2::ZERO) - 2, map.size())?,
        };
        let (gx, gy) = dispatch_size(device, region.size)?;
        let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("NormalParams"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let bind_group = bind_buffers(
            device,
            "NormalPass",
            &self.layout,
            &[&uniform, map.buffer(), out.buffer()],
        );
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("NormalPass"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(gx, gy, 1);
        Ok(())
    }

    /// Records the derivatives of the whole map.
    pub fn encode_full(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuHeightMap,
        out: &GpuDerivativeMap,
    ) -> Result<(), GpuError> {
        self.encode(device, encoder, map, out, Rect::from_size(map.size()))
    }
}
