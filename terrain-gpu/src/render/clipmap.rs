//! `ClipmapRenderer`: draws a geometry clipmap (terrain-lod's shared mesh, instanced per part)
//! displaced by the coarse-map with wrap addressing and lit with the derivative normals, drawn
//! into the caller's render pass. The surface may also be a granular map or a tile atlas
//! ([`ClipmapSurface`]).

use crate::device::compute::shader_module;
use crate::device::scope::{buffer_init, scoped};
use crate::error::GpuError;
use crate::render::camera::{RenderView, ResolvedView};
pub use crate::render::surface::ClipmapSurface;
pub(crate) use crate::render::surface::{
    ATLAS_BESIDE_DETAIL, BoundBuffers, SurfaceInfo, SurfaceKind,
};
use crate::render::surface::{DetailUniform, fragment_reach, with_surface_weights};
use crate::render::target::TargetFormat;
use crate::resources::materials::{
    self, GpuColorLayer, GpuMaterials, MaterialSlot, MaterialStyle, ShadingBindings, SurfaceShading,
};
use glam::{IVec2, UVec2, Vec2, Vec3};
use terrain_core::WrapMode;
use terrain_lod::{
    ClipmapFrame, ClipmapInstance, ClipmapLayout, ClipmapVertex, MAX_DRAWS_PER_LEVEL, MeshPart,
};

pub(crate) use crate::render::frame::{FrameUniform, frame_uniform};

/// Lighting and colouring of the terrain.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct TerrainStyle {
    /// Direction towards the sun.
    pub light_dir: Vec3,
    /// Heights (metres) the colour ramp spans, low to high.
    pub ramp: (f32, f32),
    /// Colour the terrain fades to with distance.
    pub fog_color: Vec3,
    /// Fog density per metre (0: none).
    pub fog_density: f32,
    /// Draw the map once, as an island: what lies outside its texels (the repeats of a
    /// toroidal map, the extended edges of a clamped one) is not drawn, so the sky shows
    /// there. For views that frame a whole map; off by default.
    pub hide_outside_map: bool,
    /// The height ramp, or the materials ([`crate::GpuMaterials`]) weighted by the autoshader.
    #[cfg_attr(feature = "serde", serde(default))]
    pub shading: SurfaceShading,
    /// How the materials are laid on the surface (with [`SurfaceShading::Materials`]).
    #[cfg_attr(feature = "serde", serde(default))]
    pub materials: MaterialStyle,
}

impl Default for TerrainStyle {
    fn default() -> Self {
        Self {
            light_dir: Vec3::new(-0.5, 0.8, -0.35),
            ramp: (0.0, 12.0),
            fog_color: Vec3::new(0.74, 0.82, 0.90),
            fog_density: 0.0,
            hide_outside_map: false,
            shading: SurfaceShading::Ramp,
            materials: MaterialStyle::default(),
        }
    }
}

/// Draws a placed [`ClipmapFrame`] into the caller's render pass: build it once for the pass's
/// formats, then per frame [`ClipmapRenderer::prepare`] (writes the frame's uniforms and
/// instances) and [`ClipmapRenderer::draw`] (records the draws), after [`crate::SkyPass`].
///
/// Everything is made in `new`: the pipeline, the shared mesh, the uniform buffer and an
/// instance buffer large enough for any frame of its layout. The bind group over a map and its
/// normals is made on the first frame that draws them. One renderer draws one view per submit
/// (its uniforms are rewritten by the next `prepare`); use one renderer per view.
///
/// On a device with [`wgpu::Features::POLYGON_MODE_LINE`], `new` also builds a wireframe
/// pipeline per surface kind (same bindings, triangle edges as lines), drawn instead of the
/// filled one after [`ClipmapRenderer::set_wireframe`]; without the feature nothing extra is
/// made and wireframe is refused.
#[derive(Debug)]
pub struct ClipmapRenderer {
    coarse: SurfacePipeline,
    granular: SurfacePipeline,
    atlas: SurfacePipeline,
    detail: SurfacePipeline,
    /// Built on the first frame over an atlas with detail tiles (few renderers draw one, and
    /// its parallax shader is the slowest to compile).
    atlas_detail: Option<SurfacePipeline>,
    /// The engine's `surface_weights` ([`ClipmapRenderer::set_surface_shader`]), for the
    /// pipelines built later.
    user_surface: Option<String>,
    target: TargetFormat,
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    uniform: wgpu::Buffer,
    /// The detail surface's `DetailInfo` (binding 3 of its pipeline).
    detail_uniform: DetailUniform,
    instances: wgpu::Buffer,
    parts: Vec<MeshPart>,
    n: u32,
    levels: u32,
    /// The bind group of the last surface drawn, with the buffers it binds and its kind.
    bound: Option<(BoundBuffers, SurfaceKind, wgpu::BindGroup)>,
    /// Draws of the prepared frame: (part index, first instance, instance count).
    runs: Vec<(usize, u32, u32)>,
    /// The materials of [`SurfaceShading::Materials`].
    materials: MaterialSlot,
    /// Draw the wireframe pipelines (only when they exist).
    wireframe: bool,
    /// Texels another renderer draws (see [`ClipmapRenderer::exclude`]).
    excluded: Option<(IVec2, IVec2)>,
}

