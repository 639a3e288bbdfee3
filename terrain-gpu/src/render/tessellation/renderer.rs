//! [`TessRenderer`]: draws the triangles the tessellation pass wrote.

use super::*;
use crate::render::surface::SurfaceKind;

/// Everything one tessellated frame is drawn from.
#[derive(Debug, Clone, Copy)]
pub struct TessDraw<'a> {
    /// What the fragments are shaded from: [`ClipmapSurface::Coarse`] (the map the
    /// tessellation was made of, with its normals) or [`ClipmapSurface::Detail`] (the same
    /// with a detail layer, shaded as the clipmap shades it); for a streamed world
    /// [`ClipmapSurface::Atlas`] or [`ClipmapSurface::AtlasDetail`] (its atlas).
    pub surface: ClipmapSurface<'a>,
    /// The camera: a [`crate::Camera`], an engine's [`crate::ViewMatrices`], or any
    /// [`RenderView`].
    pub camera: &'a dyn RenderView,
    /// Lighting and colours.
    pub style: &'a TerrainStyle,
    /// The render target's size in pixels.
    pub target_size: UVec2,
}

/// Draws the triangles of a [`GpuTessellation`] into passes of one [`TargetFormat`]: build it
/// once, then per frame [`TessRenderer::prepare`] and [`TessRenderer::draw`] (after the
/// tessellation pass was encoded, and after [`crate::SkyPass`], as the clipmap).
#[derive(Debug)]
pub struct TessRenderer {
    /// A pipeline per surface kind drawn so far (the coarse-map's built first).
    pipelines: Vec<(SurfaceKind, SurfacePipeline)>,
    /// The detail surface's uniform.
    detail_uniform: DetailUniform,
    /// The surface kind of the bound group.
    kind: SurfaceKind,
    target: TargetFormat,
    uniform: wgpu::Buffer,
    bound: Option<(BoundBuffers, wgpu::BindGroup)>,
    wireframe: bool,
    /// The materials of [`crate::SurfaceShading::Materials`].
    materials: MaterialSlot,
    /// An engine's `surface_weights` ([`TessRenderer::set_surface_shader`]).
    user_surface: Option<String>,
    /// Texels another renderer draws (see [`TessRenderer::exclude`]).
    excluded: Option<(glam::IVec2, glam::IVec2)>,
}

impl TessRenderer {
    /// The layers it binds (`TerrainRenderer::adopt_layers` copies them).
    pub(crate) fn layers(&self) -> &MaterialSlot {
        &self.materials
    }

    /// The layers it binds, to change.
    pub(crate) fn layers_mut(&mut self) -> &mut MaterialSlot {
        &mut self.materials
    }
    /// Builds the pipeline.
    pub fn new(device: &wgpu::Device, target: &TargetFormat) -> Result<Self, GpuError> {
        target.validate(device)?;
        let pipeline = tess_pipeline(device, target, SurfaceKind::Coarse, None)?;
        let uniform = scoped(device, "TessRenderer", || {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("tessellated frame"),
                size: std::mem::size_of::<crate::render::clipmap::FrameUniform>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })?;
        Ok(Self {
            pipelines: vec![(SurfaceKind::Coarse, pipeline)],
            detail_uniform: DetailUniform::new(device, "tessellated detail"),
            kind: SurfaceKind::Coarse,
            target: *target,
            uniform,
            bound: None,
            wireframe: false,
            materials: MaterialSlot::default(),
            user_surface: None,
            excluded: None,
        })
    }

    /// Leaves the texels `region` (first and one-past-last vertex, relative to the camera's
    /// whole texel, as [`crate::RefinePass::region`] gives them) to another renderer from the
    /// next [`TessRenderer::prepare`] on: their fragments are discarded. `None` draws
    /// everything again. The meshes meet only where the tessellation draws the region's edge
    /// through every texel at its true height: tessellate with the region at full resolution
    /// ([`TessellationPass::set_full_resolution`], as [`crate::TerrainRenderer`] does).
    pub fn exclude(&mut self, region: Option<(glam::IVec2, glam::IVec2)>) {
        self.excluded = region;
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
        let pipeline = tess_pipeline(device, &self.target, SurfaceKind::Coarse, wgsl_function)
            .map_err(GpuError::user_shader)?;
        self.pipelines = vec![(SurfaceKind::Coarse, pipeline)];
        self.kind = SurfaceKind::Coarse;
        self.user_surface = wgsl_function.map(str::to_owned);
        self.bound = None;
        Ok(())
    }

