//! The default scenario: footprints, craters and a shockwave stamped on the coarse-map, once:
//! on the GPU map when there is one (the CPU's map then follows it through the collision
//! readback only), else on the CPU map; a collision mirror fed by readbacks of the dirty
//! regions, and a camera on it (`--camera`): walking behind the walker, or orbiting or flying
//! over the whole map (the default with `--heightmap`). A hole cut beside the walker's path
//! (`[stamps] hole_frame`) leaves its cells out of collision and of every GPU frame.
//!
//! With `--detail parallax` or `refine` the footprints go into a detail layer instead (Flower 2010
//! sec. 2.3: 8-bit tiles refined x3 over the coarse-map), held by a detail cache (the band
//! regions around the camera, dirty tiles written back to `<out>/detail_world`). With a GPU they
//! are stamped on its tiles and the stamped rects read back into the cache as they arrive
//! (collision and the write-back take the GPU's texels); without one they are stamped on the
//! cache.

use super::FinishStats;
use super::stamp_script::{DetailTarget, StampScript};
use super::{FRAME_DT, FrameContext, FrameOutcome, Scenario, ScenarioInfo, heightmap};
use crate::camera_rig::{CameraRig, path_params};
use crate::cli::{CameraMode, Cli};
use crate::config::DemoParams;
use crate::frame_plan::{FramePlan, StampKind};
use crate::gpu_scene::GpuScene;
use crate::report::FrameStats;
use crate::timings::{Step, ms_since};
use crate::usage_error::UsageExt;
use anyhow::Context as _;
use anyhow::Result;
use glam::Vec2;
use std::collections::HashMap;
use std::sync::Arc;
use std::time::Instant;
use terrain_cache::detail::{DetailCache, detail_manifest_layout};
use terrain_cache::{BandSelection, FsStore, Manifest, TileStore, World};
use terrain_core::detail::DetailLayout;
use terrain_core::{
    CoarseMap, DerivativeMap, Grid, HoleOp, StampPlacement, apply_hole_stamp, bilinear,
};
use terrain_physics::{CameraPath, MapFrame};
use terrain_physics::{
    CollisionMirror, CpuRegionSource, DetailGround, ReadbackScheduler, RequestId,
};

/// The default scenario.
#[derive(Debug)]
pub struct StampScenario {
    info: ScenarioInfo,
    script: StampScript,
    /// The CPU map, held by a region source: without a GPU it is the map deformed and the
    /// scheduler reads collision regions from it; with a GPU the regions come from the GPU map
    /// and this map receives them from the mirror (the overview, `terrain_final.png`).
    cpu: CpuRegionSource,
    /// The CPU map's normals, regenerated where it is deformed: without a GPU only (the CPU
    /// path does the GPU's work once; with a GPU the normals live there).
    normals: DerivativeMap,
    mirror: CollisionMirror,
    scheduler: ReadbackScheduler,
    /// When each collision readback in flight was requested.
    requested_at: HashMap<RequestId, Instant>,
    rig: CameraRig,
    /// `--detail parallax|refine`: the detail tiles the footprints go into, cached in a world
    /// under the output folder (`detail_world`).
    detail: Option<DetailCache>,
    /// How the GPU draws it (`--detail`).
    detail_mode: crate::cli::DetailArg,
    /// The hole mask of the coarse-map (`terrain_core::holes`), once a hole is cut: the CPU
    /// holds it and hands it to collision and the GPU.
    holes: Option<Grid<u8>>,
}

/// Detail texels per coarse texel (Flower 2010's 1/gamma = 3).
pub const DETAIL_REFINE: u32 = 3;
/// Detail tile side in detail texels (34 m at 3.3 cm; 1 MiB a GPU slot). The band regions hold
/// the camera's tile and its neighbours on the camera's side, so the detail reaches at least
/// two thirds of a tile (22 m) in every direction: the demo fades it out by then.
pub const DETAIL_TILE: u32 = 1024;

/// How long the end of a run waits for the GPU's last regions to come back.
const FLUSH_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(60);

/// Samples the detail cache uploads per frame at most: the nine tiles of a band.
const DETAIL_UPLOAD_BUDGET: u64 = 9 * (DETAIL_TILE as u64) * (DETAIL_TILE as u64);

/// The detail tiles within this distance of the walker are read ahead (by the cache's loaders):
/// the walker needs those within 2 m, and covers a few metres a frame.
const DETAIL_READ_AHEAD_M: f32 = 8.0;

