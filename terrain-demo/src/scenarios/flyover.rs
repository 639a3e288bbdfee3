//! The flyover scenario (`--scenario flyover`): a camera flies, then drives, over a streamed
//! world larger than the cache budgets (built once into `--world`), and stamps craters on its
//! path. terrain-cache's `RamPool` streams the tiles around the camera on worker threads and,
//! with a GPU, its `VramPool` keeps the nearest in the atlas the frame is drawn from.
//!
//! A crater changes every level-0 tile it touches, through terrain-cache's `TileStamps`: on the
//! GPU where the tile is in the atlas (stamped in its slot, the changed rect read back into the
//! RAM tile; the VRAM pool holds the slot and the RAM pool pins the tile until it arrives),
//! else on the CPU in RAM. Changed tiles are written back into the world (atomically, off the
//! frame thread) when evicted and at the end, so a second run starts from the deformed world.
//!
//! On frame [`HOLE_FRAME`] a hole is cut beside the path into the world's hole tiles, and the
//! craters paint dirt into its material tiles, both written by a thread of their own
//! (`world_overlays`); collision and the GPU's frames follow, in this run and the next. With a
//! GPU the paint (and a colour layer, where the world has one) streams into overlay atlases
//! with the heights' selection (`OverlayStream`), the VRAM budget split into slots of heights
//! and overlays.
//!
//! The world scenario's `--detail`: a walker's footprints in the world's detail tiles
//! (`world_detail`), under the camera's ground too.
//!
//! Collision follows the camera: a `CollisionWindow` of [`COLLISION_WINDOW`] texels filled from
//! the RAM pool (coarser data where a level-0 tile is not loaded yet, refilled when it is)
//! and updated by every crater's changed rects; the camera's ground is read from it.
//!
//! The overview shows an overview level of the world (the level whose side is at most
//! [`OVERVIEW_MAX`] texels), with the cache's tile states and the camera's view over it. It is
//! never stamped: each level-0 rect that changed in RAM (stamped there, or read back from the
//! GPU) is reduced to the overview level as the pyramid is built (`reduce_levels`), and at the
//! end it is reloaded from the world.

use super::tile_overlay;
use super::trails::Trails;
use super::world_detail::WorldDetail;
use super::world_files;
use super::world_overlays::WorldOverlays;
use super::world_stamps::{WorldShock, reach};

#[path = "world_lod.rs"]
mod world_lod;
use super::{FrameContext, FrameOutcome, Scenario, ScenarioInfo};
use crate::cli::Cli;
use crate::gpu_scene::{AtlasConfig, Camera, GpuScene};
use crate::images::Image;
use crate::report::{CacheStats, FrameStats};
use crate::timings::{Step, ms_since};
use crate::usage_error::usage;
use anyhow::{Context, Result, bail};
use glam::{UVec2, Vec2, Vec3};
use std::time::{Duration, Instant};
use terrain_cache::{
    CameraState, Layer, Manifest, RamPool, RegionBounds, StreamedWorld, TileId, WindowFill,
};
use terrain_core::{
    CoarseMap, DirtyRect, GaussianStamp, Rect, StampPlacement, TileStamp, WrapMode,
};
use terrain_lod::{CdlodConfig, TessConfig};
use terrain_physics::CollisionWindow;

/// Longest side of the overview level in texels.
pub const OVERVIEW_MAX: u32 = 1024;
/// Seconds of flight before the camera comes down to drive.
const FLY_SECONDS: f32 = 0.6;
/// Eye height above ground while flying and while driving (metres).
const FLY_HEIGHT: f32 = 80.0;
const DRIVE_HEIGHT: f32 = 2.5;
/// A crater every this many frames, this far ahead of the camera (metres), this wide and deep.
const CRATER_EVERY: u32 = 6;
const CRATER_AHEAD: f32 = 30.0;
const CRATER_SIZE: f32 = 12.0;
const CRATER_DEPTH: f32 = -2.0;
/// The frame a hole is cut, this far ahead (metres) and to the side opposite the craters,
/// this wide.
pub const HOLE_FRAME: u32 = 8;
const HOLE_AHEAD: f32 = 25.0;
const HOLE_ASIDE: f32 = 10.0;
const HOLE_SIZE: f32 = 12.0;
/// Side of the collision window around the camera (level-0 texels).
pub const COLLISION_WINDOW: u32 = 512;
/// How long the end of the run may wait for the last write-backs.
const SHUTDOWN_TIMEOUT: Duration = Duration::from_secs(60);

