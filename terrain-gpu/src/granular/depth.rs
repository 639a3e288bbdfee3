//! `DepthFromBelowPass` (Persson 2019, sec. 4.1.2): the objects rendered with an orthographic camera
//! looking up from below the terrain over an active area, leaving per column the lowest object
//! surface above it in fixed-point height units; the GPU side of
//! [`terrain_core::granular::depth_from_below_into`].
//!
//! Each fragment keeps the lowest height per column with `atomicMin` into a `u32` storage
//! buffer, exact to the unit (fragment-stage storage writes: ask
//! [`DepthFromBelowPass::is_supported`]); pixel centres are the CPU reference's sample points,
//! and heights travel relative to each triangle's lowest vertex. Why a buffer and not a depth
//! attachment, and how pixel centres and heights match the CPU reference, is derived in the
//! repository's `docs/derivations.md` ("Depth from below on the GPU").
//!
//! # Resources
//!
//! The pipeline, its bind group layout and a uniform ring (one slot per tile) are made in
//! [`DepthFromBelowPass::new`]. The tile target, the buffer of [`NO_OBJECT`]s the output is
//! cleared from and the vertex buffer persist in the pass and are replaced only by larger ones
//! when an area or an object list needs more; triangles are written with `queue.write_buffer`
//! at the next free offset of the vertex buffer, so several areas can be recorded into one
//! encoder. Call [`DepthFromBelowPass::recall`] after the submit that carries them.

use bytemuck::{Pod, Zeroable};
use glam::UVec2;
use terrain_core::granular::{GranularObject, NO_OBJECT};
use terrain_core::{CoreError, Grid, HeightEncoding, HeightSample, Rect};

use super::upload::UploadRing;
use crate::device::compute::{PassBindings, StorageBinding, shader_module};
use crate::device::download::download_bytes;
use crate::device::scope::scoped;
use crate::error::GpuError;
use crate::resources::maps::{GpuHeightMap, map_buffer};

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
pub(super) struct TileParams {
    origin_f: [f32; 2],
    size_f: [f32; 2],
    origin: [u32; 2],
    area_width: u32,
    _pad: u32,
}

// The WGSL struct's size (WGSL alignment rules): a mismatch fails the build, not a draw.
const _: () = assert!(std::mem::size_of::<TileParams>() == 32);
const _: () = assert!(std::mem::size_of::<DepthVertex>() == 16);

/// What a depth-from-below render looks at: a non-empty area (in map columns) and the map's
/// height encoding and texel size (positive and finite), checked when made. The arguments of
/// [`terrain_core::granular::depth_from_below_into`] besides the objects and the output.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthArea {
    encoding: HeightEncoding,
    texel_size: f32,
    rect: Rect,
}

impl DepthArea {
    /// Checks the encoding, the texel size and the area.
    pub fn new(encoding: HeightEncoding, texel_size: f32, rect: Rect) -> Result<Self, GpuError> {
        check_params(encoding, texel_size)?;
        if rect.is_empty() {
            return Err(CoreError::EmptyGrid {
                width: rect.size.x,
                height: rect.size.y,
            }
            .into());
        }
        Ok(Self {
            encoding,
            texel_size,
            rect,
        })
    }

    /// `rect` of `map`, in its encoding and texel size.
    pub fn for_map<T: HeightSample>(map: &GpuHeightMap<T>, rect: Rect) -> Result<Self, GpuError> {
        Self::new(map.encoding(), map.texel_size(), rect)
    }

    /// The height encoding the depths are written in.
    pub fn encoding(&self) -> HeightEncoding {
        self.encoding
    }

    /// Metres per texel.
    pub fn texel_size(&self) -> f32 {
        self.texel_size
    }

    /// The area in map columns.
    pub fn rect(&self) -> Rect {
        self.rect
    }
}

/// Renders [`GranularObject`]s from below over an active area into a `u32` per column
/// (Persson 2019, sec. 4.1.2); see the module docs for the method, its precision and its resources.
#[derive(Debug)]
pub struct DepthFromBelowPass {
    pipeline: wgpu::RenderPipeline,
    pub(super) bindings: PassBindings<TileParams>,
    tile_side: u32,
    target: Option<(wgpu::Texture, wgpu::TextureView)>,
    clear: Option<wgpu::Buffer>,
    vertices: UploadRing,
    triangles: Vec<DepthVertex>,
}