impl StampScenario {
    /// Loads or generates the terrain and places the walker and the camera.
    /// `planned` is the heightmap as the memory estimate measured it (read only as such).
    pub fn new(
        cli: &Cli,
        params: &DemoParams,
        planned: Option<heightmap::PlannedMap>,
    ) -> Result<Self> {
        let t = Instant::now();
        let terrain = heightmap::load_planned(cli, planned)?;
        let map = terrain.map;
        let holes = terrain.holes;
        let load_ms = ms_since(t);
        let t = Instant::now();
        let normals = DerivativeMap::from_map(&map);
        let initial_normals_ms = ms_since(t);
        let script = StampScript::new(map.extent_m(), cli.seed, params.stamps)?;
        let detail = match cli.detail {
            crate::cli::DetailArg::None => None,
            crate::cli::DetailArg::Parallax | crate::cli::DetailArg::Refine => {
                let layout =
                    DetailLayout::new(map.size(), map.texel_size(), DETAIL_REFINE, DETAIL_TILE)
                        .map_err(|e| crate::usage_error::usage(anyhow::anyhow!("--detail: {e}")))?;
                Some(detail_cache(&cli.out, &map, layout)?)
            }
        };
        let mirror = CollisionMirror::from_map(&map)?;
        if let Some(mask) = &holes {
            mirror.set_holes(Some(Arc::new(mask.clone())))?;
        }
        // The GPU scene's readback ring has `max_in_flight` buffers (see `driver::open_gpu`).
        let scheduler = ReadbackScheduler::for_mirror(&mirror, params.scheduler)?;
        let mode = camera_mode(cli);
        let rig = match mode {
            CameraMode::Walker => {
                let start = script.walker_start();
                CameraRig::new(
                    start,
                    bilinear(&map, start)?,
                    map.extent_m().max_element(),
                    &params.camera,
                )?
            }
            CameraMode::Orbit | CameraMode::Flyover => {
                let (lo, hi) = terrain_core::hillshade_range(&map);
                let frame = MapFrame {
                    extent: map.extent_m(),
                    low: map.encoding().to_metres(lo),
                    high: map.encoding().to_metres(hi),
                };
                let shape = path_params(&params.camera);
                // The map's heights and extent come from the user's file or flags: a frame no
                // camera can fly (heights of 1e29 m) is theirs to fix.
                let path = if mode == CameraMode::Orbit {
                    CameraPath::orbit(frame, shape)
                } else {
                    CameraPath::flyover(frame, shape)
                };
                let path = path
                    .with_context(|| format!("the {} camera over {}", mode.name(), terrain.source))
                    .usage()?;
                CameraRig::on_path(path, |p| bilinear(&map, p).unwrap_or(frame.low))
            }
        };
        Ok(Self {
            info: ScenarioInfo {
                name: "default",
                source: terrain.source,
                load_ms,
                initial_normals_ms,
                heights: Some(terrain.heights),
                camera: Some(mode.name()),
            },
            script,
            cpu: CpuRegionSource::new(map),
            normals,
            mirror,
            scheduler,
            requested_at: HashMap::new(),
            rig,
            detail,
            detail_mode: cli.detail,
            holes,
        })
    }
}

/// The camera `cli` asks for: `--camera`, else orbit over a heightmap (a DEM seen from eye
/// height is a plain) and the walker over the procedural terrain.
pub fn camera_mode(cli: &Cli) -> CameraMode {
    cli.camera.unwrap_or(if cli.heightmap.is_some() {
        CameraMode::Orbit
    } else {
        CameraMode::Walker
    })
}

/// The detail cache of `--detail`: a world of `map`'s size with only a detail layer, in
/// `out/detail_world` (a previous run's is replaced: every run starts from untouched detail).
fn detail_cache(
    out: &std::path::Path,
    map: &CoarseMap,
    layout: DetailLayout,
) -> Result<DetailCache> {
    let dir = out.join("detail_world");
    if dir.join(terrain_cache::manifest::MANIFEST_KEY).exists() {
        std::fs::remove_dir_all(&dir)
            .with_context(|| format!("clearing the previous {}", dir.display()))?;
    }
    let store: std::sync::Arc<dyn TileStore> = std::sync::Arc::new(FsStore::open(&dir)?);
    let mut manifest = Manifest::new(
        map.size(),
        256,
        map.texel_size(),
        map.encoding(),
        map.wrap(),
    )?;
    manifest.detail = Some(detail_manifest_layout(&layout)?);
    let world = World::create(store, manifest)?;
    Ok(DetailCache::open(
        world,
        layout,
        BandSelection::default(),
        DETAIL_UPLOAD_BUDGET,
    )?)
}

