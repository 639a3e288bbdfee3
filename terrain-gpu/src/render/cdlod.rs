//! `CdlodRenderer`: draws a CDLOD selection (terrain-lod's `CdlodFrame`) into the caller's render
//! pass: one shared quadrant mesh, instanced per drawn quadrant, morphed per vertex in the vertex
//! shader (`cdlod.wgsl`) and shaded exactly as the clipmap (same frame uniform, surface and
//! fragment shader), so the two LOD schemes compare on equal terms. The surface is a
//! coarse-map, a coarse-map with a detail layer (shaded as the clipmap shades it) or a
//! streamed world's tile atlas.

use crate::device::scope::{buffer_init, scoped};
use crate::error::GpuError;
use crate::render::camera::RenderView;
use crate::render::clipmap::{
    ClipmapSurface, SurfaceKind, SurfacePipeline, TerrainStyle, VertexShape, check_view,
    check_wireframe, frame_uniform,
};
use crate::render::surface::{BoundBuffers, DetailUniform, fragment_reach, with_surface_weights};
use crate::render::target::TargetFormat;
use crate::resources::materials::{GpuColorLayer, GpuMaterials, MaterialSlot};
use glam::UVec2;
use terrain_core::WrapMode;
use terrain_lod::cdlod::MAX_CDLOD_LODS;
use terrain_lod::{CdlodFrame, CdlodInstance, CdlodMesh};

/// The `CdlodLods` uniform of `cdlod.wgsl`: per LOD (morph start, morph end, 0, 0) in metres,
/// end < 0 for no morph.
type LodsUniform = [[f32; 4]; MAX_CDLOD_LODS as usize];

/// Instances the renderer holds room for at first; a frame with more grows the buffer once.
const START_INSTANCES: u64 = 4096;

/// Draws CDLOD frames of one quadrant mesh into passes of one [`TargetFormat`]: build it once,
/// then per frame [`CdlodRenderer::prepare`] and [`CdlodRenderer::draw`] (after
/// [`crate::SkyPass`], as the clipmap).
#[derive(Debug)]
pub struct CdlodRenderer {
    /// A pipeline per surface kind drawn so far (the coarse-map's built first).
    pipelines: Vec<(SurfaceKind, SurfacePipeline)>,
    /// The surface kind of the bound group.
    kind: SurfaceKind,
    /// The detail surface's uniform.
    detail_uniform: DetailUniform,
    target: TargetFormat,
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    index_count: u32,
    uniform: wgpu::Buffer,
    lods: wgpu::Buffer,
    instances: wgpu::Buffer,
    instance_count: u32,
    bound: Option<(BoundBuffers, wgpu::BindGroup)>,
    wireframe: bool,
    /// The materials of [`crate::SurfaceShading::Materials`].
    materials: MaterialSlot,
    /// An engine's `surface_weights` ([`CdlodRenderer::set_surface_shader`]).
    user_surface: Option<String>,
    /// Texels another renderer draws (see [`CdlodRenderer::exclude`]).
    excluded: Option<(glam::IVec2, glam::IVec2)>,
}

/// Everything one CDLOD frame is drawn from.
#[derive(Debug, Clone, Copy)]
pub struct CdlodDraw<'a> {
    /// The surface: [`ClipmapSurface::Coarse`], [`ClipmapSurface::Detail`] or
    /// [`ClipmapSurface::Atlas`] (a granular surface is [`GpuError::Unsupported`]).
    pub surface: ClipmapSurface<'a>,
    /// The selection (instances and range table) of this frame.
    pub frame: &'a CdlodFrame,
    /// The camera the selection was made for: a [`crate::Camera`], an engine's
    /// [`crate::ViewMatrices`], or any [`RenderView`].
    pub camera: &'a dyn RenderView,
    /// Lighting and colours.
    pub style: &'a TerrainStyle,
    /// The render target's size in pixels.
    pub target_size: UVec2,
}

impl CdlodRenderer {
    /// The layers it binds (`TerrainRenderer::adopt_layers` copies them).
    pub(crate) fn layers(&self) -> &MaterialSlot {
        &self.materials
    }