/// A size that grows by half again at least, so an input that grows a little every frame
/// does not reallocate every frame.
fn grown(old: u64, need: u64) -> u64 {
    need.max(old + old / 2)
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

    /// Builds the pipeline (one shader module), its bindings and uniform ring. Fails with
    /// [`GpuError::Unsupported`] on devices without storage buffers, or
    /// [`GpuError::Validation`] if the shader is rejected (which is what a device without
    /// fragment-stage storage writes gives: check [`Self::is_supported`] first).
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
        let bindings = PassBindings::new(
            device,
            "DepthFromBelowPass",
            wgpu::ShaderStages::VERTEX_FRAGMENT,
            &[StorageBinding {
                visibility: wgpu::ShaderStages::FRAGMENT,
                read_only: false,
            }],
        );
        let module = shader_module(
            device,
            "granular_depth.wgsl",
            terrain_shaders::GRANULAR_DEPTH,
        )?;
        let pipeline = scoped(device, "DepthFromBelowPass", || {
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("DepthFromBelowPass"),
                bind_group_layouts: &[Some(bindings.layout())],
                immediate_size: 0,
            });
            let attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Uint32];
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
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
            })
        })?;
        Ok(Self {
            pipeline,
            bindings,
            tile_side: device
                .limits()
                .max_texture_dimension_2d
                .clamp(1, MAX_TILE_SIDE),
            target: None,
            clear: None,
            vertices: UploadRing::new("DepthFromBelowPass vertices", wgpu::BufferUsages::VERTEX),
            triangles: Vec::new(),
        })
    }

    /// Frees the uniform slots and vertex uploads recorded so far: call it after the submit
    /// that carries them.
    pub fn recall(&mut self) {
        self.bindings.recall();
        self.vertices.recall();
    }

    /// A buffer for the depth of `area`: one `u32` per column, row-major, with the usages
    /// [`Self::encode`] and [`Self::read`] need (`STORAGE | COPY_DST | COPY_SRC`). A granular
    /// step renders into its scratch's [`super::GranularScratch::depth`] instead.
    pub fn create_output(device: &wgpu::Device, area: Rect) -> Result<wgpu::Buffer, GpuError> {
        let bytes = output_bytes(device, area)?;
        map_buffer(device, "DepthFromBelowPass output", area.size, bytes)
    }

    /// Makes the buffer of [`NO_OBJECT`]s the output is cleared from hold at least `bytes`.
    fn ensure_clear(&mut self, device: &wgpu::Device, bytes: u64) -> Result<(), GpuError> {
        let old = self.clear.as_ref().map_or(0, wgpu::Buffer::size);
        if old >= bytes {
            return Ok(());
        }
        // Whole u32s (so whole COPY_BUFFER_ALIGNMENT units, as mapping at creation needs).
        let size = (grown(old, bytes).min(device.limits().max_buffer_size.max(bytes)) / 4) * 4;
        let buffer = scoped(device, "DepthFromBelowPass clear", || {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("DepthFromBelowPass clear"),
                size,
                usage: wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: true,
            })
        })?;
        // NO_OBJECT is all ones.
        buffer
            .slice(..)
            .get_mapped_range_mut()?
            .slice(..)
            .fill(0xff);
        buffer.unmap();
        self.clear = Some(buffer);
        Ok(())
    }

    /// Makes the tile target cover `size` texels.
    fn ensure_target(&mut self, device: &wgpu::Device, size: UVec2) -> Result<(), GpuError> {
        let old = self
            .target
            .as_ref()
            .map_or(UVec2::ZERO, |(t, _)| UVec2::new(t.width(), t.height()));
        if old.cmpge(size).all() {
            return Ok(());
        }
        let side = |o: u32, n: u32| {
            if o >= n {
                o
            } else {
                (grown(u64::from(o), u64::from(n)) as u32)
                    .min(self.tile_side)
                    .max(n)
            }
        };
        let new = UVec2::new(side(old.x, size.x), side(old.y, size.y));
        let texture = scoped(device, "DepthFromBelowPass tile target", || {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some("DepthFromBelowPass tile target"),
                size: wgpu::Extent3d {
                    width: new.x,
                    height: new.y,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: TILE_FORMAT,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
                view_formats: &[],
            })
        })?;
        let view = texture.create_view(&Default::default());
        self.target = Some((texture, view));
        Ok(())
    }

    /// Records the depth from below of `objects` over `area` into `out` (at least
    /// `4 * area.size.x * area.size.y` bytes, usages `STORAGE | COPY_DST`; see
    /// [`Self::create_output`]): element `j * area.size.x + i` is column `area.min + (i, j)`,
    /// in units of the area's encoding (`floor((y - offset) / scale)` clamped to
    /// `0 ..= NO_OBJECT - 1`), or [`NO_OBJECT`] where no object covers it. The whole area is
    /// overwritten.
    ///
    /// The objects' world-space triangles are written into the pass's vertex buffer on every
    /// call (triangles with zero projected area, or wholly outside the area, are dropped on the
    /// CPU as the reference does). Whether the area lies inside the map is the caller's
    /// concern, as with the CPU reference's `_into` form: any non-empty area is rendered.
    ///
    /// Fails on an output buffer that is too small, an object that fails
    /// [`GranularObject::validate`] (non-finite transform, vertices beyond
    /// `MAX_COORDINATE_M`; reported as [`GpuError::Granular`]), more triangles than the
    /// device's largest buffer holds, or a wgpu validation error.
    pub fn encode(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        objects: &[GranularObject<'_>],
        area: &DepthArea,
        out: &wgpu::Buffer,
    ) -> Result<(), GpuError> {
        let rect = area.rect;
        let bytes = output_bytes(device, rect)?;
        if out.size() < bytes {
            return Err(CoreError::OutOfRange {
                what: "DepthFromBelowPass output buffer size in bytes",
                value: out.size() as f64,
                expected: "at least 4 bytes per column of the area",
            }
            .into());
        }
        world_triangles(objects, area, &mut self.triangles)?;
        let vertex_bytes = std::mem::size_of_val(self.triangles.as_slice()) as u64;
        if vertex_bytes > device.limits().max_buffer_size
            || self.triangles.len() > u32::MAX as usize
        {
            return Err(CoreError::OutOfRange {
                what: "DepthFromBelowPass vertex bytes (3 vertices of 16 bytes per triangle)",
                value: vertex_bytes as f64,
                expected: "within the device's max_buffer_size",
            }
            .into());
        }
        self.ensure_clear(device, bytes)?;
        if let Some(clear) = &self.clear {
            encoder.copy_buffer_to_buffer(clear, 0, out, 0, bytes);
        }
        if self.triangles.is_empty() {
            return Ok(());
        }
        let (vertex_buffer, vertex_offset) =
            self.vertices
                .push(device, queue, bytemuck::cast_slice(&self.triangles))?;
        let vertex_count = self.triangles.len() as u32;
        let tile_side = self.tile_side;
        self.ensure_target(device, rect.size.min(UVec2::splat(tile_side)))?;
        let Some((_, view)) = &self.target else {
            return Ok(());
        };
        for ty in (0..rect.size.y).step_by(tile_side as usize) {
            for tx in (0..rect.size.x).step_by(tile_side as usize) {
                let size = (rect.size - UVec2::new(tx, ty)).min(UVec2::splat(tile_side));
                let params = TileParams {
                    origin_f: [tx as f32, ty as f32],
                    size_f: [size.x as f32, size.y as f32],
                    origin: [tx, ty],
                    area_width: rect.size.x,
                    _pad: 0,
                };
                let (group, offset) = self.bindings.bind(device, queue, &params, &[out])?;
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("DepthFromBelowPass"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view,
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
                pass.set_bind_group(0, &group, &[offset]);
                pass.set_vertex_buffer(
                    0,
                    vertex_buffer.slice(vertex_offset..vertex_offset + vertex_bytes),
                );
                pass.draw(0..vertex_count, 0..1);
            }
        }
        Ok(())
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

    /// Convenience: allocates an output, encodes, submits, recalls and reads back; the GPU
    /// counterpart of [`terrain_core::granular::depth_from_below_into`] for tests and CPU-side
    /// users.
    pub fn run(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        objects: &[GranularObject<'_>],
        area: &DepthArea,
    ) -> Result<Grid<u32>, GpuError> {
        let out = Self::create_output(device, area.rect)?;
        let mut encoder = device.create_command_encoder(&Default::default());
        let recorded = self.encode(device, queue, &mut encoder, objects, area, &out);
        if recorded.is_ok() {
            queue.submit([encoder.finish()]);
            crate::device::trace::record("granular depth: submitted", 0);
        }
        self.recall();
        recorded?;
        Self::read(device, queue, &out, area.rect)
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

/// Every triangle of `objects` that may cover a column of `area`, as area-relative vertices.
fn world_triangles(
    objects: &[GranularObject<'_>],
    area: &DepthArea,
    out: &mut Vec<DepthVertex>,
) -> Result<(), GpuError> {
    let ts = f64::from(area.texel_size);
    let scale = f64::from(area.encoding.scale);
    let offset = f64::from(area.encoding.offset);
    let rect = area.rect;
    let (x0, y0) = (f64::from(rect.min.x), f64::from(rect.min.y));
    let (x1, y1) = (x0 + f64::from(rect.size.x), y0 + f64::from(rect.size.y));
    let max_depth = f64::from(NO_OBJECT - 1);
    out.clear();
    for object in objects {
        let verts = object.world_vertices()?;
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
    Ok(())
}
