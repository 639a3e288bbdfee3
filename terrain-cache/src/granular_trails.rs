//! Granular trails that follow moving objects over a streamed world (Persson 2019, ch. 4):
//! a [`GranularWindow`] kept around the objects, stepped on the CPU or, through a
//! [`GranularStepper`] the application provides, on the GPU, every changed area handed back
//! into the tiles, and the window moved on ahead of the objects when they near its edge.
//!
//! **Moving without a wait.** Areas stepped on a GPU come back a frame or more later. Once the
//! objects are within [`TrailConfig::edge_margin_m`] of the window's edge, the window moves on
//! to one centred ahead of them on the first frame where the caller has none of its own writes
//! on their way into the world (`others_in_flight`). A stepper that
//! [`shifts`](GranularStepper::shifts) (terrain-gpu's `GranularField::shift`) moves its map on
//! the GPU without waiting for the steps still on their way: the old window retires, its late
//! areas landing through [`GranularStepper::poll_retired`] on the following frames, the volume
//! exact across the hand-over ([`GranularWindow::shift`]). Only objects within
//! [`TrailConfig::forced_margin_m`] of the edge while something is still on its way force a
//! move that waits (the stepper's `drain_retired` and `stop`): writes of the caller's own, a
//! window that moved a frame or two earlier, or a stepper that does not shift.
//!
//! **Volume.** The window holds the world's stored units (see [`GranularWindow`]); the units
//! it held when taken, less what compression removed since, equal the scratch map's sum at
//! every step ([`TrailFrame::volume`] against [`TrailFrame::volume_taken`], and each
//! [`TrailMeasure`] of a GPU step), and the window's release checks the tiles against them.

use crate::{CacheError, CameraState, GranularWindow, Manifest, RamPool};
use glam::Vec2;
use std::time::{Duration, Instant};
pub use terrain_core::granular::{CpuOnly, GranularStepper, SHIFT_TAG};
use terrain_core::granular::{GranularArrivals, GranularObject, GranularParams, GranularSim};
use terrain_core::{FixedPointMap, Grid, Rect};

/// The longest [`TrailConfig::take_timeout`]: a frame must end in bounded time.
pub const MAX_TAKE_TIMEOUT: Duration = Duration::from_secs(3600);

/// Where and when the window moves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrailConfig {
    /// Side of the window in level-0 texels (at most [`crate::MAX_WINDOW_SIDE`], clipped to the
    /// world).
    pub side: u32,
    /// Metres the objects keep from the window's edge before it moves on without a wait (the
    /// step's active area reaches a few texels past an object).
    pub edge_margin_m: f32,
    /// Metres from the edge past which the window moves even with writes on their way,
    /// waiting for them (smaller than `edge_margin_m`).
    pub forced_margin_m: f32,
    /// How long a new window may wait for its tiles to load (at most [`MAX_TAKE_TIMEOUT`]).
    pub take_timeout: Duration,
}

impl Default for TrailConfig {
    /// 128 texels (64 m at 0.5 m), moving 8 m from the edge, forced at 4 m, 10 s for tiles.
    fn default() -> Self {
        Self {
            side: 128,
            edge_margin_m: 8.0,
            forced_margin_m: 4.0,
            take_timeout: Duration::from_secs(10),
        }
    }
}

/// Why a [`GranularTrails`] call failed.
#[derive(Debug, thiserror::Error)]
pub enum TrailsError<E> {
    /// The pool, the window or the step refused (a tile not resident, a volume that does not
    /// add up, bad parameters).
    #[error(transparent)]
    Cache(#[from] CacheError),
    /// The GPU stepper failed.
    #[error("the granular step on the GPU failed: {0}")]
    Stepper(E),
    /// A new window's tiles did not reach RAM in time.
    #[error("the granular window's tiles ({rect:?}) did not load within {timeout:?}")]
    TilesLate {
        /// The window asked for (level-0 texels).
        rect: Rect,
        /// [`TrailConfig::take_timeout`].
        timeout: Duration,
    },
}

/// A GPU step's measures, for the frame that stepped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TrailMeasure {
    /// The tag the step was given.
    pub tag: u64,
    /// The scratch map's units after the step.
    pub volume: u64,
    /// The units the window held when taken, less compression's (equal to `volume`).
    pub volume_taken: Option<u64>,
}

/// Areas handed back into the tiles: level-0 texels and their stored heights.
pub type HandedBack = Vec<(Rect, Grid<u16>)>;