/// The detail tiles a frame needs beyond the camera's band: those its footprints stamp (the
/// GPU refuses stamps over tiles it does not hold) and those under the walker (collision).
fn needed_detail_tiles(layout: &DetailLayout, plan: &FramePlan) -> Result<Vec<glam::UVec2>> {
    let mut needed = layout.tiles_within(plan.walker.0, 2.0)?;
    for d in plan.deformations.iter() {
        if d.kind == StampKind::Footprint {
            needed.extend(layout.tiles_under(&d.placement)?);
        }
    }
    needed.sort_unstable_by_key(|t| (t.y, t.x));
    needed.dedup();
    Ok(needed)
}

impl StampScenario {
    /// Cuts a hole at `placement` into the coarse-map's hole mask (made on the first cut), and
    /// hands the mask to collision (rays and bodies pass through) and to the GPU's renderers.
    /// Returns the rects it changed.
    fn cut_hole(
        &mut self,
        placement: &StampPlacement,
        gpu: Option<&mut GpuScene>,
    ) -> Result<Vec<terrain_core::DirtyRect>> {
        let map = self.cpu.map();
        let (size, wrap, texel) = (map.size(), map.wrap(), map.texel_size());
        let mask = match self.holes.as_mut() {
            Some(mask) => mask,
            None => self
                .holes
                .insert(Grid::new(size.x, size.y, terrain_core::GROUND)?),
        };
        let rects = apply_hole_stamp(mask, wrap, texel, placement, HoleOp::Cut)?;
        self.mirror.set_holes(Some(Arc::new(mask.clone())))?;
        if let Some(scene) = gpu {
            scene.update_holes(mask, &rects)?;
        }
        Ok(rects)
    }
}

impl Scenario for StampScenario {
    fn info(&self) -> &ScenarioInfo {
        &self.info
    }

    fn finish(&mut self, gpu: Option<&mut GpuScene>) -> Result<FinishStats> {
        // The GPU's last deformations come back (quiet gap or not) into the mirror and the
        // CPU's map, so `terrain_final.png` is the GPU's map.
        if let Some(scene) = gpu {
            if let Some(cache) = self.detail.as_mut() {
                let mut timings = crate::timings::Timings::default();
                scene.take_detail_readbacks(cache, true, &mut timings)?;
            }
            let report = scene.flush_collision(&mut self.scheduler, &self.mirror, FLUSH_TIMEOUT)?;
            for rect in &report.applied_rects {
                self.mirror.copy_into(*rect, self.cpu.map_mut())?;
            }
        }
        // The detail tiles still in RAM and deformed are written back: every footprint is on
        // disk when the run ends.
        let written = match self.detail.as_mut() {
            Some(cache) => Some(cache.flush()? as u64),
            None => None,
        };
        Ok(FinishStats {
            written_back_tiles: written,
            ..FinishStats::default()
        })
    }

    fn map(&self) -> &CoarseMap {
        self.cpu.map()
    }

    fn holes(&self) -> Option<&Grid<u8>> {
        self.holes.as_ref()
    }

    fn prepare_gpu(&mut self, scene: &mut GpuScene) -> Result<()> {
        scene.set_fog(self.rig.fog_density());
        if let Some(radius) = self.rig.view_radius() {
            // A camera that frames the whole map shows it once, not its toroidal repeats.
            scene.reach(radius)?;
            scene.hide_outside_map(true);
        }
        if let Some(cache) = &self.detail {
            let refine = self.detail_mode == crate::cli::DetailArg::Refine;
            scene.enable_detail(*cache.layout(), refine)?;
        }
        if let Some(mask) = &self.holes {
            scene.update_holes(mask, &[mask.rect()])?;
        }
        scene.set_footprint(self.script.footprint())
    }

