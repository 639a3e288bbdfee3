//! `GranularTrails` on a real RAM pool: a wheel driven across the world, the window moved on
//! ahead of it, stepped on the CPU or through a stepper whose results come back frames late
//! (as a GPU's do). The volume is exact at every step, every area of a late stepper reaches the
//! tiles before its window moves on, an unforced move waits for nothing, and bad settings are
//! refused.

mod common;

use common::build;
use glam::{Affine3A, UVec2, Vec2, Vec3};
use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Duration;
use terrain_cache::{
    CameraState, CpuOnly, GranularStepper, GranularTrails, Layer, ObjectTileStore, PoolConfig,
    RamPool, TileStore, TrailConfig, TrailFrame, TrailsError, World,
};
use terrain_core::granular::{
    GranularArrivals, GranularObject, GranularParams, GranularSim, StepMeasure, TriMesh,
};
use terrain_core::{FixedPointMap, Grid, Rect};

const WORLD: u32 = 128;
const TILE: u32 = 32;

fn world() -> World {
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
    build(store, UVec2::splat(WORLD), TILE)
}

fn camera() -> CameraState {
    CameraState::at(Vec3::new(64.0, 5.0, 64.0))
}

/// A pool with every level-0 tile of the world loaded.
fn loaded_pool(world: &World) -> RamPool {
    let mut pool = RamPool::new(world.clone(), PoolConfig::new(Layer::Height, 64 << 20)).unwrap();
    common::load_level0(&mut pool);
    pool
}

fn heights(pool: &RamPool) -> Grid<u16> {
    let mut g = Grid::new(WORLD, WORLD, 0u16).unwrap();
    assert_eq!(
        pool.read_region(Rect::from_size(UVec2::splat(WORLD)), &mut g)
            .unwrap(),
        0
    );
    g
}

/// Areas a step changed, with their heights.
type Areas = Vec<(Rect, Grid<u32>)>;

/// A GPU stand-in: terrain-core's simulation, whose areas and measures arrive `delay` polls
/// after their step, as a readback ring hands them over.
struct LateStepper {
    sim: Option<GranularSim>,
    delay: usize,
    /// Steps' results on their way: polls left, areas, measure.
    queue: VecDeque<(usize, Areas, StepMeasure)>,
    removed: u64,
    /// The heights of each map when it was stopped.
    stopped: Vec<Grid<u32>>,
}

impl LateStepper {
    fn new(delay: usize) -> Self {
        Self {
            sim: None,
            delay,
            queue: VecDeque::new(),
            removed: 0,
            stopped: Vec::new(),
        }
    }

    fn take_arrived(&mut self) -> GranularArrivals {
        let mut out = GranularArrivals::default();
        for entry in &mut self.queue {
            entry.0 = entry.0.saturating_sub(1);
        }
        while self.queue.front().is_some_and(|e| e.0 == 0) {
            let (_, areas, measure) = self.queue.pop_front().unwrap();
            out.areas.extend(areas);
            out.measured.push(measure);
        }
        out.in_flight = !self.queue.is_empty();
        out
    }
}

impl GranularStepper for LateStepper {
    type Error = String;

    fn start(&mut self, map: &FixedPointMap, params: GranularParams) -> Result<(), String> {
        assert!(
            self.queue.is_empty(),
            "a new map while the last one's are on their way"
        );
        self.sim = Some(GranularSim::new(map.clone(), params).map_err(|e| e.to_string())?);
        self.removed = 0;
        Ok(())
    }

