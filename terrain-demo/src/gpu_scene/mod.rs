//! The GPU side of a demo frame: stamps and normals on the GPU map, clipmap placement, sky and
//! terrain rendering, capture. Glue only: every step is a library call. This is the one module
//! of the demo that calls terrain-gpu (the detail layer in `detail`, CDLOD and tessellation in
//! `lod`); the rest sees [`GpuScene`] and [`Camera`].

use anyhow::{Context, Result};
use glam::{UVec2, Vec2};
use terrain_cache::detail::{DetailCache, DetailFrame};
use terrain_core::detail::DetailLayout;
use terrain_core::granular::{GranularObject, GranularParams};
use terrain_core::{CoarseMap, DirtyRect, Grid, TextureStamp};
use terrain_core::{FixedPointMap, Rect};
use terrain_gpu::granular::GranularField;
use terrain_gpu::{
    AtlasStamper, ClipmapSurface, DeformableMap, DetailShading, GpuContext, GpuRegionSource,
    GpuStamp, GpuTextureStamp, OffscreenTarget, RefineDraw, RefinePass, RefineRenderer,
    RegionReadback, SkyColors, SkyPass, SpillPass, StampOp, TerrainRenderer, TerrainStyle,
    TerrainView,
};
use terrain_lod::{CdlodConfig, CdlodTree, ClipmapLayout, TessConfig};
use terrain_physics::{CollisionMirror, ReadbackScheduler, UpdateReport};

use crate::frame_plan::{FramePlan, StampKind};
use crate::report::{GpuObjects, GpuTiming};
use crate::timings::{GpuFigure, Step, Timings};

mod detail;
mod frame_timer;
mod granular;
mod lod;
mod paint;

pub use detail::{DETAIL_SLOTS, SPILL_WINDOW_TEXELS};
use detail::{DetailScene, RefinedGeometry};
use frame_timer::FrameTimer;
pub use paint::CRATER_DIRT;

pub use terrain_gpu::Camera;

/// Clipmap vertices per level side (Flower 2010, sec. 3.3 uses 255).
pub const CLIPMAP_N: u32 = 255;
/// Clipmap levels, the inner grid included: 5 levels of N = 255 span 406 m at 0.1 m per texel,
/// about twice the default map, so the toroidal repeat stays in the fog.
pub const CLIPMAP_LEVELS: u32 = 5;

/// Everything that lives on the GPU for the demo.
pub struct GpuScene {
    ctx: GpuContext,
    /// The in-memory map, its normals and the passes that deform it.
    ground: DeformableMap,
    sky: SkyPass,
    /// The terrain in its LOD mode (the clipmap unless `--lod` says otherwise).
    terrain: TerrainRenderer,
    target: OffscreenTarget,
    footprint: Option<GpuTextureStamp>,
    /// The shockwave's change of the frame, rewritten in place each frame.
    shock: Option<GpuTextureStamp>,
    readback: RegionReadback,
    /// Times the GPU steps: timestamps read back later, or submit-and-wait (`frame_timer`).
    timer: FrameTimer,
    style: TerrainStyle,
    /// Lowest and highest height the map can hold (metres): the culling boxes' vertical extent.
    height_range: (f32, f32),
    /// Granular deformation on the GPU (the snow scenario), drawn instead of the coarse-map.
    granular: Option<GranularField>,
    /// A streamed world's granular trails on the GPU (made on first use).
    trails: Option<terrain_gpu::granular::FieldStepper>,
    /// A streamed world's tile atlas (the flyover), drawn instead of the coarse-map.
    atlas: Option<GpuTileAtlas>,
    /// Stamps on atlas tiles, their changed rects read back.
    tile_stamper: Option<AtlasStamper>,
    /// The detail layer's tiles (`--detail parallax|refine`), drawn with the coarse-map.
    detail: Option<DetailScene>,
    /// `--detail refine`: the refined geometry near the camera (the clipmap shades the rest
    /// with the detail normals, no parallax).
    refined: Option<RefinedGeometry>,
    /// The material layer the default scenario's deformations paint (`paint`).
    paint: Option<paint::Paint>,
    /// The hole mask every renderer leaves out, once a hole is cut.
    holes: Option<terrain_gpu::GpuHoleMask>,
    /// A streamed world's paint and colour, in tile slots the scenario's streams fill.
    streamed_paint: Option<terrain_gpu::GpuOverlayAtlas>,
    streamed_color: Option<terrain_gpu::GpuOverlayAtlas>,
    /// Frames rendered so far.
    frames: u32,
    /// Fault injection for the device-loss test: destroy the device before rendering this
    /// frame (`TERRAIN_DEMO_DESTROY_DEVICE_AT_FRAME`; never set in normal use).
    destroy_at: Option<u32>,
}