/// How far ahead of the camera the world scenario's vehicle drives (metres).
const VEHICLE_AHEAD: f32 = 14.0;
/// How far ahead of the camera, and to the side opposite the craters, the world scenario's
/// walker leaves footprints (`--detail`; metres).
const WALKER_AHEAD: f32 = 16.0;
const WALKER_ASIDE: f32 = 3.0;
/// The world scenario's eye height above ground (metres): high enough to see the tracks.
const WORLD_EYE_HEIGHT: f32 = 5.0;
/// The world scenario's craters land this far to the side of the path (metres), clear of the
/// granular window around the vehicle.
const CRATER_ASIDE: f32 = 48.0;

/// The flyover scenario.
#[derive(Debug)]
pub struct FlyoverScenario {
    info: ScenarioInfo,
    /// The world scenario's granular trails (`--scenario world`), `None` for the flyover.
    trails: Option<Trails>,
    /// Craters not stamped because they would land in the granular window.
    craters_skipped: u32,
    /// The world scenario's shockwave, `None` for the flyover.
    shock: Option<WorldShock>,
    /// The world scenario's footprints in detail tiles (`--detail`), and how they are drawn.
    detail: Option<WorldDetail>,
    detail_mode: crate::cli::DetailArg,
    /// With `--lod cdlod` or `tessellated`: the level-0 bounds the GPU scene's quadtree is kept
    /// current from.
    bounds: Option<RegionBounds>,
    /// The world's pools (with a GPU, its VRAM pool and its paint's and colour's streams) and
    /// the craters on their way into its tiles; `None` once finished.
    streamed: Option<StreamedWorld>,
    manifest: Manifest,
    vram_budget: u64,
    tile_size: u32,
    texel_size: f32,
    /// The world's extent in metres.
    extent: Vec2,
    overview: CoarseMap,
    /// The world level the overview shows.
    overview_level: u32,
    /// Path: start, unit heading, speed (m/s).
    start: Vec2,
    heading: Vec2,
    speed: f32,
    frame: u32,
    /// Collision around the camera.
    window: CollisionWindow,
    /// Fills the window from the pool, refilling what coarser data stood in for.
    window_fill: WindowFill,
    /// The world's holes and paint around the camera.
    overlays: WorldOverlays,
    /// The camera of the last frame, for the overview's view lines.
    last_camera: Option<CameraState>,
    /// Milliseconds of this frame timed as their own steps (GPU stamps and granular steps,
    /// CDLOD updates), not cache work.
    gpu_stamp_ms: f64,
}

