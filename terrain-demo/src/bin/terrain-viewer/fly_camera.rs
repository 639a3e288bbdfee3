//! The fly camera: yaw and pitch from mouse drags, WASD along the view, Space/E up and
//! Shift/Q down, the speed scaled by the scroll wheel, kept above the ground.

use glam::{Vec2, Vec3};
use terrain_gpu::Camera;

/// Radians of turn per pixel of mouse drag.
const LOOK_PER_PIXEL: f32 = 0.004;
/// The steepest pitch up or down (radians), short of straight up where yaw is lost.
const MAX_PITCH: f32 = 1.5;
/// Metres the eye stays above the ground at least.
pub const CLEARANCE: f32 = 0.6;
/// Slowest and fastest speed (metres per second).
const SPEED_RANGE: (f32, f32) = (0.25, 400.0);

/// Which movement keys are held.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Motion {
    pub forward: bool,
    pub back: bool,
    pub left: bool,
    pub right: bool,
    pub up: bool,
    pub down: bool,
}

/// A free-flying camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlyCamera {
    /// Eye position (metres, Y up).
    pub position: Vec3,
    /// Heading in radians: 0 looks along +X, positive turns towards +Z.
    pub yaw: f32,
    /// Radians above the horizon (negative looks down).
    pub pitch: f32,
    /// Metres per second.
    pub speed: f32,
}

impl FlyCamera {
    /// A camera at `position` looking along `yaw` and `pitch`, flying at 6 m/s.
    pub fn new(position: Vec3, yaw: f32, pitch: f32) -> Self {
        Self {
            position,
            yaw,
            pitch: pitch.clamp(-MAX_PITCH, MAX_PITCH),
            speed: 6.0,
        }
    }

    /// The unit viewing direction.
    pub fn forward(&self) -> Vec3 {
        let (sy, cy) = self.yaw.sin_cos();
        let (sp, cp) = self.pitch.sin_cos();
        Vec3::new(cp * cy, sp, cp * sy)
    }

    /// Turns by a mouse drag of `delta` pixels (right turns right, down looks down).
    pub fn look(&mut self, delta: Vec2) {
        self.yaw = (self.yaw + delta.x * LOOK_PER_PIXEL).rem_euclid(std::f32::consts::TAU);
        self.pitch = (self.pitch - delta.y * LOOK_PER_PIXEL).clamp(-MAX_PITCH, MAX_PITCH);
    }

    /// Scales the speed by 1.25 per scroll step up (slower down), within its range.
    pub fn scroll(&mut self, steps: f32) {
        self.speed = (self.speed * 1.25f32.powf(steps)).clamp(SPEED_RANGE.0, SPEED_RANGE.1);
    }

    /// Moves for `dt` seconds with the keys of `motion`, then lifts the eye to
    /// [`CLEARANCE`] above `ground` (metres at a position X Z) where it would be lower.
    pub fn step(&mut self, dt: f32, motion: Motion, ground: impl Fn(Vec2) -> f32) {
        let forward = self.forward();
        let right = forward.cross(Vec3::Y).normalize_or_zero();
        let axis = |plus: bool, minus: bool| f32::from(u8::from(plus)) - f32::from(u8::from(minus));
        let dir = forward * axis(motion.forward, motion.back)
            + right * axis(motion.right, motion.left)
            + Vec3::Y * axis(motion.up, motion.down);
        self.position += dir.normalize_or_zero() * self.speed * dt;
        let floor = ground(Vec2::new(self.position.x, self.position.z)) + CLEARANCE;
        if self.position.y < floor {
            self.position.y = floor;
        }
    }

    /// The render camera (terrain-gpu's).
    pub fn camera(&self) -> Camera {
        Camera::looking(self.position, self.forward())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moves_along_the_view_and_stays_above_the_ground() {
        let mut cam = FlyCamera::new(Vec3::new(0.0, 5.0, 0.0), 0.0, 0.0);
        let forward = Motion {
            forward: true,
            ..Motion::default()
        };
        cam.step(1.0, forward, |_| 0.0);
        assert!((cam.position - Vec3::new(6.0, 5.0, 0.0)).length() < 1e-4);
        let down = Motion {
            down: true,
            ..Motion::default()
        };
        cam.step(10.0, down, |_| 2.0);
        assert_eq!(cam.position.y, 2.0 + CLEARANCE);
        // Strafing right with yaw 0 (looking along +X) goes towards +Z.
        let right = Motion {
            right: true,
            ..Motion::default()
        };
        cam.step(1.0, right, |_| 0.0);
        assert!(cam.position.z > 5.9);
    }

    #[test]
    fn looking_turns_and_clamps_the_pitch() {
        let mut cam = FlyCamera::new(Vec3::ZERO, 0.0, 0.0);
        cam.look(Vec2::new(0.0, 10_000.0));
        assert_eq!(cam.pitch, -MAX_PITCH);
        assert!(cam.camera().is_valid());
        cam.scroll(1000.0);
        assert_eq!(cam.speed, SPEED_RANGE.1);
    }
}
