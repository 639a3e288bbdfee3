//! The world scenario's granular trails: a four-wheeled vehicle drives over the streamed world
//! and its wheels push the ground aside as granular material (Persson 2019, ch. 4), inside a
//! terrain-cache `GranularWindow` around it. Each frame the step runs on the GPU (the scene's
//! granular passes over the window's scratch map; the changed areas come back by readback) or,
//! without one, on the CPU; the areas are handed back into the RAM tiles, from where the VRAM
//! pool re-uploads them. When the vehicle nears the window's edge, the window is drained,
//! released (its volume checked) and taken again ahead of the vehicle.

use crate::gpu_scene::{GpuScene, StepMeasure};
use crate::timings::{GranularFigure, Step, Timings};
use anyhow::{Context, Result, bail};
use glam::{Affine3A, Quat, Vec2, Vec3};
use std::time::{Duration, Instant};
use terrain_cache::{CameraState, GranularWindow, Manifest, RamPool};
use terrain_core::granular::{GranularObject, GranularParams, GranularSim, TriMesh};
use terrain_core::{FixedPointMap, Grid, Rect};

/// Side of the granular window in texels (64 m at the default world's 0.5 m).
pub const WINDOW_SIDE: u32 = 128;
/// Vehicle: wheel radius and half width, wheelbase and track, how deep the wheels sink
/// (metres): a heavy truck, so its tracks are a couple of texels of the world wide.
const WHEEL_RADIUS: f32 = 0.9;
const WHEEL_HALF_WIDTH: f32 = 0.5;
const WHEELBASE: f32 = 4.0;
const TRACK: f32 = 2.6;
const WHEEL_SINK: f32 = 0.35;
/// How long a window may wait for its tiles to load.
pub const TAKE_TIMEOUT: Duration = Duration::from_secs(10);
/// Metres the wheels keep from the window's edge before it moves on (the step's active area
/// reaches a few texels past an object).
const EDGE_MARGIN: f32 = 8.0;
/// Metres from the window's edge past which it moves even with writes on their way (waiting
/// for them): between the two margins a move waits for them to land, a frame or two.
const FORCED_MARGIN: f32 = 4.0;

/// What the trails did in one frame.
#[derive(Debug, Default)]
pub struct TrailFrame {
    /// Areas handed back into the tiles this frame: world texels and stored heights.
    pub changed: HandedBack,
    /// The scratch map's units after the step (`None` while no window is taken).
    pub volume: Option<u64>,
    /// The units the window held when taken, less compression's (equal to `volume`).
    pub volume_taken: Option<u64>,
    /// `gpu` or `cpu`.
    pub backend: Option<&'static str>,
    /// Milliseconds of the step itself (timed as `granular_gpu` or `granular_cpu`).
    pub step_ms: f64,
    /// On a frame where the window moved on: whether it had to wait for writes on their way
    /// (the wheels reached [`FORCED_MARGIN`] before they landed).
    pub move_waited: Option<bool>,
    /// The measures of earlier GPU steps that arrived (read back without a wait), for the
    /// report to credit to their frames; a GPU step's own `volume` is not known in its frame.
    pub measured: Vec<GranularFigure>,
}

/// Areas handed back into the tiles: world texels and stored heights.
pub type HandedBack = Vec<(Rect, Grid<u16>)>;

/// The vehicle's granular trails over a streamed world.
#[derive(Debug)]
pub struct Trails {
    window: GranularWindow,
    /// Metres per level-0 texel.
    texel_size: f32,
    params: GranularParams,
    wheel: TriMesh,
    /// The CPU simulation of the taken window (without a GPU).
    sim: Option<GranularSim>,
    /// Whether the taken window steps on the GPU.
    on_gpu: bool,
    /// The window's heights when taken: the wheels' reference ground, so a wheel sinks by the
    /// same depth whatever the trail in front of it did.
    initial: Option<FixedPointMap>,
    /// Units removed by compression in the taken window.
    removed: u64,
    /// Windows released with their volume checked.
    pub windows_released: u32,
}

