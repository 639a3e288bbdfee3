//! The demo camera as a physics body: a `CameraBody` with gravity, pulled along behind the
//! walker by a damped spring on X/Z, standing on the collision ground at its eye height.

use crate::gpu_scene::Camera;
use anyhow::Result;
use glam::{Vec2, Vec3};
use terrain_physics::{CameraBody, GroundQuery};

/// Eye height above the ground in metres (a tall viewpoint over the trail).
const EYE_HEIGHT: f32 = 3.0;
/// How far behind the walker the camera walks, and how far ahead of the walker it looks.
const BEHIND: f32 = 9.0;
const AHEAD: f32 = 12.0;
/// Spring stiffness per unit mass on X/Z (1/s^2); friction is set for critical damping.
const STIFFNESS: f32 = 30.0;
/// Physics substeps per frame.
const SUBSTEPS: u32 = 8;

/// The walking camera.
#[derive(Debug)]
pub struct CameraRig {
    body: CameraBody,
}

impl CameraRig {
    /// A camera standing at `xz` on ground of height `ground_y`.
    pub fn new(xz: Vec2, ground_y: f32) -> Self {
        let mut body = CameraBody::new(Vec3::new(xz.x, ground_y + EYE_HEIGHT, xz.y));
        body.eye_height = EYE_HEIGHT;
        body.mass = 1.0;
        body.friction = 2.0 * STIFFNESS.sqrt();
        body.gravity_enabled = true;
        Self { body }
    }

    /// Advances `dt` seconds following the walker at `walker` heading along `heading`, on
    /// `ground` (the collision mirror with pending-deformation bounds); returns the camera
    /// looking at the ground ahead of the walker (`look_height` gives the height there).
    pub fn step(
        &mut self,
        walker: (Vec2, Vec2),
        dt: f32,
        ground: &impl GroundQuery,
        look_height: impl Fn(Vec2) -> f32,
    ) -> Result<Camera> {
        let (pos, heading) = walker;
        let target = pos - heading * BEHIND;
        let h = dt / SUBSTEPS as f32;
        for _ in 0..SUBSTEPS {
            let xz = Vec2::new(self.body.position.x, self.body.position.z);
            let pull = (target - xz) * STIFFNESS * self.body.mass;
            self.body.step(h, Vec3::new(pull.x, 0.0, pull.y), ground)?;
        }
        let ahead = pos + heading * AHEAD;
        let look = Vec3::new(ahead.x, look_height(ahead), ahead.y);
        Ok(Camera::looking(
            self.body.position,
            look - self.body.position,
        ))
    }

    /// The eye position.
    pub fn eye(&self) -> Vec3 {
        self.body.position
    }
}