impl FlyoverScenario {
    /// Opens (or builds, from `heightmap` as the memory estimate measured it) the world and
    /// starts the RAM pool.
    pub fn new(
        cli: &Cli,
        params: &crate::config::DemoParams,
        heightmap: Option<super::heightmap::PlannedMap>,
    ) -> Result<Self> {
        let t = Instant::now();
        let (world, source, built_from) = world_files::open_or_build(cli, heightmap)?;
        let manifest = *world.manifest();
        if manifest.world_size.max_element() < manifest.tile_size {
            bail!(
                "the world in {} is smaller than one tile",
                cli.world.display()
            );
        }
        let overview_level = overview_level(&manifest);
        let overview = world.read_level(overview_level)?;
        let load_ms = ms_since(t);
        let budget = cli.ram_budget.saturating_mul(1 << 20);
        let overlays = WorldOverlays::new(&world)?;
        let world_scenario = cli.scenario == crate::cli::ScenarioKind::World;
        let detail = (world_scenario && cli.detail != crate::cli::DetailArg::None)
            .then(|| WorldDetail::open(&world))
            .transpose()?;
        let streamed = StreamedWorld::open(world, budget)?;
        let extent = manifest.world_size.as_vec2() * manifest.texel_size;
        let tile = manifest.tile_size;
        let window = CollisionWindow::new(
            COLLISION_WINDOW,
            manifest.world_size,
            manifest.encoding,
            manifest.texel_size,
        )?;
        let trails = match cli.scenario {
            crate::cli::ScenarioKind::World => Some(Trails::new(&manifest, params.granular)?),
            _ => None,
        };
        let shock = trails.as_ref().map(|_| WorldShock::new(params));
        Ok(Self {
            trails,
            shock,
            detail,
            detail_mode: cli.detail,
            bounds: None,
            craters_skipped: 0,
            info: ScenarioInfo {
                name: if cli.scenario == crate::cli::ScenarioKind::World {
                    "world"
                } else {
                    "flyover"
                },
                source,
                load_ms,
                // The overview shades from the heights: no normal map on the CPU.
                initial_normals_ms: 0.0,
                heights: Some(built_from.unwrap_or_else(|| {
                    super::heightmap::HeightsInfo::of_encoding(
                        overview.encoding(),
                        terrain_core::hillshade_range(&overview),
                        "world",
                    )
                })),
                camera: None,
            },
            streamed: Some(streamed),
            manifest,
            vram_budget: cli.vram_budget.saturating_mul(1 << 20),
            tile_size: tile,
            texel_size: manifest.texel_size,
            extent,
            overview,
            overview_level,
            start: extent * 0.3,
            heading: Vec2::new(1.0, 0.6).normalize(),
            speed: cli.speed,
            frame: 0,
            window,
            window_fill: WindowFill::new(&manifest),
            overlays,
            last_camera: None,
            gpu_stamp_ms: 0.0,
        })
    }

    fn streamed(&mut self) -> Result<&mut StreamedWorld> {
        self.streamed
            .as_mut()
            .ok_or_else(|| anyhow::anyhow!("the world's pools were shut down"))
    }

    fn pool(&self) -> Option<&RamPool> {
        self.streamed.as_ref().map(StreamedWorld::ram)
    }

    /// Ground height (metres) at `xz`: the coarse heights plus the footprints' detail, where
    /// the world scenario has them (the detail cache holds the camera's tiles).
    fn ground(&self, xz: Vec2) -> f32 {
        self.coarse_ground(xz) + self.detail.as_ref().map_or(0.0, |d| d.height_m(xz))
    }

    /// The coarse ground (metres) at `xz`: the collision window's, else the finest resident
    /// tile under it, else the overview's.
    fn coarse_ground(&self, xz: Vec2) -> f32 {
        let xz = xz.clamp(Vec2::ZERO, self.extent);
        // The window's texels where their tile is in RAM, else the finest level loaded.
        let stand_in = |t| self.window_fill.is_stand_in(t);
        if let Ok(Some(h)) = self.window.ground(xz, stand_in) {
            return h;
        }
        let pool = self.pool().and_then(|pool| pool.ground_m(xz));
        pool.unwrap_or_else(|| terrain_core::bilinear(&self.overview, xz).unwrap_or(0.0))
    }

    /// Level-0 tiles the frame needs now (those within half a tile of the camera: under it
    /// and what the near view and collision read) that are not in RAM, so coarser data stands
    /// in. Tiles further out that the selection wants are prefetches, not missing.
    fn tiles_missing(&self, xz: Vec2) -> usize {
        let half_tile = 0.5 * self.tile_size as f32 * self.texel_size;
        self.pool()
            .map_or(0, |pool| pool.missing_near(xz, half_tile))
    }

    /// Hands the rects of GPU-stamped tiles that arrived to the RAM pool through the tile
    /// stamps (the tile becomes dirty and is written back; its hold and pin end) and to the
    /// collision window; returns them in world texels.
    fn take_tile_readbacks(&mut self, scene: &mut GpuScene, wait: bool) -> Result<Vec<Rect>> {
        let mut arrived = Vec::new();
        for arrived_rect in scene.tile_readbacks(wait)? {
            let crate::gpu_scene::ArrivedTileRect {
                ticket,
                rect,
                heights,
            } = arrived_rect;
            let world = self.streamed()?.receive(ticket, rect, &heights)?;
            self.window.apply(world, &heights)?;
            arrived.push(world);
        }
        Ok(arrived)
    }