impl Trails {
    /// Trails on the world of `manifest` with granular material `params`.
    pub fn new(manifest: &Manifest, params: GranularParams) -> Result<Self> {
        let side = WINDOW_SIDE.min(manifest.world_size.min_element());
        Ok(Self {
            window: GranularWindow::new(manifest, side).context("the granular window")?,
            texel_size: manifest.texel_size,
            params,
            wheel: TriMesh::wheel(WHEEL_RADIUS, WHEEL_HALF_WIDTH, 24)?,
            sim: None,
            on_gpu: false,
            initial: None,
            removed: 0,
            windows_released: 0,
        })
    }

    /// The taken window (level-0 texels), where no tile stamp may go.
    pub fn window(&self) -> Option<Rect> {
        self.window.rect()
    }

    /// Whether the next [`advance`](Self::advance) with the vehicle at `centre` heading
    /// `heading` must move the window whatever is on its way (every write to the world must
    /// have landed by then: the caller waits for its own).
    pub fn must_move(&self, (centre, heading): (Vec2, Vec2)) -> bool {
        self.window.rect().is_some()
            && !self
                .window
                .covers(&wheel_positions(centre, heading), FORCED_MARGIN)
    }

    /// One frame with the vehicle at `centre` heading `heading` (metres, X Z): moves the
    /// window when the wheels near its edge, steps, and hands the changed areas back into
    /// `pool`'s tiles. A move waits for nothing: it comes once the areas stepped on the GPU
    /// are back and the caller has no write on its way (`others_in_flight` false), a frame or
    /// two after the wheels pass [`EDGE_MARGIN`]; only wheels past [`FORCED_MARGIN`] force it
    /// (the caller lands its writes first, [`Trails::must_move`], and the drain waits). The
    /// new window's tiles are waited for (up to [`TAKE_TIMEOUT`]) as `camera` wants them: the
    /// trails do not depend on load timing. The caller keeps every other write out of the
    /// window ([`Trails::window`]).
    pub fn advance(
        &mut self,
        pool: &mut RamPool,
        scene: Option<&mut GpuScene>,
        (centre, heading): (Vec2, Vec2),
        camera: &CameraState,
        others_in_flight: bool,
        timings: &mut Timings,
    ) -> Result<TrailFrame> {
        let wheels = wheel_positions(centre, heading);
        let mut frame = TrailFrame::default();
        let mut scene = scene;
        let leaving = !self.window.covers(&wheels, EDGE_MARGIN);
        let mut move_now = leaving && self.window.rect().is_none();
        if leaving && self.window.rect().is_some() {
            // Areas stepped in earlier frames that are back go into the tiles now.
            let mut settled = !others_in_flight;
            if let Some(s) = scene.as_deref_mut()
                && self.on_gpu
            {
                let arrivals = s.poll_granular()?;
                for (area, heights) in arrivals.areas {
                    frame
                        .changed
                        .push(self.window.hand_back(pool, area, &heights)?);
                }
                frame.measured = self.figures(&arrivals.measured);
                settled &= !arrivals.in_flight;
            }
            let forced = !self.window.covers(&wheels, FORCED_MARGIN);
            if settled || forced {
                frame.move_waited = Some(!settled);
                let (released, measured) = self.release(pool, scene.as_deref_mut())?;
                frame.changed.extend(released);
                frame.measured.extend(measured);
                move_now = true;
            }
        }
        if move_now {
            // A quarter of the window ahead of the vehicle: it drives through the middle half.
            let ahead = centre + heading * (self.window.side() as f32 * self.texel_size * 0.25);
            let rect = self.window.placement(ahead);
            let deadline = Instant::now() + TAKE_TIMEOUT;
            let map = loop {
                if let Some(map) = self.window.take(pool, rect)? {
                    break map;
                }
                if Instant::now() > deadline {
                    bail!(
                        "the granular window's tiles ({rect:?}) did not load within {} s",
                        TAKE_TIMEOUT.as_secs()
                    );
                }
                std::thread::sleep(Duration::from_millis(2));
                pool.update(camera)?;
            };
            match scene.as_deref_mut() {
                Some(s) => {
                    s.enable_granular(&map, self.params)?;
                    self.on_gpu = true;
                }
                None => self.sim = Some(GranularSim::new(map.clone(), self.params)?),
            }
            self.initial = Some(map);
            self.removed = 0;
        }
        let Some(initial) = &self.initial else {
            return Ok(frame);
        };
        let rotation = Quat::from_rotation_y(heading.x.atan2(heading.y));
        let corner =
            self.window.rect().map_or(Vec2::ZERO, |r| r.min.as_vec2()) * initial.texel_size();
        let poses: Vec<Affine3A> = wheels
            .iter()
            .map(|&xz| {
                let ground = terrain_core::bilinear(initial, xz - corner).unwrap_or(0.0);
                let at = Vec3::new(
                    xz.x - corner.x,
                    ground - WHEEL_SINK + WHEEL_RADIUS,
                    xz.y - corner.y,
                );
                Affine3A::from_rotation_translation(rotation, at)
            })
            .collect();
        let objects: Vec<GranularObject<'_>> = poses
            .iter()
            .map(|t| GranularObject::new(&self.wheel, *t))
            .collect();
        let mut arrived = Vec::new();
        let t = std::time::Instant::now();
        match (scene, &mut self.sim) {
            (Some(s), _) if self.on_gpu => {
                let step = s.granular_step(&objects, timings)?;
                let measured = self.figures(&step.measured);
                frame.measured.extend(measured);
                frame.backend = Some("gpu");
                arrived = step.arrived;
            }
            (_, Some(sim)) => {
                let report = timings.time(Step::GranularCpu, || sim.step(&objects))?;
                self.removed += report.removed;
                frame.volume = Some(report.volume);
                frame.backend = Some("cpu");
                for area in report.active_areas {
                    arrived.push((area.rect, sim.map().grid().copy_rect(area.rect)?));
                }
            }
            _ => return Ok(frame),
        }
        frame.step_ms = crate::timings::ms_since(t);
        if frame.volume.is_some() {
            frame.volume_taken = self.window.volume_taken().checked_sub(self.removed);
        }
        for (area, heights) in arrived {
            frame
                .changed
                .push(self.window.hand_back(pool, area, &heights)?);
        }
        Ok(frame)
    }