impl ClipmapRenderer {
    /// The layers it binds (`TerrainRenderer::adopt_layers` copies them).
    pub(crate) fn layers(&self) -> &MaterialSlot {
        &self.materials
    }

    /// The layers it binds, to change.
    pub(crate) fn layers_mut(&mut self) -> &mut MaterialSlot {
        &mut self.materials
    }
    /// Uploads the shared mesh of `layout` and builds the pipeline for passes of `target`.
    pub fn new(
        device: &wgpu::Device,
        target: &TargetFormat,
        layout: &ClipmapLayout,
    ) -> Result<Self, GpuError> {
        target.validate(device)?;
        let mesh = layout.mesh();
        // Every instance a placed frame of this layout can hold.
        let max_instances = u64::from(layout.levels()) * MAX_DRAWS_PER_LEVEL as u64;
        let [coarse, granular, atlas, detail] = clipmap_pipelines(device, target, None)?;
        let vertices = buffer_init(
            device,
            "clipmap vertices",
            bytemuck::cast_slice(&mesh.vertices),
            wgpu::BufferUsages::VERTEX,
        )?;
        let indices = buffer_init(
            device,
            "clipmap indices",
            bytemuck::cast_slice(&mesh.indices),
            wgpu::BufferUsages::INDEX,
        )?;
        scoped(device, "ClipmapRenderer", || {
            let uniform = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("clipmap frame"),
                size: std::mem::size_of::<FrameUniform>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let detail_uniform = DetailUniform::new(device, "clipmap detail");
            let instances = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("clipmap instances"),
                size: max_instances * std::mem::size_of::<ClipmapInstance>() as u64,
                usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            Self {
                coarse,
                granular,
                atlas,
                detail,
                atlas_detail: None,
                user_surface: None,
                target: *target,
                vertices,
                indices,
                uniform,
                detail_uniform,
                instances,
                parts: mesh.parts.clone(),
                n: layout.n(),
                levels: layout.levels(),
                bound: None,
                runs: Vec::new(),
                materials: MaterialSlot::default(),
                wireframe: false,
                excluded: None,
            }
        })
    }

    /// Whether this renderer can draw wireframe: its device has
    /// [`wgpu::Features::POLYGON_MODE_LINE`].
    pub fn has_wireframe(&self) -> bool {
        self.coarse.wireframe.is_some()
    }

    /// Shades [`SurfaceShading::Materials`] frames with `materials` from the next prepare
    /// (until then, and without a call, with [`GpuMaterials::procedural`]).
    pub fn set_materials(&mut self, materials: &GpuMaterials) {
        self.materials.set(materials);
    }

    /// Draws `color` as the surface's albedo from the next prepare (`None`: no colour layer).
    /// Its size must be the drawn surface's, else the prepare fails.
    pub fn set_color_layer(&mut self, color: Option<&GpuColorLayer>) {
        self.materials.set_color(color);
    }

    /// Blends `layer`'s painted weights over the surface's ([`crate::GpuMaterialLayer`]) in
    /// [`SurfaceShading::Materials`] frames from the next prepare (`None`: none). Its size must
    /// be the drawn surface's, else the prepare fails.
    pub fn set_material_layer(&mut self, layer: Option<&crate::GpuMaterialLayer>) {
        self.materials.set_paint(layer);
    }

