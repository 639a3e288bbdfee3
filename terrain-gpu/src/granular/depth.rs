//! `DepthFromBelowPass` (seed 001 sec 4.1.2): the objects rendered with an orthographic camera
//! looking up from below the terrain over an active area, leaving per column the lowest object
//! surface above it in fixed-point height units; the GPU side of
//! [`terrain_core::granular::depth_from_below_into`].
//!
//! # Why a storage buffer and not a depth attachment
//!
//! Each fragment computes its height in the map's u32 units and keeps the lowest with
//! `atomicMin` into a `u32` storage buffer, one element per column of the area (row-major),
//! cleared to [`NO_OBJECT`] first. A `Depth32Float` attachment would have to map the objects'
//! whole vertical span to `0..1` with 24 bits of mantissa (under 1 unit only for spans below
//! about 1.6 km at the default 10 000 units per metre) and be copied and converted afterwards;
//! `R32Float` colour targets are not renderable on GL. The buffer is exact to the unit, needs no
//! depth range, and is already in the layout the next pass (penetration) reads. It needs
//! fragment-stage storage writes ([`wgpu::DownlevelFlags::FRAGMENT_WRITABLE_STORAGE`]), which
//! Vulkan (lavapipe included) and GL 4.3 / GLES 3.1 (llvmpipe included) have; ask
//! [`DepthFromBelowPass::is_supported`] first, as [`DepthFromBelowPass::new`] can only report
//! their absence as an error. The render pass still needs one attachment (wgpu
//! refuses attachment-less passes): a small `R8Unorm` colour target per tile, never read.
//!
//! # Pixel centres
//!
//! The CPU reference samples column `(x, y)` at world `(x * texel_size, y * texel_size)` in X
//! and Z. Vertices are uploaded in area-relative texel units
//! `(u, v) = (X / texel_size - area.min.x, Z / texel_size - area.min.y)` (computed in f64), and
//! the vertex shader maps `(u, v)` to framebuffer `(u + 0.5, v + 0.5)` (minus the tile origin):
//! the centre of pixel `(i, j)` is exactly the sample point of column `area.min + (i, j)`.
//! Framebuffer y grows with world Z, so the rasterizer's top-left rule (Vulkan, D3D, Metal)
//! resolves samples on shared edges as the CPU reference does. Culling is off: the lowest
//! surface counts whatever its winding. Hardware snaps vertices to sub-pixel precision (8 bits
//! on lavapipe), so columns within a fraction of a texel of a triangle edge may differ in
//! coverage from the exact CPU rasterizer; columns inside agree within one unit.
//!
//! # Heights
//!
//! Per triangle, `base` = `floor` of its lowest vertex in units (`(y - offset) / scale`, f64,
//! clamped to `0 ..= NO_OBJECT - 1`) travels as a flat `u32`, and each vertex's units minus
//! `base` as an interpolated f32, so precision follows the triangle's own height span rather
//! than its absolute height. The fragment floors, saturates and adds, as the CPU reference's
//! `floor((y - offset) / scale)` clamped to `0 ..= NO_OBJECT - 1`.
//!
//! Areas larger than the device's largest texture (or 4096 texels) are rendered in tiles.

use bytemuck::{Pod, Zeroable};
use glam::UVec2;
use terrain_core::granular::{GranularError, GranularObject, NO_OBJECT};
use terrain_core::{CoreError, Grid, HeightEncoding, Rect};
use wgpu::util::DeviceExt;

use crate::compute::bind_buffers;
use crate::download::download_bytes;
use crate::error::GpuError;
use crate::maps::map_buffer;
use crate::scope::scoped;

/// Largest tile side rendered in one render pass (further limited by the device's
/// `max_texture_dimension_2d`).
pub const MAX_TILE_SIDE: u32 = 4096;

/// Format of the per-tile colour attachment that only makes the render pass valid.
const TILE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R8Unorm;