    /// Brings the overview level with the level-0 rects `changed` (world texels) in RAM: each
    /// rect grown to whole overview texels is reduced from the RAM pool's level 0, as the
    /// pyramid is built. Returns the overview rects redrawn. (A block reaching a tile not in
    /// RAM reads its coarser stand-in there; the overview is reloaded from the world at the
    /// end.)
    fn update_overview(&mut self, changed: &[Rect]) -> Result<Vec<DirtyRect>> {
        let Some(pool) = self.streamed.as_ref().map(StreamedWorld::ram) else {
            return Ok(Vec::new());
        };
        let mut redrawn = Vec::new();
        for r in changed {
            if let Some((at, reduced)) = pool.read_reduced(*r, self.overview_level)? {
                self.overview.grid_mut().paste(&reduced, at.min)?;
                redrawn.push(at);
            }
        }
        Ok(redrawn)
    }

    /// Moves the collision window with the camera, filling what comes into it from the RAM
    /// pool, and refills the parts filled from coarser data whose level-0 tile has loaded.
    fn update_window(&mut self, xz: Vec2) -> Result<()> {
        let Some(pool) = self.streamed.as_ref().map(StreamedWorld::ram) else {
            return Ok(());
        };
        self.window.follow(xz, &mut self.window_fill.over(pool))?;
        Ok(())
    }
}

/// The level shown in the overview: the finest whose side is at most [`OVERVIEW_MAX`].
pub fn overview_level(manifest: &Manifest) -> u32 {
    manifest.finest_level_within(OVERVIEW_MAX)
}

/// GPU bytes of one tile slot of the world `manifest` describes, across its atlases: heights
/// (2 bytes a texel), paint (4) and, `colored`, colour (4). The VRAM budget holds as many of
/// these as fit, so paint and colour stream within it.
pub fn vram_slot_bytes(manifest: &Manifest, colored: bool) -> u64 {
    let world = manifest.tile_layout();
    let heights = AtlasConfig { slots: 1, world }.slot_bytes();
    let overlay = world.tile_texels() * 4;
    heights + overlay * (1 + u64::from(colored))
}

impl Scenario for FlyoverScenario {
    fn info(&self) -> &ScenarioInfo {
        &self.info
    }

    fn map(&self) -> &CoarseMap {
        &self.overview
    }

    /// With a GPU the world is drawn from a tile atlas, and its paint (and colour) from overlay
    /// atlases, of as many slots as the VRAM budget holds ([`vram_slot_bytes`]), filled by the
    /// VRAM pools with one selection.
    fn prepare_gpu(&mut self, scene: &mut GpuScene) -> Result<()> {
        let world = self.manifest.tile_layout();
        let files = self.streamed()?.world().clone();
        let colored = !files.store().list(Layer::Color.folder())?.is_empty();
        let slot_bytes = vram_slot_bytes(&self.manifest, colored);
        let slots = u32::try_from(self.vram_budget / slot_bytes).unwrap_or(u32::MAX);
        if slots < 2 {
            return Err(usage(anyhow::anyhow!(
                "--vram-budget holds {slots} tile(s) of {} KiB: at least 2 are needed",
                slot_bytes >> 10
            )));
        }
        let too_large = |e: anyhow::Error| {
            // The adapter's buffers are smaller than the budget asks for: the user's to fix.
            let too_large = e.downcast_ref::<terrain_gpu::GpuError>().is_some_and(|g| {
                matches!(
                    g,
                    terrain_gpu::GpuError::MapTooLarge { .. } | terrain_gpu::GpuError::Core(_)
                )
            });
            let e = e.context(format!(
                "--vram-budget {} MiB: the tile atlases do not fit this adapter",
                self.vram_budget >> 20
            ));
            if too_large { usage(e) } else { e }
        };
        scene
            .enable_atlas(&AtlasConfig { slots, world })
            .map_err(too_large)?;
        scene
            .enable_streamed_layers(world, slots, colored)
            .map_err(too_large)?;
        // The paint streams with the heights; the colour too, where the world has one.
        self.streamed()?.enable_gpu(slots, true, colored)?;
        if let Some(detail) = &self.detail {
            let refine = self.detail_mode == crate::cli::DetailArg::Refine;
            scene.enable_detail(detail.layout(), refine)?;
        }
        Ok(())
    }

