//! `GranularNormalsPass`: normals of the granular map by the symmetric difference with 3x3
//! Gaussian blur passes, as `terrain_core::granular::{symmetric_normals, blur_normals}` within
//! a float tolerance.

use super::map::GpuGranularMap;
use super::scratch::area_dispatch;
use crate::compute::compute_pipeline_entry;
use crate::compute::{bind_buffers, buffer_entry};
use crate::error::GpuError;
use crate::maps::map_buffer;
use bytemuck::{Pod, Zeroable};
use terrain_core::Rect;
use wgpu::util::DeviceExt;

/// The uniform block of `granular_normals.wgsl`, byte for byte.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct NormalParams {
    area_min: [u32; 2],
    area_size: [u32; 2],
    map_size: [u32; 2],
    k: f32,
    scale: f32,
}

const _: () = assert!(std::mem::size_of::<NormalParams>() == 32);

/// Writes unit normals and the float copy of the heights (`vec4<f32>` per map texel: normal
/// xyz, height in metres in w; row-major) of an area.
#[derive(Debug)]
pub struct GranularNormalsPass {
    normals: wgpu::ComputePipeline,
    blur: wgpu::ComputePipeline,
    copy_back: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

impl GranularNormalsPass {
    /// Builds the pipelines.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        use wgpu::BufferBindingType as B;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("GranularNormalsPass"),
            entries: &[
                buffer_entry(0, B::Uniform),
                buffer_entry(1, B::Storage { read_only: true }),
                buffer_entry(2, B::Storage { read_only: false }),
                buffer_entry(3, B::Storage { read_only: false }),
            ],
        });
        let src = terrain_shaders::GRANULAR_NORMALS;
        Ok(Self {
            normals: compute_pipeline_entry(device, "GranularNormalsPass", src, &layout, "main")?,
            blur: compute_pipeline_entry(device, "GranularNormalsPass blur", src, &layout, "blur")?,
            copy_back: compute_pipeline_entry(
                device,
                "GranularNormalsPass copy",
                src,
                &layout,
                "copy_back",
            )?,
            layout,
        })
    }

    /// A normal buffer for `map` (16 bytes per texel, zeroed; copyable both ways). The pass
    /// needs two: the normals and a blur scratch.
    pub fn normal_buffer(
        device: &wgpu::Device,
        map: &GpuGranularMap,
    ) -> Result<wgpu::Buffer, GpuError> {
        let size = map.size();
        let bytes = u64::from(size.x) * u64::from(size.y) * 16;
        map_buffer(device, "granular normals", size, bytes)
    }

    /// Records the normals of `area` into `normals`, then `blur_iterations` blur passes over
    /// `area` (through `scratch`); both buffers from [`Self::normal_buffer`].
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuGranularMap,
        normals: &wgpu::Buffer,
        scratch: &wgpu::Buffer,
        area: Rect,
        blur_iterations: u32,
    ) -> Result<(), GpuError> {
        let groups = area_dispatch(device, area, map.size())?;
        let need = map.size().x as u64 * map.size().y as u64 * 16;
        if normals.size() < need || scratch.size() < need {
            return Err(GpuError::Unsupported {
                what: "GranularNormalsPass",
                reason: "the normal buffers are smaller than the map",
            });
        }
        let k = (f64::from(map.encoding().scale) * 0.5 / f64::from(map.texel_size())) as f32;
        let params = NormalParams {
            area_min: [area.min.x as u32, area.min.y as u32],
            area_size: area.size.to_array(),
            map_size: map.size().to_array(),
            k,
            scale: map.encoding().scale,
        };
        let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("GranularNormalParams"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let bg = bind_buffers(
            device,
            "GranularNormalsPass",
            &self.layout,
            &[&uniform, map.buffer(), normals, scratch],
        );
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("GranularNormalsPass"),
            timestamp_writes: None,
        });
        pass.set_bind_group(0, &bg, &[]);
        pass.set_pipeline(&self.normals);
        pass.dispatch_workgroups(groups.0, groups.1, 1);
        for _ in 0..blur_iterations {
            pass.set_pipeline(&self.blur);
            pass.dispatch_workgroups(groups.0, groups.1, 1);
            pass.set_pipeline(&self.copy_back);
            pass.dispatch_workgroups(groups.0, groups.1, 1);
        }
        Ok(())
    }
}