/// One vertex: area-relative texel position `(u, v)`, height units above `base`, and `base`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct DepthVertex {
    uvh: [f32; 3],
    base: u32,
}

/// The WGSL `Tile` uniform.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct TileParams {
    origin_f: [f32; 2],
    size_f: [f32; 2],
    origin: [u32; 2],
    area_width: u32,
    _pad: u32,
}

// The WGSL struct's size (WGSL alignment rules): a mismatch fails the build, not a draw.
const _: () = assert!(std::mem::size_of::<TileParams>() == 32);
const _: () = assert!(std::mem::size_of::<DepthVertex>() == 16);

/// Renders [`GranularObject`]s from below over an active area into a `u32` per column
/// (seed 001 sec 4.1.2); see the module docs for the method and its precision.
#[derive(Debug)]
pub struct DepthFromBelowPass {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
}

impl DepthFromBelowPass {
    /// Whether `adapter` can run this pass: it needs storage writes and atomics in fragment
    /// shaders ([`wgpu::DownlevelFlags::FRAGMENT_WRITABLE_STORAGE`]; Vulkan, Metal, D3D12 and
    /// GL 4.3 / GLES 3.1 have them, WebGL2 does not).
    pub fn is_supported(adapter: &wgpu::Adapter) -> bool {
        adapter
            .get_downlevel_capabilities()
            .flags
            .contains(wgpu::DownlevelFlags::FRAGMENT_WRITABLE_STORAGE)
    }