    fn advance(&mut self, ctx: &mut FrameContext<'_>) -> Result<FrameOutcome> {
        let mut plan = self.script.plan_next_frame()?;
        let encoding = self.cpu.map().encoding();
        let now = ctx.now;

        // Collision first: a frame of scenario time after the last frame's deformations the
        // quiet gap has passed, so the scheduler requests their regions now; arrivals apply here.
        let t = Instant::now();
        let report = match ctx.gpu.as_deref_mut() {
            Some(scene) => scene.update_collision(&mut self.scheduler, &self.mirror, now)?,
            None => self.scheduler.update(now, &mut self.cpu, &self.mirror)?,
        };
        for (id, _) in &report.requested {
            self.requested_at.insert(*id, Instant::now());
        }
        for id in &report.abandoned {
            self.requested_at.remove(id);
        }
        let readback_ms = report
            .applied
            .iter()
            .filter_map(|(id, _)| self.requested_at.remove(id))
            .map(ms_since)
            .reduce(f64::max);
        // With a GPU the CPU's map is the GPU's as read back: the regions that arrived in the
        // mirror are copied into it (the overview, `terrain_final.png`). It is never stamped.
        if ctx.gpu.is_some() {
            for rect in &report.applied_rects {
                self.mirror.copy_into(*rect, self.cpu.map_mut())?;
            }
        }
        ctx.timings.add(Step::Physics, ms_since(t));

        // The detail tiles: the camera's band, the tiles this frame's footprints stamp and the
        // walker's (it stands on them), then the GPU's slots follow. The cache reads and writes
        // on its own threads; the tiles around the walker, who runs ahead of the camera's band,
        // are read ahead so none is read here when it is needed.
        if let Some(cache) = self.detail.as_mut() {
            let t = Instant::now();
            let eye = self.rig.eye();
            let mut needed = needed_detail_tiles(cache.layout(), &plan)?;
            // Tiles whose stamped rects are still on their way back stay in RAM for them.
            if let Some(scene) = ctx.gpu.as_deref() {
                needed.extend(scene.detail_tiles_in_flight());
                needed.sort_unstable_by_key(|t| (t.y, t.x));
                needed.dedup();
            }
            let ahead = cache
                .layout()
                .tiles_within(plan.walker.0, DETAIL_READ_AHEAD_M)?;
            let frame = cache.update_ahead(Vec2::new(eye.x, eye.z), &needed, &ahead)?;
            if let Some((tile, e)) = frame.failed.first() {
                return Err(anyhow::anyhow!("detail tile {tile}: {e}"));
            }
            ctx.timings.add(Step::Detail, ms_since(t));
            if let Some(scene) = ctx.gpu.as_deref_mut() {
                scene.stream_detail(cache, &frame, ctx.timings)?;
            }
        }
        // The deformations, applied once: on the GPU when there is one (its stamped detail
        // rects read back into the cache, its coarse rects reaching the CPU's map through the
        // collision readback), else on the CPU map and the cache.
        let (deformed, dirty, cpu_detail_texels) = match ctx.gpu.as_deref_mut() {
            Some(scene) => {
                let rects = scene.deform(&plan, self.script.crater(), ctx.timings)?;
                for (i, rect) in &rects {
                    let bound = StampScript::bound(&plan.deformations[*i], encoding)?;
                    self.scheduler.note_deformation(*rect, bound, now)?;
                }
                if let Some(cache) = self.detail.as_mut() {
                    scene.take_detail_readbacks(cache, false, ctx.timings)?;
                }
                let deformed: Vec<_> = rects.into_iter().map(|(_, r)| r).collect();
                (deformed, report.applied_rects, 0)
            }
            None => {
                let target = match self.detail.as_mut() {
                    None => DetailTarget::None,
                    Some(cache) => DetailTarget::Cpu(cache),
                };
                let (by_deformation, detail_texels) = ctx.timings.time(Step::StampCpu, || {
                    self.script.apply_cpu(self.cpu.map_mut(), &mut plan, target)
                })?;
                ctx.timings.time(Step::NormalsCpu, || -> Result<()> {
                    for rect in by_deformation.iter().flatten() {
                        self.normals.update_rect(self.cpu.map(), *rect)?;
                    }
                    Ok(())
                })?;
                for (d, rects) in plan.deformations.iter().zip(&by_deformation) {
                    let bound = StampScript::bound(d, encoding)?;
                    for rect in rects {
                        self.scheduler.note_deformation(*rect, bound, now)?;
                    }
                }
                let deformed: Vec<_> = by_deformation.into_iter().flatten().collect();
                (deformed.clone(), deformed, detail_texels)
            }
        };

        let mut dirty = dirty;
        if let Some(placement) = plan.hole {
            dirty.extend(self.cut_hole(&placement, ctx.gpu.as_deref_mut())?);
        }

        // The camera: a body on the mirror, kept above pending deformations by their bounds.
        let t = Instant::now();
        let collider = self.mirror.collider();
        let ground = self.scheduler.ground(&collider);
        let map = self.cpu.map();
        let look = |p| bilinear(map, p).unwrap_or(0.0);
        // With a detail layer the body walks on coarse + detail (it steps into the footprints).
        let camera = match &self.detail {
            Some(cache) => {
                let ground = DetailGround::new(&ground, cache.layer());
                self.rig.step(plan.walker, FRAME_DT as f32, &ground, look)?
            }
            None => self.rig.step(plan.walker, FRAME_DT as f32, &ground, look)?,
        };
        let eye = self.rig.eye();
        let camera_clearance_m = eye.y - bilinear(map, Vec2::new(eye.x, eye.z))?;
        ctx.timings.add(Step::Physics, ms_since(t));

        // The GPU's figures where it holds the tiles, else the CPU layer's.
        let detail = self.detail.as_ref().map(|cache| {
            match ctx.gpu.as_deref().and_then(|scene| scene.detail_stats()) {
                Some(stats) => stats,
                None => (cache.loaded_tiles().len() as u32, cpu_detail_texels),
            }
        });
        Ok(FrameOutcome {
            camera,
            camera_clearance_m,
            stats: FrameStats {
                footprints: plan.count(StampKind::Footprint),
                craters: plan.count(StampKind::Crater),
                shockwaves: plan.count(StampKind::Shockwave),
                dirty_texels: deformed.iter().map(|r| r.area()).sum(),
                readback_ms,
                detail_tiles_resident: detail.map(|d| d.0),
                detail_dirty_texels: detail.map(|d| d.1),
                ..FrameStats::default()
            },
            dirty,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenarios::FrameContext;
    use crate::timings::Timings;
    use clap::Parser;

    /// The GPU scene for `scenario` as the driver opens it, or `None` (skipped) without an
    /// adapter unless `TERRAIN_REQUIRE_GPU=1`, where its absence fails the test.
    fn gpu_scene(scenario: &mut StampScenario, test: &str) -> Option<GpuScene> {
        match GpuScene::new(scenario.map(), glam::UVec2::new(64, 48), 16) {
            Ok(mut scene) => {
                scenario.prepare_gpu(&mut scene).expect("prepare");
                Some(scene)
            }
            Err(e) if std::env::var("TERRAIN_REQUIRE_GPU").is_ok_and(|v| v == "1") => {
                panic!("{test}: TERRAIN_REQUIRE_GPU=1 but no GPU: {e:#}")
            }
            Err(e) => {
                crate::console::note!("skipping {test}: {e:#}");
                None
            }
        }
    }

    /// With a GPU the deformations are applied there only: the CPU's map changes only when a
    /// readback arrives, never on the frame that deforms (a stamp applied to it would change
    /// it at once), and after the run's flush it is the GPU's map, bit for bit. With
    /// `--detail`, the footprints' detail texels come back from the GPU as well.
    #[test]
    fn with_a_gpu_the_cpu_map_is_never_deformed_only_read_back() {
        for detail in ["none", "refine"] {
            let cli =
                Cli::try_parse_from(["demo", "--size", "128", "--seed", "3", "--detail", detail])
                    .expect("flags");
            let params = DemoParams::default();
            let mut scenario = StampScenario::new(&cli, &params, None).expect("scenario");
            let Some(mut scene) = gpu_scene(&mut scenario, "cpu_map_is_only_read_back") else {
                return;
            };
            let start = scenario.map().clone();
            let t0 = Instant::now();
            let mut timings = Timings::default();
            let mut deformed = 0;
            let mut frame = 0;
            // Frames until something was deformed on the GPU; until a readback arrives (the
            // quiet gap passes one frame later) the CPU's map must not have moved.
            while deformed == 0 {
                let out = scenario
                    .advance(&mut FrameContext {
                        now: t0 + std::time::Duration::from_secs_f64(frame as f64 * FRAME_DT),
                        gpu: Some(&mut scene),
                        timings: &mut timings,
                    })
                    .expect("frame");
                deformed = out.stats.dirty_texels + out.stats.detail_dirty_texels.unwrap_or(0);
                assert!(out.dirty.is_empty(), "{detail}: nothing read back yet");
                assert_eq!(
                    scenario.map(),
                    &start,
                    "{detail}: frame {frame} stamped the CPU map"
                );
                frame += 1;
                assert!(frame < 30, "{detail}: no deformation in 30 frames");
            }
            for _ in 0..20 {
                let now = t0 + std::time::Duration::from_secs_f64(frame as f64 * FRAME_DT);
                scenario
                    .advance(&mut FrameContext {
                        now,
                        gpu: Some(&mut scene),
                        timings: &mut timings,
                    })
                    .expect("frame");
                frame += 1;
            }
            // The detail cache holds the GPU's detail tiles once the last rects are back.
            if let Some(cache) = scenario.detail.as_mut() {
                scene
                    .take_detail_readbacks(cache, true, &mut timings)
                    .expect("detail readbacks");
                let mut compared = 0;
                for (tile, _) in cache.loaded_tiles() {
                    if let Some(gpu) = scene.read_detail(tile).expect("download") {
                        assert_eq!(cache.tile(tile), Some(&gpu), "detail tile {tile}");
                        compared += 1;
                    }
                }
                assert!(compared > 0, "no stamped detail tile to compare");
            }
            scenario.finish(Some(&mut scene)).expect("finish");
            let gpu_map = scene.read_map().expect("download");
            assert_ne!(
                gpu_map.grid(),
                start.grid(),
                "{detail}: the GPU map was deformed"
            );
            assert_eq!(
                scenario.map().grid(),
                gpu_map.grid(),
                "{detail}: CPU map != GPU map"
            );
            for step in ["stamp_cpu", "normals_cpu"] {
                assert!(
                    !timings.wall_by_name().contains_key(step),
                    "{detail}: {step} ran beside the GPU"
                );
            }
        }
    }

    /// The hole the script cuts (`[stamps] hole_frame`) reaches collision on both paths: a ray
    /// down through its middle misses, one beside it hits; with a GPU its renderers get the
    /// mask too.
    #[test]
    fn the_scripted_hole_reaches_collision_and_the_gpu() {
        let cli = Cli::try_parse_from(["demo", "--size", "256", "--seed", "3"]).expect("flags");
        let params = DemoParams::default();
        for gpu in [false, true] {
            let mut scenario = StampScenario::new(&cli, &params, None).expect("scenario");
            let mut scene = match gpu {
                true => match gpu_scene(&mut scenario, "scripted_hole") {
                    Some(scene) => Some(scene),
                    None => continue,
                },
                false => None,
            };
            let t0 = Instant::now();
            let mut timings = Timings::default();
            for frame in 0..=params.stamps.hole_frame {
                assert!(
                    scenario.holes.is_none(),
                    "gpu {gpu}: a hole before frame {frame}"
                );
                let now = t0 + std::time::Duration::from_secs_f64(f64::from(frame) * FRAME_DT);
                scenario
                    .advance(&mut FrameContext {
                        now,
                        gpu: scene.as_mut(),
                        timings: &mut timings,
                    })
                    .expect("frame");
            }
            // A cell deep inside the hole (every cell within 2 of it cut), in metres.
            let mask = scenario.holes.as_ref().expect("a mask");
            let cut = |x: i32, y: i32| {
                let v = mask.get_wrapped(glam::IVec2::new(x, y), terrain_core::WrapMode::Repeat);
                terrain_core::is_hole(v)
            };
            let inner = (0..mask.height() as i32)
                .flat_map(|y| (0..mask.width() as i32).map(move |x| (x, y)))
                .find(|&(x, y)| (-2..=2).all(|j| (-2..=2).all(|i| cut(x + i, y + j))))
                .expect("a hole 9 m wide");
            let texel = scenario.map().texel_size();
            let centre = (glam::Vec2::new(inner.0 as f32, inner.1 as f32) + 0.5) * texel;
            let collider = scenario.mirror.collider();
            let above = glam::Vec3::new(centre.x, 500.0, centre.y);
            let through = collider
                .raycast(above, glam::Vec3::NEG_Y, 1000.0)
                .expect("ray");
            assert_eq!(through, None, "gpu {gpu}: the ray through the hole hit");
            let side = glam::Vec3::new(centre.x + 20.0, 500.0, centre.y);
            assert!(
                collider
                    .raycast(side, glam::Vec3::NEG_Y, 1000.0)
                    .expect("ray")
                    .is_some()
            );
            if let Some(scene) = &scene {
                assert!(scene.has_holes(), "the GPU's renderers got no mask");
            }
        }
    }
}