/// What the trails did in one frame.
#[derive(Debug, Default)]
pub struct TrailFrame {
    /// Areas handed back into the tiles.
    pub changed: HandedBack,
    /// A CPU step's scratch-map units after it (a GPU step's come later, in `measured`).
    pub volume: Option<u64>,
    /// The units the window held when taken, less compression's (equal to `volume`).
    pub volume_taken: Option<u64>,
    /// Whether this frame's step ran on the GPU (`None`: no step).
    pub on_gpu: Option<bool>,
    /// On a frame where the window moved on: whether the move had to wait (forced, or after a
    /// failed shift).
    pub move_waited: Option<bool>,
    /// The stepper's error when it could not shift its map this frame (the window then moved
    /// the waiting way: stopped, released, taken again).
    pub shift_failed: Option<String>,
    /// Measures of earlier GPU steps that arrived, in arrival order (a retiring window's last
    /// ones may come after the moved window's first).
    pub measured: Vec<TrailMeasure>,
}

/// Granular trails over a streamed world (module docs).
#[derive(Debug)]
pub struct GranularTrails {
    window: GranularWindow,
    config: TrailConfig,
    params: GranularParams,
    /// The CPU simulation of the taken window (no GPU stepper).
    sim: Option<GranularSim>,
    /// Whether the taken window steps on the GPU.
    on_gpu: bool,
    /// The ground objects are placed on, and the window it was taken for (kept past a release
    /// so the next window carries it over where the two overlap).
    ground: Option<(Rect, FixedPointMap)>,
    /// Units removed by compression in the taken window.
    removed: u64,
    /// Units removed by compression in the retiring window (its late measures add to it).
    retired_removed: u64,
    /// Whether every area and measure of the retiring window has arrived.
    retired_done: bool,
    windows_released: u32,
}

impl GranularTrails {
    /// Trails on the world of `manifest`, of material `params` (checked), moving as `config`
    /// says (margins finite, `0 <= forced <= edge`).
    pub fn new(
        manifest: &Manifest,
        params: GranularParams,
        config: TrailConfig,
    ) -> Result<Self, CacheError> {
        params.validate()?;
        let (forced, edge) = (config.forced_margin_m, config.edge_margin_m);
        // Written so that a NaN fails.
        if !(forced >= 0.0 && forced <= edge && edge.is_finite()) {
            return Err(CacheError::OutOfRange {
                what: "granular trail margins (metres)",
                value: f64::from(config.forced_margin_m),
                expected: "0 <= forced_margin_m <= edge_margin_m, both finite",
            });
        }
        if config.take_timeout > MAX_TAKE_TIMEOUT {
            return Err(CacheError::OutOfRange {
                what: "granular trail tile timeout (seconds)",
                value: config.take_timeout.as_secs_f64(),
                expected: "at most an hour",
            });
        }
        let side = config.side.min(manifest.world_size.min_element());
        Ok(Self {
            window: GranularWindow::new(manifest, side)?,
            config,
            params,
            sim: None,
            on_gpu: false,
            ground: None,
            removed: 0,
            retired_removed: 0,
            retired_done: false,
            windows_released: 0,
        })
    }

    /// The taken window (level-0 texels), where objects are stepped. Other writes must keep out
    /// of [`Self::keep_out`], which also holds a retiring window.
    pub fn window(&self) -> Option<Rect> {
        self.window.rect()
    }

    /// The window's ground as taken (the scratch map's encoding, its origin at the window's
    /// corner): a reference ground to place objects on, whatever their trails did. Where a
    /// window overlaps the last one, it keeps the last one's ground, so objects are placed alike
    /// whether a move waited for the GPU or not (and on the CPU).
    pub fn ground(&self) -> Option<&FixedPointMap> {
        let rect = self.window.rect()?;
        self.ground
            .as_ref()
            .filter(|(r, _)| *r == rect)
            .map(|(_, map)| map)
    }

    /// Where an object at `xz` (world metres, X Z) stands in the taken window: its position in
    /// the window's frame (metres from the window's corner) and the height of the window's
    /// [`ground`](Self::ground) under it (bilinear; a point off the window reads its nearest
    /// edge), to pose objects on. `None` without a window, or for a point not finite.
    pub fn ground_at(&self, xz: Vec2) -> Option<(Vec2, f32)> {
        let (ground, window) = (self.ground()?, self.window()?);
        let local = xz - window.min.as_vec2() * ground.texel_size();
        let height = terrain_core::bilinear(ground, local).ok()?;
        Some((local, height))
    }

    /// Where no other write may go: the taken window and, while one retires, the window it
    /// moved away from (the smallest rect holding both).
    pub fn keep_out(&self) -> Option<Rect> {
        let now = self.window.rect()?;
        Some(self.window.retiring_rect().map_or(now, |r| r.union(&now)))
    }