/// The environment variable of [`GpuScene`]'s device-loss fault injection.
pub const DESTROY_DEVICE_ENV: &str = "TERRAIN_DEMO_DESTROY_DEVICE_AT_FRAME";

pub use terrain_gpu::ArrivedTileRect;

/// The streamed world's tiles on the GPU: slots, indirection table, coarser fallback.
pub use terrain_gpu::{AtlasConfig, GpuTileAtlas};

/// Readbacks of deformed atlas tiles in flight at most (the ring's staging buffers).
const TILE_READBACK_RING: usize = 16;

/// One rendered frame.
pub struct RenderedFrame {
    /// The captured image.
    pub image: Grid<[u8; 4]>,
    /// Non-degenerate triangles drawn.
    pub triangles: u64,
    /// The LOD scheme (`clipmap` or `cdlod`) and its figures.
    pub lod: LodStats,
}

/// What the LOD scheme drew in a frame.
#[derive(Debug, Clone, Copy, Default)]
pub struct LodStats {
    /// `clipmap` or `cdlod`.
    pub mode: &'static str,
    /// Vertices drawn (per instance of the shared meshes).
    pub vertices: u64,
    /// CDLOD: the largest projected geometric error of the drawn nodes, pixels.
    pub max_screen_error_px: Option<f32>,
    /// `--detail refine`: whether the refined cells were drawn (the LOD left their region
    /// out); `None` without refinement.
    pub refined: Option<bool>,
}

impl GpuScene {
    /// `e`, or the device's loss when that is what caused it: after a loss wgpu reports only
    /// secondary failures (a mapping that failed), so the loss is looked for first.
    fn lost_or(&self, e: anyhow::Error) -> anyhow::Error {
        let _ = self.ctx.device.poll(wgpu::PollType::Poll);
        // `is_lost` first: `check` drains the errors of submitted work, which must stay for
        // the caller when the device is not lost.
        if !self.ctx.is_lost() {
            return e;
        }
        match self.ctx.check() {
            Err(lost @ terrain_gpu::GpuError::DeviceLost { .. }) => {
                anyhow::Error::new(lost).context("the GPU frame stopped")
            }
            _ => e,
        }
    }

