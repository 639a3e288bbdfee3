//! The GPU side of a demo frame: stamps and normals on the GPU map, clipmap placement, sky and
//! terrain rendering, capture. Glue only: every step is a library call. This is the one file of
//! the demo that calls terrain-gpu; the rest sees [`GpuScene`] and [`Camera`].

use anyhow::{Context, Result};
use glam::{UVec2, Vec2};
use terrain_core::{CoarseMap, DirtyRect, Grid, TextureStamp};
use terrain_gpu::{
    ClipmapRenderer, ClipmapSurface, ClipmapView, GpuContext, GpuDerivativeMap, GpuHeightMap,
    GpuRegionSource, GpuStamp, GpuTextureStamp, GpuTimer, GpuTiming, NormalPass, OffscreenTarget,
    RegionReadback, SkyColors, SkyPass, StampOp, StampPass, TerrainStyle,
};
use terrain_lod::{ClipmapLayout, Frustum};
use terrain_physics::{CollisionMirror, ReadbackScheduler, UpdateReport};

use crate::report::GpuObjects;
use crate::scenarios::{FramePlan, StampKind};
use crate::timings::{Step, Timings};

pub use terrain_gpu::Camera;

/// Clipmap vertices per level side (seed 000 sec 3.3 uses 255).
pub const CLIPMAP_N: u32 = 255;
/// Clipmap levels, the inner grid included: 5 levels of N = 255 span 406 m at 0.1 m per texel,
/// about twice the default map, so the toroidal repeat stays in the fog.
pub const CLIPMAP_LEVELS: u32 = 5;

/// Everything that lives on the GPU for the demo.
pub struct GpuScene {
    ctx: GpuContext,
    map: GpuHeightMap<u16>,
    normals: GpuDerivativeMap,
    stamps: StampPass,
    normal_pass: NormalPass,
    sky: SkyPass,
    renderer: ClipmapRenderer,
    layout: ClipmapLayout,
    target: OffscreenTarget,
    footprint: Option<GpuTextureStamp>,
    /// The shockwave's change of the frame, rewritten in place each frame.
    shock: Option<GpuTextureStamp>,
    readback: RegionReadback,
    timer: GpuTimer,
    style: TerrainStyle,
    /// Lowest and highest height the map can hold (metres): the culling boxes' vertical extent.
    height_range: (f32, f32),
}

/// One rendered frame.
pub struct RenderedFrame {
    /// The captured image.
    pub image: Grid<[u8; 4]>,
    /// Non-degenerate triangles drawn.
    pub triangles: u64,
}

/// Records a GPU timing as `step`.
fn record(timings: &mut Timings, step: Step, t: GpuTiming) {
    timings.add_gpu(step, t.ms, t.timestamp_ms);
}