    /// CDLOD draws the world's level 0 from the atlas.
    fn cdlod_extent(&self) -> (UVec2, WrapMode, f32) {
        let m = &self.manifest;
        (m.world_size, m.wrap, m.texel_size)
    }

    /// CDLOD draws the world's quadtree (`world_lod`).
    fn enable_cdlod(&mut self, scene: &mut GpuScene, config: CdlodConfig) -> Result<()> {
        let tree = self.world_tree(config, "--lod cdlod")?;
        scene.enable_cdlod_tree(tree)
    }

    /// The tessellation is decided from the world's quadtree (`world_lod`); no density map.
    fn enable_tessellation(
        &mut self,
        scene: &mut GpuScene,
        config: TessConfig,
        _density: bool,
    ) -> Result<()> {
        let tree_config = terrain_lod::StreamedTessellation::tree_config(config.patch_size);
        let tree = self.world_tree(tree_config, "--lod tessellated")?;
        scene.enable_tessellation_tree(tree, config, self.manifest.encoding)
    }

    fn overlay(&self, overview: &Image) -> Option<Image> {
        let streamed = self.streamed.as_ref()?;
        let statuses = streamed.ram().statuses();
        let vram = streamed.vram();
        let active = |id: TileId| vram.is_some_and(|v| v.slot_of(id).is_some());
        Some(tile_overlay::draw(
            overview,
            &tile_overlay::OverlayInput {
                world_size: self.manifest.world_size,
                tile_size: self.tile_size,
                texel_size: self.texel_size,
                statuses: &statuses,
                active: &active,
                camera: self.last_camera,
            },
        ))
    }