    /// Builds the pipeline. Fails with [`GpuError::Unsupported`] on devices without storage
    /// buffers, or [`GpuError::Validation`] if the shader is rejected (which is what a device
    /// without fragment-stage storage writes gives: check [`Self::is_supported`] first).
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        // `Device::limits` reflects what the device was created with; downlevel support is the
        // adapter's, which the device does not expose, so the limit stands in for it.
        if device.limits().max_storage_buffers_per_shader_stage == 0 {
            return Err(GpuError::Unsupported {
                what: "DepthFromBelowPass",
                reason: "the device has no storage buffers in the fragment stage \
                         (FRAGMENT_WRITABLE_STORAGE)",
            });
        }
        scoped(device, "DepthFromBelowPass", || {
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("DepthFromBelowPass"),
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
                    wgpu::BindGroupLayoutEntry {
                        binding: 1,
                        visibility: wgpu::ShaderStages::FRAGMENT,
                        ty: wgpu::BindingType::Buffer {
                            ty: wgpu::BufferBindingType::Storage { read_only: false },
                            has_dynamic_offset: false,
                            min_binding_size: None,
                        },
                        count: None,
                    },
                ],
            });
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("granular_depth"),
                source: wgpu::ShaderSource::Wgsl(terrain_shaders::GRANULAR_DEPTH.into()),
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("DepthFromBelowPass"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Uint32];
            let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("DepthFromBelowPass"),
                layout: Some(&pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[Some(wgpu::VertexBufferLayout {
                        array_stride: std::mem::size_of::<DepthVertex>() as u64,
                        step_mode: wgpu::VertexStepMode::Vertex,
                        attributes: &attributes,
                    })],
                },
                primitive: wgpu::PrimitiveState {
                    topology: wgpu::PrimitiveTopology::TriangleList,
                    cull_mode: None,
                    ..Default::default()
                },
                depth_stencil: None,
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs_main"),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format: TILE_FORMAT,
                        blend: None,
                        write_mask: wgpu::ColorWrites::empty(),
                    })],
                }),
                multiview_mask: None,
                cache: None,
            });
            Self { pipeline, layout }
        })
    }

    /// A buffer for the depth of `area`: one `u32` per column, row-major, with the usages
    /// [`Self::encode`] and [`Self::read`] need (`STORAGE | COPY_DST | COPY_SRC`).
    pub fn create_output(device: &wgpu::Device, area: Rect) -> Result<wgpu::Buffer, GpuError> {
        let bytes = output_bytes(device, area)?;
        map_buffer(device, "DepthFromBelowPass output", area.size, bytes)
    }

    /// Records the depth from below of `objects` over `area` into `out` (at least
    /// `4 * area.size.x * area.size.y` bytes, usages `STORAGE | COPY_DST`; see
    /// [`Self::create_output`]): element `j * area.size.x + i` is column `area.min + (i, j)`,
    /// in units of `encoding` (`floor((y - offset) / scale)` clamped to `0 ..= NO_OBJECT - 1`),
    /// or [`NO_OBJECT`] where no object covers it. The whole area is overwritten.
    ///
    /// The objects' world-space triangles are uploaded on every call (triangles with zero
    /// projected area, or wholly outside the area, are dropped on the CPU as the reference
    /// does). Whether `area` lies inside the map is the caller's concern, as with the CPU
    /// reference's `_into` form: any non-empty area is rendered.
    ///
    /// Fails on an empty area, a non-positive or non-finite `texel_size` or encoding, an
    /// output buffer that is too small, an object that fails
    /// [`GranularObject::validate`] (non-finite transform, vertices beyond
    /// `MAX_COORDINATE_M`; reported as [`GpuError::Core`]), more triangles than the device's
    /// largest buffer holds, or a wgpu validation error.
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        objects: &[GranularObject<'_>],
        encoding: HeightEncoding,
        texel_size: f32,
        area: Rect,
        out: &wgpu::Buffer,
    ) -> Result<(), GpuError> {
        check_params(encoding, texel_size)?;
        let bytes = output_bytes(device, area)?;
        if out.size() < bytes {
            return Err(CoreError::OutOfRange {
                what: "DepthFromBelowPass output buffer size in bytes",
                value: out.size() as f64,
                expected: "at least 4 bytes per column of the area",
            }
            .into());
        }
        let vertices = world_triangles(objects, encoding, texel_size, area)?;
        let vertex_bytes = (vertices.len() * std::mem::size_of::<DepthVertex>()) as u64;
        if vertex_bytes > device.limits().max_buffer_size || vertices.len() > u32::MAX as usize {
            return Err(CoreError::OutOfRange {
                what: "DepthFromBelowPass vertex bytes (3 vertices of 16 bytes per triangle)",
                value: vertex_bytes as f64,
                expected: "within the device's max_buffer_size",
            }
            .into());
        }
        let tile_side = device
            .limits()
            .max_texture_dimension_2d
            .clamp(1, MAX_TILE_SIDE);
        scoped(device, "DepthFromBelowPass::encode", || {
            let count = (u64::from(area.size.x) * u64::from(area.size.y)) as usize;
            let clear = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("DepthFromBelowPass clear"),
                contents: bytemuck::cast_slice(&vec![NO_OBJECT; count]),
                usage: wgpu::BufferUsages::COPY_SRC,
            });
            encoder.copy_buffer_to_buffer(&clear, 0, out, 0, bytes);
            if vertices.is_empty() {
                return;
            }
            let vertex_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("DepthFromBelowPass vertices"),
                contents: bytemuck::cast_slice(&vertices),
                usage: wgpu::BufferUsages::VERTEX,
            });
            let target_size = area.size.min(UVec2::splat(tile_side));
            let target = device.create_texture(&wgpu::TextureDescriptor {
                label: Some("DepthFromBelowPass tile target"),
                size: wgpu::Extent3d {
                    width: target_size.x,
                    height: target_size.y,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: TILE_FORMAT,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
                view_formats: &[],
            });
            let view = target.create_view(&Default::default());
            for ty in (0..area.size.y).step_by(tile_side as usize) {
                for tx in (0..area.size.x).step_by(tile_side as usize) {
                    let size = (area.size - UVec2::new(tx, ty)).min(UVec2::splat(tile_side));
                    let params = TileParams {
                        origin_f: [tx as f32, ty as f32],
                        size_f: [size.x as f32, size.y as f32],
                        origin: [tx, ty],
                        area_width: area.size.x,
                        _pad: 0,
                    };
                    let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                        label: Some("DepthFromBelowPass tile"),
                        contents: bytemuck::bytes_of(&params),
                        usage: wgpu::BufferUsages::UNIFORM,
                    });
                    let bind_group =
                        bind_buffers(device, "DepthFromBelowPass", &self.layout, &[&uniform, out]);
                    let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                        label: Some("DepthFromBelowPass"),
                        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                            view: &view,
                            depth_slice: None,
                            resolve_target: None,
                            ops: wgpu::Operations {
                                load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                                store: wgpu::StoreOp::Discard,
                            },
                        })],
                        depth_stencil_attachment: None,
                        timestamp_writes: None,
                        occlusion_query_set: None,
                        multiview_mask: None,
                    });
                    pass.set_viewport(0.0, 0.0, size.x as f32, size.y as f32, 0.0, 1.0);
                    pass.set_scissor_rect(0, 0, size.x, size.y);
                    pass.set_pipeline(&self.pipeline);
                    pass.set_bind_group(0, &bind_group, &[]);
                    pass.set_vertex_buffer(0, vertex_buffer.slice(..));
                    pass.draw(0..vertices.len() as u32, 0..1);
                }
            }
        })
    }

    /// Reads a depth buffer written by [`Self::encode`] for `area` into a grid of `area.size`
    /// (sample `(i, j)` is column `area.min + (i, j)`), waiting for the GPU. `out` needs
    /// `COPY_SRC`; submit the encoder first.
    pub fn read(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        out: &wgpu::Buffer,
        area: Rect,
    ) -> Result<Grid<u32>, GpuError> {
        let bytes = output_bytes(device, area)?;
        let data = download_bytes(device, queue, out, 0, bytes)?;
        let values: Vec<u32> = bytemuck::pod_collect_to_vec(&data);
        Ok(Grid::from_vec(area.size.x, area.size.y, values)?)
    }

    /// Convenience: allocates an output, encodes, submits and reads back; the GPU counterpart
    /// of [`terrain_core::granular::depth_from_below_into`] for tests and CPU-side users.
    pub fn run(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        objects: &[GranularObject<'_>],
        encoding: HeightEncoding,
        texel_size: f32,
        area: Rect,
    ) -> Result<Grid<u32>, GpuError> {
        let out = Self::create_output(device, area)?;
        let mut encoder = device.create_command_encoder(&Default::default());
        self.encode(
            device,
            &mut encoder,
            objects,
            encoding,
            texel_size,
            area,
            &out,
        )?;
        queue.submit([encoder.finish()]);
        Self::read(device, queue, &out, area)
    }
}

