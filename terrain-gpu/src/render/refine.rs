//! Refined geometry for a detail layer (Flower 2010, sec. 2.4.3, `--detail refine`): the coarse
//! cells around the camera split by the refinement patterns of eq. 2.2 (fig. 2.7) and displaced
//! by coarse + detail height. wgpu has no geometry or tessellation stage, so [`RefinePass`]
//! does the geometry shader's work in a compute shader (`refine.wgsl`): one thread per base
//! triangle picks `rho = t0 + 2 t1 + 4 t2` from its vertices' flags, appends its sub-triangles
//! to a vertex buffer and counts them into the indirect draw arguments. [`RefineRenderer`]
//! draws them with `draw_indirect`, shaded as the clipmap with eq. 3.4's composite normal.
//!
//! The CPU reference is [`terrain_lod::refine`]: same region, flags and patterns. A side is
//! split only when both its vertices are flagged, and the region's edge lies beyond the
//! refinement radius, so the refined mesh meets itself and the clipmap around it without cracks
//! by construction; the clipmap leaves the region to it ([`ClipmapRenderer::exclude`]).
//!
//! [`ClipmapRenderer::exclude`]: crate::ClipmapRenderer::exclude

use crate::device::compute::{buffer_entry, compute_pipeline, shader_module};
use crate::device::download::download_bytes;
use crate::device::scope::scoped;
use crate::device::small_readback::SmallReadback;
use crate::error::GpuError;
use crate::render::camera::{RenderView, ResolvedView};
use crate::render::clipmap::{
    ClipmapSurface, FrameUniform, SurfaceInfo, SurfacePipeline, TerrainStyle, VertexShape,
    atlas_detail_storage, check_view, check_wireframe, frame_uniform,
};
use crate::render::surface::{BoundBuffers, SurfaceKind, with_surface_weights};
use crate::render::target::TargetFormat;
use crate::resources::detail::{DetailInfo, DetailShading};
use crate::resources::materials::{GpuColorLayer, GpuMaterials, MaterialSlot};
use bytemuck::{Pod, Zeroable};
use glam::{IVec2, UVec2, Vec2, Vec3};
use terrain_core::WrapMode;
use terrain_lod::refine::{MAX_REFINE_HALF_CELLS, RefineView};

/// The uniform block of `refine.wgsl`, byte for byte.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable, Default)]
struct Params {
    half_cells: u32,
    capacity: u32,
    radius_m: f32,
    fade_start_m: f32,
}

/// Bytes of the counter block: count, overflow, two pads, then the four `draw_indirect`
/// arguments.
const STATE_BYTES: u64 = 32;
/// Where the draw arguments start in the counter block.
const ARGS_OFFSET: u64 = 16;
/// Bytes per refined vertex: x, z (texels from the camera's whole texel), height (m).
const VERTEX_BYTES: u64 = 12;
/// Bytes per refined triangle.
const TRIANGLE_BYTES: u64 = 3 * VERTEX_BYTES;
/// The most sub-triangles one base triangle splits into (`rho = 7`).
const MOST_PER_TRIANGLE: u64 = 9;

/// Everything one refined frame is made and drawn from.
#[derive(Debug, Clone, Copy)]
pub struct RefineDraw<'a> {
    /// The coarse heights with their detail layer: a coarse-map's
    /// ([`ClipmapSurface::Detail`]) or a streamed world's atlas
    /// ([`ClipmapSurface::AtlasDetail`]). Detail tiles without a slot are 0 m and are not
    /// refined. The fragments shade with the detail's gradient as its shading fades it (no
    /// parallax on displaced geometry): with the clipmap outside the region drawn through the
    /// same shading and no parallax steps, the normals fade alike on both sides of its edge.
    pub surface: ClipmapSurface<'a>,
    /// Vertices closer than this (metres, horizontally) to the camera may be refined. The
    /// detail displaces them fully up to half this distance from the eye and not at all from
    /// it on, smoothly in between, so the region's edge is the coarse surface.
    pub radius_m: f32,
    /// The camera: a [`crate::Camera`], an engine's [`crate::ViewMatrices`], or any
    /// [`RenderView`].
    pub camera: &'a dyn RenderView,
    /// Lighting and colours.
    pub style: &'a TerrainStyle,
    /// The render target's size in pixels.
    pub target_size: UVec2,
}