    /// `transform` in world metres, in the window's frame (see [`GranularWindow::to_local`]).
    pub fn to_local(&self, transform: glam::Affine3A) -> glam::Affine3A {
        self.window.to_local(transform)
    }

    /// Windows released so far, each with its volume checked.
    pub fn windows_released(&self) -> u32 {
        self.windows_released
    }

    /// Whether the next [`follow`](Self::follow) with objects at `points` (metres, X Z) moves
    /// the window whatever is on its way: the caller lands its own writes first.
    pub fn must_move(&self, points: &[Vec2]) -> bool {
        self.window.rect().is_some() && !self.window.covers(points, self.config.forced_margin_m)
    }

    /// Keeps the window around `points` (the objects, metres X Z): once they near its edge
    /// it hands back what arrived and moves on (module docs) to a window centred on `ahead`,
    /// whose tiles it waits for (up to the timeout, updating `pool` for `camera`).
    /// `others_in_flight`: the caller still has writes on their way into the world. A
    /// non-finite position is refused, nothing changed.
    pub fn follow<G: GranularStepper>(
        &mut self,
        pool: &mut RamPool,
        mut gpu: Option<&mut G>,
        points: &[Vec2],
        ahead: Vec2,
        camera: &CameraState,
        others_in_flight: bool,
    ) -> Result<TrailFrame, TrailsError<G::Error>> {
        if let Some(p) = points.iter().chain([&ahead]).find(|p| !p.is_finite()) {
            return Err(CacheError::OutOfRange {
                what: "granular trail object position (metres)",
                value: f64::from(if p.x.is_finite() { p.y } else { p.x }),
                expected: "finite coordinates",
            }
            .into());
        }
        let mut frame = TrailFrame::default();
        if let Some(g) = gpu.as_deref_mut()
            && self.window.retiring_rect().is_some()
        {
            let arrivals = g.poll_retired().map_err(TrailsError::Stepper)?;
            self.land_retired(pool, &arrivals, &mut frame)?;
            self.retired_done = !arrivals.in_flight;
            self.try_retire(pool)?;
        }
        // Objects spread wider than a window are never covered: a move to where the window
        // already is would do nothing but wait.
        let stays = self.window.rect() == Some(self.window.placement(ahead));
        let leaving = !stays && !self.window.covers(points, self.config.edge_margin_m);
        let mut move_now = leaving && self.window.rect().is_none();
        if leaving && self.window.rect().is_some() {
            let shifting = self.on_gpu && gpu.as_deref().is_some_and(|g| g.shifts());
            let mut settled = !others_in_flight;
            if let Some(g) = gpu.as_deref_mut()
                && self.on_gpu
            {
                let arrivals = g.poll().map_err(TrailsError::Stepper)?;
                self.hand_back(pool, &arrivals, &mut frame)?;
                // A shifting stepper's steps on their way move on with its map.
                settled &= match shifting {
                    true => self.window.retiring_rect().is_none(),
                    false => !arrivals.in_flight,
                };
            }
            let mut moved = false;
            if let (true, true, Some(g)) = (settled, shifting, gpu.as_deref_mut()) {
                match self.shift(pool, g, ahead, camera) {
                    Ok(()) => (frame.move_waited, moved) = (Some(false), true),
                    // The stepper could not move its map: the window moves the waiting way.
                    Err(TrailsError::Stepper(e)) => frame.shift_failed = Some(e.to_string()),
                    Err(e) => return Err(e),
                }
            }
            if !moved && (settled || self.must_move(points)) {
                frame.move_waited = Some(!settled || frame.shift_failed.is_some());
                let (changed, measured) = self.release(pool, gpu.as_deref_mut())?;
                frame.changed.extend(changed);
                frame.measured.extend(measured);
                move_now = true;
            }
        }
        if move_now {
            self.take(pool, gpu, ahead, camera)?;
        }
        Ok(frame)
    }

    /// Waits (up to the timeout, updating `pool` for `camera`) until `read` finds the tiles of
    /// `rect` in RAM.
    fn wait_for_tiles<T, E>(
        &mut self,
        pool: &mut RamPool,
        camera: &CameraState,
        rect: Rect,
        mut read: impl FnMut(&mut GranularWindow, &mut RamPool) -> Result<Option<T>, CacheError>,
    ) -> Result<T, TrailsError<E>> {
        let deadline = Instant::now() + self.config.take_timeout;
        loop {
            if let Some(got) = read(&mut self.window, pool)? {
                return Ok(got);
            }
            if Instant::now() > deadline {
                let timeout = self.config.take_timeout;
                return Err(TrailsError::TilesLate { rect, timeout });
            }
            std::thread::sleep(Duration::from_millis(2));
            pool.update(camera)?;
        }
    }

