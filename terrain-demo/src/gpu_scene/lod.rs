//! CDLOD and adaptive tessellation on the GPU scene (Cervin 2012): the quadtree or the
//! tessellation hierarchy and density map, kept current from the regions read back, their
//! renderers, and the popping metric of the last two frames.

use super::*;

/// CDLOD on the GPU scene: the quadtree (on the CPU, kept current by the deformations), the
/// renderer, and the selections of the last two frames (for the popping metric).
pub(super) struct CdlodScene {
    pub(super) tree: CdlodSource,
    pub(super) renderer: CdlodRenderer,
    pub(super) mesh: CdlodMesh,
    /// The last frame's selection with its camera, and the one before.
    pub(super) last: Option<(CdlodFrame, glam::Vec3)>,
    pub(super) previous: Option<(CdlodFrame, glam::Vec3)>,
}

/// Where CDLOD's quadtree comes from: a map's, updated from the changed regions on a worker
/// thread (terrain-lod's `CdlodUpdater`), or a streamed world's, built from leaf bounds and
/// kept current by its scenario.
pub(super) enum CdlodSource {
    Map(CdlodUpdater<u16>),
    Streamed(CdlodTree),
}

impl CdlodSource {
    pub(super) fn tree(&self) -> &CdlodTree {
        match self {
            Self::Map(updater) => updater.tree(),
            Self::Streamed(tree) => tree,
        }
    }
}

/// Adaptive tessellation on the GPU scene: the hierarchy and density map (on the CPU, kept
/// current from the changed regions on a worker thread, and copied to the GPU where they
/// change), the compute pass that tessellates, the renderer, and the cameras of the last two
/// frames (for the popping metric).
pub(super) struct TessScene {
    pub(super) updater: TessUpdater<u16>,
    pub(super) gpu: terrain_gpu::GpuTessellation,
    pub(super) pass: TessellationPass,
    pub(super) renderer: TessRenderer,
    /// The last frame's view (camera, viewport width, hfov), and the one before.
    pub(super) last: Option<(glam::Vec3, f32, f32)>,
    pub(super) previous: Option<(glam::Vec3, f32, f32)>,
    /// Where the popping metric looks: up to [`JUMP_PROBES`] drawn vertices of each of the
    /// last two frames (texels).
    pub(super) probes: Vec<Vec2>,
    pub(super) previous_probes: Vec<Vec2>,
}

/// Drawn vertices per frame the tessellation's popping metric probes.
pub(super) const JUMP_PROBES: usize = 4096;

/// Triangles the tessellation's output holds (72 MiB of vertices).
pub(super) const TESS_CAPACITY: u32 = 1 << 21;

impl GpuScene {
    /// Draws the coarse-map with CDLOD instead of the clipmap: the quadtree of `map` with
    /// `config`, kept current by [`GpuScene::update_lod`].
    pub fn enable_cdlod(&mut self, map: &CoarseMap, config: CdlodConfig) -> Result<()> {
        let tree = CdlodTree::from_map(map, config)?;
        self.enable_cdlod_source(CdlodSource::Map(CdlodUpdater::spawn(tree, map)?))
    }

    /// Draws a streamed world's atlas with CDLOD instead of the clipmap: `tree` is the world's
    /// quadtree (terrain-lod's `CdlodTree::from_leaf_bounds`), kept current by the caller
    /// through [`GpuScene::cdlod_tree_mut`].
    pub fn enable_cdlod_tree(&mut self, tree: CdlodTree) -> Result<()> {
        self.enable_cdlod_source(CdlodSource::Streamed(tree))
    }

    fn enable_cdlod_source(&mut self, tree: CdlodSource) -> Result<()> {
        let mesh = CdlodMesh::new(tree.tree().config().grid_size);
        let renderer = CdlodRenderer::new(&self.ctx.device, &self.target.format(), &mesh)?;
        self.cdlod = Some(CdlodScene {
            tree,
            renderer,
            mesh,
            last: None,
            previous: None,
        });
        Ok(())
    }

    /// The streamed world's CDLOD quadtree, when CDLOD draws one.
    pub fn cdlod_tree_mut(&mut self) -> Option<&mut CdlodTree> {
        match self.cdlod.as_mut().map(|c| &mut c.tree) {
            Some(CdlodSource::Streamed(tree)) => Some(tree),
            _ => None,
        }
    }