impl GpuScene {
    /// Uploads `map` and builds every pass, rendering at `resolution`.
    pub fn new(map: &CoarseMap, resolution: UVec2) -> Result<Self> {
        let ctx = GpuContext::new_headless().context("no GPU adapter for the 3D frames")?;
        let (device, queue) = (&ctx.device, &ctx.queue);
        let gpu_map = GpuHeightMap::from_map(device, queue, map)?;
        let normals = GpuDerivativeMap::for_map(device, &gpu_map)?;
        let mut normal_pass = NormalPass::new(device)?;
        let mut encoder = device.create_command_encoder(&Default::default());
        normal_pass.encode_full(device, queue, &mut encoder, &gpu_map, &normals)?;
        queue.submit([encoder.finish()]);
        normal_pass.recall();
        let target = OffscreenTarget::new(device, resolution)?;
        let layout = ClipmapLayout::new(CLIPMAP_N, CLIPMAP_LEVELS)?;
        let (lo, hi) = map.encoding().range::<u16>();
        Ok(Self {
            map: gpu_map,
            normals,
            stamps: StampPass::new(device)?,
            normal_pass,
            sky: SkyPass::new(device, &target.format())?,
            renderer: ClipmapRenderer::new(device, &target.format(), &layout)?,
            layout,
            target,
            footprint: None,
            shock: None,
            readback: RegionReadback::new(device, 4)?,
            timer: GpuTimer::new(device, queue),
            height_range: (lo, hi),
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

    /// Sets the heights (metres) the colour ramp spans: below `low` is valley green, above
    /// `high` snow white.
    pub fn set_ramp(&mut self, low: f32, high: f32) {
        self.style.ramp = (low, high);
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

    /// The adapter's name and backend.
    pub fn adapter(&self) -> (String, String) {
        let r = self.ctx.report();
        (r.name.clone(), r.backend.clone())
    }

    /// Applies `plan` on the GPU and regenerates the normals, timed as [`Step::Stamp`] and
    /// [`Step::Normals`]; returns the rects covered, each with the index of its deformation.
    pub fn deform(
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
        let stamp_time = self.timer.time(device, queue, |encoder| {
            for (i, d) in plan.deformations.iter().enumerate() {
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
                let rects = self.stamps.encode(device, queue, encoder, &self.map, &op)?;
                dirty.extend(rects.into_iter().map(|r| (i, r)));
            }
            Ok(())
        })?;
        let normal_time = self.timer.time(device, queue, |encoder| {
            for (_, r) in &dirty {
                self.normal_pass
                    .encode(device, queue, encoder, &self.map, &self.normals, *r)?;
            }
            Ok(())
        })?;
        // Both submits are done: the passes' uniform slots are free again.
        self.stamps.recall();
        self.normal_pass.recall();
        record(timings, Step::Stamp, stamp_time);
        record(timings, Step::Normals, normal_time);
        Ok(dirty)
    }

    /// Replaces the GPU map with `map` (same size) and recomputes its normals: for maps
    /// deformed on the CPU (the snow scenario's granular simulation); timed as [`Step::Normals`].
    pub fn upload(&mut self, map: &CoarseMap, timings: &mut Timings) -> Result<()> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        self.map.write(queue, map)?;
        let timing = self.timer.time(device, queue, |encoder| {
            self.normal_pass
                .encode_full(device, queue, encoder, &self.map, &self.normals)
        })?;
        self.normal_pass.recall();
        record(timings, Step::Normals, timing);
        Ok(())
    }

    /// One step of the collision readback: the scheduler requests merged dirty regions of the
    /// GPU map after the quiet gap and applies those that arrived to `mirror`, never waiting.
    pub fn update_collision(
        &mut self,
        scheduler: &mut ReadbackScheduler,
        mirror: &CollisionMirror,
        now: std::time::Instant,
    ) -> Result<UpdateReport> {
        let mut source = GpuRegionSource::new(
            &self.ctx.device,
            &self.ctx.queue,
            &self.map,
            &mut self.readback,
        );
        Ok(scheduler.update(now, &mut source, mirror)?)
    }

    /// Renders the terrain from `camera` and reads the image back, timed as [`Step::Lod`],
    /// [`Step::Render`] and [`Step::Capture`].
    pub fn render(&mut self, camera: &Camera, timings: &mut Timings) -> Result<RenderedFrame> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let size = self.target.size().as_vec2();
        let aspect = size.x / size.y;
        let t = std::time::Instant::now();
        let frustum = Frustum::from_view_proj(camera.view_proj_world(aspect));
        let placement = self.layout.place(
            Vec2::new(camera.position.x, camera.position.z),
            self.map.texel_size(),
            self.height_range,
            Some(&frustum),
        )?;
        timings.add(Step::Lod, crate::timings::ms_since(t));
        let view_proj = camera.view_proj_relative(aspect);
        let sky_colors = SkyColors::default();
        let view = ClipmapView {
            surface: ClipmapSurface::Coarse {
                map: &self.map,
                normals: &self.normals,
            },
            frame: &placement,
            camera,
            style: &self.style,
            target_size: self.target.size(),
        };
        let timing = self.timer.time(device, queue, |encoder| {
            self.sky.prepare(queue, view_proj, &sky_colors)?;
            self.renderer.prepare(device, queue, &view)?;
            let mut pass = self.target.begin_pass(encoder, wgpu::Color::BLACK);
            self.sky.draw(&mut pass);
            self.renderer.draw(&mut pass);
            Ok(())
        })?;
        let t = std::time::Instant::now();
        let image = self.target.read_rgba8(device, queue)?;
        self.ctx.check()?;
        timings.add(Step::Capture, crate::timings::ms_since(t));
        record(timings, Step::Render, timing);
        Ok(RenderedFrame {
            image,
            triangles: placement.triangle_count(self.layout.mesh()),
        })
    }
}