impl RefineDraw<'_> {
    /// Checks the parts agree (as the detail clipmap surface does) and returns the map's
    /// description, the refinement view and the texels the shaders may read from the camera.
    fn check(
        &self,
        target: Option<&TargetFormat>,
    ) -> Result<(SurfaceInfo, RefineView, u32, ResolvedView), GpuError> {
        let resolved = check_view(
            self.camera,
            target,
            self.target_size,
            "refine target size (pixels)",
        )?;
        self.detail_layer()?;
        let info = self.surface.check()?;
        let xz = Vec2::new(resolved.eye.x, resolved.eye.z);
        let view = RefineView::new(xz, info.texel_size, self.radius_m)?;
        // Vertices reach one texel past the region, the fragments' differences two more.
        let reach = view.half_cells() + 3;
        Ok((info, view, reach, resolved))
    }

    /// The frame uniform of this draw for `target`, its wrap offset covering the region.
    fn frame(
        &self,
        info: &SurfaceInfo,
        view: &ResolvedView,
        target: &TargetFormat,
        reach: u32,
    ) -> Result<FrameUniform, GpuError> {
        let mut uniform = frame_uniform(info, view, self.style, target, (0, 0), [0, 0])?;
        if info.wrap == WrapMode::Repeat {
            let lowest = IVec2::from(uniform.camera_texel)
                - IVec2::splat(reach as i32 + crate::render::surface::MATERIAL_REACH);
            uniform.wrap_offset = crate::device::compute::wrap_offset(lowest, info.size)?;
        }
        Ok(uniform)
    }

    /// The surface's detail tiles and shading; a surface without them is refused.
    fn detail_layer(&self) -> Result<(&crate::GpuDetailTiles, &DetailShading), GpuError> {
        self.surface.detail().ok_or(GpuError::Unsupported {
            what: "RefineDraw",
            reason: "the surface has no detail layer to refine: draw a ClipmapSurface::Detail \
                     or ClipmapSurface::AtlasDetail",
        })
    }

    fn detail_info(&self, uniform: &FrameUniform, reach: u32) -> Result<DetailInfo, GpuError> {
        let (detail, shading) = self.detail_layer()?;
        // No parallax on displaced geometry: the hook reads the gradient where it shades.
        let shading = DetailShading {
            parallax_steps: 0,
            max_reach_texels: 0.0,
            ..*shading
        };
        detail.info(IVec2::from(uniform.camera_texel), &shading, reach)
    }
}

/// The compute pass that refines the cells around the camera into a vertex buffer, with the
/// draw arguments of what it wrote. Build it once per device for the largest region it must
/// hold; one [`RefinePass::encode`] per submit (its uniforms are written at encode time).
#[derive(Debug)]
pub struct RefinePass {
    /// The pipelines of each surface drawn so far (a coarse-map's built with the pass).
    pipelines: Vec<(SurfaceKind, RefineCompute)>,
    frame: wgpu::Buffer,
    detail_info: wgpu::Buffer,
    params: wgpu::Buffer,
    output: wgpu::Buffer,
    state: wgpu::Buffer,
    capacity: u32,
    max_half_cells: u32,
    /// The surface buffers the bind group binds and the group.
    bound: Option<(BoundBuffers, wgpu::BindGroup)>,
    /// The view of the last encode.
    view: Option<RefineView>,
    /// Triangle counts on their way back without a wait ([`RefinePass::request_count`]).
    counts: SmallReadback,
}