    fn take<G: GranularStepper>(
        &mut self,
        pool: &mut RamPool,
        gpu: Option<&mut G>,
        ahead: Vec2,
        camera: &CameraState,
    ) -> Result<(), TrailsError<G::Error>> {
        let rect = self.window.placement(ahead);
        let map = self.wait_for_tiles(pool, camera, rect, |w, p| w.take(p, rect))?;
        match gpu {
            Some(g) => {
                g.start(&map, self.params).map_err(TrailsError::Stepper)?;
                self.on_gpu = true;
            }
            None => {
                let sim = GranularSim::new(map.clone(), self.params).map_err(CacheError::from)?;
                self.sim = Some(sim);
            }
        }
        self.carry_ground(rect, map)?;
        self.removed = 0;
        Ok(())
    }

    /// Moves the window on to one centred on `ahead` with its map on the GPU, without a wait
    /// (module docs): the old one retires.
    fn shift<G: GranularStepper>(
        &mut self,
        pool: &mut RamPool,
        g: &mut G,
        ahead: Vec2,
        camera: &CameraState,
    ) -> Result<(), TrailsError<G::Error>> {
        let rect = self.window.placement(ahead);
        let (map, offset) = self.wait_for_tiles(pool, camera, rect, |w, p| w.shift(p, rect))?;
        // A stepper that could not move keeps stepping the old window: so does this.
        match g.shift(&map, offset, SHIFT_TAG) {
            Ok(true) => {}
            Ok(false) => {
                self.window.undo_shift(pool);
                return Err(CacheError::OutOfRange {
                    what: "granular steppers that say they shift but did not",
                    value: 0.0,
                    expected: "a stepper whose shift moves its map when shifts() is true",
                }
                .into());
            }
            Err(e) => {
                self.window.undo_shift(pool);
                return Err(TrailsError::Stepper(e));
            }
        }
        self.carry_ground(rect, map)?;
        self.retired_removed = std::mem::take(&mut self.removed);
        self.retired_done = false;
        Ok(())
    }

    /// Keeps `map` (the window at `rect` as taken) as the ground, the last ground where the
    /// two overlap.
    fn carry_ground(&mut self, rect: Rect, mut map: FixedPointMap) -> Result<(), CacheError> {
        if let Some((last, ground)) = &self.ground
            && let Some(shared) = last.intersect(&rect)
        {
            let from = Rect::new(shared.min - last.min, shared.size);
            let part = ground.grid().copy_rect(from)?;
            map.grid_mut().paste(&part, shared.min - rect.min)?;
        }
        self.ground = Some((rect, map));
        Ok(())
    }

    /// Lands what arrived of the retiring window: its areas outside the taken window, and its
    /// measures against the units it held.
    fn land_retired<E>(
        &mut self,
        pool: &mut RamPool,
        arrivals: &GranularArrivals,
        frame: &mut TrailFrame,
    ) -> Result<(), TrailsError<E>> {
        let mut first = None;
        for (area, heights) in &arrivals.areas {
            match self.window.hand_back_retired(pool, *area, heights) {
                Ok(parts) => frame.changed.extend(parts),
                Err(e) => first = first.or(Some(e)),
            }
        }
        let held = self.window.retiring_volume();
        for m in &arrivals.measured {
            self.retired_removed += m.removed;
            frame.measured.push(TrailMeasure {
                tag: m.tag,
                volume: m.volume,
                volume_taken: held.and_then(|v| v.checked_sub(self.retired_removed)),
            });
        }
        first.map_or(Ok(()), |e| Err(e.into()))
    }

    /// Retires the retiring window once all of it has arrived and the moved window's sum is
    /// known, its hand-over checked.
    fn try_retire(&mut self, pool: &mut RamPool) -> Result<(), CacheError> {
        if self.retired_done && self.window.retiring_rect().is_some() && !self.window.awaits_sum() {
            self.window.retire(pool, self.retired_removed)?;
            self.windows_released += 1;
        }
        Ok(())
    }