    /// The layers it binds, to change.
    pub(crate) fn layers_mut(&mut self) -> &mut MaterialSlot {
        &mut self.materials
    }
    /// Uploads `mesh` (the quadrant mesh of the tree's grid size) and builds the pipeline.
    pub fn new(
        device: &wgpu::Device,
        target: &TargetFormat,
        mesh: &CdlodMesh,
    ) -> Result<Self, GpuError> {
        target.validate(device)?;
        let pipeline = surface_pipeline(device, target, SurfaceKind::Coarse, None)?;
        let vertices = buffer_init(
            device,
            "cdlod vertices",
            bytemuck::cast_slice(&mesh.vertices),
            wgpu::BufferUsages::VERTEX,
        )?;
        let indices = buffer_init(
            device,
            "cdlod indices",
            bytemuck::cast_slice(&mesh.indices),
            wgpu::BufferUsages::INDEX,
        )?;
        let (uniform, lods, instances) = scoped(device, "CdlodRenderer", || {
            let buffer = |label, size, usage| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size,
                    usage: usage | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            };
            (
                buffer(
                    "cdlod frame",
                    std::mem::size_of::<crate::render::clipmap::FrameUniform>() as u64,
                    wgpu::BufferUsages::UNIFORM,
                ),
                buffer(
                    "cdlod lods",
                    std::mem::size_of::<LodsUniform>() as u64,
                    wgpu::BufferUsages::UNIFORM,
                ),
                instance_buffer(device, START_INSTANCES),
            )
        })?;
        Ok(Self {
            pipelines: vec![(SurfaceKind::Coarse, pipeline)],
            kind: SurfaceKind::Coarse,
            detail_uniform: DetailUniform::new(device, "cdlod detail"),
            target: *target,
            vertices,
            indices,
            index_count: mesh.indices.len() as u32,
            uniform,
            lods,
            instances,
            instance_count: 0,
            bound: None,
            wireframe: false,
            materials: MaterialSlot::default(),
            user_surface: None,
            excluded: None,
        })
    }

    /// Leaves the texels `region` (first and one-past-last vertex, relative to the camera's
    /// whole texel, as [`crate::RefinePass::region`] gives them) to another renderer from the
    /// next [`CdlodRenderer::prepare`] on: their fragments are discarded. `None` draws
    /// everything again. Every node the region meets must be of LOD 0 with a vertex on every
    /// texel, and the region must end before LOD 0 starts to morph (so its edge vertices are
    /// the stored heights the refined mesh meets); prepare refuses it otherwise.
    pub fn exclude(&mut self, region: Option<(glam::IVec2, glam::IVec2)>) {
        self.excluded = region;
    }

    /// The region the next prepare leaves out (what [`Self::exclude`] set last).
    pub(crate) fn excluded(&self) -> Option<(glam::IVec2, glam::IVec2)> {
        self.excluded
    }

    /// Shades [`crate::SurfaceShading::Materials`] frames with `materials` from the next
    /// prepare (until then, and without a call, with [`GpuMaterials::procedural`]).
    pub fn set_materials(&mut self, materials: &GpuMaterials) {
        self.materials.set(materials);
    }

    /// Draws `color` as the surface's albedo from the next prepare (`None`: no colour layer).
    /// Its size must be the drawn surface's, else the prepare fails.
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
        // The coarse pipeline now, so a function that does not compile fails here; the other
        // surfaces' on their first frame.
        let coarse = surface_pipeline(device, &self.target, SurfaceKind::Coarse, wgsl_function)
            .map_err(GpuError::user_shader)?;
        self.pipelines = vec![(SurfaceKind::Coarse, coarse)];
        self.user_surface = wgsl_function.map(str::to_owned);
        self.kind = SurfaceKind::Coarse;
        self.bound = None;
        Ok(())
    }

    /// Draws triangle edges as lines from the next draw; fails without
    /// [`wgpu::Features::POLYGON_MODE_LINE`].
    pub fn set_wireframe(&mut self, on: bool) -> Result<(), GpuError> {
        for (_, pipeline) in &self.pipelines {
            check_wireframe(pipeline, on, "CdlodRenderer wireframe")?;
        }
        self.wireframe = on;
        Ok(())
    }

    /// Writes the uniforms and instances of one frame. Checks everything before wgpu sees it.
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        draw: &CdlodDraw<'_>,
    ) -> Result<(), GpuError> {
        let view = check_view(
            draw.camera,
            Some(&self.target),
            draw.target_size,
            "cdlod target size (pixels)",
        )?;
        let surface = draw.surface;
        let kind = surface.kind();
        if kind == SurfaceKind::Granular {
            return Err(GpuError::Unsupported {
                what: "CdlodRenderer",
                reason: "the surface must be a coarse-map or a tile atlas, with or without detail",
            });
        }
        let info = surface.check()?;
        if !self.pipelines.iter().any(|(k, _)| *k == kind) {
            let pipeline =
                surface_pipeline(device, &self.target, kind, self.user_surface.as_deref())?;
            self.pipelines.push((kind, pipeline));
        }
        let frame = draw.frame;
        if frame.ranges.morph.len() > MAX_CDLOD_LODS as usize {
            return Err(GpuError::Unsupported {
                what: "CdlodRenderer",
                reason: "the frame's range table has more than 16 LODs",
            });
        }
        let wrap_offset = match info.wrap {
            WrapMode::Repeat => {
                // Every texel read: instance origins less the bilinear and normal reach, and
                // a detail surface's parallax reach.
                let reach = 2 + fragment_reach(&surface);
                let min = frame
                    .instances
                    .iter()
                    .map(|i| glam::IVec2::from(i.origin) - reach)
                    .fold(glam::IVec2::ZERO, |a, b| a.min(b));
                crate::device::compute::wrap_offset(min, info.size)?
            }
            WrapMode::Clamp => [0, 0],
        };
        let mut uniform =
            frame_uniform(&info, &view, draw.style, &self.target, (0, 0), wrap_offset)?;
        if let Some((lo, hi)) = self.excluded {
            check_exclusion(frame, &view, info.texel_size, (lo, hi))?;
            uniform.excluded = crate::render::frame::exclusion_rect(lo, hi)?;
        }
        let (shading, new_shading) = self.materials.get(device, queue, info.size)?;
        uniform.set_layers(&shading);
        let mut lods: LodsUniform = [[0.0, -1.0, 0.0, 0.0]; MAX_CDLOD_LODS as usize];
        for (slot, &(start, end)) in lods.iter_mut().zip(&frame.ranges.morph) {
            if end.is_finite() && start.is_finite() && end > start {
                *slot = [start, end, 0.0, 0.0];
            }
        }
        let needed = frame.instances.len() as u64;
        let capacity = self.instances.size() / std::mem::size_of::<CdlodInstance>() as u64;
        if needed > capacity {
            // A one-off growth to the next power of two; steady frames allocate nothing.
            self.instances = scoped(device, "CdlodRenderer", || {
                instance_buffer(device, needed.next_power_of_two())
            })?;
        }
        if !frame.instances.is_empty() {
            queue.write_buffer(&self.instances, 0, bytemuck::cast_slice(&frame.instances));
        }
        self.instance_count = frame.instances.len() as u32;
        queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&uniform));
        queue.write_buffer(&self.lods, 0, bytemuck::cast_slice(&lods));
        let camera_texel = glam::IVec2::from(uniform.camera_texel);
        let buffers =
            self.detail_uniform
                .surface_buffers(queue, &surface, info.texel_size, camera_texel)?;
        if new_shading
            || self.kind != kind
            || self.bound.as_ref().is_none_or(|(b, _)| *b != buffers)
        {
            let group = self.pipeline(kind).bind_group(
                device,
                "CdlodRenderer",
                &self.uniform,
                &buffers,
                &[(LODS_BINDING, &self.lods)],
                &shading,
            )?;
            self.bound = Some((buffers, group));
            self.kind = kind;
        }
        Ok(())
    }

    /// The pipeline of a surface kind prepared before (the coarse-map's otherwise).
    fn pipeline(&self, kind: SurfaceKind) -> &SurfacePipeline {
        let found = self.pipelines.iter().find(|(k, _)| *k == kind);
        &found.unwrap_or(&self.pipelines[0]).1
    }

    /// Records the prepared frame into `pass`. Draws nothing before the first prepare.
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>) {
        let Some((_, group)) = &self.bound else {
            return;
        };
        if self.instance_count == 0 {
            return;
        }
        pass.set_pipeline(self.pipeline(self.kind).pick(self.wireframe));
        pass.set_bind_group(0, group, &[]);
        pass.set_vertex_buffer(0, self.vertices.slice(..));
        pass.set_vertex_buffer(1, self.instances.slice(..));
        pass.set_index_buffer(self.indices.slice(..), wgpu::IndexFormat::Uint32);
        pass.draw_indexed(0..self.index_count, 0, 0..self.instance_count);
    }
}

