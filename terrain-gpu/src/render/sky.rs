//! `SkyPass`: a sky gradient by view-ray elevation, drawn first into the caller's render pass.

use crate::device::compute::shader_module;
use crate::device::scope::scoped;
use crate::error::GpuError;
use crate::render::target::TargetFormat;
use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3};

#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct SkyParams {
    inv_view_proj: [[f32; 4]; 4],
    horizon: [f32; 4],
    zenith: [f32; 4],
    flags: [u32; 4],
}

// The WGSL struct's size (WGSL alignment rules): a mismatch fails the build, not a draw.
const _: () = assert!(std::mem::size_of::<SkyParams>() == 112);

/// Sky colours at the horizon and straight up (linear 0..1 RGB).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SkyColors {
    /// Colour at the horizon.
    pub horizon: Vec3,
    /// Colour straight up.
    pub zenith: Vec3,
}

impl Default for SkyColors {
    fn default() -> Self {
        Self {
            horizon: Vec3::new(0.78, 0.86, 0.95),
            zenith: Vec3::new(0.30, 0.50, 0.82),
        }
    }
}

/// Draws the sky into the caller's render pass; the first draw of a frame (it writes no depth
/// and tests none, so the terrain drawn after covers it). Built once for the pass's formats;
/// [`SkyPass::prepare`] writes the frame's uniforms, [`SkyPass::draw`] records the draw.
#[derive(Debug)]
pub struct SkyPass {
    pipeline: wgpu::RenderPipeline,
    uniform: wgpu::Buffer,
    group: wgpu::BindGroup,
    srgb_target: u32,
    /// 1 when the target's depth falls with distance (reverse-Z).
    reverse_depth: u32,
}

impl SkyPass {
    /// Builds the pipeline for passes of `target`.
    pub fn new(device: &wgpu::Device, target: &TargetFormat) -> Result<Self, GpuError> {
        target.validate(device)?;
        let module = shader_module(device, "sky.wgsl", terrain_shaders::SKY)?;
        scoped(device, "SkyPass", || {
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("SkyPass"),
                entries: &[wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                }],
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("SkyPass"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("SkyPass"),
                layout: Some(&pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                primitive: wgpu::PrimitiveState::default(),
                depth_stencil: Some(target.depth_state(false, wgpu::CompareFunction::Always)),
                multisample: target.multisample(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs_main"),
                    compilation_options: Default::default(),
                    targets: &[Some(target.color.into())],
                }),
                multiview_mask: None,
                cache: None,
            });
            let uniform = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("SkyParams"),
                size: std::mem::size_of::<SkyParams>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("SkyPass"),
                layout: &layout,
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: uniform.as_entire_binding(),
                }],
            });
            Self {
                pipeline,
                uniform,
                group,
                srgb_target: target.srgb_flag(),
                reverse_depth: u32::from(
                    target.depth_convention == crate::DepthConvention::Reverse,
                ),
            }
        })
    }

    /// Writes the frame's uniforms: the camera's `view_proj` (world or camera-relative, with
    /// the target's depth convention, finite or infinite far plane; its inverse must exist)
    /// and the colours.
    pub fn prepare(
        &self,
        queue: &wgpu::Queue,
        view_proj: Mat4,
        colors: &SkyColors,
    ) -> Result<(), GpuError> {
        let inverse = view_proj.inverse();
        if !inverse.is_finite() || !colors.horizon.is_finite() || !colors.zenith.is_finite() {
            return Err(GpuError::Unsupported {
                what: "SkyPass::prepare",
                reason: "the view-projection matrix must be invertible and the colours finite",
            });
        }
        let params = SkyParams {
            inv_view_proj: inverse.to_cols_array_2d(),
            horizon: colors.horizon.extend(1.0).to_array(),
            zenith: colors.zenith.extend(1.0).to_array(),
            flags: [self.srgb_target, self.reverse_depth, 0, 0],
        };
        queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&params));
        Ok(())
    }

    /// Records the sky into `pass` (a pass of this renderer's [`TargetFormat`]).
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>) {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.group, &[]);
        pass.draw(0..3, 0..1);
    }
}
