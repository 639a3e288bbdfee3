//! `ClipmapRenderer`: draws a geometry clipmap (terrain-lod's shared mesh, instanced per part)
//! displaced by the coarse-map with wrap addressing and lit with the derivative normals.

use crate::camera::Camera;
use crate::error::GpuError;
use crate::maps::{GpuDerivativeMap, GpuHeightMap};
use crate::offscreen::{COLOR_FORMAT, DEPTH_FORMAT, OffscreenTarget};
use crate::scope::scoped;
use bytemuck::{Pod, Zeroable};
use glam::{Vec3, Vec4};
use terrain_lod::{ClipmapFrame, ClipmapInstance, ClipmapLayout, ClipmapVertex, MeshPart};
use wgpu::util::DeviceExt;

/// The uniform block `Frame` of `clipmap.wgsl`, byte for byte.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct FrameUniform {
    view_proj: [[f32; 4]; 4],
    camera_texel: [i32; 2],
    camera_frac: [f32; 2],
    camera_height: f32,
    texel_size: f32,
    height_scale: f32,
    height_offset: f32,
    map_size: [u32; 2],
    wrap_offset: [i32; 2],
    n: u32,
    levels: u32,
    morph_width: f32,
    ramp_low: f32,
    ramp_high: f32,
    pad: [f32; 3],
    light_dir: [f32; 4],
    fog_color: [f32; 4],
}

// The WGSL struct's size (WGSL alignment rules): a mismatch fails the build, not a draw.
const _: () = assert!(std::mem::size_of::<FrameUniform>() == 176);

/// Lighting and colouring of the terrain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TerrainStyle {
    /// Direction towards the sun.
    pub light_dir: Vec3,
    /// Heights (metres) the colour ramp spans, low to high.
    pub ramp: (f32, f32),
    /// Colour the terrain fades to with distance.
    pub fog_color: Vec3,
    /// Fog density per metre (0: none).
    pub fog_density: f32,
}

impl Default for TerrainStyle {
    fn default() -> Self {
        Self {
            light_dir: Vec3::new(-0.5, 0.8, -0.35),
            ramp: (0.0, 12.0),
            fog_color: Vec3::new(0.74, 0.82, 0.90),
            fog_density: 0.0,
        }
    }
}

/// Renders a placed [`ClipmapFrame`] into an [`OffscreenTarget`] after the sky.
#[derive(Debug)]
pub struct ClipmapRenderer {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    parts: Vec<MeshPart>,
    n: u32,
    levels: u32,
}