/// The refinement's compute pipelines over one surface kind: a coarse-map's heights at 1 (and
/// its normals at 2, unread) or an atlas at 20 to 22, the detail layer at 3 to 5, the pass's
/// own buffers at 0 and 6 to 8.
#[derive(Debug)]
struct RefineCompute {
    layout: wgpu::BindGroupLayout,
    triangles: wgpu::ComputePipeline,
    finish: wgpu::ComputePipeline,
}

impl RefineCompute {
    fn new(device: &wgpu::Device, kind: SurfaceKind) -> Result<Self, GpuError> {
        let (label, source, surface): (_, _, &[u32]) = match kind {
            SurfaceKind::AtlasDetail => {
                ("refine atlas", terrain_shaders::REFINE_ATLAS, &[20, 21, 22])
            }
            _ => ("refine.wgsl", terrain_shaders::REFINE, &[1, 2]),
        };
        let module = shader_module(device, label, source)?;
        let uniform = wgpu::BufferBindingType::Uniform;
        let read = wgpu::BufferBindingType::Storage { read_only: true };
        let write = wgpu::BufferBindingType::Storage { read_only: false };
        let mut entries: Vec<_> = surface.iter().map(|&b| buffer_entry(b, read)).collect();
        entries.extend([
            buffer_entry(0, uniform),
            buffer_entry(3, uniform),
            buffer_entry(4, read),
            buffer_entry(5, read),
            buffer_entry(6, uniform),
            buffer_entry(7, write),
            buffer_entry(8, write),
        ]);
        let layout = scoped(device, "RefinePass", || {
            device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("RefinePass"),
                entries: &entries,
            })
        })?;
        let triangles = compute_pipeline(
            device,
            "refine triangles",
            &module,
            &layout,
            "refine_triangles",
        )?;
        let finish = compute_pipeline(device, "refine finish", &module, &layout, "refine_finish")?;
        Ok(Self {
            layout,
            triangles,
            finish,
        })
    }
}

/// Counts in flight at most: a frame asks for one, and it arrives a frame or two later.
const COUNT_RING: usize = 4;