/// Fails unless every node of `frame` that meets the texels `lo .. hi` (relative to the
/// camera's whole texel) is of LOD 0 with a vertex on every texel, and every point of their
/// edge lies nearer the camera (at any height of those nodes) than where LOD 0 starts to
/// morph.
fn check_exclusion(
    frame: &CdlodFrame,
    view: &crate::render::camera::ResolvedView,
    texel_size: f32,
    (lo, hi): (glam::IVec2, glam::IVec2),
) -> Result<(), GpuError> {
    let refuse = GpuError::CannotExclude {
        what: "CdlodRenderer::exclude",
        reason: "the excluded region reaches beyond LOD 0's unmorphed range (or LOD 0 has no \
                 vertex on every texel): refine a smaller radius or use a larger finest range",
    };
    let eye = glam::Vec2::new(view.eye.x, view.eye.z) / texel_size;
    let base = eye.floor().as_ivec2();
    let (lo, hi) = (base.saturating_add(lo), base.saturating_add(hi));
    let morph_start = frame.ranges.morph.first().map_or(f32::INFINITY, |m| m.0);
    let full = frame.instances.iter().all(|i| i.lod != 0 || i.step == 1);
    // The edge's farthest point horizontally (texels) from the eye.
    let far = (lo.as_vec2() - eye).abs().max((hi.as_vec2() - eye).abs()) * texel_size;
    for node in &frame.nodes {
        let end = node.origin + node.size as i32;
        if node.origin.cmpgt(hi).any() || end.cmplt(lo).any() {
            continue;
        }
        let dy = (view.eye.y - node.bounds.min)
            .abs()
            .max((node.bounds.max - view.eye.y).abs());
        if node.lod != 0 || !full || far.length_squared() + dy * dy >= morph_start * morph_start {
            return Err(refuse);
        }
    }
    Ok(())
}

