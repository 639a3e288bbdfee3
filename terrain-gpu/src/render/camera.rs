//! The render view. Renderers take any [`RenderView`]: the perspective [`Camera`] of the
//! examples, an engine's own view and projection matrices ([`ViewMatrices`]: roll, TAA
//! jitter, orthographic views, reverse-Z, an infinite far plane), or an engine's camera type
//! implementing the trait. A renderer derives from it once a frame the eye, the
//! camera-relative matrix the shaders use, the world matrix the culling uses, the field of
//! view the LOD's screen-space error uses, and the depth convention.

use crate::error::GpuError;
use glam::camera::rh::view::look_to_mat4;
use glam::{Mat3, Mat4, UVec2, Vec3, Vec4};

/// How a projection maps distance to depth, and so how a renderer tests depth. Part of the
/// [`crate::TargetFormat`] a renderer is built for; a view whose projection follows the other
/// convention is refused at draw time ([`GpuError::DepthConventionMismatch`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum DepthConvention {
    /// Depth grows with distance (0 at the near plane): the depth buffer is cleared to 1 and
    /// the nearer fragment has the smaller depth (`CompareFunction::Less`).
    #[default]
    Forward,
    /// Depth falls with distance (1 at the near plane, 0 at the far plane or at infinity):
    /// cleared to 0, the nearer fragment has the greater depth (`CompareFunction::Greater`).
    /// Bevy and most modern engines use it because float depth then keeps its precision far
    /// away, usually with an infinite far plane.
    Reverse,
}

impl DepthConvention {
    /// The value to clear the depth attachment to: the depth of the farthest point.
    pub fn clear_depth(self) -> f32 {
        match self {
            Self::Forward => 1.0,
            Self::Reverse => 0.0,
        }
    }

    /// The depth test that keeps the nearer fragment.
    pub fn compare(self) -> wgpu::CompareFunction {
        match self {
            Self::Forward => wgpu::CompareFunction::Less,
            Self::Reverse => wgpu::CompareFunction::Greater,
        }
    }
}

/// What a renderer needs of a camera: its view and projection matrices.
///
/// Conventions (those of glam's `rh` functions and of Bevy): world metres with +Y up; view
/// space right-handed, looking down −Z; the projection maps view space to wgpu's clip space
/// (x and y in [−w, w], z in [0, w]), forward or reverse depth, finite or infinite far plane,
/// perspective or orthographic. An engine with a left-handed view space flips Z into it.
pub trait RenderView: std::fmt::Debug + Sync {
    /// World to view space.
    fn view_matrix(&self) -> Mat4;

    /// View to clip space, for a render target of `target_size` pixels (a camera that keeps
    /// its aspect ratio elsewhere ignores the size).
    fn projection_matrix(&self, target_size: UVec2) -> Mat4;

    /// The eye in world metres. By default derived from [`Self::view_matrix`]; a camera that
    /// knows it exactly returns it (the shaders place vertices relative to it).
    fn position(&self) -> Vec3 {
        eye_of(self.view_matrix()).unwrap_or(Vec3::NAN)
    }
}

/// A perspective camera with +Y up and forward depth: what the examples and the demo use.
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
        self.projection(aspect) * self.view_matrix()
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

impl RenderView for Camera {
    /// The view matrix, or a non-finite one for a camera that is not
    /// [`valid`](Camera::is_valid) (which the renderers then refuse).
    fn view_matrix(&self) -> Mat4 {
        if !self.is_valid() {
            return Mat4::NAN;
        }
        look_to_mat4(self.position, self.forward.normalize(), self.up())
    }

    fn projection_matrix(&self, target_size: UVec2) -> Mat4 {
        self.projection(aspect(target_size))
    }

    fn position(&self) -> Vec3 {
        self.position
    }
}

/// An engine's view and projection, used as given (see [`RenderView`] for the conventions).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewMatrices {
    /// World to view space.
    pub view: Mat4,
    /// View to clip space (with the engine's aspect ratio, jitter and depth convention).
    pub projection: Mat4,
}

impl ViewMatrices {
    /// From the camera's transform in the world (view space to world, e.g. Bevy's
    /// `GlobalTransform` as a matrix) and its projection (Bevy's `clip_from_view`).
    pub fn from_camera_transform(camera_to_world: Mat4, projection: Mat4) -> Self {
        Self {
            view: camera_to_world.inverse(),
            projection,
        }
    }
}

impl RenderView for ViewMatrices {
    fn view_matrix(&self) -> Mat4 {
        self.view
    }

    fn projection_matrix(&self, _target_size: UVec2) -> Mat4 {
        self.projection
    }
}