    /// Draws the coarse-map with adaptive tessellation instead of the clipmap: the hierarchy of
    /// `map` with `config` (and its density map when `density`), kept current by
    /// [`GpuScene::update_lod`].
    pub fn enable_tessellation(
        &mut self,
        map: &CoarseMap,
        config: TessConfig,
        density: bool,
    ) -> Result<()> {
        let density = density
            .then(|| DensityMap::from_map(map, DensityParams::default()))
            .transpose()?;
        // The CPU reference selects before the GPU draws, bounded as the GPU's output: a view
        // that needs more triangles fails with a clear error instead of drawing holes.
        let config = TessConfig {
            max_triangles: config.max_triangles.min(TESS_CAPACITY as usize),
            ..config
        };
        let hierarchy = TessHierarchy::from_map(map, density.as_ref(), config)?;
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let capacity = config.max_triangles as u32;
        let gpu = terrain_gpu::GpuTessellation::new(device, queue, &hierarchy, capacity)?;
        self.tess = Some(TessScene {
            updater: TessUpdater::spawn(TessState { hierarchy, density }, map)?,
            gpu,
            pass: TessellationPass::new(device)?,
            renderer: TessRenderer::new(device, &self.target.format())?,
            last: None,
            previous: None,
            probes: Vec::new(),
            previous_probes: Vec::new(),
        });
        Ok(())
    }

    /// Hands the deformations in `dirty` (already in `map`) to the LOD data's worker thread
    /// and takes in what it finished: the CDLOD quadtree, or the tessellation's hierarchy and
    /// density map, whose changed rows are copied to the GPU (timed as `lod`: the frame pays
    /// for copying the rects' rows, not for the update). Nothing under the clipmap; a streamed
    /// world's quadtree is kept current by its scenario.
    pub fn update_lod(
        &mut self,
        map: &CoarseMap,
        dirty: &[Rect],
        timings: &mut Timings,
    ) -> Result<()> {
        let t = std::time::Instant::now();
        if let Some(CdlodSource::Map(updater)) = self.cdlod.as_mut().map(|c| &mut c.tree) {
            updater.poll()?;
            for r in dirty {
                updater.submit(map, *r)?;
            }
            timings.add(Step::Lod, crate::timings::ms_since(t));
        }
        if let Some(c) = &mut self.tess {
            let updater = &mut c.updater;
            updater.poll()?;
            let rows = updater.take_changes();
            if !rows.is_empty() {
                c.gpu
                    .upload(&self.ctx.queue, &updater.state().hierarchy, &rows)?;
            }
            for r in dirty {
                updater.submit(map, *r)?;
            }
            timings.add(Step::Lod, crate::timings::ms_since(t));
        }
        Ok(())
    }

    /// The popping metric of the last frame against the one before (`None` on the first
    /// frame or without CDLOD): the largest screen-space jump of the drawn surface, in pixels,
    /// at probes ahead of `camera`, both frames evaluated on `map` and projected with
    /// `camera`, so only a change of the mesh counts.
    pub fn lod_jump_px(&self, map: &CoarseMap, camera: &Camera) -> Option<f32> {
        if let Some(t) = &self.tess {
            return tess_jump_px(t, camera, self.target.size().as_vec2());
        }
        let c = self.cdlod.as_ref()?;
        let ((now, eye), (then, then_eye)) = (c.last.as_ref()?, c.previous.as_ref()?);
        let size = self.target.size().as_vec2();
        let view = terrain_lod::PoppingView {
            forward: camera.forward,
            view_proj: camera.view_proj_world(size.x / size.y),
            target: size,
        };
        Some(
            c.tree
                .tree()
                .popping_px(map, (now, *eye), (then, *then_eye), &view),
        )
    }
}

/// What CDLOD's and the tessellation's decisions are made for: the camera, its frustum and the
/// target's width and horizontal field of view.
pub(super) fn lod_view<'a>(camera: &Camera, size: UVec2, frustum: &'a Frustum) -> CdlodView<'a> {
    let aspect = size.x as f32 / size.y as f32;
    CdlodView {
        camera: camera.position,
        frustum: Some(frustum),
        viewport_width: size.x as f32,
        hfov: 2.0 * ((camera.fov_y * 0.5).tan() * aspect).atan(),
    }
}

