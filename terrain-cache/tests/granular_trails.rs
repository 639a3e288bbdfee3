//! `GranularTrails` on a real RAM pool: a wheel driven across the world, the window moved on
//! ahead of it, stepped on the CPU or through a stepper whose results come back frames late
//! (as a GPU's do), which either stops its map at each move or shifts it on without a wait.
//! The volume is exact at every step and across each hand-over, every area of a late stepper
//! reaches the tiles, the world ends as on the CPU, an unforced move waits for nothing, and bad
//! settings are refused.

mod common;

use common::build;
use glam::{Affine3A, IVec2, UVec2, Vec2, Vec3};
use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Duration;
use terrain_cache::{
    CameraState, CpuOnly, GranularStepper, GranularTrails, Layer, ObjectTileStore, PoolConfig,
    RamPool, TileId, TileState, TileStore, TrailConfig, TrailFrame, TrailsError, World,
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
    queue: Queue,
    /// Whether it moves its map on without a wait (as terrain-gpu's `GranularField::shift`).
    shifting: bool,
    /// The old map's results still on their way after a shift.
    retired: Queue,
    shifts: u32,
    /// The shift (counted from 0) that fails, as a lost device's would.
    fail_shift: Option<u32>,
    failed: u32,
    /// The heights of each map when it was stopped.
    stopped: Vec<Grid<u32>>,
}

/// Results on their way: polls left, areas, measure.
type Queue = VecDeque<(usize, Areas, StepMeasure)>;

impl LateStepper {
    fn new(delay: usize) -> Self {
        Self {
            sim: None,
            delay,
            queue: VecDeque::new(),
            shifting: false,
            retired: VecDeque::new(),
            shifts: 0,
            fail_shift: None,
            failed: 0,
            stopped: Vec::new(),
        }
    }

    fn shifting(delay: usize) -> Self {
        Self {
            shifting: true,
            ..Self::new(delay)
        }
    }
}

fn take_arrived(queue: &mut Queue) -> GranularArrivals {
    let mut out = GranularArrivals::default();
    for entry in queue.iter_mut() {
        entry.0 = entry.0.saturating_sub(1);
    }
    while queue.front().is_some_and(|e| e.0 == 0) {
        let (_, areas, measure) = queue.pop_front().unwrap();
        out.areas.extend(areas);
        out.measured.push(measure);
    }
    out.in_flight = !queue.is_empty();
    out
}

fn drain(queue: &mut Queue) -> GranularArrivals {
    let mut out = GranularArrivals::default();
    for (_, areas, measure) in queue.drain(..) {
        out.areas.extend(areas);
        out.measured.push(measure);
    }
    out
}

impl GranularStepper for LateStepper {
    type Error = String;

    fn start(&mut self, map: &FixedPointMap, params: GranularParams) -> Result<(), String> {
        assert!(
            self.queue.is_empty(),
            "a new map while the last one's are on their way"
        );
        self.sim = Some(GranularSim::new(map.clone(), params).map_err(|e| e.to_string())?);
        Ok(())
    }

