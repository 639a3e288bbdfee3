//! The render camera: a perspective view in world metres (Y up), with the camera-relative
//! matrix the shaders use and the world matrix frustum culling uses.

use glam::camera::rh::view::look_to_mat4;
use glam::{Mat4, Vec3};

/// A perspective camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Eye position in world metres.
    pub position: Vec3,
    /// Viewing direction (any length; normalised on use, since the view matrix needs a unit
    /// vector or it scales the scene along the view axis).
    pub forward: Vec3,
    /// Vertical field of view in radians.
    pub fov_y: f32,
    /// Near plane in metres.
    pub near: f32,
    /// Far plane in metres.
    pub far: f32,
}

impl Camera {
    /// A camera at `position` looking towards `forward`, 60° vertical field of view.
    pub fn looking(position: Vec3, forward: Vec3) -> Self {
        Self {
            position,
            forward,
            fov_y: 60f32.to_radians(),
            near: 0.25,
            far: 30_000.0,
        }
    }

    fn projection(&self, aspect: f32) -> Mat4 {
        // wgpu's clip space: right-handed view, NDC Z in [0, 1], Y up (glam's `directx`).
        glam::camera::rh::proj::directx::perspective(self.fov_y, aspect, self.near, self.far)
    }

    fn up(&self) -> Vec3 {
        // Looking straight up or down, pick another up vector.
        if self.forward.normalize_or_zero().y.abs() > 0.999 {
            Vec3::Z
        } else {
            Vec3::Y
        }
    }

    /// View-projection with the camera at the origin (what the shaders get: positions are
    /// computed relative to the camera so large worlds keep their precision).
    pub fn view_proj_relative(&self, aspect: f32) -> Mat4 {
        self.projection(aspect) * look_to_mat4(Vec3::ZERO, self.forward.normalize(), self.up())
    }

    /// View-projection in world coordinates (for frustum culling).
    pub fn view_proj_world(&self, aspect: f32) -> Mat4 {
        self.projection(aspect) * look_to_mat4(self.position, self.forward.normalize(), self.up())
    }

    /// Whether every field is finite, the direction non-zero and the planes ordered.
    pub fn is_valid(&self) -> bool {
        self.position.is_finite()
            && self.forward.is_finite()
            && self.forward.length_squared() > 0.0
            && self.fov_y > 0.0
            && self.fov_y < std::f32::consts::PI
            && self.near > 0.0
            && self.far > self.near
            && self.far.is_finite()
    }
}