    fn advance(&mut self, ctx: &mut FrameContext<'_>) -> Result<FrameOutcome> {
        let t_frame = Instant::now();
        self.gpu_stamp_ms = 0.0;
        let time = self.frame as f32 / 30.0;
        self.frame += 1;
        // Along a straight path, reflected at the world's edges so it stays inside.
        let travelled = self.start + self.heading * (self.speed * time);
        let xz = reflect_into(travelled, self.extent);
        let ahead = reflect_into(travelled + self.heading * 5.0, self.extent);
        let forward2 = (ahead - xz).normalize_or(self.heading);
        let ground = self.ground(xz);
        let height = match self.trails {
            Some(_) => WORLD_EYE_HEIGHT,
            None if time < FLY_SECONDS => FLY_HEIGHT,
            None => DRIVE_HEIGHT,
        };
        let eye = Vec3::new(xz.x, ground + height, xz.y);
        let look = Vec3::new(forward2.x, -0.18, forward2.y);
        let camera = Camera::looking(eye, look);

        // Craters on the path ahead, into the level-0 tiles as they are resident (persisted
        // by write-back).
        let mut crater = false;
        if self.frame.is_multiple_of(CRATER_EVERY) {
            // The world scenario's craters go beside the path, clear of the vehicle's trails.
            let aside = match self.trails {
                Some(_) => self.heading.perp() * CRATER_ASIDE,
                None => Vec2::ZERO,
            };
            let center = reflect_into(travelled + self.heading * CRATER_AHEAD + aside, self.extent);
            // Between 8 texels and one tile wide: a crater touches at most 4 tiles.
            let ts = self.texel_size;
            let size = CRATER_SIZE.clamp(8.0 * ts, self.tile_size as f32 * ts);
            let placement = StampPlacement::new(center, Vec2::splat(size), CRATER_DEPTH)?;
            // A granular window's tiles take no other writes while it lives.
            let keep_out = self.trails.as_ref().and_then(Trails::keep_out);
            if keep_out.is_some_and(|w| w.intersect(&reach(&placement, ts)).is_some()) {
                self.craters_skipped += 1;
            } else {
                let crater_stamp = TileStamp::Gaussian(GaussianStamp::default());
                crater = self.streamed()?.push(crater_stamp, placement)? > 0;
            }
            // Its dirt goes into the world's material tiles (on the overlays' writer thread).
            if crater {
                self.overlays
                    .paint(&placement, &crate::gpu_scene::CRATER_DIRT)?;
            }
        }
        // The world scenario's shockwave beside the path.
        let mut shock = false;
        if let Some(wave) = self.shock.as_mut() {
            let keep_out = self.trails.as_ref().and_then(Trails::keep_out);
            let path = (xz, forward2);
            if let Some((stamp, placement)) =
                wave.next(self.frame, path, self.texel_size, keep_out)?
            {
                shock = self.streamed()?.push(stamp, placement)? > 0;
            }
        }
        let state = CameraState {
            position: eye,
            forward: look,
            fov_y: camera.fov_y,
            aspect: 16.0 / 9.0,
        };
        self.last_camera = Some(state);
        // A tile that could not be read (corrupt, unreadable) or written back ends the run;
        // the driver still writes the report of the frames done.
        let streamed = self.streamed.as_mut().context("the world was finished")?;
        let report = streamed.update(&state)?;
        // The VRAM pool uploads the nearest wanted tiles in RAM, within the per-frame budget,
        // and the paint and colour of the same tiles, each within its own budget.
        let (mut vram_report, mut overlay) = (None, None);
        if let Some(scene) = ctx.gpu.as_deref_mut() {
            if let Some(atlas) = scene.atlas_mut() {
                vram_report = streamed.upload(&state, atlas)?;
            }
            let (paint, color) = scene.streamed_layers_mut();
            let mut streamed_layers = [None, None];
            if let Some(atlas) = paint {
                streamed_layers[0] = streamed.upload_paint(&state, atlas)?;
            }
            if let Some(atlas) = color {
                streamed_layers[1] = streamed.upload_color(&state, atlas)?;
            }
            overlay = Some(streamed_layers);
        }
        // Craters on the tiles, after the uploads: a GPU stamp lands on what the slot holds
        // this frame.
        let mut changed = Vec::new();
        {
            // Slots are stamped only where there is a GPU to stamp them.
            let report = match ctx.gpu.as_deref_mut() {
                Some(scene) => {
                    let (report, ms) = scene
                        .with_tile_deformer(ctx.timings, |deformer| streamed.deform(deformer))?;
                    self.gpu_stamp_ms += ms;
                    report?
                }
                None => streamed.deform_in_ram()?,
            };
            for (rect, heights) in &report.changed {
                self.window.apply(*rect, heights)?;
                changed.push(*rect);
            }
        }
        if let Some(scene) = ctx.gpu.as_deref_mut() {
            changed.extend(self.take_tile_readbacks(scene, false)?);
        }
        // The vehicle's trails, once no crater's readback is on its way (a new window's tiles
        // must hold every write made to them).
        let mut trail = None;
        if self.trails.is_some() {
            let vehicle = reflect_into(travelled + self.heading * VEHICLE_AHEAD, self.extent);
            let next = reflect_into(
                travelled + self.heading * (VEHICLE_AHEAD + 1.0),
                self.extent,
            );
            let vehicle = (vehicle, (next - vehicle).normalize_or(self.heading));
            // A window that moves takes its tiles with every crater in them: it waits for
            // those on their way back from the GPU, unless the wheels force it (they land
            // first, waited for).
            if let Some(scene) = ctx.gpu.as_deref_mut()
                && self.streamed()?.readbacks_in_flight() > 0
                && self.trails.as_ref().is_some_and(|t| t.must_move(vehicle))
            {
                changed.extend(self.take_tile_readbacks(scene, true)?);
            }
            let craters_in_flight = self.streamed()?.readbacks_in_flight() > 0;
            let (Some(trails), Some(streamed)) = (self.trails.as_mut(), self.streamed.as_mut())
            else {
                bail!("the world's pool was shut down");
            };
            let pool = streamed.ram_mut();
            let gpu = ctx.gpu.as_deref_mut();
            let (frame, step_ms) =
                trails.advance(pool, gpu, vehicle, &state, craters_in_flight, ctx.timings)?;
            for (rect, heights) in &frame.changed {
                self.window.apply(*rect, heights)?;
                changed.push(*rect);
            }
            for figure in super::trails::figures(&frame.measured) {
                ctx.timings.add_late_granular(figure);
            }
            self.gpu_stamp_ms += step_ms;
            trail = Some(frame);
        }
        // The walker's footprints into the detail tiles (timed as their own steps).
        let mut footprints = None;
        if let Some(detail) = self.detail.as_mut() {
            let (start, heading, extent) = (self.start, self.heading, self.extent);
            let line = move |s: f32| {
                let aside = heading.perp() * WALKER_ASIDE;
                reflect_into(start + heading * (s + WALKER_AHEAD) - aside, extent)
            };
            let t = Instant::now();
            let walked = self.speed * time;
            footprints =
                Some(detail.advance(xz, walked, &line, ctx.gpu.as_deref_mut(), ctx.timings)?);
            self.gpu_stamp_ms += ms_since(t);
        }
        let dirty = self.update_overview(&changed)?;
        self.update_window(xz)?;
        // The hole, written into the world off the frame thread; the layers around the camera
        // follow.
        let world = self.streamed()?.world().clone();
        if self.frame == HOLE_FRAME {
            let ts = self.texel_size;
            let aside = -self.heading.perp() * HOLE_ASIDE;
            let center = reflect_into(travelled + self.heading * HOLE_AHEAD + aside, self.extent);
            let size = HOLE_SIZE.clamp(4.0 * ts, self.tile_size as f32 * ts);
            let placement = StampPlacement::new(center, Vec2::splat(size), 0.0)?;
            self.overlays.cut(&placement)?;
        }
        let painted = self
            .overlays
            .follow(&world, &self.window, xz, ctx.gpu.as_deref_mut())?;
        // Paint the writer put into the world is read again by the paint stream.
        self.streamed()?.reload_paint(&painted);
        // The streamed LOD's quadtree follows the changes (timed as `lod`).
        self.gpu_stamp_ms += self.follow_bounds(&changed, ctx)?;
        // The GPU stamps and granular steps are timed as their own steps.
        let cache_ms = (ms_since(t_frame) - self.gpu_stamp_ms).max(0.0);
        ctx.timings.add(Step::Cache, cache_ms);
        let camera_clearance_m = eye.y - self.ground(xz);
        let tiles_missing = vram_report.map_or(self.tiles_missing(xz), |v| v.tiles_missing);
        let streamed = self.streamed()?;
        let (gpu_tile_stamps, cpu_tile_stamps) = streamed.tiles_stamped();
        Ok(FrameOutcome {
            camera,
            camera_clearance_m,
            stats: FrameStats {
                footprints: footprints.map_or(0, |f| f.footprints),
                detail_tiles_resident: footprints.map(|f| f.tiles),
                detail_dirty_texels: footprints.map(|f| f.texels),
                craters: u32::from(crater),
                shockwaves: u32::from(shock),
                dirty_texels: changed.iter().map(Rect::area).sum(),
                granular_volume: trail.as_ref().and_then(|t| t.volume),
                granular_volume_taken: trail.as_ref().and_then(|t| t.volume_taken),
                granular_backend: trail.as_ref().and_then(|t| t.on_gpu).map(|gpu| match gpu {
                    true => "gpu",
                    false => "cpu",
                }),
                granular_move_waited: trail.as_ref().and_then(|t| t.move_waited),
                cache: Some(CacheStats {
                    // With a GPU: wanted tiles drawn from a coarser level; without one, the
                    // tiles under and around the camera not in RAM.
                    tiles_missing,
                    // The heights' atlas and the paint and colour atlases: one VRAM budget.
                    vram_bytes: vram_report.map(|v| {
                        let streamed = overlay.into_iter().flatten().flatten();
                        v.vram_bytes + streamed.map(|r| r.vram_bytes).sum::<u64>()
                    }),
                    upload_bytes: vram_report.map(|v| v.upload_bytes),
                    uploads: vram_report.map(|v| v.uploads),
                    material_tiles_missing: overlay.and_then(|[p, _]| p).map(|r| r.tiles_missing),
                    color_tiles_missing: overlay.and_then(|[_, c]| c).map(|r| r.tiles_missing),
                    overlay_upload_bytes: overlay.map(|[p, c]| {
                        p.map_or(0, |r| r.upload_bytes) + c.map_or(0, |r| r.upload_bytes)
                    }),
                    prefetching: report.wanted.saturating_sub(report.wanted_resident),
                    ram_bytes: report.ram_bytes,
                    ram_budget_bytes: report.budget_bytes,
                    loads: report.loads,
                    evictions: report.evictions,
                    dirty_tiles: report.dirty,
                    pending_craters: streamed.stamps_pending(),
                    gpu_tile_stamps,
                    cpu_tile_stamps,
                    tile_readbacks_in_flight: streamed.readbacks_in_flight(),
                    collision_window: self
                        .window
                        .window()
                        .map(|w| [w.min.x, w.min.y, w.size.x as i32, w.size.y as i32]),
                    collision_coarse_tiles: self.window_fill.stand_ins(),
                    frame_thread_ms: cache_ms,
                }),
                ..FrameStats::default()
            },
            dirty,
        })
    }