    /// Draws triangle edges as lines from the next draw; fails without
    /// [`wgpu::Features::POLYGON_MODE_LINE`].
    pub fn set_wireframe(&mut self, on: bool) -> Result<(), GpuError> {
        for (_, pipeline) in &self.pipelines {
            check_wireframe(pipeline, on, "TessRenderer wireframe")?;
        }
        self.wireframe = on;
        Ok(())
    }

    /// Writes the frame uniform. Checks everything before wgpu sees it.
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        draw: &TessDraw<'_>,
    ) -> Result<(), GpuError> {
        let view = check_view(
            draw.camera,
            Some(&self.target),
            draw.target_size,
            "tessellated target size (pixels)",
        )?;
        let surface = draw.surface;
        let kind = surface.kind();
        if kind == SurfaceKind::Granular {
            return Err(GpuError::Unsupported {
                what: "TessRenderer",
                reason: "the surface must be the coarse-map or the world's atlas the \
                         tessellation was made of, with or without a detail layer",
            });
        }
        let info = surface.check()?;
        if !self.pipelines.iter().any(|(k, _)| *k == kind) {
            let pipeline = tess_pipeline(device, &self.target, kind, self.user_surface.as_deref())?;
            self.pipelines.push((kind, pipeline));
        }
        let wrap_offset = match info.wrap {
            // Vertices lie in 0 ..= the map size; fragments read a texel either side, and a
            // detail surface's parallax reach beyond.
            WrapMode::Repeat => {
                let reach = 2 + fragment_reach(&surface);
                crate::device::compute::wrap_offset(glam::IVec2::splat(-reach), info.size)?
            }
            WrapMode::Clamp => [0, 0],
        };
        let mut uniform =
            frame_uniform(&info, &view, draw.style, &self.target, (0, 0), wrap_offset)?;
        if let Some((lo, hi)) = self.excluded {
            uniform.excluded = crate::render::frame::exclusion_rect(lo, hi)?;
        }
        let (shading, new_shading) = self.materials.get(device, queue, info.size)?;
        uniform.set_layers(&shading);
        queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&uniform));
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
                "TessRenderer",
                &self.uniform,
                &buffers,
                &[],
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

    /// Records the draw of `gpu`'s triangles (as many as the last tessellation wrote) into
    /// `pass`. Draws nothing before the first prepare.
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>, gpu: &GpuTessellation) {
        let Some((_, group)) = &self.bound else {
            return;
        };
        pass.set_pipeline(self.pipeline(self.kind).pick(self.wireframe));
        pass.set_bind_group(0, group, &[]);
        pass.set_vertex_buffer(0, gpu.output.slice(..));
        pass.draw_indirect(&gpu.state, ARGS_OFFSET);
    }
}

/// The tessellated pipeline over a surface of `kind` (not granular), with an engine's
/// `surface_weights` (`user`) or the built-in one. The vertices carry their heights: only the
/// fragments read the surface.
fn tess_pipeline(
    device: &wgpu::Device,
    target: &TargetFormat,
    kind: SurfaceKind,
    user: Option<&str>,
) -> Result<SurfacePipeline, GpuError> {
    const ATTRS: [wgpu::VertexAttribute; 1] = wgpu::vertex_attr_array![0 => Float32x3];
    let fragment = wgpu::ShaderStages::FRAGMENT;
    let (label, source, storage, uniforms) = match kind {
        SurfaceKind::Detail => (
            "tessellated detail",
            terrain_shaders::TESSELLATED_DETAIL,
            vec![(fragment, 1), (fragment, 2), (fragment, 4), (fragment, 5)],
            vec![(fragment, 3)],
        ),
        SurfaceKind::Atlas => (
            "tessellated atlas",
            terrain_shaders::TESSELLATED_ATLAS,
            vec![(fragment, 1), (fragment, 2), (fragment, 3)],
            vec![],
        ),
        SurfaceKind::AtlasDetail => (
            "tessellated atlas detail",
            terrain_shaders::TESSELLATED_ATLAS_DETAIL,
            crate::render::clipmap::atlas_detail_storage()
                .map(|(_, b)| (fragment, b))
                .to_vec(),
            vec![(fragment, 3)],
        ),
        SurfaceKind::Coarse | SurfaceKind::Granular => (
            "tessellated.wgsl",
            terrain_shaders::TESSELLATED,
            vec![(fragment, 1), (fragment, 2)],
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
            entry: "vs_tess",
            vertex_stride: std::mem::size_of::<TessVertex>() as u64,
            vertex_attrs: &ATTRS,
            instance_stride: 0,
            instance_attrs: &[],
            extra_uniforms: &[],
        },
    )
}