impl RefinePass {
    /// Compiles the shader and makes room for regions of up to `max_half_cells` cells from the
    /// camera (the worst case: every base triangle split in nine). Fails for 0 or more than
    /// [`MAX_REFINE_HALF_CELLS`], or when the output exceeds the device's storage limit.
    pub fn new(device: &wgpu::Device, max_half_cells: u32) -> Result<Self, GpuError> {
        if !(1..=MAX_REFINE_HALF_CELLS).contains(&max_half_cells) {
            return Err(terrain_core::CoreError::OutOfRange {
                what: "refined region half side (cells)",
                value: f64::from(max_half_cells),
                expected: "1 to 256",
            }
            .into());
        }
        let side = 2 * u64::from(max_half_cells);
        let capacity = 2 * side * side * MOST_PER_TRIANGLE;
        let bytes = capacity * TRIANGLE_BYTES;
        let limits = device.limits();
        if bytes > limits.max_storage_buffer_binding_size || bytes > limits.max_buffer_size {
            return Err(GpuError::Unsupported {
                what: "RefinePass",
                reason: "the refined region's worst case (36 bytes per triangle, 9 per base \
                         triangle) exceeds the device's storage buffer limit: refine a smaller \
                         radius",
            });
        }
        let coarse = RefineCompute::new(device, SurfaceKind::Detail)?;
        let (frame, detail_info, params, output, state) = scoped(device, "RefinePass", || {
            let buffer = |label, size: u64, usage| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size,
                    usage,
                    mapped_at_creation: false,
                })
            };
            let uniform = wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST;
            (
                buffer(
                    "refine frame",
                    std::mem::size_of::<FrameUniform>() as u64,
                    uniform,
                ),
                buffer(
                    "refine detail",
                    std::mem::size_of::<DetailInfo>() as u64,
                    uniform,
                ),
                buffer(
                    "refine params",
                    std::mem::size_of::<Params>() as u64,
                    uniform,
                ),
                buffer(
                    "refine output",
                    bytes,
                    wgpu::BufferUsages::STORAGE
                        | wgpu::BufferUsages::VERTEX
                        | wgpu::BufferUsages::COPY_SRC,
                ),
                buffer(
                    "refine state",
                    STATE_BYTES,
                    wgpu::BufferUsages::STORAGE
                        | wgpu::BufferUsages::INDIRECT
                        | wgpu::BufferUsages::COPY_SRC
                        | wgpu::BufferUsages::COPY_DST,
                ),
            )
        })?;
        Ok(Self {
            pipelines: vec![(SurfaceKind::Detail, coarse)],
            frame,
            detail_info,
            params,
            output,
            state,
            capacity: capacity as u32,
            max_half_cells,
            bound: None,
            view: None,
            counts: SmallReadback::new(device, COUNT_RING, STATE_BYTES)?,
        })
    }

    /// Triangles the output holds.
    pub fn capacity(&self) -> u32 {
        self.capacity
    }

    /// The view of the last [`RefinePass::encode`]: its region and camera.
    pub fn view(&self) -> Option<&RefineView> {
        self.view.as_ref()
    }

    /// The texels (relative to the camera's whole texel, first and one-past-last vertex) the
    /// last encode refined: what the clipmap must leave out ([`crate::ClipmapRenderer::exclude`]).
    pub fn region(&self) -> Option<(IVec2, IVec2)> {
        self.view.map(|v| v.region())
    }

    /// Records the refinement of the region around `draw.camera` into `encoder`: clears the
    /// counter, splits every base triangle, writes the draw arguments. Checks everything
    /// before wgpu sees it; fails when the region is wider than this pass was built for.
    pub fn encode(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        draw: &RefineDraw<'_>,
    ) -> Result<RefineView, GpuError> {
        let (info, view, reach, resolved) = draw.check(None)?;
        if view.half_cells() > self.max_half_cells {
            return Err(GpuError::Unsupported {
                what: "RefinePass",
                reason: "the radius spans more cells than this pass was built for: build it \
                         with more half cells or refine a smaller radius",
            });
        }
        // The compute pass reads the frame's camera, encoding and wrap, not its target.
        let frame = draw.frame(&info, &resolved, &TargetFormat::CAPTURE, reach)?;
        let detail = draw.detail_info(&frame, reach)?;
        let params = Params {
            half_cells: view.half_cells(),
            capacity: self.capacity,
            radius_m: view.radius_m,
            fade_start_m: 0.5 * view.radius_m,
        };
        queue.write_buffer(&self.frame, 0, bytemuck::bytes_of(&frame));
        queue.write_buffer(&self.detail_info, 0, bytemuck::bytes_of(&detail));
        queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        let kind = draw.surface.kind();
        if !self.pipelines.iter().any(|(k, _)| *k == kind) {
            self.pipelines
                .push((kind, RefineCompute::new(device, kind)?));
        }
        let Some((_, compute)) = self.pipelines.iter().find(|(k, _)| *k == kind) else {
            return Err(GpuError::Unsupported {
                what: "RefinePass",
                reason: "no pipeline for the surface",
            });
        };
        let buffers = draw.surface.buffers();
        let group = match &self.bound {
            Some((b, group)) if *b == buffers => group.clone(),
            _ => {
                let own = [
                    (0, &self.frame),
                    (3, &self.detail_info),
                    (6, &self.params),
                    (7, &self.output),
                    (8, &self.state),
                ];
                let entries: Vec<_> = own
                    .into_iter()
                    .chain(buffers.iter().map(|(binding, b)| (*binding, b)))
                    .map(|(binding, b)| wgpu::BindGroupEntry {
                        binding,
                        resource: b.as_entire_binding(),
                    })
                    .collect();
                let group = scoped(device, "RefinePass", || {
                    device.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some("RefinePass"),
                        layout: &compute.layout,
                        entries: &entries,
                    })
                })?;
                self.bound = Some((buffers, group.clone()));
                group
            }
        };
        encoder.clear_buffer(&self.state, 0, None);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("RefinePass"),
            timestamp_writes: None,
        });
        pass.set_bind_group(0, &group, &[]);
        pass.set_pipeline(&compute.triangles);
        // At most 2 * 512^2 / 64 = 8192 groups: within every device's dispatch limit.
        pass.dispatch_workgroups(view.base_triangles().div_ceil(64), 1, 1);
        pass.set_pipeline(&compute.finish);
        pass.dispatch_workgroups(1, 1, 1);
        drop(pass);
        self.view = Some(view);
        Ok(view)
    }

    /// Records, after an encode in the same `encoder`, the copy of the triangle count it
    /// writes, to arrive without a wait ([`RefinePass::poll_count`]). `false` when
    /// `COUNT_RING` (4) counts are still on their way (this one is skipped).
    pub fn request_count(&mut self, encoder: &mut wgpu::CommandEncoder) -> Result<bool, GpuError> {
        Ok(self.counts.request(encoder, &self.state, 0)?.is_some())
    }

    /// The newest of the requested counts that have arrived since the last call, as
    /// [`RefinePass::read_count`] gives it, or `None`; never waits.
    pub fn poll_count(&mut self, device: &wgpu::Device) -> Result<Option<(u32, bool)>, GpuError> {
        let newest = self.counts.poll(device)?.pop();
        Ok(newest.map(|(_, bytes)| {
            let words: &[u32] = bytemuck::cast_slice(&bytes);
            (words[0].min(self.capacity), words[1] != 0)
        }))
    }

    /// Reads back how many triangles the last encode wrote (at most [`RefinePass::capacity`])
    /// and whether more were generated than the output holds. Blocking (a 32-byte download):
    /// for tests and tools; a frame uses [`RefinePass::request_count`].
    pub fn read_count(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<(u32, bool), GpuError> {
        let state = download_bytes(device, queue, &self.state, 0, STATE_BYTES)?;
        let words: &[u32] = bytemuck::cast_slice(&state);
        Ok((words[0].min(self.capacity), words[1] != 0))
    }

    /// Reads back what the last encode wrote: its triangles (in no particular order; each
    /// vertex x, z in texels from the camera's whole texel and the drawn height in metres)
    /// and whether more were generated than the output holds. Blocking: for tests and tools.
    pub fn read_triangles(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<(Vec<[Vec3; 3]>, bool), GpuError> {
        let (count, overflow) = self.read_count(device, queue)?;
        if count == 0 {
            return Ok((Vec::new(), overflow));
        }
        let bytes = download_bytes(
            device,
            queue,
            &self.output,
            0,
            u64::from(count) * TRIANGLE_BYTES,
        )?;
        let floats: &[f32] = bytemuck::cast_slice(&bytes);
        let tris = floats
            .chunks_exact(9)
            .map(|c| {
                [
                    Vec3::new(c[0], c[1], c[2]),
                    Vec3::new(c[3], c[4], c[5]),
                    Vec3::new(c[6], c[7], c[8]),
                ]
            })
            .collect();
        Ok((tris, overflow))
    }
}

/// Draws the triangles of a [`RefinePass`] into passes of one [`TargetFormat`]: build it once,
/// then per frame [`RefineRenderer::prepare`] and [`RefineRenderer::draw`] after the pass was
/// encoded for the same draw (with the clipmap, which leaves the region out).
#[derive(Debug)]
pub struct RefineRenderer {
    /// Over a coarse-map.
    pipeline: SurfacePipeline,
    /// Over an atlas: built on the first frame that draws one.
    atlas: Option<SurfacePipeline>,
    /// The engine's `surface_weights`, for the pipelines built later.
    user_surface: Option<String>,
    target: TargetFormat,
    uniform: wgpu::Buffer,
    detail_uniform: wgpu::Buffer,
    /// The surface buffers bound, whether over an atlas, and the group.
    bound: Option<(BoundBuffers, bool, wgpu::BindGroup)>,
    wireframe: bool,
    /// The materials of [`crate::SurfaceShading::Materials`].
    materials: MaterialSlot,
}

impl RefineRenderer {
    /// Builds the pipeline.
    pub fn new(device: &wgpu::Device, target: &TargetFormat) -> Result<Self, GpuError> {
        target.validate(device)?;
        let pipeline = refine_pipeline(device, target, None, SurfaceKind::Detail)?;
        let (uniform, detail_uniform) = scoped(device, "RefineRenderer", || {
            let buffer = |label, size| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size,
                    usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            };
            (
                buffer("refined frame", std::mem::size_of::<FrameUniform>() as u64),
                buffer("refined detail", std::mem::size_of::<DetailInfo>() as u64),
            )
        })?;
        Ok(Self {
            pipeline,
            atlas: None,
            user_surface: None,
            target: *target,
            uniform,
            detail_uniform,
            bound: None,
            wireframe: false,
            materials: MaterialSlot::default(),
        })
    }

    /// Binds the layers `terrain` binds (materials, colour and material layers, hole mask, a
    /// streamed world's paint and colour) from the next prepare: a refined renderer made after
    /// they were bound draws its cells as the terrain around them.
    pub fn adopt_layers(&mut self, terrain: &crate::TerrainRenderer) {
        self.materials.adopt(terrain.layers());
    }

    /// Shades [`crate::SurfaceShading::Materials`] frames with `materials` from the next
    /// prepare (until then, and without a call, with [`GpuMaterials::procedural`]).
    pub fn set_materials(&mut self, materials: &GpuMaterials) {
        self.materials.set(materials);
    }

    /// Draws `color` as the surface's albedo from the next prepare (`None`: no colour layer);
    /// its size must be the coarse-map's.
    pub fn set_color_layer(&mut self, color: Option<&GpuColorLayer>) {
        self.materials.set_color(color);
    }

    /// Blends `layer`'s painted weights over the surface's, as
    /// [`crate::ClipmapRenderer::set_material_layer`].
    pub fn set_material_layer(&mut self, layer: Option<&crate::GpuMaterialLayer>) {
        self.materials.set_paint(layer);
    }

    /// Leaves out the cells `mask` marks as holes, as [`crate::ClipmapRenderer::set_hole_mask`].
    pub fn set_hole_mask(&mut self, mask: Option<&crate::GpuHoleMask>) {
        self.materials.set_holes(mask);
    }

    /// Draws a streamed world's paint and colour, as
    /// [`crate::ClipmapRenderer::set_streamed_layers`].
    pub fn set_streamed_layers(
        &mut self,
        paint: Option<&crate::GpuOverlayAtlas>,
        color: Option<&crate::GpuOverlayAtlas>,
    ) {
        self.materials.set_streamed(paint, color);
    }

    /// Computes the material weights with an engine's `surface_weights` function, or the
    /// autoshader for `None` (as [`crate::ClipmapRenderer::set_surface_shader`]).
    pub fn set_surface_shader(
        &mut self,
        device: &wgpu::Device,
        wgsl_function: Option<&str>,
    ) -> Result<(), GpuError> {
        self.pipeline = refine_pipeline(device, &self.target, wgsl_function, SurfaceKind::Detail)
            .map_err(GpuError::user_shader)?;
        self.atlas = None;
        self.user_surface = wgsl_function.map(str::to_owned);
        self.bound = None;
        Ok(())
    }

    /// Draws triangle edges as lines from the next draw; fails without
    /// [`wgpu::Features::POLYGON_MODE_LINE`].
    pub fn set_wireframe(&mut self, on: bool) -> Result<(), GpuError> {
        check_wireframe(&self.pipeline, on, "RefineRenderer wireframe")?;
        self.wireframe = on;
        Ok(())
    }

    /// Writes the uniforms of `draw`, which `refine` was last encoded for (the refined
    /// vertices are relative to that camera's whole texel: another camera is refused).
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        draw: &RefineDraw<'_>,
        refine: &RefinePass,
    ) -> Result<(), GpuError> {
        let (info, view, reach, resolved) = draw.check(Some(&self.target))?;
        if refine.view() != Some(&view) {
            return Err(GpuError::Unsupported {
                what: "RefineRenderer",
                reason: "the refine pass was last encoded for another camera or radius",
            });
        }
        let mut frame = draw.frame(&info, &resolved, &self.target, reach)?;
        let (shading, new_shading) = self.materials.get(device, queue, info.size)?;
        frame.set_layers(&shading);
        let detail = draw.detail_info(&frame, reach)?;
        queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&frame));
        queue.write_buffer(&self.detail_uniform, 0, bytemuck::bytes_of(&detail));
        let atlas = draw.surface.kind() == SurfaceKind::AtlasDetail;
        if atlas && self.atlas.is_none() {
            let user = self.user_surface.as_deref();
            let kind = SurfaceKind::AtlasDetail;
            self.atlas = Some(refine_pipeline(device, &self.target, user, kind)?);
        }
        let buffers = draw.surface.buffers();
        if new_shading || self.bound.as_ref().is_none_or(|(b, _, _)| *b != buffers) {
            // The vertices carry their heights; the fragments read the surface's (the material
            // shading's curvature).
            let group = self.pipeline_for(atlas).bind_group(
                device,
                "RefineRenderer",
                &self.uniform,
                &buffers,
                &[(3, &self.detail_uniform)],
                &shading,
            )?;
            self.bound = Some((buffers, atlas, group));
        }
        Ok(())
    }

    /// Records the draw of `refine`'s triangles (as many as its last encode wrote) into `pass`.
    /// Draws nothing before the first prepare.
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>, refine: &RefinePass) {
        let Some((_, atlas, group)) = &self.bound else {
            return;
        };
        pass.set_pipeline(self.pipeline_for(*atlas).pick(self.wireframe));
        pass.set_bind_group(0, group, &[]);
        pass.set_vertex_buffer(0, refine.output.slice(..));
        pass.draw_indirect(&refine.state, ARGS_OFFSET);
    }

    /// The atlas pipeline when `atlas` (and built), else the coarse-map's.
    fn pipeline_for(&self, atlas: bool) -> &SurfacePipeline {
        match (&self.atlas, atlas) {
            (Some(p), true) => p,
            _ => &self.pipeline,
        }
    }
}