/// Bytes of the output of `area`, checked against emptiness and the storage binding limit.
fn output_bytes(device: &wgpu::Device, area: Rect) -> Result<u64, GpuError> {
    if area.size.x == 0 || area.size.y == 0 {
        return Err(CoreError::EmptyGrid {
            width: area.size.x,
            height: area.size.y,
        }
        .into());
    }
    let bytes = 4 * u64::from(area.size.x) * u64::from(area.size.y);
    let limit = device
        .limits()
        .max_storage_buffer_binding_size
        .min(device.limits().max_buffer_size);
    if bytes > limit {
        return Err(GpuError::MapTooLarge {
            size: area.size,
            bytes,
            limit,
        });
    }
    Ok(bytes)
}

fn check_params(encoding: HeightEncoding, texel_size: f32) -> Result<(), GpuError> {
    let checks = [
        ("texel_size", texel_size, texel_size > 0.0),
        (
            "height encoding scale",
            encoding.scale,
            encoding.scale > 0.0,
        ),
        ("height encoding offset", encoding.offset, true),
    ];
    for (what, value, positive) in checks {
        if !value.is_finite() {
            return Err(CoreError::NonFinite { what, value }.into());
        }
        if !positive {
            return Err(CoreError::OutOfRange {
                what,
                value: f64::from(value),
                expected: "> 0",
            }
            .into());
        }
    }
    Ok(())
}