    fn step(
        &mut self,
        objects: &[GranularObject<'_>],
        tag: u64,
    ) -> Result<GranularArrivals, String> {
        let arrived = take_arrived(&mut self.queue);
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
        Ok(take_arrived(&mut self.queue))
    }

    fn stop(&mut self) -> Result<GranularArrivals, String> {
        let out = drain(&mut self.queue);
        if let Some(sim) = self.sim.take() {
            self.stopped.push(sim.map().grid().clone());
        }
        Ok(out)
    }

    fn shifts(&self) -> bool {
        self.shifting
    }

    fn shift(&mut self, map: &FixedPointMap, offset: IVec2, tag: u64) -> Result<bool, String> {
        assert!(
            self.retired.is_empty(),
            "a shift while the last is on its way"
        );
        if self.fail_shift == Some(self.shifts + self.failed) {
            self.failed += 1;
            return Err(INJECTED.into());
        }
        let old = self.sim.take().ok_or("not started")?;
        let size = map.size();
        // The shared columns are the old map's now (as a GPU copy after every step).
        let shared = Rect::from_size(size).intersect(&Rect::new(-offset, size));
        let mut grid = map.grid().clone();
        if let Some(r) = shared {
            let from = Rect::new(r.min + offset, r.size);
            grid.paste(&old.map().grid().copy_rect(from).unwrap(), r.min)
                .unwrap();
        }
        let moved = FixedPointMap::new(grid, map.encoding(), map.texel_size(), map.wrap()).unwrap();
        let sum = moved.grid().as_slice().iter().map(|&u| u64::from(u)).sum();
        let areas = shared
            .map(|r| vec![(r, moved.grid().copy_rect(r).unwrap())])
            .unwrap_or_default();
        self.retired = std::mem::take(&mut self.queue);
        // The old map's last areas come after the new map's first (a full readback ring
        // requests them late): the shared part must not take them.
        for entry in &mut self.retired {
            entry.0 += 3;
        }
        let first = StepMeasure {
            tag,
            volume: sum,
            removed: 0,
        };
        self.queue.push_back((self.delay + 1, areas, first));
        self.sim = Some(GranularSim::new(moved, *old.params()).map_err(|e| e.to_string())?);
        self.shifts += 1;
        Ok(true)
    }

    fn poll_retired(&mut self) -> Result<GranularArrivals, String> {
        Ok(take_arrived(&mut self.retired))
    }

    fn drain_retired(&mut self) -> Result<GranularArrivals, String> {
        Ok(drain(&mut self.retired))
    }
}

/// The error of a shift made to fail.
const INJECTED: &str = "injected shift failure";

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
fn drive(gpu: Option<&mut LateStepper>) -> (Vec<TrailFrame>, Grid<u16>, u32) {
    let path: Vec<(Vec2, Vec2)> = (0..68)
        .map(|i| (Vec2::new(10.0 + 1.5 * i as f32, 60.0), Vec2::X))
        .collect();
    drive_along(gpu, &path)
}

/// [`drive`] along `path`: the wheel's position and heading (the window moves on 10 m ahead).
fn drive_along(
    mut gpu: Option<&mut LateStepper>,
    path: &[(Vec2, Vec2)],
) -> (Vec<TrailFrame>, Grid<u16>, u32) {
    let world = world();
    let mut pool = loaded_pool(&world);
    let mut trails =
        GranularTrails::new(world.manifest(), GranularParams::snow(), config()).unwrap();
    let wheel = TriMesh::wheel(2.0, 1.0, 16).unwrap();
    let mut frames = Vec::new();
    for (i, &(xz, heading)) in (0u64..).zip(path) {
        let ahead = xz + heading * 10.0;
        let before = trails.window();
        let stops = gpu.as_deref().map_or(0, |late| late.stopped.len());
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
        if let (Some(late), Some(rect)) = (gpu.as_deref(), before)
            && late.stopped.len() > stops
        {
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
        let (local, below) = trails.ground_at(xz).expect("a window around the wheel");
        assert_eq!(local, xz - corner, "texels of 1 m");
        assert_eq!(below, terrain_core::bilinear(ground, local).unwrap());
        // The wheel's bottom 0.5 m under the ground the window was taken with.
        let at = Vec3::new(local.x, below + 1.5, local.y);
        let wheel_at = [GranularObject::new(&wheel, Affine3A::from_translation(at))];
        trails
            .step(&mut pool, gpu.as_deref_mut(), &wheel_at, i, &mut frame)
            .unwrap();
        frames.push(frame);
    }
    let (_, measured) = trails.release(&mut pool, gpu).unwrap();
    assert!(trails.window().is_none());
    assert_eq!(trails.ground_at(Vec2::ZERO), None, "no window, no ground");
    let tiles = WORLD / TILE;
    for id in (0..tiles * tiles).map(|k| TileId::new(0, k % tiles, k / tiles)) {
        let state = pool.status(id).map(|s| s.state);
        assert_ne!(state, Some(TileState::InUse), "{id:?} still pinned");
    }
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
fn a_shifting_stepper_moves_on_without_a_wait_and_leaves_the_cpu_world() {
    // Results two frames late, which forced every move to wait for a stepper that cannot
    // shift (the test above): moved on the "GPU", nothing waits, every unit is accounted
    // for across each hand-over, and the world ends as on the CPU.
    let (_, on_cpu, _) = drive(None);
    let mut late = LateStepper::shifting(2);
    let (frames, after, released) = drive(Some(&mut late));
    assert!(late.shifts >= 2, "{} shifts", late.shifts);
    assert_eq!(late.stopped.len(), 1, "only the end stops the map");
    assert_eq!(
        released,
        late.shifts + 1,
        "a retired window was never checked"
    );
    let moves: Vec<bool> = frames.iter().filter_map(|f| f.move_waited).collect();
    assert!(moves.iter().all(|waited| !waited), "{moves:?}");
    let measured: Vec<_> = frames.iter().flat_map(|f| f.measured.iter()).collect();
    assert_eq!(measured.len(), frames.len(), "a step's measure was lost");
    for m in &measured {
        assert_eq!(Some(m.volume), m.volume_taken, "step {}", m.tag);
    }
    assert!(
        after.as_slice() == on_cpu.as_slice(),
        "the world differs from the CPU's"
    );
    // The waiting stepper leaves the same world too.
    let (_, waited, _) = drive(Some(&mut LateStepper::new(0)));
    assert!(waited.as_slice() == on_cpu.as_slice());
}

#[test]
fn shifting_along_the_world_edge_and_after_a_jump_keeps_every_unit() {
    // Along the world's edge (the window clamped there needs no margin on that side, or it
    // would move every frame), then a jump to the far corner (windows that share nothing)
    // and back along the other edge, off the world for a while.
    let mut path: Vec<(Vec2, Vec2)> = (0..40)
        .map(|i| (Vec2::new(6.0 + 2.5 * i as f32, 1.5), Vec2::X))
        .collect();
    path.extend((0..40).map(|i| (Vec2::new(126.0, 124.0 - 3.5 * i as f32), Vec2::NEG_Y)));
    path.extend((0..12).map(|i| (Vec2::new(140.0 + i as f32, 10.0), Vec2::X)));
    let (_, on_cpu, cpu_windows) = drive_along(None, &path);
    let mut late = LateStepper::shifting(2);
    let (frames, after, released) = drive_along(Some(&mut late), &path);
    assert!(late.shifts >= 3, "{} shifts", late.shifts);
    // One window along the bottom edge beyond the first moves, then the jump.
    assert!(
        cpu_windows <= 12,
        "{cpu_windows} windows: moved every frame at the edge"
    );
    let forced = frames
        .iter()
        .filter(|f| f.move_waited == Some(true))
        .count() as u32;
    assert_eq!(released, late.shifts + forced + 1);
    let measured: Vec<_> = frames.iter().flat_map(|f| f.measured.iter()).collect();
    assert_eq!(measured.len(), frames.len(), "a step's measure was lost");
    for m in &measured {
        assert_eq!(Some(m.volume), m.volume_taken, "step {}", m.tag);
    }
    assert!(after.as_slice() == on_cpu.as_slice(), "the world differs");
}

#[test]
fn a_failed_shift_falls_back_to_a_move_that_waits_and_loses_nothing() {
    let (_, on_cpu, _) = drive(None);
    let mut late = LateStepper::shifting(2);
    late.fail_shift = Some(1);
    let (frames, after, released) = drive(Some(&mut late));
    assert_eq!(late.failed, 1);
    assert!(late.shifts >= 2, "{} shifts", late.shifts);
    let failed: Vec<_> = frames
        .iter()
        .filter_map(|f| f.shift_failed.as_ref())
        .collect();
    assert_eq!(failed, [&INJECTED.to_string()]);
    // The failed shift's move stopped the map and took the next window.
    assert_eq!(late.stopped.len(), 2);
    assert_eq!(released, late.shifts + 2);
    assert!(after.as_slice() == on_cpu.as_slice(), "the world differs");
    let measured: Vec<_> = frames.iter().flat_map(|f| f.measured.iter()).collect();
    assert_eq!(measured.len(), frames.len(), "a step's measure was lost");
    for m in &measured {
        assert_eq!(Some(m.volume), m.volume_taken, "step {}", m.tag);
    }
}

#[test]
fn objects_wider_than_the_window_do_not_move_it_every_frame() {
    let world = world();
    let mut pool = loaded_pool(&world);
    let mut trails =
        GranularTrails::new(world.manifest(), GranularParams::snow(), config()).unwrap();
    for i in 0..30 {
        let centre = Vec2::new(40.0 + 0.5 * i as f32, 64.0);
        let points = [centre - Vec2::X * 22.5, centre + Vec2::X * 22.5];
        let stepper = None::<&mut CpuOnly>;
        trails
            .follow(&mut pool, stepper, &points, centre, &camera(), false)
            .unwrap();
    }
    // One window taken; it moves only when the place it would take changes (a texel each
    // other frame here), not every frame.
    assert!(
        trails.windows_released() <= 16,
        "{}",
        trails.windows_released()
    );
    trails.release(&mut pool, None::<&mut CpuOnly>).unwrap();
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