    /// Leaves out the cells `mask` marks as holes ([`crate::GpuHoleMask`],
    /// `terrain_core::holes`) from the next prepare (`None`: none), in every shading: their
    /// fragments are discarded, so what lies behind shows through. Its size must be the drawn
    /// surface's, else the prepare fails.
    pub fn set_hole_mask(&mut self, mask: Option<&crate::GpuHoleMask>) {
        self.materials.set_holes(mask);
    }

    /// Draws a streamed world's paint and colour, held around the camera by terrain-cache's
    /// VRAM pool (`VramPool::update_overlay`) in [`crate::GpuOverlayAtlas`]es, from the next
    /// prepare (`None`: not streamed): far ground's look at the level its heights are drawn
    /// from. They replace the material and colour layers; their world must be the drawn
    /// surface's size, else the prepare fails.
    pub fn set_streamed_layers(
        &mut self,
        paint: Option<&crate::GpuOverlayAtlas>,
        color: Option<&crate::GpuOverlayAtlas>,
    ) {
        self.materials.set_streamed(paint, color);
    }

    /// Computes the material weights with `wgsl_function`, an engine's
    /// `fn surface_weights(p: SurfacePoint) -> vec4<f32>` (see terrain-shaders'
    /// `surface_weights.wgsl` for `SurfacePoint`), or with the autoshader again for `None`.
    /// The pipelines are rebuilt now; a function that does not compile is
    /// [`GpuError::UserShader`] and leaves the renderer as it was.
    pub fn set_surface_shader(
        &mut self,
        device: &wgpu::Device,
        wgsl_function: Option<&str>,
    ) -> Result<(), GpuError> {
        let [coarse, granular, atlas, detail] =
            clipmap_pipelines(device, &self.target, wgsl_function)
                .map_err(GpuError::user_shader)?;
        (self.coarse, self.granular, self.atlas, self.detail) = (coarse, granular, atlas, detail);
        self.atlas_detail = None;
        self.user_surface = wgsl_function.map(str::to_owned);
        self.bound = None;
        Ok(())
    }

    /// Draws triangle edges as lines (`true`) or filled triangles (`false`, the default) from
    /// the next [`ClipmapRenderer::draw`]. Turning it on fails without
    /// [`ClipmapRenderer::has_wireframe`].
    pub fn set_wireframe(&mut self, on: bool) -> Result<(), GpuError> {
        check_wireframe(&self.coarse, on, "ClipmapRenderer wireframe")?;
        self.wireframe = on;
        Ok(())
    }

    /// Whether wireframe is on.
    pub fn wireframe(&self) -> bool {
        self.wireframe
    }

    /// Leaves the texels `region` (first and one-past-last vertex, relative to the camera's
    /// whole texel, as [`crate::RefinePass::region`] gives them) to another renderer from the
    /// next [`ClipmapRenderer::prepare`] on: their fragments are discarded. `None` draws
    /// everything again. The region must lie where the finest level does not morph (so its
    /// edge vertices are the stored heights the refined mesh meets); prepare refuses it
    /// otherwise.
    pub fn exclude(&mut self, region: Option<(IVec2, IVec2)>) {
        self.excluded = region;
    }

    /// The region the next prepare leaves out (what [`Self::exclude`] set last).
    pub(crate) fn excluded(&self) -> Option<(IVec2, IVec2)> {
        self.excluded
    }

    /// The formats this renderer draws into.
    pub fn target(&self) -> &TargetFormat {
        &self.target
    }

