//! The world scenario's vehicle: four wheels that push the ground aside as granular material
//! (Persson 2019, ch. 4) inside terrain-cache's `GranularTrails`, which keeps its window
//! around them, steps it (on the GPU scene's `FieldStepper`, timed, or on the CPU) and hands
//! the changed areas back into the RAM tiles, from where the VRAM pool re-uploads them.

use crate::gpu_scene::GpuScene;
use crate::timings::{GranularFigure, Step, Timings};
use anyhow::{Context, Result};
use glam::{Affine3A, Quat, Vec2, Vec3};
use terrain_cache::{
    CameraState, GranularTrails, HandedBack, Manifest, RamPool, TrailConfig, TrailFrame,
    TrailMeasure,
};
use terrain_core::Rect;
use terrain_core::granular::{GranularObject, GranularParams, TriMesh};

/// Side of the granular window in texels (64 m at the default world's 0.5 m).
pub const WINDOW_SIDE: u32 = 128;
/// Vehicle: wheel radius and half width, wheelbase and track, how deep the wheels sink
/// (metres): a heavy truck, so its tracks are a couple of texels of the world wide.
const WHEEL_RADIUS: f32 = 0.9;
const WHEEL_HALF_WIDTH: f32 = 0.5;
const WHEELBASE: f32 = 4.0;
const TRACK: f32 = 2.6;
const WHEEL_SINK: f32 = 0.35;

/// The vehicle's granular trails over a streamed world.
#[derive(Debug)]
pub struct Trails {
    trails: GranularTrails,
    wheel: TriMesh,
}

impl Trails {
    /// Trails on the world of `manifest` with granular material `params`.
    pub fn new(manifest: &Manifest, params: GranularParams) -> Result<Self> {
        let config = TrailConfig {
            side: WINDOW_SIDE,
            ..TrailConfig::default()
        };
        Ok(Self {
            trails: GranularTrails::new(manifest, params, config).context("the granular trails")?,
            wheel: TriMesh::wheel(WHEEL_RADIUS, WHEEL_HALF_WIDTH, 24)?,
        })
    }

    /// Where no tile stamp may go (level-0 texels): the taken window, and the one retiring.
    pub fn keep_out(&self) -> Option<Rect> {
        self.trails.keep_out()
    }

    /// Whether the next [`advance`](Self::advance) with the vehicle at `centre` heading
    /// `heading` moves the window whatever is on its way (the caller lands its writes first).
    pub fn must_move(&self, (centre, heading): (Vec2, Vec2)) -> bool {
        self.trails.must_move(&wheel_positions(centre, heading))
    }

    /// One frame with the vehicle at `centre` heading `heading` (metres, X Z): the window kept
    /// around the wheels (moved a quarter of its side ahead of them when they near its edge),
    /// the wheels pressed into it at the depth they sink into the ground it was taken with.
    /// Returns the frame and the milliseconds of the step itself.
    pub fn advance(
        &mut self,
        pool: &mut RamPool,
        mut scene: Option<&mut GpuScene>,
        (centre, heading): (Vec2, Vec2),
        camera: &CameraState,
        others_in_flight: bool,
        timings: &mut Timings,
    ) -> Result<(TrailFrame, f64)> {
        let wheels = wheel_positions(centre, heading);
        let side_m = WINDOW_SIDE as f32 * pool.world().manifest().texel_size;
        let ahead = centre + heading * (side_m * 0.25);
        let mut gpu = scene
            .as_deref_mut()
            .map(|scene| scene.trails(&mut *timings));
        let mut frame =
            (self.trails).follow(pool, gpu.as_mut(), &wheels, ahead, camera, others_in_flight)?;
        if let Some(e) = &frame.shift_failed {
            tracing::warn!("the granular window moved waiting: its GPU map could not shift ({e})");
        }
        if self.trails.window().is_none() {
            return Ok((frame, 0.0));
        }
        let rotation = Quat::from_rotation_y(heading.x.atan2(heading.y));
        // Each wheel on the ground the window was taken with.
        let poses: Vec<Affine3A> = wheels
            .iter()
            .filter_map(|&xz| self.trails.ground_at(xz))
            .map(|(local, ground)| {
                let at = Vec3::new(local.x, ground - WHEEL_SINK + WHEEL_RADIUS, local.y);
                Affine3A::from_rotation_translation(rotation, at)
            })
            .collect();
        let objects: Vec<GranularObject<'_>> = poses
            .iter()
            .map(|t| GranularObject::new(&self.wheel, *t))
            .collect();
        let tag = scene.as_deref().map_or(0, GpuScene::frames_rendered);
        let t = std::time::Instant::now();
        let mut gpu = scene.map(|scene| scene.trails(&mut *timings));
        (self.trails).step(pool, gpu.as_mut(), &objects, tag, &mut frame)?;
        let step_ms = crate::timings::ms_since(t);
        if frame.on_gpu == Some(false) {
            timings.add(Step::GranularCpu, step_ms);
        }
        Ok((frame, step_ms))
    }

    /// Hands the last areas back and releases the window (its volume checked): the end of the
    /// run. Returns the areas handed back and the last GPU steps' measures.
    pub fn release(
        &mut self,
        pool: &mut RamPool,
        scene: Option<&mut GpuScene>,
        timings: &mut Timings,
    ) -> Result<(HandedBack, Vec<GranularFigure>)> {
        let mut gpu = scene.map(|scene| scene.trails(timings));
        let (changed, measured) = self.trails.release(pool, gpu.as_mut())?;
        Ok((changed, figures(&measured)))
    }
}

/// The report's figures of GPU steps' measures, for their frames.
pub fn figures(measured: &[TrailMeasure]) -> Vec<GranularFigure> {
    measured
        .iter()
        .map(|m| GranularFigure {
            frame: m.tag,
            volume: m.volume,
            volume_taken: m.volume_taken,
            removed: None,
        })
        .collect()
}

/// The four wheels' centres (metres, X Z) of a vehicle at `centre` heading `heading`.
fn wheel_positions(centre: Vec2, heading: Vec2) -> [Vec2; 4] {
    let side = heading.perp();
    [(1.0f32, 1.0f32), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)].map(|(along, across)| {
        centre + heading * (along * WHEELBASE * 0.5) + side * (across * TRACK * 0.5)
    })
}