    fn finish(&mut self, gpu: Option<&mut GpuScene>) -> Result<FinishStats> {
        // The holes and paint still on their way are in the world's files.
        self.overlays.finish()?;
        // The tiles stamped on the GPU reach RAM before anything is written back.
        let mut gpu = gpu;
        if let Some(scene) = gpu.as_deref_mut() {
            self.take_tile_readbacks(scene, true)?;
        }
        // Every footprint is in the world's detail files.
        let detail_written = match self.detail.as_mut() {
            Some(detail) => detail.finish(gpu.as_deref_mut())?,
            None => 0,
        };
        // The trails' last areas reach the tiles, and the window's volume is checked.
        let mut granular = Vec::new();
        if let (Some(trails), Some(streamed)) = (self.trails.as_mut(), self.streamed.as_mut()) {
            let mut timings = crate::timings::Timings::default();
            (_, granular) = trails.release(streamed.ram_mut(), gpu, &mut timings)?;
        }
        let Some(streamed) = self.streamed.take() else {
            return Ok(FinishStats {
                granular,
                ..FinishStats::default()
            });
        };
        // Every dirty tile goes back into the world, and craters whose tiles never became
        // resident go straight into its files.
        let (written, world) = streamed.finish(SHUTDOWN_TIMEOUT)?;
        // The overview as the world now holds it (`terrain_final.png`).
        self.overview = world.read_level(self.overview_level)?;
        Ok(FinishStats {
            granular,
            written_back_tiles: Some(
                written.written_back + written.stamped_at_finish + detail_written,
            ),
        })
    }
}

use super::FinishStats;

/// `p` folded into `[0, extent]` by reflection at the edges (a path that bounces).
fn reflect_into(p: Vec2, extent: Vec2) -> Vec2 {
    let fold = |v: f32, e: f32| {
        if e <= 0.0 {
            return 0.0;
        }
        let period = 2.0 * e;
        let m = v.rem_euclid(period);
        if m > e { period - m } else { m }
    };
    Vec2::new(fold(p.x, extent.x), fold(p.y, extent.y))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_path_stays_inside_the_world_for_any_distance() {
        let e = Vec2::new(100.0, 50.0);
        for p in [
            Vec2::new(-1e30, 3.0),
            Vec2::new(1e30, -1e30),
            Vec2::new(250.0, 120.0),
            Vec2::ZERO,
        ] {
            let q = reflect_into(p, e);
            assert!(
                q.x >= 0.0 && q.x <= e.x && q.y >= 0.0 && q.y <= e.y,
                "{p} -> {q}"
            );
        }
        assert_eq!(
            reflect_into(Vec2::new(120.0, 10.0), e),
            Vec2::new(80.0, 10.0)
        );
    }
}