    /// Writes the uniforms and instances of one frame: `frame` (placed and culled by
    /// terrain-lod) seen by `camera` on a target of `target_size` pixels, displaced by `map`
    /// and lit with `normals`. Checks everything before wgpu sees it.
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        view: &ClipmapView<'_>,
    ) -> Result<(), GpuError> {
        let ClipmapView {
            surface,
            frame,
            camera,
            style,
            target_size,
        } = *view;
        let resolved = check_view(
            camera,
            Some(&self.target),
            target_size,
            "clipmap target size (pixels)",
        )?;
        if frame.levels.len() != self.levels as usize {
            return Err(GpuError::Unsupported {
                what: "ClipmapRenderer",
                reason: "the frame was placed by a layout with another number of levels",
            });
        }
        let info = surface.check()?;
        if surface.kind() == SurfaceKind::AtlasDetail && self.atlas_detail.is_none() {
            let user = self.user_surface.as_deref();
            self.atlas_detail = Some(atlas_detail_pipeline(device, &self.target, user)?);
        }
        // A detail surface's parallax moves the texels a fragment reads by up to its reach.
        let reach = fragment_reach(&surface);
        let wrap_offset = match info.wrap {
            WrapMode::Repeat => wrap_offset_for_frame(frame, info.size, reach)?,
            WrapMode::Clamp => [0, 0],
        };
        let mut uniform = frame_uniform(
            &info,
            &resolved,
            style,
            &self.target,
            (self.n, self.levels),
            wrap_offset,
        )?;
        if let Some(region) = self.excluded {
            uniform.excluded = self.exclusion(region, Vec2::from(uniform.camera_frac))?;
        }
        let (shading, new_shading) = self.materials.get(device, queue, info.size)?;
        uniform.set_layers(&shading);

        // Instances grouped by part, so each part is one instanced draw.
        let mut by_part: Vec<Vec<ClipmapInstance>> = vec![Vec::new(); self.parts.len()];
        for draw in &frame.draws {
            if let Some(part) = self.parts.iter().position(|p| p.kind == draw.part) {
                by_part[part].push(draw.instance);
            }
        }
        let count: usize = by_part.iter().map(Vec::len).sum();
        let capacity = self.instances.size() / std::mem::size_of::<ClipmapInstance>() as u64;
        if count as u64 > capacity {
            return Err(GpuError::Unsupported {
                what: "ClipmapRenderer",
                reason: "the frame holds more instances than its layout can place",
            });
        }
        self.runs.clear();
        let mut all = Vec::with_capacity(count);
        for (part, list) in by_part.iter().enumerate() {
            if !list.is_empty() {
                self.runs.push((part, all.len() as u32, list.len() as u32));
                all.extend_from_slice(list);
            }
        }
        if !all.is_empty() {
            queue.write_buffer(&self.instances, 0, bytemuck::cast_slice(&all));
        }
        queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&uniform));

        let camera_texel = IVec2::from(uniform.camera_texel);
        let buffers =
            self.detail_uniform
                .surface_buffers(queue, &surface, info.texel_size, camera_texel)?;
        let kind = surface.kind();
        let rebind = match &self.bound {
            Some((bound, k, _)) => {
                new_shading || *k != kind || bound.as_slice() != buffers.as_slice()
            }
            None => true,
        };
        if rebind {
            let group = self.pipeline(kind).bind_group(
                device,
                "ClipmapRenderer",
                &self.uniform,
                &buffers,
                &[],
                &shading,
            )?;
            self.bound = Some((buffers, kind, group));
        }
        Ok(())
    }

    /// Records the prepared frame into `pass` (a pass of this renderer's [`TargetFormat`]).
    /// Draws nothing before the first [`ClipmapRenderer::prepare`].
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>) {
        let Some((_, kind, group)) = &self.bound else {
            return;
        };
        if self.runs.is_empty() {
            return;
        }
        pass.set_pipeline(self.pipeline(*kind).pick(self.wireframe));
        pass.set_bind_group(0, group, &[]);
        pass.set_vertex_buffer(0, self.vertices.slice(..));
        pass.set_vertex_buffer(1, self.instances.slice(..));
        pass.set_index_buffer(self.indices.slice(..), wgpu::IndexFormat::Uint32);
        for &(part, first, count) in &self.runs {
            let part = &self.parts[part];
            pass.draw_indexed(part.indices.clone(), part.base_vertex, first..first + count);
        }
    }
}

impl ClipmapRenderer {
    /// The exclusion rect of `(lo, hi)` for a camera `frac` into its whole texel
    /// ([`crate::render::frame::exclusion_rect`]), refused where the finest level morphs.
    fn exclusion(&self, (lo, hi): (IVec2, IVec2), frac: Vec2) -> Result<[f32; 4], GpuError> {
        let half = (self.n - 1) as f32 * 0.5;
        let unmorphed = half - 1.0 - terrain_lod::morph::default_morph_width(self.n);
        let reach = (lo.as_vec2() - frac)
            .abs()
            .max((hi.as_vec2() - frac).abs())
            .max_element();
        if lo.cmpge(hi).any() {
            return Err(GpuError::Unsupported {
                what: "ClipmapRenderer::exclude",
                reason: "the excluded region is empty",
            });
        }
        if reach + 1.0 > unmorphed {
            return Err(GpuError::CannotExclude {
                what: "ClipmapRenderer::exclude",
                reason: "the excluded region reaches where the finest level morphs: refine a \
                         smaller radius or use a larger clipmap",
            });
        }
        crate::render::frame::exclusion_rect(lo, hi)
    }