/// The error of a failed [`GranularObject::validate`] as a [`GpuError`] (terrain-gpu's error
/// has no granular variant: the values travel in a [`CoreError`]).
fn object_error(e: GranularError) -> GpuError {
    match e {
        GranularError::Core(c) => c.into(),
        GranularError::NonFiniteTransform(cols) => {
            let value = cols
                .iter()
                .copied()
                .find(|v| !v.is_finite())
                .unwrap_or(f32::NAN);
            CoreError::NonFinite {
                what: "granular object transform",
                value,
            }
            .into()
        }
        GranularError::BadVertex { value, limit, .. } => {
            let worst = value
                .iter()
                .copied()
                .find(|v| !v.is_finite() || v.abs() > limit)
                .unwrap_or(value[0]);
            CoreError::OutOfRange {
                what: "granular object world vertex coordinate (m)",
                value: f64::from(worst),
                expected: "finite and within MAX_COORDINATE_M of the origin",
            }
            .into()
        }
        _ => CoreError::OutOfRange {
            what: "granular object",
            value: f64::NAN,
            expected: "an object that passes GranularObject::validate",
        }
        .into(),
    }
}

/// Every triangle of `objects` that may cover a column of `area`, as area-relative vertices.
fn world_triangles(
    objects: &[GranularObject<'_>],
    encoding: HeightEncoding,
    texel_size: f32,
    area: Rect,
) -> Result<Vec<DepthVertex>, GpuError> {
    let ts = f64::from(texel_size);
    let scale = f64::from(encoding.scale);
    let offset = f64::from(encoding.offset);
    let (x0, y0) = (f64::from(area.min.x), f64::from(area.min.y));
    let (x1, y1) = (x0 + f64::from(area.size.x), y0 + f64::from(area.size.y));
    let max_depth = f64::from(NO_OBJECT - 1);
    let mut out = Vec::new();
    for object in objects {
        let verts = object.world_vertices().map_err(object_error)?;
        for tri in object.mesh.triangles() {
            // Indices were checked by `TriMesh::new`; `get` keeps a bad one from panicking.
            let mut p = [glam::DVec3::ZERO; 3];
            for (k, &i) in tri.iter().enumerate() {
                match verts.get(i as usize) {
                    Some(v) => p[k] = v.as_dvec3(),
                    None => {
                        return Err(CoreError::OutOfRange {
                            what: "granular mesh vertex index",
                            value: f64::from(i),
                            expected: "below the mesh's vertex count",
                        }
                        .into());
                    }
                }
            }
            let uv = p.map(|q| glam::DVec2::new(q.x / ts, q.z / ts));
            // As the CPU reference: no projected area, no coverage.
            if (uv[1] - uv[0]).perp_dot(uv[2] - uv[0]) == 0.0 {
                continue;
            }
            let lo = uv[0].min(uv[1]).min(uv[2]);
            let hi = uv[0].max(uv[1]).max(uv[2]);
            // Samples lie at integer (u, v) in [x0, x1) x [y0, y1); keep a texel of margin.
            if hi.x < x0 - 1.0 || hi.y < y0 - 1.0 || lo.x > x1 || lo.y > y1 {
                continue;
            }
            let units = p.map(|q| (q.y - offset) / scale);
            let min_units = units[0].min(units[1]).min(units[2]).floor();
            let base = min_units.clamp(0.0, max_depth);
            for k in 0..3 {
                let rel = if min_units >= max_depth {
                    0.0
                } else {
                    units[k] - base
                };
                out.push(DepthVertex {
                    uvh: [(uv[k].x - x0) as f32, (uv[k].y - y0) as f32, rel as f32],
                    base: base as u32,
                });
            }
        }
    }
    Ok(out)
}