/// Half the horizontal field of view's tangent that an orthographic view's LOD is chosen
/// for: an orthographic view has no distance falloff, so CDLOD's and the tessellation's
/// distance-based choices are made as for a perspective view with a 53° horizontal field of
/// view from the same eye (its width equals the distance at which it is seen).
const ORTHOGRAPHIC_LOD_HALF_TAN: f32 = 0.5;

/// What a renderer derives from a [`RenderView`] for one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ResolvedView {
    /// The eye in world metres.
    pub(crate) eye: Vec3,
    /// The unit viewing direction in world space.
    pub(crate) forward: Vec3,
    /// World to clip space (frustum culling, the popping probe).
    pub(crate) view_proj_world: Mat4,
    /// Clip from positions relative to the eye (what the shaders get, so large worlds keep
    /// their precision).
    pub(crate) view_proj_relative: Mat4,
    /// The horizontal field of view (radians) the LOD's screen-space error is computed for.
    pub(crate) hfov: f32,
    /// Whether the projection's depth grows or falls with distance.
    pub(crate) depth: DepthConvention,
}

impl ResolvedView {
    /// Resolves `view` for a target of `target_size` pixels. Errors: non-finite matrices, a
    /// view that is not invertible, a projection that does not look down −Z or maps every
    /// distance to one depth, or a zero-sized target.
    pub(crate) fn new(view: &dyn RenderView, target_size: UVec2) -> Result<Self, GpuError> {
        let invalid = |reason| Err(GpuError::InvalidView { reason });
        if target_size.x == 0 || target_size.y == 0 {
            return invalid("the target has no pixels");
        }
        let (v, p) = (view.view_matrix(), view.projection_matrix(target_size));
        if !v.is_finite() || !p.is_finite() {
            return invalid("the view or projection matrix has a non-finite entry");
        }
        if eye_of(v).is_none() {
            return invalid("the view matrix is not invertible");
        }
        let eye = view.position();
        if !eye.is_finite() {
            return invalid("the eye position is not finite");
        }
        let linear = Mat3::from_mat4(v);
        let forward = (linear.inverse() * Vec3::NEG_Z).normalize_or_zero();
        let det = p.determinant();
        if !forward.is_finite() || forward == Vec3::ZERO || !(det.is_finite() && det != 0.0) {
            return invalid("the view or projection matrix is singular");
        }
        // Two points in front of the eye: both must land in front (w > 0), and their depths
        // tell the convention apart.
        let depth_at = |distance: f32| {
            let clip = p * Vec4::new(0.0, 0.0, -distance, 1.0);
            (clip.w > 0.0).then(|| clip.z / clip.w)
        };
        let (Some(near), Some(far)) = (depth_at(1.0), depth_at(2.0)) else {
            return invalid("the projection does not look down -Z of view space");
        };
        let depth = if far > near {
            DepthConvention::Forward
        } else if far < near {
            DepthConvention::Reverse
        } else {
            return invalid("the projection maps every distance to one depth");
        };
        // Perspective: w grows with distance, and x / w = P00 x / (−P32 z).
        let half_tan = if p.z_axis.w != 0.0 {
            (p.z_axis.w / p.x_axis.x).abs()
        } else {
            ORTHOGRAPHIC_LOD_HALF_TAN
        };
        let hfov = 2.0 * half_tan.atan();
        if !(hfov.is_finite() && hfov > 0.0) {
            return invalid("the projection has no horizontal extent");
        }
        Ok(Self {
            eye,
            forward,
            view_proj_world: p * v,
            view_proj_relative: p * Mat4::from_mat3(linear),
            hfov,
            depth,
        })
    }

    /// Checks that this view's depth convention is the one `target` was built for.
    pub(crate) fn check_depth(&self, target: &crate::TargetFormat) -> Result<(), GpuError> {
        if self.depth == target.depth_convention {
            Ok(())
        } else {
            Err(GpuError::DepthConventionMismatch {
                view: self.depth,
                target: target.depth_convention,
            })
        }
    }
}

/// The eye of a view matrix `[M | t]`: the point it maps to the origin, `−M⁻¹ t`.
fn eye_of(v: Mat4) -> Option<Vec3> {
    let linear = Mat3::from_mat4(v);
    let det = linear.determinant();
    if !(det.is_finite() && det != 0.0) {
        return None;
    }
    let eye = -(linear.inverse() * v.w_axis.truncate());
    eye.is_finite().then_some(eye)
}