    /// Runs `apply` (terrain-cache's `TileStamps::apply`, say) with the atlas's deformer
    /// (terrain-gpu's `AtlasDeformer`: each stamp in its tile's slot, the changed rect read
    /// back), its submits timed as [`Step::StampGpu`]. Returns what `apply` returned and the
    /// milliseconds spent in those submits.
    pub fn with_tile_deformer<R>(
        &mut self,
        timings: &mut Timings,
        apply: impl FnOnce(&mut terrain_gpu::AtlasDeformer<'_>) -> R,
    ) -> Result<(R, f64)> {
        let ctx = &self.ctx;
        let (Some(atlas), Some(stamper)) = (&self.atlas, self.tile_stamper.as_mut()) else {
            anyhow::bail!("stamping tiles needs the tile atlas (enable_atlas)");
        };
        let mut submit = granular::TimedSubmit::new(ctx, &mut self.timer, timings);
        let mut deformer = terrain_gpu::AtlasDeformer {
            device: &ctx.device,
            queue: &ctx.queue,
            atlas,
            stamper,
            submit: Some(&mut submit),
        };
        let applied = apply(&mut deformer);
        let spent = submit.spent_ms();
        // wgpu maps a staging buffer even when the commands before it were invalid: the
        // stamps' rects would then deliver stale bytes into the world. Refuse the frame.
        let checked = self.ctx.check();
        checked
            .map_err(|e| self.lost_or(e.into()))
            .context("stamping a tile of the streamed world")?;
        Ok((applied, spent))
    }

    /// The rects of deformed atlas tiles that have arrived, never waiting; with `wait`, waits
    /// for every one in flight (the end of the run).
    pub fn tile_readbacks(&mut self, wait: bool) -> Result<Vec<ArrivedTileRect>> {
        self.tile_readbacks_inner(wait).map_err(|e| self.lost_or(e))
    }

    /// Applies `plan` on the GPU and regenerates the normals, timed as [`Step::StampGpu`] and
    /// [`Step::NormalsGpu`]; returns the rects covered, each with the index of its deformation.
    pub fn deform(
        &mut self,
        plan: &FramePlan,
        crater: &terrain_core::GaussianStamp,
        timings: &mut Timings,
    ) -> Result<Vec<(usize, DirtyRect)>> {
        self.deform_inner(plan, crater, timings)
            .map_err(|e| self.lost_or(e))
    }

    /// One step of the collision readback: the scheduler requests merged dirty regions of the
    /// GPU map after the quiet gap and applies those that arrived to `mirror`, never waiting.
    pub fn update_collision(
        &mut self,
        scheduler: &mut ReadbackScheduler,
        mirror: &CollisionMirror,
        now: std::time::Instant,
    ) -> Result<UpdateReport> {
        self.update_collision_inner(scheduler, mirror, now)
            .map_err(|e| self.lost_or(e))
    }

    /// Reads back every region `scheduler` still has dirty or in flight, quiet gap or not,
    /// and waits until `mirror` holds them: the end of a run, so that the CPU's copy of the
    /// map is the GPU's. Bounded by `timeout`.
    pub fn flush_collision(
        &mut self,
        scheduler: &mut ReadbackScheduler,
        mirror: &CollisionMirror,
        timeout: std::time::Duration,
    ) -> Result<UpdateReport> {
        let mut source = self.map_source();
        scheduler
            .flush(&mut source, mirror, timeout)
            .context("reading the GPU map's last deformations back")
            .map_err(|e| self.lost_or(e))
    }

    /// Renders the terrain from `camera` and reads the image back, timed as [`Step::Lod`],
    /// [`Step::Render`] and [`Step::Capture`].
    pub fn render(&mut self, camera: &Camera, timings: &mut Timings) -> Result<RenderedFrame> {
        self.render_inner(camera, timings)
            .map_err(|e| self.lost_or(e))
    }

    /// Uploads `map` and builds every pass, rendering at `resolution`, with `readback_ring`
    /// collision readbacks in flight at most.
    pub fn new(map: &CoarseMap, resolution: UVec2, readback_ring: usize) -> Result<Self> {
        let ctx = GpuContext::new_headless().context("no GPU adapter for the 3D frames")?;
        let (device, queue) = (&ctx.device, &ctx.queue);
        let ground = DeformableMap::new(device, queue, map)?;
        let target = OffscreenTarget::new(device, resolution)?;
        let layout = ClipmapLayout::new(CLIPMAP_N, CLIPMAP_LEVELS)?;
        let (lo, hi) = map.encoding().range::<u16>();
        let timer = FrameTimer::new(&ctx);
        tracing::info!(mode = ?timer.mode(), "GPU steps timed");
        Ok(Self {
            ground,
            sky: SkyPass::new(device, &target.format())?,
            terrain: TerrainRenderer::clipmap(device, &target.format(), layout, (lo, hi))?,
            target,
            footprint: None,
            shock: None,
            readback: RegionReadback::new(device, readback_ring)?,
            timer,
            height_range: (lo, hi),
            granular: None,
            trails: None,
            atlas: None,
            tile_stamper: None,
            detail: None,
            refined: None,
            paint: None,
            holes: None,
            streamed_paint: None,
            streamed_color: None,
            frames: 0,
            destroy_at: std::env::var(DESTROY_DEVICE_ENV)
                .ok()
                .and_then(|v| v.parse().ok()),
            style: TerrainStyle {
                ramp: (lo, hi),
                fog_density: 0.008,
                ..TerrainStyle::default()
            },
            ctx,
        })
    }

    /// Uploads the footprint texture stamp that [`StampKind::Footprint`] deformations use.
    pub fn set_footprint(&mut self, footprint: &TextureStamp) -> Result<()> {
        self.footprint = Some(GpuTextureStamp::new(&self.ctx.device, footprint)?);
        Ok(())
    }

    /// Applies the configured light and fog colour, and the fog density and colour ramp where
    /// the configuration sets them (over what the scenario chose).
    pub fn apply_style(&mut self, style: &crate::config::StyleParams) {
        self.style.light_dir = style.light_dir;
        self.style.fog_color = style.fog_color;
        if let Some(d) = style.fog_density {
            self.style.fog_density = d;
        }
        if let Some(r) = style.ramp_m {
            self.style.ramp = (r.x, r.y);
        }
        self.style.shading = match style.shading {
            crate::config::ShadingParam::Materials => terrain_gpu::SurfaceShading::Materials,
            crate::config::ShadingParam::Ramp => terrain_gpu::SurfaceShading::Ramp,
        };
        self.style.materials.scale_m = style.material_scale_m;
    }

    /// Draws `colors` (one RGBA8 texel per map texel: `--color`) as the terrain's albedo.
    pub fn set_color_layer(&mut self, colors: &Grid<[u8; 4]>) -> Result<()> {
        let layer = terrain_gpu::GpuColorLayer::new(&self.ctx.device, &self.ctx.queue, colors)?;
        self.terrain.set_color_layer(Some(&layer));
        if let Some(refined) = self.refined.as_mut() {
            refined.renderer.set_color_layer(Some(&layer));
        }
        Ok(())
    }

    /// Sets the fog's density per metre (the terrain fades to the fog colour with distance).
    pub fn set_fog(&mut self, density: f32) {
        self.style.fog_density = density;
    }

    /// Draws the map once, as an island in the sky, instead of with its toroidal repeats: for
    /// cameras that frame the whole map.
    pub fn hide_outside_map(&mut self, hide: bool) {
        self.style.hide_outside_map = hide;
    }

    /// How far the clipmap reaches from the camera, metres: its coarsest level's half side.
    pub fn clipmap_reach_m(&self) -> f32 {
        let levels = self
            .terrain
            .clipmap_layout()
            .map_or(CLIPMAP_LEVELS, ClipmapLayout::levels);
        (CLIPMAP_N - 1) as f32 / 2.0
            * (1u32 << (levels - 1)) as f32
            * self.ground.heights().texel_size()
    }

    /// Makes the clipmap reach `radius` metres around the camera (its coarsest level's half
    /// side): levels are added to the default [`CLIPMAP_LEVELS`], up to terrain-lod's
    /// maximum, each doubling the reach. For cameras that see a whole map from afar.
    pub fn reach(&mut self, radius: f32) -> Result<()> {
        let levels = terrain_lod::clipmap_levels_to_reach(
            CLIPMAP_N,
            radius,
            self.ground.heights().texel_size(),
            CLIPMAP_LEVELS,
        );
        let now = self.terrain.clipmap_layout().map(ClipmapLayout::levels);
        if now.is_some_and(|n| n != levels) {
            let layout = ClipmapLayout::new(CLIPMAP_N, levels)?;
            let (device, format) = (&self.ctx.device, self.target.format());
            let terrain = TerrainRenderer::clipmap(device, &format, layout, self.height_range)?;
            self.set_terrain(terrain);
        }
        Ok(())
    }

    /// Sets the heights (metres) the colour ramp spans: below `low` is valley green, above
    /// `high` snow white.
    pub fn set_ramp(&mut self, low: f32, high: f32) {
        self.style.ramp = (low, high);
    }

    /// Draws a streamed world from now on: a tile atlas of `config` (slots, the world's tile
    /// layout) that a VRAM pool fills through [`GpuScene::atlas_mut`].
    pub fn enable_atlas(&mut self, config: &AtlasConfig) -> Result<()> {
        let atlas = GpuTileAtlas::new(&self.ctx.device, &self.ctx.queue, config)?;
        let enc = config.world.encoding;
        self.height_range = (enc.to_metres(0.0), enc.to_metres(f64::from(u16::MAX)));
        self.terrain.set_height_range(self.height_range);
        self.atlas = Some(atlas);
        self.tile_stamper = Some(AtlasStamper::new(&self.ctx.device, TILE_READBACK_RING)?);
        Ok(())
    }

    fn tile_readbacks_inner(&mut self, wait: bool) -> Result<Vec<ArrivedTileRect>> {
        let device = &self.ctx.device;
        let Some(stamper) = self.tile_stamper.as_mut() else {
            return Ok(Vec::new());
        };
        Ok(if wait {
            stamper.wait(device)?
        } else {
            stamper.poll(device)?
        })
    }

    /// The tile atlas, when a streamed world is drawn.
    pub fn atlas_mut(&mut self) -> Option<&mut GpuTileAtlas> {
        self.atlas.as_mut()
    }

    /// The GPU's coarse-map, downloaded (waits for the GPU): for tests that compare the CPU's
    /// copy with the truth.
    #[cfg(test)]
    pub fn read_map(&self) -> Result<CoarseMap> {
        Ok(self.ground.read(&self.ctx.device, &self.ctx.queue)?)
    }

    /// The GPU objects alive on the device now.
    pub fn live_objects(&self) -> GpuObjects {
        let hal = self.ctx.device.get_internal_counters().hal;
        GpuObjects {
            buffers: hal.buffers.read(),
            textures: hal.textures.read(),
            bind_groups: hal.bind_groups.read(),
            shader_modules: hal.shader_modules.read(),
            pipelines: hal.render_pipelines.read() + hal.compute_pipelines.read(),
        }
    }

    /// How the GPU steps are timed: timestamps read back a frame or more later (no wait), or
    /// the wall time of submit and wait per step; report.json's `gpu_timing`.
    pub fn gpu_timing(&self) -> GpuTiming {
        self.timer.mode()
    }

    /// The end of the run: waits (bounded) for the GPU timestamps still on their way and
    /// returns their figures, each for the frame it belongs to (none in wall mode).
    pub fn flush_gpu_timings(&mut self) -> Result<Vec<GpuFigure>> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        self.timer
            .flush(device, queue)
            .context("reading the last GPU timestamps back")
            .map_err(|e| self.lost_or(e))
    }