    fn pipeline(&self, kind: SurfaceKind) -> &SurfacePipeline {
        match kind {
            SurfaceKind::Coarse => &self.coarse,
            SurfaceKind::Granular => &self.granular,
            SurfaceKind::Atlas => &self.atlas,
            SurfaceKind::Detail => &self.detail,
            // Built by the prepare that first drew the surface.
            SurfaceKind::AtlasDetail => self.atlas_detail.as_ref().unwrap_or(&self.atlas),
        }
    }
}

/// Checks a view and a target size before a renderer built for `target` (or a compute pass,
/// `None`) uses them, and resolves the view.
pub(crate) fn check_view(
    camera: &dyn RenderView,
    target: Option<&TargetFormat>,
    target_size: UVec2,
    what: &'static str,
) -> Result<ResolvedView, GpuError> {
    if target_size.x == 0 || target_size.y == 0 {
        return Err(terrain_core::CoreError::OutOfRange {
            what,
            value: f64::from(target_size.min_element()),
            expected: "at least 1 x 1",
        }
        .into());
    }
    let view = ResolvedView::new(camera, target_size)?;
    if let Some(target) = target {
        view.check_depth(target)?;
    }
    Ok(view)
}

/// Everything one clipmap frame is drawn from.
#[derive(Debug, Clone, Copy)]
pub struct ClipmapView<'a> {
    /// The heights and normals to draw.
    pub surface: ClipmapSurface<'a>,
    /// The placed, culled frame of the renderer's layout.
    pub frame: &'a ClipmapFrame,
    /// The camera: a [`crate::Camera`], an engine's [`crate::ViewMatrices`], or any
    /// [`RenderView`].
    pub camera: &'a dyn RenderView,
    /// Lighting and colours.
    pub style: &'a TerrainStyle,
    /// Size of the render target in pixels (for the aspect ratio).
    pub target_size: UVec2,
}

/// The clipmap's pipelines over a coarse-map, a granular map, an atlas and a coarse-map with
/// detail, with an engine's `surface_weights` (`user`) or the built-in one.
fn clipmap_pipelines(
    device: &wgpu::Device,
    target: &TargetFormat,
    user: Option<&str>,
) -> Result<[SurfacePipeline; 4], GpuError> {
    let coarse = SurfacePipeline::new(
        device,
        target,
        "clipmap.wgsl",
        &with_surface_weights(terrain_shaders::CLIPMAP, user),
        &[
            // The fragments read heights too (the material shading's curvature).
            (wgpu::ShaderStages::VERTEX_FRAGMENT, 1),
            (wgpu::ShaderStages::FRAGMENT, 2),
        ],
        &[],
        &clipmap_shape(),
    )?;
    let granular = SurfacePipeline::new(
        device,
        target,
        "clipmap granular",
        &with_surface_weights(terrain_shaders::CLIPMAP_GRANULAR, user),
        &[(wgpu::ShaderStages::VERTEX_FRAGMENT, 1)],
        &[],
        &clipmap_shape(),
    )?;
    let atlas = SurfacePipeline::new(
        device,
        target,
        "clipmap atlas",
        &with_surface_weights(terrain_shaders::CLIPMAP_ATLAS, user),
        &[
            (wgpu::ShaderStages::VERTEX_FRAGMENT, 1),
            (wgpu::ShaderStages::VERTEX_FRAGMENT, 2),
            (wgpu::ShaderStages::VERTEX_FRAGMENT, 3),
        ],
        &[],
        &clipmap_shape(),
    )?;
    let detail = SurfacePipeline::new(
        device,
        target,
        "clipmap detail",
        &with_surface_weights(terrain_shaders::CLIPMAP_DETAIL, user),
        &[
            // The fragments read heights too (the material shading's curvature).
            (wgpu::ShaderStages::VERTEX_FRAGMENT, 1),
            (wgpu::ShaderStages::FRAGMENT, 2),
            (wgpu::ShaderStages::FRAGMENT, 4),
            (wgpu::ShaderStages::FRAGMENT, 5),
        ],
        &[(wgpu::ShaderStages::FRAGMENT, 3)],
        &clipmap_shape(),
    )?;
    Ok([coarse, granular, atlas, detail])
}