/// The aspect ratio of a target (1 for a degenerate size, which the renderers refuse).
pub(crate) fn aspect(size: UVec2) -> f32 {
    size.x as f32 / size.y.max(1) as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::camera::rh::proj::directx;

    const SIZE: UVec2 = UVec2::new(320, 180);

    #[test]
    fn a_camera_resolves_to_its_own_matrices() {
        let cam = Camera::looking(Vec3::new(100.0, 50.0, -20.0), Vec3::new(1.0, -0.5, 0.3));
        let r = ResolvedView::new(&cam, SIZE).unwrap();
        let a = aspect(SIZE);
        assert_eq!(r.eye, cam.position);
        assert_eq!(r.view_proj_relative, cam.view_proj_relative(a));
        assert_eq!(r.view_proj_world, cam.view_proj_world(a));
        assert!((r.forward - cam.forward.normalize()).length() < 1e-6);
        assert_eq!(r.depth, DepthConvention::Forward);
        let hfov = 2.0 * ((cam.fov_y * 0.5).tan() * a).atan();
        assert!((r.hfov - hfov).abs() < 1e-5, "{} vs {hfov}", r.hfov);
    }

    #[test]
    fn engine_matrices_with_reverse_z_infinite_far_and_roll() {
        let eye = Vec3::new(-3000.0, 120.0, 8000.0);
        let forward = Vec3::new(0.2, -0.3, -1.0).normalize();
        let up = (Vec3::Y + Vec3::X * 0.4).normalize(); // rolled
        let view = look_to_mat4(eye, forward, up);
        let projection = directx::perspective_infinite_reverse(1.0, aspect(SIZE), 0.1);
        let r = ResolvedView::new(&ViewMatrices { view, projection }, SIZE).unwrap();
        assert_eq!(r.depth, DepthConvention::Reverse);
        assert!((r.eye - eye).length() < 0.01, "{}", r.eye);
        assert!((r.forward - forward).length() < 1e-5);
        let hfov = 2.0 * ((0.5f32).tan() * aspect(SIZE)).atan();
        assert!((r.hfov - hfov).abs() < 1e-5);
        // The relative matrix sees the eye at the origin: a point ahead lands as in the world.
        let p = eye + forward * 50.0;
        let world = r.view_proj_world.project_point3(p);
        let rel = r.view_proj_relative.project_point3(p - eye);
        assert!((world - rel).abs().max_element() < 1e-3, "{world} {rel}");
    }

    #[test]
    fn orthographic_and_jittered_projections_resolve() {
        let view = look_to_mat4(Vec3::new(0.0, 500.0, 0.0), Vec3::NEG_Y, Vec3::Z);
        let ortho = directx::orthographic(-200.0, 200.0, -100.0, 100.0, 1.0, 1000.0);
        let r = ResolvedView::new(
            &ViewMatrices {
                view,
                projection: ortho,
            },
            SIZE,
        )
        .unwrap();
        assert_eq!(r.depth, DepthConvention::Forward);
        assert!((r.hfov - 2.0 * ORTHOGRAPHIC_LOD_HALF_TAN.atan()).abs() < 1e-6);
        // A TAA jitter moves x and y in clip space and nothing the LOD reads.
        let mut jittered = directx::perspective(1.0, 2.0, 0.5, 900.0);
        let plain = ResolvedView::new(
            &ViewMatrices {
                view,
                projection: jittered,
            },
            SIZE,
        );
        jittered.z_axis.x += 0.3 / SIZE.x as f32;
        jittered.z_axis.y -= 0.7 / SIZE.y as f32;
        let jit = ResolvedView::new(
            &ViewMatrices {
                view,
                projection: jittered,
            },
            SIZE,
        );
        let (plain, jit) = (plain.unwrap(), jit.unwrap());
        assert_eq!(
            (plain.hfov, plain.eye, plain.depth),
            (jit.hfov, jit.eye, jit.depth)
        );
        assert_ne!(plain.view_proj_world, jit.view_proj_world);
    }

    #[test]
    fn bad_views_are_refused() {
        let view = Mat4::IDENTITY;
        let good = directx::perspective(1.0, 1.0, 0.5, 900.0);
        let bad = [
            (Mat4::from_diagonal(Vec4::new(1.0, 0.0, 1.0, 1.0)), good),
            (Mat4::from_cols_array(&[f32::NAN; 16]), good),
            (view, Mat4::ZERO),
            // Looking down +Z (a left-handed projection handed in without flipping Z).
            (
                view,
                glam::camera::lh::proj::directx::perspective(1.0, 1.0, 0.5, 900.0),
            ),
            (view, good * Mat4::from_scale(Vec3::new(1.0, 1.0, 0.0))),
        ];
        for (view, projection) in bad {
            let err = ResolvedView::new(&ViewMatrices { view, projection }, SIZE);
            assert!(matches!(err, Err(GpuError::InvalidView { .. })), "{err:?}");
        }
        let cam = Camera::looking(Vec3::ZERO, Vec3::X);
        assert!(ResolvedView::new(&cam, UVec2::new(0, 4)).is_err());
    }
}