impl ClipmapRenderer {
    /// Uploads the shared mesh of `layout` and builds the pipeline.
    pub fn new(device: &wgpu::Device, layout: &ClipmapLayout) -> Result<Self, GpuError> {
        let mesh = layout.mesh();
        scoped(device, "ClipmapRenderer", || {
            let storage = |binding, stages| wgpu::BindGroupLayoutEntry {
                binding,
                visibility: stages,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only: true },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            };
            let bind_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("ClipmapRenderer"),
                entries: &[
                    wgpu::BindGroupLayoutEntry {
                        binding: 0,
                        visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                        ty: wgpu::BindingType::Buffer {
                            ty: wgpu::BufferBindingType::Uniform,
                            has_dynamic_offset: false,
                            min_binding_size: None,
                        },
                        count: None,
                    },
                    storage(1, wgpu::ShaderStages::VERTEX),
                    storage(2, wgpu::ShaderStages::FRAGMENT),
                ],
            });
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("clipmap"),
                source: wgpu::ShaderSource::Wgsl(terrain_shaders::CLIPMAP.into()),
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("ClipmapRenderer"),
                bind_group_layouts: &[Some(&bind_layout)],
                immediate_size: 0,
            });
            let vertex_attrs = wgpu::vertex_attr_array![0 => Float32x2];
            let instance_attrs = wgpu::vertex_attr_array![1 => Sint32x2, 2 => Uint32, 3 => Uint32];
            let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("ClipmapRenderer"),
                layout: Some(&pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[
                        Some(wgpu::VertexBufferLayout {
                            array_stride: std::mem::size_of::<ClipmapVertex>() as u64,
                            step_mode: wgpu::VertexStepMode::Vertex,
                            attributes: &vertex_attrs,
                        }),
                        Some(wgpu::VertexBufferLayout {
                            array_stride: std::mem::size_of::<ClipmapInstance>() as u64,
                            step_mode: wgpu::VertexStepMode::Instance,
                            attributes: &instance_attrs,
                        }),
                    ],
                },
                // No culling: degenerate triangles and both windings of the parts are drawn.
                primitive: wgpu::PrimitiveState::default(),
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: DEPTH_FORMAT,
                    depth_write_enabled: Some(true),
                    depth_compare: Some(wgpu::CompareFunction::Less),
                    stencil: Default::default(),
                    bias: Default::default(),
                }),
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs_main"),
                    compilation_options: Default::default(),
                    targets: &[Some(COLOR_FORMAT.into())],
                }),
                multiview_mask: None,
                cache: None,
            });
            let vertices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("clipmap vertices"),
                contents: bytemuck::cast_slice(&mesh.vertices),
                usage: wgpu::BufferUsages::VERTEX,
            });
            let indices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("clipmap indices"),
                contents: bytemuck::cast_slice(&mesh.indices),
                usage: wgpu::BufferUsages::INDEX,
            });
            Self {
                pipeline,
                layout: bind_layout,
                vertices,
                indices,
                parts: mesh.parts.clone(),
                n: layout.n(),
                levels: layout.levels(),
            }
        })
    }

    /// Records the terrain into `target` (after [`crate::SkyPass`], which clears it).
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        target: &OffscreenTarget,
        map: &GpuHeightMap<u16>,
        normals: &GpuDerivativeMap,
        frame: &ClipmapFrame,
        camera: &Camera,
        style: &TerrainStyle,
    ) -> Result<(), GpuError> {
        if !camera.is_valid() {
            return Err(GpuError::InvalidCamera { camera: *camera });
        }
        if map.wrap() != terrain_core::WrapMode::Repeat {
            return Err(GpuError::Unsupported {
                what: "ClipmapRenderer",
                reason: "the clipmap renders toroidal (repeating) coarse-maps only",
            });
        }
        if frame.levels.len() != self.levels as usize {
            return Err(GpuError::Unsupported {
                what: "ClipmapRenderer",
                reason: "the frame was placed by a layout with another number of levels",
            });
        }
        if normals.size() != map.size() {
            return Err(GpuError::SizeMismatch {
                expected: map.size(),
                actual: normals.size(),
            });
        }
        let size = target.size().as_vec2();
        let ts = map.texel_size();
        let cam_texel = glam::Vec2::new(camera.position.x, camera.position.z) / ts;
        let cam_int = cam_texel.floor();
        let enc = map.encoding();
        let uniform = FrameUniform {
            view_proj: camera
                .view_proj_relative(size.x / size.y)
                .to_cols_array_2d(),
            camera_texel: cam_int.as_ivec2().to_array(),
            camera_frac: (cam_texel - cam_int).to_array(),
            camera_height: camera.position.y,
            texel_size: ts,
            height_scale: enc.scale,
            height_offset: enc.offset,
            map_size: map.size().to_array(),
            wrap_offset: wrap_offset_for_frame(frame, map)?,
            n: self.n,
            levels: self.levels,
            morph_width: terrain_lod::morph::default_morph_width(self.n),
            ramp_low: style.ramp.0,
            ramp_high: style.ramp.1,
            pad: [0.0; 3],
            light_dir: style.light_dir.extend(0.0).to_array(),
            fog_color: Vec4::from((style.fog_color, style.fog_density)).to_array(),
        };
        let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("clipmap frame"),
            contents: bytemuck::bytes_of(&uniform),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ClipmapRenderer"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: map.buffer().as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: normals.buffer().as_entire_binding() },
            ],
        });

        // Instances grouped by part, so each part is one instanced draw.
        let mut runs: Vec<(usize, Vec<ClipmapInstance>)> = Vec::new();
        for draw in &frame.draws {
            let Some(part) = self.parts.iter().position(|p| p.kind == draw.part) else {
                continue;
            };
            match runs.iter_mut().find(|(p, _)| *p == part) {
                Some((_, list)) => list.push(draw.instance),
                None => runs.push((part, vec![draw.instance])),
            }
        }
        let all: Vec<ClipmapInstance> = runs.iter().flat_map(|(_, l)| l.iter().copied()).collect();
        if all.is_empty() {
            return Ok(());
        }
        let instances = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("clipmap instances"),
            contents: bytemuck::cast_slice(&all),
            usage: wgpu::BufferUsages::VERTEX,
        });

        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("ClipmapRenderer"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: target.color_view(),
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Load,
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: target.depth_view(),
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Load,
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.set_vertex_buffer(0, self.vertices.slice(..));
        pass.set_vertex_buffer(1, instances.slice(..));
        pass.set_index_buffer(self.indices.slice(..), wgpu::IndexFormat::Uint32);
        let mut first = 0u32;
        for (part, list) in &runs {
            let part = &self.parts[*part];
            let count = list.len() as u32;
            pass.draw_indexed(part.indices.clone(), part.base_vertex, first..first + count);
            first += count;
        }
        Ok(())
    }
}

/// A multiple of the map size that makes every texel the frame can read non-negative (the
/// coarsest level's origin, less the morph's one-texel reach).
fn wrap_offset_for_frame(frame: &ClipmapFrame, map: &GpuHeightMap<u16>) -> Result<[i32; 2], GpuError> {
    let min = frame
        .levels
        .iter()
        .map(|l| l.origin - glam::IVec2::splat(l.scale as i32 + 1))
        .fold(glam::IVec2::ZERO, |a, b| a.min(b));
    crate::compute::wrap_offset(min, map.size())
}