/// The clipmap's pipeline over an atlas with detail tiles (atlas at 20 to 22, see
/// [`ATLAS_BESIDE_DETAIL`]).
fn atlas_detail_pipeline(
    device: &wgpu::Device,
    target: &TargetFormat,
    user: Option<&str>,
) -> Result<SurfacePipeline, GpuError> {
    SurfacePipeline::new(
        device,
        target,
        "clipmap atlas detail",
        &with_surface_weights(terrain_shaders::CLIPMAP_ATLAS_DETAIL, user),
        &atlas_detail_storage(),
        &[(wgpu::ShaderStages::FRAGMENT, 3)],
        &clipmap_shape(),
    )
}

/// The storage bindings of an atlas with detail tiles: the atlas for both stages, the tiles
/// for the fragments.
pub(crate) fn atlas_detail_storage() -> [(wgpu::ShaderStages, u32); 5] {
    let both = wgpu::ShaderStages::VERTEX_FRAGMENT;
    let fragment = wgpu::ShaderStages::FRAGMENT;
    let a = ATLAS_BESIDE_DETAIL;
    [
        (both, a),
        (both, a + 1),
        (both, a + 2),
        (fragment, 4),
        (fragment, 5),
    ]
}

/// The vertex inputs and entry point of a terrain pipeline: the clipmap's, or another
/// renderer's drawing with the same frame uniform, surfaces and fragment shader.
pub(crate) struct VertexShape<'a> {
    /// The vertex shader's entry point.
    pub entry: &'static str,
    /// Bytes per mesh vertex.
    pub vertex_stride: u64,
    /// The mesh vertex attributes (a `Float32x2` grid position at location 0 for the
    /// instanced meshes).
    pub vertex_attrs: &'a [wgpu::VertexAttribute],
    /// Bytes per instance (0: no instance buffer).
    pub instance_stride: u64,
    /// The instance attributes (locations 1 and up).
    pub instance_attrs: &'a [wgpu::VertexAttribute],
    /// Uniform buffers bound after the surface's storage buffers (vertex stage).
    pub extra_uniforms: &'a [u32],
}

/// The grid position of the instanced meshes' vertices.
pub(crate) const GRID_ATTRS: [wgpu::VertexAttribute; 1] = wgpu::vertex_attr_array![0 => Float32x2];

/// The clipmap's vertex inputs.
fn clipmap_shape() -> VertexShape<'static> {
    const ATTRS: [wgpu::VertexAttribute; 3] =
        wgpu::vertex_attr_array![1 => Sint32x2, 2 => Uint32, 3 => Uint32];
    VertexShape {
        entry: "vs_main",
        vertex_stride: std::mem::size_of::<ClipmapVertex>() as u64,
        vertex_attrs: &GRID_ATTRS,
        instance_stride: std::mem::size_of::<ClipmapInstance>() as u64,
        instance_attrs: &ATTRS,
        extra_uniforms: &[],
    }
}

/// The pipeline and bind group layout of one surface kind.
#[derive(Debug)]
pub(crate) struct SurfacePipeline {
    pub(crate) pipeline: wgpu::RenderPipeline,
    /// The same pipeline drawing triangle edges as lines, on devices that can.
    pub(crate) wireframe: Option<wgpu::RenderPipeline>,
    pub(crate) layout: wgpu::BindGroupLayout,
}

