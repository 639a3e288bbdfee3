//! The demo camera as a physics body (a `CameraBody` standing on the collision ground, never
//! below it). `--camera walker`: with gravity, pulled along behind the walker by a damped
//! spring on X/Z, at eye height. `--camera orbit` / `flyover`: moved along a
//! [`CameraPath`] (each step's velocity takes it to the path's next point), the ground clamp
//! keeping it at least the path's clearance above the terrain.

use crate::camera_path::{CameraPath, Pose};
use crate::config::CameraParams;
use crate::gpu_scene::Camera;
use anyhow::Result;
use glam::{Vec2, Vec3};
use terrain_physics::{CameraBody, GroundQuery};

/// Spring stiffness per unit mass on X/Z (1/s^2); friction is set for critical damping.
const STIFFNESS: f32 = 30.0;
/// Physics substeps per frame.
const SUBSTEPS: u32 = 8;
/// Fog of the walker on the default 204.8 m map (per metre); larger maps get less, in
/// proportion, so a walk over a DEM is not lost in fog.
const WALKER_FOG: f32 = 0.008;
const WALKER_FOG_SIDE: f32 = 204.8;
/// Near and far planes of the walker (those of `Camera::looking`).
const WALKER_NEAR: f32 = 0.25;
const WALKER_FAR: f32 = 30_000.0;

/// The camera.
#[derive(Debug)]
pub struct CameraRig {
    body: CameraBody,
    /// The path of an orbit or flyover camera, and the time along it; `None` for the walker.
    path: Option<(CameraPath, f32)>,
    /// Fog density per metre for the map the rig was made for.
    fog: f32,
    /// How far behind the walker the camera walks, and how far ahead of the walker it looks
    /// (metres).
    behind: f32,
    ahead: f32,
}

impl CameraRig {
    /// A walking camera standing at `xz` on ground of height `ground_y`, on a map whose longer
    /// side is `map_side` metres, shaped by `params` (eye height, distances to the walker).
    pub fn new(xz: Vec2, ground_y: f32, map_side: f32, params: &CameraParams) -> Self {
        let eye_height = params.walker_eye_height_m;
        let mut body = CameraBody::new(Vec3::new(xz.x, ground_y + eye_height, xz.y));
        body.eye_height = eye_height;
        body.mass = 1.0;
        body.friction = 2.0 * STIFFNESS.sqrt();
        body.gravity_enabled = true;
        Self {
            body,
            path: None,
            fog: WALKER_FOG * (WALKER_FOG_SIDE / map_side.max(1.0)).min(1.0),
            behind: params.walker_behind_m,
            ahead: params.walker_ahead_m,
        }
    }

    /// A camera on `path`, starting at its first pose (`ground` gives the terrain's height).
    pub fn on_path(path: CameraPath, ground: impl Fn(Vec2) -> f32) -> Self {
        let start = path.pose(0.0, &ground);
        let mut body = CameraBody::new(start.eye);
        body.eye_height = path.clearance();
        // Moved kinematically: no gravity or friction acts on the velocity each step sets.
        body.gravity_enabled = false;
        body.friction = 0.0;
        body.mass = 1.0;
        Self {
            body,
            fog: path.fog_density(),
            path: Some((path, 0.0)),
            behind: 0.0,
            ahead: 0.0,
        }
    }

    /// Fog density per metre for this camera.
    pub fn fog_density(&self) -> f32 {
        self.fog
    }

    /// How far (metres, horizontally) the view must reach: the clipmap's coarsest level and
    /// the far plane are sized from it. `None` for the walker (the defaults serve it).
    pub fn view_radius(&self) -> Option<f32> {
        self.path.map(|(p, _)| p.view_radius())
    }

    /// Advances `dt` seconds: the walker follows the walker at `walker` heading along
    /// `heading`; a path camera moves to the path's next pose. Both stand on `ground` (the
    /// collision mirror with pending-deformation bounds). `look_height` gives the terrain's
    /// height at a point (where the walker looks; what the flyover clears).
    pub fn step(
        &mut self,
        walker: (Vec2, Vec2),
        dt: f32,
        ground: &impl GroundQuery,
        look_height: impl Fn(Vec2) -> f32,
    ) -> Result<Camera> {
        if let Some((path, t)) = self.path.as_mut() {
            *t += dt;
            let Pose { eye, look_at } = path.pose(*t, &look_height);
            let (near, far) = planes(path);
            if dt > 0.0 {
                // The velocity that reaches the path's point in one step; the ground clamp
                // then lifts the eye if the terrain (or a deformation pending readback) is
                // closer than the clearance.
                self.body.velocity = (eye - self.body.position) / dt;
                self.body.step(dt, Vec3::ZERO, ground)?;
            }
            let mut camera = Camera::looking(self.body.position, look_at - self.body.position);
            camera.near = near;
            camera.far = far;
            return Ok(camera);
        }
        let (pos, heading) = walker;
        let target = pos - heading * self.behind;
        let h = dt / SUBSTEPS as f32;
        for _ in 0..SUBSTEPS {
            let xz = Vec2::new(self.body.position.x, self.body.position.z);
            let pull = (target - xz) * STIFFNESS * self.body.mass;
            self.body.step(h, Vec3::new(pull.x, 0.0, pull.y), ground)?;
        }
        let ahead = pos + heading * self.ahead;
        let look = Vec3::new(ahead.x, look_height(ahead), ahead.y);
        let mut camera = Camera::looking(self.body.position, look - self.body.position);
        camera.near = WALKER_NEAR;
        camera.far = WALKER_FAR;
        Ok(camera)
    }

    /// The eye position.
    pub fn eye(&self) -> Vec3 {
        self.body.position
    }
}

/// Near and far planes for a path camera: the far plane past the farthest point of the map
/// (and never nearer than the walker's), the near plane a ten-thousandth of the subject's
/// distance (depth precision follows the ratio), at most the clearance.
fn planes(path: &CameraPath) -> (f32, f32) {
    let d = path.subject_distance();
    let near = (d * 1e-4).clamp(WALKER_NEAR, path.clearance() * 0.5);
    let far = (2.0 * path.view_radius() + d).max(WALKER_FAR);
    (near, far)
}