    fn step(
        &mut self,
        objects: &[GranularObject<'_>],
        tag: u64,
    ) -> Result<GranularArrivals, String> {
        let arrived = self.take_arrived();
        let sim = self.sim.as_mut().ok_or("not started")?;
        let report = sim.step(objects).map_err(|e| e.to_string())?;
        let areas = report
            .active_areas
            .iter()
            .map(|a| (a.rect, sim.map().grid().copy_rect(a.rect).unwrap()))
            .collect();
        let measure = StepMeasure {
            tag,
            volume: report.volume,
            removed: report.removed,
        };
        self.queue.push_back((self.delay + 1, areas, measure));
        Ok(arrived)
    }

    fn poll(&mut self) -> Result<GranularArrivals, String> {
        Ok(self.take_arrived())
    }

    fn stop(&mut self) -> Result<GranularArrivals, String> {
        let mut out = GranularArrivals::default();
        for (_, areas, measure) in self.queue.drain(..) {
            out.areas.extend(areas);
            out.measured.push(measure);
        }
        if let Some(sim) = self.sim.take() {
            self.stopped.push(sim.map().grid().clone());
        }
        Ok(out)
    }
}

fn config() -> TrailConfig {
    TrailConfig {
        side: 40,
        edge_margin_m: 8.0,
        forced_margin_m: 4.0,
        take_timeout: Duration::from_secs(10),
    }
}

/// Drives a wheel from x = 10 to x = 110 m along z = 60, 1.5 m a frame, on the CPU
/// (`gpu` none) or through `gpu`; returns the frames, the world's heights after release and
/// the windows released.
fn drive(mut gpu: Option<&mut LateStepper>) -> (Vec<TrailFrame>, Grid<u16>, u32) {
    let world = world();
    let mut pool = loaded_pool(&world);
    let mut trails =
        GranularTrails::new(world.manifest(), GranularParams::snow(), config()).unwrap();
    let wheel = TriMesh::wheel(2.0, 1.0, 16).unwrap();
    let mut frames = Vec::new();
    for i in 0..68u64 {
        let xz = Vec2::new(10.0 + 1.5 * i as f32, 60.0);
        let ahead = xz + Vec2::X * 10.0;
        let before = trails.window();
        let mut frame = trails
            .follow(
                &mut pool,
                gpu.as_deref_mut(),
                &[xz],
                ahead,
                &camera(),
                false,
            )
            .unwrap();
        // A window that moved on left the tiles with its map's last heights, every one.
        if let (Some(late), Some(rect), Some(_)) = (gpu.as_deref(), before, frame.move_waited) {
            let mut now = Grid::new(rect.size.x, rect.size.y, 0u16).unwrap();
            assert_eq!(pool.read_region(rect, &mut now).unwrap(), 0);
            let last = late.stopped.last().expect("the window's map was stopped");
            let last: Vec<u16> = last.as_slice().iter().map(|&u| u as u16).collect();
            assert!(
                now.as_slice() == last.as_slice(),
                "frame {i}: an area never landed"
            );
        }
        let ground = trails.ground().expect("a window around the wheel");
        let corner = trails.window().unwrap().min.as_vec2();
        let below = terrain_core::bilinear(ground, xz - corner).unwrap();
        // The wheel's bottom 0.5 m under the ground the window was taken with.
        let at = Vec3::new(xz.x - corner.x, below + 1.5, xz.y - corner.y);
        let wheel_at = [GranularObject::new(&wheel, Affine3A::from_translation(at))];
        trails
            .step(&mut pool, gpu.as_deref_mut(), &wheel_at, i, &mut frame)
            .unwrap();
        frames.push(frame);
    }
    let (_, measured) = trails.release(&mut pool, gpu).unwrap();
    assert!(trails.window().is_none());
    if let Some(last) = frames.last_mut() {
        last.measured.extend(measured);
    }
    (frames, heights(&pool), trails.windows_released())
}

#[test]
fn cpu_trails_keep_the_volume_exact_and_move_with_the_wheel() {
    let world = world();
    let before = heights(&loaded_pool(&world));
    let (frames, after, released) = drive(None);
    assert!(
        released >= 3,
        "the window moved {released} times over 100 m"
    );
    for (i, f) in frames.iter().enumerate() {
        assert_eq!(f.on_gpu, Some(false));
        assert_eq!(f.volume, f.volume_taken, "frame {i}");
        assert!(f.volume.is_some());
    }
    assert!(frames.iter().any(|f| !f.changed.is_empty()));
    assert_ne!(
        before.as_slice(),
        after.as_slice(),
        "no trail reached the tiles"
    );
}

#[test]
fn late_results_all_reach_the_tiles_and_moves_wait_for_nothing() {
    // Each step's results arrive by the next frame's poll, as they do where the frame waits
    // for the GPU (the demo's capture).
    let mut late = LateStepper::new(0);
    let (frames, _, released) = drive(Some(&mut late));
    assert!(
        released >= 3,
        "the window moved {released} times over 100 m"
    );
    assert_eq!(late.stopped.len() as u32, released);
    // Every step's measure came back, in order, each the volume the window should hold.
    let measured: Vec<_> = frames.iter().flat_map(|f| f.measured.iter()).collect();
    assert_eq!(measured.len(), frames.len());
    for m in &measured {
        assert_eq!(Some(m.volume), m.volume_taken, "step {}", m.tag);
    }
    let by_tag: Vec<u64> = measured.iter().map(|m| m.tag).collect();
    assert!(by_tag.windows(2).all(|w| w[0] < w[1]));
    assert!(
        frames
            .iter()
            .all(|f| f.on_gpu == Some(true) && f.volume.is_none())
    );
    // 1.5 m a frame and 4 m between the margins: results a frame late never force a move.
    let moves: Vec<bool> = frames.iter().filter_map(|f| f.move_waited).collect();
    assert!(moves.len() >= 3, "{moves:?}");
    assert!(moves.iter().all(|waited| !waited), "{moves:?}");
}

#[test]
fn results_that_come_later_force_a_move_that_drains_them() {
    // Two frames late: something is always on its way while the wheel steps every frame.
    let mut late = LateStepper::new(2);
    let (frames, _, _) = drive(Some(&mut late));
    let moves: Vec<bool> = frames.iter().filter_map(|f| f.move_waited).collect();
    assert!(moves.contains(&true), "{moves:?}");
    let measured = frames.iter().map(|f| f.measured.len()).sum::<usize>();
    assert_eq!(measured, frames.len(), "a step's measure was lost");
}

#[test]
fn bad_settings_and_a_missing_stepper_are_refused() {
    let world = world();
    let m = world.manifest();
    let params = GranularParams::snow();
    for (edge, forced) in [(8.0, 9.0), (8.0, -1.0), (f32::NAN, 4.0), (8.0, f32::NAN)] {
        let c = TrailConfig {
            edge_margin_m: edge,
            forced_margin_m: forced,
            ..config()
        };
        assert!(
            GranularTrails::new(m, params, c).is_err(),
            "{edge} {forced}"
        );
    }
    let mut bad = params;
    bad.compression = f32::NAN;
    assert!(GranularTrails::new(m, bad, config()).is_err());
    let forever = TrailConfig {
        take_timeout: Duration::MAX,
        ..config()
    };
    assert!(GranularTrails::new(m, params, forever).is_err());
    // A window taken on the "GPU" is stepped and released with it, never without.
    let mut pool = loaded_pool(&world);
    let mut trails = GranularTrails::new(m, params, config()).unwrap();
    let mut late = LateStepper::new(1);
    let xz = Vec2::splat(60.0);
    trails
        .follow(&mut pool, Some(&mut late), &[xz], xz, &camera(), false)
        .unwrap();
    let nan = Vec2::new(f32::NAN, 1.0);
    let late_again = Some(&mut late);
    let refused = trails.follow(&mut pool, late_again, &[nan], xz, &camera(), false);
    assert!(matches!(refused, Err(TrailsError::Cache(_))));
    let far = Vec2::splat(f32::MAX);
    assert!(
        trails
            .follow(&mut pool, Some(&mut late), &[xz], far, &camera(), false)
            .is_ok()
    );
    let mut frame = TrailFrame::default();
    let err = trails.step(&mut pool, None::<&mut CpuOnly>, &[], 0, &mut frame);
    assert!(matches!(err, Err(TrailsError::Cache(_))));
    assert!(trails.release(&mut pool, None::<&mut CpuOnly>).is_err());
    trails.release(&mut pool, Some(&mut late)).unwrap();
    // CpuOnly refuses to be a GPU.
    assert!(matches!(
        trails.follow(&mut pool, Some(&mut CpuOnly), &[xz], xz, &camera(), false),
        Err(TrailsError::Stepper(_))
    ));
}