/// The refined geometry's pipeline, with an engine's `surface_weights` (`user`) or the
/// built-in one.
fn refine_pipeline(
    device: &wgpu::Device,
    target: &TargetFormat,
    user: Option<&str>,
    kind: SurfaceKind,
) -> Result<SurfacePipeline, GpuError> {
    const ATTRS: [wgpu::VertexAttribute; 1] = wgpu::vertex_attr_array![0 => Float32x3];
    let fragment = wgpu::ShaderStages::FRAGMENT;
    let (label, source, storage) = match kind {
        SurfaceKind::AtlasDetail => (
            "refine atlas",
            terrain_shaders::REFINE_ATLAS,
            atlas_detail_storage().to_vec(),
        ),
        _ => (
            "refine.wgsl",
            terrain_shaders::REFINE,
            vec![(fragment, 1), (fragment, 2), (fragment, 4), (fragment, 5)],
        ),
    };
    SurfacePipeline::new(
        device,
        target,
        label,
        &with_surface_weights(source, user),
        &storage,
        &[(wgpu::ShaderStages::FRAGMENT, 3)],
        &VertexShape {
            entry: "vs_refined",
            vertex_stride: VERTEX_BYTES,
            vertex_attrs: &ATTRS,
            instance_stride: 0,
            instance_attrs: &[],
            extra_uniforms: &[],
        },
    )
}
