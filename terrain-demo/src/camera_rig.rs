//! The demo camera: terrain-physics' `CameraRig` (a body standing on the collision ground)
//! shaped by `[camera]` of `--config`, its view as a GPU camera, and the fog each camera gets.
//! `--camera walker` follows the walker; `--camera orbit` / `flyover` move along a
//! `CameraPath` over the whole map.

use crate::config::CameraParams;
use crate::gpu_scene::Camera;
use anyhow::Result;
use glam::Vec2;
use terrain_physics::{CameraPath, FollowShape, GroundQuery, PathParams, RigView};

/// Fog of the walker on the default 204.8 m map (per metre); larger maps get less, in
/// proportion, so a walk over a DEM is not lost in fog.
const WALKER_FOG: f32 = 0.008;
const WALKER_FOG_SIDE: f32 = 204.8;

/// The camera and the fog it is drawn with.
#[derive(Debug)]
pub struct CameraRig {
    rig: terrain_physics::CameraRig,
    fog: f32,
}

impl CameraRig {
    /// A walking camera standing at `xz` on ground of height `ground_y`, on a map whose longer
    /// side is `map_side` metres, shaped by `params` (eye height, distances to the walker).
    pub fn new(xz: Vec2, ground_y: f32, map_side: f32, params: &CameraParams) -> Result<Self> {
        let shape = FollowShape {
            eye_height: params.walker_eye_height_m,
            behind: params.walker_behind_m,
            ahead: params.walker_ahead_m,
        };
        Ok(Self {
            rig: terrain_physics::CameraRig::follower(xz, ground_y, shape)?,
            fog: WALKER_FOG * (WALKER_FOG_SIDE / map_side.max(1.0)).min(1.0),
        })
    }

    /// A camera on `path`, starting at its first pose (`ground` gives the terrain's height),
    /// its fog light at the subject, the toroidal map's repeats beyond it fading out.
    pub fn on_path(path: CameraPath, ground: impl Fn(Vec2) -> f32) -> Self {
        Self {
            fog: 0.25 / path.subject_distance().max(1.0),
            rig: terrain_physics::CameraRig::on_path(path, ground),
        }
    }

    /// Fog density per metre for this camera.
    pub fn fog_density(&self) -> f32 {
        self.fog
    }

    /// How far (metres, horizontally) the view must reach (a path camera's); `None` for the
    /// walker (the defaults serve it).
    pub fn view_radius(&self) -> Option<f32> {
        self.rig.view_radius()
    }

    /// Advances `dt` seconds (terrain-physics' `CameraRig::step`) and returns the camera.
    pub fn step(
        &mut self,
        walker: (Vec2, Vec2),
        dt: f32,
        ground: &impl GroundQuery,
        look_height: impl Fn(Vec2) -> f32,
    ) -> Result<Camera> {
        let RigView { pose, near, far } = self.rig.step(walker, dt, ground, look_height)?;
        let mut camera = Camera::looking(pose.eye, pose.look_at - pose.eye);
        camera.near = near;
        camera.far = far;
        Ok(camera)
    }

    /// The eye position.
    pub fn eye(&self) -> glam::Vec3 {
        self.rig.eye()
    }
}

/// The paths' shape from `[camera]` of `--config`.
pub fn path_params(c: &CameraParams) -> PathParams {
    PathParams {
        orbit_pitch: c.orbit_pitch_deg.to_radians(),
        orbit_period_s: c.orbit_period_s,
        flyover_period_s: c.flyover_period_s,
        flyover_height: c.flyover_height,
        flyover_pitch: c.flyover_pitch_deg.to_radians(),
    }
}