/// The binding of the LOD uniform (`cdlod.wgsl`), after every surface's bindings.
const LODS_BINDING: u32 = 6;

/// The CDLOD pipeline over a surface of `kind` (not granular), with an engine's
/// `surface_weights` (`user`) or the built-in one.
fn surface_pipeline(
    device: &wgpu::Device,
    target: &TargetFormat,
    kind: SurfaceKind,
    user: Option<&str>,
) -> Result<SurfacePipeline, GpuError> {
    const ATTRS: [wgpu::VertexAttribute; 3] =
        wgpu::vertex_attr_array![1 => Sint32x2, 2 => Uint32, 3 => Uint32];
    let fragment = wgpu::ShaderStages::FRAGMENT;
    let both = wgpu::ShaderStages::VERTEX_FRAGMENT;
    let (label, source, storage, uniforms) = match kind {
        SurfaceKind::Atlas => (
            "cdlod atlas",
            terrain_shaders::CDLOD_ATLAS,
            vec![(both, 1), (both, 2), (both, 3)],
            vec![],
        ),
        SurfaceKind::AtlasDetail => (
            "cdlod atlas detail",
            terrain_shaders::CDLOD_ATLAS_DETAIL,
            crate::render::clipmap::atlas_detail_storage().to_vec(),
            vec![(fragment, 3)],
        ),
        SurfaceKind::Detail => (
            "cdlod detail",
            terrain_shaders::CDLOD_DETAIL,
            vec![(both, 1), (fragment, 2), (fragment, 4), (fragment, 5)],
            vec![(fragment, 3)],
        ),
        SurfaceKind::Coarse | SurfaceKind::Granular => (
            "cdlod.wgsl",
            terrain_shaders::CDLOD,
            vec![(both, 1), (fragment, 2)],
            vec![],
        ),
    };
    SurfacePipeline::new(
        device,
        target,
        label,
        &with_surface_weights(source, user),
        &storage,
        &uniforms,
        &VertexShape {
            entry: "vs_cdlod",
            vertex_stride: std::mem::size_of::<[f32; 2]>() as u64,
            vertex_attrs: &crate::render::clipmap::GRID_ATTRS,
            instance_stride: std::mem::size_of::<CdlodInstance>() as u64,
            instance_attrs: &ATTRS,
            extra_uniforms: &[LODS_BINDING],
        },
    )
}

fn instance_buffer(device: &wgpu::Device, count: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("cdlod instances"),
        size: count.max(1) * std::mem::size_of::<CdlodInstance>() as u64,
        usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}