    /// The report's figures of GPU steps' measures, in step order: the volume and the units the
    /// window held when taken less those compression removed since (equal at every step).
    fn figures(&mut self, measured: &[StepMeasure]) -> Vec<GranularFigure> {
        measured
            .iter()
            .map(|m| {
                self.removed += m.removed;
                GranularFigure {
                    frame: m.tag,
                    volume: m.volume,
                    volume_taken: self.window.volume_taken().checked_sub(self.removed),
                    removed: None,
                }
            })
            .collect()
    }

    /// Hands the last areas back and releases the window (its volume checked): when it moves
    /// on and at the end of the run. Returns the areas handed back and the last GPU steps'
    /// measures.
    pub fn release(
        &mut self,
        pool: &mut RamPool,
        scene: Option<&mut GpuScene>,
    ) -> Result<(HandedBack, Vec<GranularFigure>)> {
        let mut changed = Vec::new();
        let mut measured = Vec::new();
        if self.window.rect().is_none() {
            return Ok((changed, measured));
        }
        if let Some(s) = scene
            && self.on_gpu
        {
            let drained = s.disable_granular()?;
            for (area, heights) in drained.areas {
                changed.push(self.window.hand_back(pool, area, &heights)?);
            }
            measured = self.figures(&drained.measured);
        }
        self.on_gpu = false;
        self.sim = None;
        self.initial = None;
        self.window
            .release(pool, self.removed)
            .context("the granular window's volume after its hand-backs")?;
        self.windows_released += 1;
        Ok((changed, measured))
    }
}

/// The four wheels' centres (metres, X Z) of a vehicle at `centre` heading `heading`.
fn wheel_positions(centre: Vec2, heading: Vec2) -> [Vec2; 4] {
    let side = heading.perp();
    [(1.0f32, 1.0f32), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)].map(|(along, across)| {
        centre + heading * (along * WHEELBASE * 0.5) + side * (across * TRACK * 0.5)
    })
}