    /// One step of the window with `objects` (in its frame: [`Self::to_local`]) on the GPU
    /// when it was taken with one, else on the CPU, tagged `tag`; hands the changed areas
    /// back into `pool`'s tiles (a GPU step's when they arrive). Nothing without a window.
    pub fn step<G: GranularStepper>(
        &mut self,
        pool: &mut RamPool,
        gpu: Option<&mut G>,
        objects: &[GranularObject<'_>],
        tag: u64,
        frame: &mut TrailFrame,
    ) -> Result<(), TrailsError<G::Error>> {
        match (gpu, &mut self.sim) {
            (Some(g), _) if self.on_gpu => {
                let arrivals = g.step(objects, tag).map_err(TrailsError::Stepper)?;
                frame.on_gpu = Some(true);
                self.hand_back(pool, &arrivals, frame)
            }
            (_, Some(sim)) => {
                let report = sim.step(objects).map_err(CacheError::from)?;
                self.removed += report.removed;
                frame.on_gpu = Some(false);
                frame.volume = Some(report.volume);
                frame.volume_taken = self.window.volume_taken().checked_sub(self.removed);
                for area in report.active_areas {
                    let heights = sim
                        .map()
                        .grid()
                        .copy_rect(area.rect)
                        .map_err(CacheError::from)?;
                    let back = self.window.hand_back(pool, area.rect, &heights)?;
                    frame.changed.push(back);
                }
                Ok(())
            }
            (None, None) if self.on_gpu => Err(CacheError::OutOfRange {
                what: "granular steppers given to a window taken on the GPU",
                value: 0.0,
                expected: "the stepper the window was taken with",
            }
            .into()),
            _ => Ok(()),
        }
    }

    /// Hands back the areas that arrived and turns the measures into the report's figures;
    /// the first measure after a shift is the moved map's sum.
    fn hand_back<E>(
        &mut self,
        pool: &mut RamPool,
        arrivals: &GranularArrivals,
        frame: &mut TrailFrame,
    ) -> Result<(), TrailsError<E>> {
        // Everything that arrived is taken in, the first failure returned at the end.
        let mut first = None;
        for (area, heights) in &arrivals.areas {
            match self.window.hand_back(pool, *area, heights) {
                Ok(back) => frame.changed.push(back),
                Err(e) => first = first.or(Some(e)),
            }
        }
        for m in &arrivals.measured {
            if self.window.awaits_sum() {
                let taken = match m.tag {
                    SHIFT_TAG => self.window.shifted_sum(m.volume),
                    _ => Err(CacheError::OutOfRange {
                        what: "tag of the first measure after a granular shift",
                        value: m.tag as f64,
                        expected: "SHIFT_TAG: the moved map's sum comes before any step's",
                    }),
                };
                let retired = taken.and_then(|()| self.try_retire(pool));
                first = first.or(retired.err());
                continue;
            }
            self.removed += m.removed;
            frame.measured.push(TrailMeasure {
                tag: m.tag,
                volume: m.volume,
                volume_taken: self.window.volume_taken().checked_sub(self.removed),
            });
        }
        first.map_or(Ok(()), |e| Err(e.into()))
    }

    /// Hands the last areas back (waiting for the GPU's, a retiring window's too) and releases
    /// the window, its volume checked: when it moves on waiting, and at the end. Returns the
    /// areas handed back and the last GPU steps' measures. Whatever fails, the window is
    /// released (its tiles unpinned) and the stepper stopped; the first failure is returned.
    pub fn release<G: GranularStepper>(
        &mut self,
        pool: &mut RamPool,
        gpu: Option<&mut G>,
    ) -> Result<(HandedBack, Vec<TrailMeasure>), TrailsError<G::Error>> {
        let mut frame = TrailFrame::default();
        if self.window.rect().is_none() {
            return Ok((frame.changed, frame.measured));
        }
        let mut first = None;
        if self.on_gpu {
            let Some(g) = gpu else {
                return Err(CacheError::OutOfRange {
                    what: "granular steppers given to release a window taken on the GPU",
                    value: 0.0,
                    expected: "the stepper the window was taken with",
                }
                .into());
            };
            // Every step runs whatever failed before it, the first failure returned at the
            // end: the window is released and the stepper stopped in any case.
            if self.window.retiring_rect().is_some() {
                let landed = match g.drain_retired() {
                    Ok(drained) => self.land_retired(pool, &drained, &mut frame),
                    Err(e) => Err(TrailsError::Stepper(e)),
                };
                self.retired_done = true;
                first = landed.err();
            }
            let stopped = match g.stop() {
                Ok(drained) => self.hand_back(pool, &drained, &mut frame),
                Err(e) => Err(TrailsError::Stepper(e)),
            };
            first = first.or(stopped.err());
            first = first.or(self.try_retire(pool).err().map(TrailsError::from));
        }
        self.on_gpu = false;
        self.sim = None;
        let released = self.window.release(pool, self.removed);
        self.windows_released += 1;
        match first.or(released.err().map(TrailsError::from)) {
            Some(e) => Err(e),
            None => Ok((frame.changed, frame.measured)),
        }
    }
}