    /// Frames rendered so far: the index of the frame being prepared.
    pub fn frames_rendered(&self) -> u64 {
        u64::from(self.frames)
    }

    /// The adapter's name and backend.
    pub fn adapter(&self) -> (String, String) {
        let r = self.ctx.report();
        (r.name.clone(), r.backend.clone())
    }

    fn deform_inner(
        &mut self,
        plan: &FramePlan,
        crater: &terrain_core::GaussianStamp,
        timings: &mut Timings,
    ) -> Result<Vec<(usize, DirtyRect)>> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        if let Some(delta) = &plan.shock_delta {
            match &mut self.shock {
                Some(shock) => shock.update(device, queue, delta)?,
                None => self.shock = Some(GpuTextureStamp::new(device, delta)?),
            }
        }
        let shock = plan.shock_delta.as_ref().and(self.shock.as_ref());
        let mut dirty = Vec::new();
        let in_detail = self.detail.is_some();
        let stamp_time = self.timer.time(device, queue, Step::StampGpu, |encoder| {
            for (i, d) in plan.deformations.iter().enumerate() {
                if in_detail && d.kind == StampKind::Footprint {
                    continue;
                }
                let stamp = match (d.kind, &shock) {
                    (StampKind::Footprint, _) => match &self.footprint {
                        Some(f) => GpuStamp::Texture(f),
                        None => continue,
                    },
                    (StampKind::Crater, _) => GpuStamp::Gaussian(crater),
                    (StampKind::Shockwave, Some(s)) => GpuStamp::Texture(s),
                    (StampKind::Shockwave, None) => continue,
                };
                let op = StampOp {
                    stamp,
                    placement: d.placement,
                    blend: terrain_core::Blend::Add,
                };
                let rects = self.ground.encode_stamp(device, queue, encoder, &op)?;
                if let Some(paint) = self.paint.as_mut() {
                    let map = self.ground.heights();
                    paint.encode(device, queue, encoder, map, d.kind, &d.placement)?;
                }
                dirty.extend(rects.into_iter().map(|r| (i, r)));
            }
            Ok(())
        })?;
        let normal_time = self
            .timer
            .time(device, queue, Step::NormalsGpu, |encoder| {
                let rects: Vec<DirtyRect> = dirty.iter().map(|(_, r)| *r).collect();
                self.ground.encode_normals(device, queue, encoder, &rects)
            })?;
        // Footprints into the detail tiles, as one more submit (a stamp on the GPU, timed as
        // the others).
        if let (Some(detail), Some(foot)) = (self.detail.as_mut(), self.footprint.as_ref()) {
            let mut texels = 0;
            let time = self.timer.time(device, queue, Step::StampGpu, |encoder| {
                for (i, d) in plan
                    .deformations
                    .iter()
                    .enumerate()
                    .filter(|(_, d)| d.kind == StampKind::Footprint)
                {
                    let op = StampOp {
                        stamp: GpuStamp::Texture(foot),
                        placement: d.placement,
                        blend: terrain_core::Blend::Add,
                    };
                    // What leaves the tiles' range spills into the coarse-map, whose
                    // normals follow it; its rects go to collision with the others.
                    let (coarse, stamps) = self.ground.stamp_target();
                    let out = detail.spill.encode(
                        device,
                        queue,
                        encoder,
                        stamps,
                        terrain_gpu::SpillTargets {
                            tiles: detail.stream.tiles_mut(),
                            coarse,
                        },
                        &op,
                    )?;
                    texels += out.detail.iter().map(|(_, r)| r.area()).sum::<u64>();
                    if let Some(paint) = self.paint.as_mut() {
                        let map = self.ground.heights();
                        paint.encode(device, queue, encoder, map, d.kind, &d.placement)?;
                    }
                    // Back to the CPU through the ring, recorded after the stamp.
                    detail.stream.request(device, encoder, out.detail)?;
                    self.ground
                        .encode_normals(device, queue, encoder, &out.coarse)?;
                    dirty.extend(out.coarse.into_iter().map(|r| (i, r)));
                }
                Ok(())
            })?;
            detail.spill.recall();
            detail.dirty_texels = texels;
            time.record(timings);
        }
        // Every submit is done: the passes' uniform slots are free again.
        self.ground.recall();
        if let Some(paint) = self.paint.as_mut() {
            paint.recall();
        }
        stamp_time.record(timings);
        normal_time.record(timings);
        Ok(dirty)
    }

    /// The coarse-map as a region source through the collision readback's ring.
    fn map_source(&mut self) -> GpuRegionSource<'_> {
        GpuRegionSource::new(
            &self.ctx.device,
            &self.ctx.queue,
            self.ground.heights(),
            &mut self.readback,
        )
    }

    fn update_collision_inner(
        &mut self,
        scheduler: &mut ReadbackScheduler,
        mirror: &CollisionMirror,
        now: std::time::Instant,
    ) -> Result<UpdateReport> {
        // A busy readback ring is back-pressure: the rects stay dirty and are requested
        // once a buffer is free (`RegionSource::is_busy`).
        let mut source = self.map_source();
        Ok(scheduler.update(now, &mut source, mirror)?)
    }

    fn render_inner(&mut self, camera: &Camera, timings: &mut Timings) -> Result<RenderedFrame> {
        if self.destroy_at == Some(self.frames) {
            self.ctx.device.destroy();
        }
        let index = u64::from(self.frames);
        self.frames += 1;
        // A lost device reports nothing for the work sent to it: stop here with the reason.
        self.ctx.check().context("rendering a frame")?;
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let size = self.target.size();
        let aspect = size.x as f32 / size.y as f32;
        // A streamed world is drawn from its atlas (even while a granular window steps on the
        // GPU: the window's areas reach the atlas through the tiles they are handed back to),
        // and its detail layer if any, else the granular map, else the coarse-map with its
        // detail layer if any.
        let surface = match (&self.atlas, &self.granular, &self.detail) {
            // A streamed world's footprints (the world scenario's `--detail`).
            (Some(atlas), _, Some(d)) => ClipmapSurface::AtlasDetail {
                atlas,
                detail: d.stream.tiles(),
                shading: &d.shading,
            },
            (Some(atlas), ..) => ClipmapSurface::Atlas { atlas },
            (None, Some(g), _) => ClipmapSurface::Granular {
                map: g.map(),
                surface: g.normals().buffer(),
            },
            (None, None, Some(d)) => ClipmapSurface::Detail {
                map: self.ground.heights(),
                normals: self.ground.normals(),
                detail: d.stream.tiles(),
                shading: &d.shading,
            },
            (None, None, None) => ClipmapSurface::Coarse {
                map: self.ground.heights(),
                normals: self.ground.normals(),
            },
        };
        let view = TerrainView {
            surface,
            camera,
            style: &self.style,
            target_size: size,
        };
        let mut drawn = None;
        let (mut lod_ms, mut lod_cpu_ms) = (0.0, None);
        let timing = self.timer.time(device, queue, Step::Render, |encoder| {
            self.sky.prepare(
                queue,
                camera.view_proj_relative(aspect),
                &SkyColors::default(),
            )?;
            // `--detail refine`: the cells near the camera refined first, the clipmap leaving
            // them out.
            let refined = match (self.refined.as_mut(), self.detail.as_ref()) {
                (Some(r), Some(_)) => {
                    // The frame's surface: the coarse-map's or the world's atlas, with detail.
                    let draw = RefineDraw {
                        surface,
                        radius_m: r.radius_m,
                        camera,
                        style: &self.style,
                        target_size: size,
                    };
                    let v = r.pass.encode(device, queue, encoder, &draw)?;
                    // The report's count rides this submit back (no wait of its own).
                    r.pass.request_count(encoder)?;
                    r.renderer.prepare(device, queue, &draw, &r.pass)?;
                    self.terrain.exclude(Some(v.region()));
                    Some(&*r)
                }
                _ => None,
            };
            // The LOD's selection is CPU work: timed as `lod`, not in the GPU's `render`; the
            // report's figures (the tessellation's CPU reference) are not timed.
            let clock = crate::timings::Clock::start();
            self.terrain.prepare(device, queue, encoder, &view)?;
            (lod_ms, lod_cpu_ms) = (clock.wall_ms(), clock.cpu_ms());
            timings.add(Step::Lod, lod_ms);
            drawn = Some(self.terrain.figures(&view)?);
            let mut pass = self.target.begin_pass(encoder, wgpu::Color::BLACK);
            self.sky.draw(&mut pass);
            self.terrain.draw(&mut pass);
            // A frame whose LOD could not leave the cells out (near a cliff, or where a streamed
            // quadtree's bounds are still a tile's) draws them itself.
            if let Some(r) = refined.filter(|_| self.terrain.excluding()) {
                r.renderer.draw(&mut pass, &r.pass);
            }
            Ok(())
        })?;
        self.terrain.recall();
        // The render was the frame's last timed step.
        self.timer.end_frame(device, queue)?;
        let clock = crate::timings::Clock::start();
        let image = self.target.read_rgba8(device, queue)?;
        self.ctx.check()?;
        timings.add_since(Step::Capture, clock);
        timing.excluding(lod_ms, lod_cpu_ms).record(timings);
        // The capture has waited for the GPU, so this frame's timestamps have usually arrived
        // too (else a later frame credits them to this one).
        self.timer.poll(device, index, timings)?;
        let drawn = drawn.context("the frame was not prepared")?;
        // The refined cells are drawn instead of the clipmap's (which still counts them).
        // The capture has waited for the frame, so its count has usually arrived; else the
        // last one that did.
        let drew_refined = self.terrain.excluding();
        let refined = match self.refined.as_mut() {
            Some(r) => {
                if let Some((count, _)) = r.pass.poll_count(device)? {
                    r.last_count = count;
                }
                if drew_refined {
                    u64::from(r.last_count)
                } else {
                    0
                }
            }
            None => 0,
        };
        Ok(RenderedFrame {
            image,
            triangles: drawn.triangles + refined,
            lod: LodStats {
                mode: drawn.mode,
                vertices: drawn.vertices,
                max_screen_error_px: drawn.max_screen_error_px,
                refined: self.refined.as_ref().map(|_| drew_refined),
            },
        })
    }
}