impl SurfacePipeline {
    /// Builds the pipeline of `source` with the frame uniform at binding 0, read-only storage
    /// buffers and uniforms of the surface at the given (stages, binding), and its wireframe
    /// twin when the device has `POLYGON_MODE_LINE`.
    pub(crate) fn new(
        device: &wgpu::Device,
        target: &TargetFormat,
        label: &'static str,
        source: &str,
        storage: &[(wgpu::ShaderStages, u32)],
        uniforms: &[(wgpu::ShaderStages, u32)],
        shape: &VertexShape<'_>,
    ) -> Result<Self, GpuError> {
        let module = shader_module(device, label, source)?;
        scoped(device, label, || {
            let mut entries = vec![wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }];
            entries.extend(storage.iter().map(|&(visibility, binding)| {
                wgpu::BindGroupLayoutEntry {
                    binding,
                    visibility,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                }
            }));
            entries.extend(uniforms.iter().map(|&(visibility, binding)| {
                wgpu::BindGroupLayoutEntry {
                    binding,
                    visibility,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                }
            }));
            entries.extend(shape.extra_uniforms.iter().map(|&binding| {
                wgpu::BindGroupLayoutEntry {
                    binding,
                    visibility: wgpu::ShaderStages::VERTEX,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                }
            }));
            entries.extend(materials::layout_entries());
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some(label),
                entries: &entries,
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(label),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let mut buffers = vec![Some(wgpu::VertexBufferLayout {
                array_stride: shape.vertex_stride,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: shape.vertex_attrs,
            })];
            if shape.instance_stride > 0 {
                buffers.push(Some(wgpu::VertexBufferLayout {
                    array_stride: shape.instance_stride,
                    step_mode: wgpu::VertexStepMode::Instance,
                    attributes: shape.instance_attrs,
                }));
            }
            let build = |polygon_mode| {
                device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                    label: Some(label),
                    layout: Some(&pipeline_layout),
                    vertex: wgpu::VertexState {
                        module: &module,
                        entry_point: Some(shape.entry),
                        compilation_options: Default::default(),
                        buffers: &buffers,
                    },
                    // No culling: degenerate triangles and both windings of the parts are drawn.
                    primitive: wgpu::PrimitiveState {
                        polygon_mode,
                        ..Default::default()
                    },
                    depth_stencil: Some(target.terrain_depth_state()),
                    multisample: target.multisample(),
                    fragment: Some(wgpu::FragmentState {
                        module: &module,
                        entry_point: Some("fs_main"),
                        compilation_options: Default::default(),
                        targets: &[Some(target.color.into())],
                    }),
                    multiview_mask: None,
                    cache: None,
                })
            };
            let pipeline = build(wgpu::PolygonMode::Fill);
            let wireframe = device
                .features()
                .contains(wgpu::Features::POLYGON_MODE_LINE)
                .then(|| build(wgpu::PolygonMode::Line));
            Self {
                pipeline,
                wireframe,
                layout,
            }
        })
    }
}

impl SurfacePipeline {
    /// The pipeline to draw with: the wireframe twin when asked for and built.
    pub(crate) fn pick(&self, wireframe: bool) -> &wgpu::RenderPipeline {
        match (&self.wireframe, wireframe) {
            (Some(lines), true) => lines,
            _ => &self.pipeline,
        }
    }

    /// A bind group of `uniform` at binding 0, the surface's `buffers` (binding, buffer),
    /// `extra` (binding, buffer) after them and the `shading` (materials, colour layer) at 10
    /// to 13, over this pipeline's layout.
    pub(crate) fn bind_group(
        &self,
        device: &wgpu::Device,
        label: &'static str,
        uniform: &wgpu::Buffer,
        buffers: &[(u32, wgpu::Buffer)],
        extra: &[(u32, &wgpu::Buffer)],
        shading: &ShadingBindings,
    ) -> Result<wgpu::BindGroup, GpuError> {
        let mut entries = vec![wgpu::BindGroupEntry {
            binding: 0,
            resource: uniform.as_entire_binding(),
        }];
        entries.extend(buffers.iter().map(|(binding, b)| wgpu::BindGroupEntry {
            binding: *binding,
            resource: b.as_entire_binding(),
        }));
        entries.extend(extra.iter().map(|&(binding, b)| wgpu::BindGroupEntry {
            binding,
            resource: b.as_entire_binding(),
        }));
        entries.extend(shading.entries());
        scoped(device, label, || {
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(label),
                layout: &self.layout,
                entries: &entries,
            })
        })
    }
}

/// Refuses turning wireframe on for renderer `what` when `pipeline` has no wireframe twin.
pub(crate) fn check_wireframe(
    pipeline: &SurfacePipeline,
    on: bool,
    what: &'static str,
) -> Result<(), GpuError> {
    if on && pipeline.wireframe.is_none() {
        return Err(GpuError::Unsupported {
            what,
            reason: "the device was made without Features::POLYGON_MODE_LINE",
        });
    }
    Ok(())
}

/// A multiple of the map size that makes every texel the frame can read non-negative (the
/// coarsest level's origin, less the morph's one-texel reach and `extra` texels more).
fn wrap_offset_for_frame(
    frame: &ClipmapFrame,
    map_size: UVec2,
    extra: i32,
) -> Result<[i32; 2], GpuError> {
    let min = frame
        .levels
        .iter()
        .map(|l| l.origin - IVec2::splat(l.scale as i32 + 1 + extra))
        .fold(IVec2::ZERO, |a, b| a.min(b));
    crate::device::compute::wrap_offset(min, map_size)
}