/// Tessellates (a compute pass, timed in `render`) and draws a frame; the CPU reference
/// selection gives the report's figures and is not timed (the `lod` step is the frustum, from
/// `lod_start`).
pub(super) fn render_tessellated(
    c: &mut TessScene,
    gpu: FrameGpu<'_>,
    camera: &Camera,
    frustum: Frustum,
    lod_start: std::time::Instant,
    timings: &mut Timings,
) -> Result<RenderedFrame> {
    let (ctx, target, sky) = (gpu.ctx, gpu.target, gpu.sky);
    let (device, queue) = (&ctx.device, &ctx.queue);
    let size = target.size();
    let aspect = size.x as f32 / size.y as f32;
    let view = lod_view(camera, size, &frustum);
    timings.add(Step::Lod, crate::timings::ms_since(lod_start));
    // The report's figures from the CPU reference (the same triangles as the GPU's), made
    // first so that a view beyond the output's capacity fails before anything is drawn.
    let hierarchy = &c.updater.state().hierarchy;
    let frame = hierarchy.select(&view)?;
    let max_screen_error_px = hierarchy.max_screen_error_px(&frame, &view);
    let view_proj = camera.view_proj_relative(aspect);
    let timing = gpu.timer.time(device, queue, |encoder| {
        sky.prepare(queue, view_proj, &SkyColors::default())?;
        c.pass
            .encode(device, queue, encoder, &c.gpu, hierarchy, &view)?;
        let draw = TessDraw {
            surface: gpu.surface,
            camera,
            style: gpu.style,
            target_size: size,
        };
        c.renderer.prepare(device, queue, &draw)?;
        let mut pass = target.begin_pass(encoder, wgpu::Color::BLACK);
        sky.draw(&mut pass);
        c.renderer.draw(&mut pass, &c.gpu);
        Ok(())
    })?;
    c.pass.recall();
    let image = capture(ctx, target, timing, timings)?;
    let stats = RenderedFrame {
        image,
        triangles: frame.triangle_count(),
        lod: LodStats {
            mode: "tessellated",
            vertices: frame.vertex_count(),
            max_screen_error_px: Some(max_screen_error_px),
        },
    };
    c.previous = c.last.replace((camera.position, size.x as f32, view.hfov));
    let stride = (frame.triangles.len() / JUMP_PROBES).max(1);
    let probes = frame
        .triangles
        .iter()
        .step_by(stride)
        .map(|t| Vec2::from(t[2].texel))
        .collect();
    c.previous_probes = std::mem::replace(&mut c.probes, probes);
    Ok(stats)
}

/// The popping metric of the tessellation: the surface's largest jump between the last two
/// frames' decisions, at drawn vertices of both frames (vertices that appeared and that
/// disappeared), both on today's heights and projected with `camera`.
pub(super) fn tess_jump_px(t: &TessScene, camera: &Camera, size: Vec2) -> Option<f32> {
    let ((eye, width, hfov), (then_eye, then_width, then_hfov)) = (t.last?, t.previous?);
    let view = CdlodView {
        camera: eye,
        frustum: None,
        viewport_width: width,
        hfov,
    };
    let previous = CdlodView {
        camera: then_eye,
        frustum: None,
        viewport_width: then_width,
        hfov: then_hfov,
    };
    let probes: Vec<Vec2> = t.probes.iter().chain(&t.previous_probes).copied().collect();
    Some(t.updater.state().hierarchy.max_height_jump(
        &view,
        &previous,
        &probes,
        camera.view_proj_world(size.x / size.y),
        size,
    ))
}

/// Selects and draws a CDLOD frame (the `lod` step is timed from `lod_start`).
pub(super) fn render_cdlod(
    c: &mut CdlodScene,
    gpu: FrameGpu<'_>,
    camera: &Camera,
    frustum: Frustum,
    lod_start: std::time::Instant,
    timings: &mut Timings,
) -> Result<RenderedFrame> {
    let FrameGpu {
        ctx,
        target,
        sky,
        timer,
        surface,
        style,
    } = gpu;
    let (device, queue) = (&ctx.device, &ctx.queue);
    let size = target.size();
    let aspect = size.x as f32 / size.y as f32;
    let view = lod_view(camera, size, &frustum);
    let tree = c.tree.tree();
    let frame = tree.select(&view)?;
    // A streamed world's tree knows its errors only as height spans: no measured error.
    let max_screen_error_px = match surface {
        ClipmapSurface::Atlas { .. } => None,
        _ => Some(tree.max_screen_error_px(&frame, &view)),
    };
    timings.add(Step::Lod, crate::timings::ms_since(lod_start));
    let view_proj = camera.view_proj_relative(aspect);
    let timing = timer.time(device, queue, |encoder| {
        sky.prepare(queue, view_proj, &SkyColors::default())?;
        c.renderer.prepare(
            device,
            queue,
            &CdlodDraw {
                surface,
                frame: &frame,
                camera,
                style,
                target_size: size,
            },
        )?;
        let mut pass = target.begin_pass(encoder, wgpu::Color::BLACK);
        sky.draw(&mut pass);
        c.renderer.draw(&mut pass);
        Ok(())
    })?;
    let image = capture(ctx, target, timing, timings)?;
    let stats = RenderedFrame {
        image,
        triangles: frame.triangle_count(&c.mesh),
        lod: LodStats {
            mode: "cdlod",
            vertices: frame.vertex_count(&c.mesh),
            max_screen_error_px,
        },
    };
    c.previous = c.last.replace((frame, camera.position));
    Ok(stats)
}
