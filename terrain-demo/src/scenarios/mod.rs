//! The scenarios behind one [`Scenario`] trait. The driver (`crate::driver`) does what every
//! run shares: output folder, GPU scene, overview, frame loop, rendering, capture, report. A
//! scenario owns its terrain and bodies, and per frame deforms, steps and places the camera.

pub mod flyover;
pub mod heightmap;
pub mod snow;
mod snow_field;
mod stamp_script;
mod stamps;
pub mod tile_overlay;
pub mod trails;
mod world_detail;
pub mod world_files;
mod world_overlays;
mod world_stamps;

use crate::cli::{Cli, ScenarioKind};
use crate::config::DemoParams;
use crate::gpu_scene::{Camera, GpuScene};
use crate::report::FrameStats;
use crate::timings::Timings;
use anyhow::Result;
use glam::UVec2;
use std::time::Instant;
use terrain_core::{CoarseMap, DirtyRect};

pub use stamps::{DETAIL_REFINE, DETAIL_TILE};
pub use world_detail::memory_bytes as world_detail_bytes;
pub use world_overlays::GPU_WINDOW as GPU_OVERLAY_WINDOW;

/// Seconds of scenario time per frame (30 frames per second), whatever the render speed.
pub const FRAME_DT: f64 = 1.0 / 30.0;

/// The scenario `cli` asks for, set up (terrain loaded or generated, bodies placed);
/// `heightmap` is the heightmap (the default scenario's, or the one a flyover builds its world
/// from) as the memory estimate measured it.
pub fn open(
    cli: &Cli,
    params: &DemoParams,
    heightmap: Option<heightmap::PlannedMap>,
) -> Result<Box<dyn Scenario>> {
    Ok(match cli.scenario {
        ScenarioKind::Default => Box::new(stamps::StampScenario::new(cli, params, heightmap)?),
        ScenarioKind::Snow => Box::new(snow::SnowScenario::new(cli, params)?),
        ScenarioKind::Flyover | ScenarioKind::World => {
            Box::new(flyover::FlyoverScenario::new(cli, params, heightmap)?)
        }
    })
}

/// The overview's size in pixels for a map of `size` texels: the map's aspect, its longer
/// side `side` pixels, at least 1 x 1.
pub fn fit_overview(size: UVec2, side: u32) -> UVec2 {
    let scale = side as f32 / size.max_element() as f32;
    (size.as_vec2() * scale).round().as_uvec2().max(UVec2::ONE)
}

/// What a scenario reports about its setup.
#[derive(Debug, Clone)]
pub struct ScenarioInfo {
    /// The report's `scenario`: `default`, `snow`.
    pub name: &'static str,
    /// Where the heights came from (the report's `source`).
    pub source: String,
    /// Milliseconds to generate or load the terrain.
    pub load_ms: f64,
    /// Milliseconds to compute the first full normal map on the CPU (0 where the scenario keeps
    /// none: its normals live on the GPU, and the overview shades from the heights).
    pub initial_normals_ms: f64,
    /// The terrain's heights (encoding, heightmap read, nodata), where the scenario knows them.
    pub heights: Option<heightmap::HeightsInfo>,
    /// The camera (`walker`, `orbit`, `flyover`), where the scenario lets `--camera` choose.
    pub camera: Option<&'static str>,
}

/// What the driver hands a scenario for one frame.
pub struct FrameContext<'a> {
    /// Scenario time of this frame (frame index times [`FRAME_DT`] after the loop started).
    pub now: Instant,
    /// The GPU scene, or `None` without a GPU (`--no-gpu`, or no adapter).
    pub gpu: Option<&'a mut GpuScene>,
    /// This frame's timings, by [`Step`](crate::timings::Step).
    pub timings: &'a mut Timings,
}

/// What one frame of a scenario did.
#[derive(Debug)]
pub struct FrameOutcome {
    /// Where the camera looks from.
    pub camera: Camera,
    /// Height of the camera's eye above the true surface under it.
    pub camera_clearance_m: f32,
    /// The rects of [`Scenario::map`] whose heights changed (map coordinates; they may wrap).
    pub dirty: Vec<DirtyRect>,
    /// The scenario's fields of the frame's report.
    pub stats: FrameStats,
}

/// What a scenario did at the end of the run.
#[derive(Debug, Clone, Default)]
pub struct FinishStats {
    /// Flyover: tiles written back into the world during and at the end of the run.
    pub written_back_tiles: Option<u64>,
    /// The last GPU granular steps' measures, which arrived at the end (credited to their
    /// frames).
    pub granular: Vec<crate::timings::GranularFigure>,
}

/// One scenario: its terrain, what deforms it and what moves over it.
pub trait Scenario {
    /// Name, source and setup timings, for the report.
    fn info(&self) -> &ScenarioInfo;

    /// The terrain as the CPU holds it, current after every [`Scenario::advance`]: written as
    /// `terrain.png` / `terrain_final.png`, shown in the overview, uploaded to the GPU scene.
    fn map(&self) -> &CoarseMap;

    /// The map's hole mask (`terrain_core::holes`), if it has a hole: the overview leaves the
    /// holes dark. The frame's `dirty` rects cover the cells a cut changed.
    fn holes(&self) -> Option<&terrain_core::Grid<u8>> {
        None
    }

    /// Uploads what the scenario needs on the GPU beyond the map (stamps, colours, a granular
    /// map to deform there); once, when the run has a GPU.
    fn prepare_gpu(&mut self, _scene: &mut GpuScene) -> Result<()> {
        Ok(())
    }

    /// The overview's size in pixels for a requested side of `side`: the map's aspect, its
    /// longer side `side` (each pixel shows the nearest texel).
    fn overview_size(&self, side: u32) -> UVec2 {
        fit_overview(self.map().size(), side)
    }

    /// The overview with what the scenario draws over it this frame (the flyover's tile
    /// states and view), `None` to show it as it is.
    fn overlay(&self, _overview: &crate::images::Image) -> Option<crate::images::Image> {
        None
    }

    /// The heightfield CDLOD draws (`--lod cdlod`): its size in texels, wrap and metres per
    /// texel. By default [`Scenario::map`]'s.
    fn cdlod_extent(&self) -> (UVec2, terrain_core::WrapMode, f32) {
        let m = self.map();
        (m.size(), m.wrap(), m.texel_size())
    }

    /// Makes `scene` draw with CDLOD of `config` (for [`Scenario::cdlod_extent`]): by default
    /// the quadtree of [`Scenario::map`].
    fn enable_cdlod(
        &mut self,
        scene: &mut GpuScene,
        config: terrain_lod::CdlodConfig,
    ) -> Result<()> {
        scene.enable_cdlod(self.map(), config)
    }

    /// Makes `scene` draw with adaptive tessellation of `config` (with the curvature density
    /// map when `density`): by default the hierarchy of [`Scenario::map`].
    fn enable_tessellation(
        &mut self,
        scene: &mut GpuScene,
        config: terrain_lod::TessConfig,
        density: bool,
    ) -> Result<()> {
        scene.enable_tessellation(self.map(), config, density)
    }

    /// Ends the run: writes back what the scenario keeps outside the report (the flyover's
    /// dirty tiles) and says what it did.
    fn finish(&mut self, _gpu: Option<&mut GpuScene>) -> Result<FinishStats> {
        Ok(FinishStats::default())
    }

    /// One frame: deforms the terrain (on `ctx.gpu` when there is one, and on the CPU map),
    /// steps the bodies and places the camera, timing each step in `ctx.timings`.
    fn advance(&mut self, ctx: &mut FrameContext<'_>) -> Result<FrameOutcome>;
}
