//! View frustum as six planes, extracted from a view-projection matrix, with point and
//! axis-aligned box tests for CPU culling (Flower 2010, sec. 2.4.3).

use glam::{Mat4, Vec3, Vec4, Vec4Swizzles};

/// A view frustum: six planes `(n, d)` with the inside where `n . p + d >= 0`.
///
/// Built from a view-projection matrix in the wgpu / Direct3D clip-space convention
/// (`-w <= x <= w`, `-w <= y <= w`, `0 <= z <= w`), which is what the projections of
/// `glam::camera::rh::proj::directx` (and `vulkan`) produce. Planes are normalised so
/// `n . p + d` is a signed distance in world units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frustum {
    planes: [Vec4; 6],
}

impl Frustum {
    /// Extracts the planes from `view_proj` (clip = `view_proj * world`) with the
    /// Gribb-Hartmann method, for clip-space depth in `[0, 1]`: forward or reverse depth
    /// (the planes `z >= 0` and `z <= w` swap roles), finite or infinite far plane (the far
    /// plane then has a zero normal and keeps everything in front of the eye), perspective or
    /// orthographic.
    ///
    /// A matrix with non-finite entries gives planes that reject nothing (every test says
    /// "inside"), so culling with it is merely ineffective, never wrong.
    pub fn from_view_proj(m: Mat4) -> Self {
        let r0 = m.row(0);
        let r1 = m.row(1);
        let r2 = m.row(2);
        let r3 = m.row(3);
        let planes = [
            r3 + r0, // left:   x >= -w
            r3 - r0, // right:  x <= w
            r3 + r1, // bottom: y >= -w
            r3 - r1, // top:    y <= w
            r2,      // near:   z >= 0
            r3 - r2, // far:    z <= w
        ]
        .map(normalize_plane);
        Self { planes }
    }

    /// The six planes `(n.x, n.y, n.z, d)` in the order left, right, bottom, top, near, far.
    pub fn planes(&self) -> &[Vec4; 6] {
        &self.planes
    }

    /// Whether `p` lies inside the frustum or on its boundary.
    pub fn contains_point(&self, p: Vec3) -> bool {
        self.planes
            .iter()
            .all(|plane| not_behind(plane_distance(*plane, p)))
    }

    /// Whether the axis-aligned box `[min, max]` may intersect the frustum.
    ///
    /// Conservative: `false` only when the whole box lies outside one plane, so a box that
    /// touches the frustum is never rejected (a box near a frustum corner may be kept
    /// although it misses it). `min` and `max` are taken per axis in either order.
    pub fn intersects_aabb(&self, min: Vec3, max: Vec3) -> bool {
        let lo = min.min(max);
        let hi = min.max(max);
        self.planes.iter().all(|plane| {
            // The box corner furthest along the plane normal.
            let n = plane.xyz();
            let far = Vec3::select(n.cmpge(Vec3::ZERO), hi, lo);
            not_behind(plane_distance(*plane, far))
        })
    }
}

fn plane_distance(plane: Vec4, p: Vec3) -> f32 {
    plane.xyz().dot(p) + plane.w
}

/// `true` unless `distance` is certainly negative (NaN counts as inside: conservative).
fn not_behind(distance: f32) -> bool {
    distance >= 0.0 || distance.is_nan()
}

fn normalize_plane(plane: Vec4) -> Vec4 {
    let len = plane.xyz().length();
    if len.is_finite() && len > 0.0 {
        plane / len
    } else {
        plane
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Camera at the origin looking along -Z (glam's right-handed view), 90 degree fov,
    /// square aspect, near 1, far 100.
    fn looking_down_neg_z() -> Frustum {
        let view = glam::camera::rh::view::look_to_mat4(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y);
        let proj =
            glam::camera::rh::proj::directx::perspective(90f32.to_radians(), 1.0, 1.0, 100.0);
        Frustum::from_view_proj(proj * view)
    }

    #[test]
    fn points_inside_and_outside() {
        let f = looking_down_neg_z();
        assert!(f.contains_point(Vec3::new(0.0, 0.0, -10.0)));
        assert!(f.contains_point(Vec3::new(4.9, -4.9, -5.0)));
        // Behind the camera, before the near plane, beyond the far plane.
        assert!(!f.contains_point(Vec3::new(0.0, 0.0, 10.0)));
        assert!(!f.contains_point(Vec3::new(0.0, 0.0, -0.5)));
        assert!(!f.contains_point(Vec3::new(0.0, 0.0, -101.0)));
        // Outside the 45 degree side planes.
        assert!(!f.contains_point(Vec3::new(5.1, 0.0, -5.0)));
        assert!(!f.contains_point(Vec3::new(0.0, -5.1, -5.0)));
    }

    #[test]
    fn planes_are_normalised_signed_distances() {
        let f = looking_down_neg_z();
        for plane in f.planes() {
            assert!((plane.xyz().length() - 1.0).abs() < 1e-5, "{plane}");
        }
        // Near plane: z = -1, distance of (0, 0, -3) is 2.
        let near = f.planes()[4];
        assert!((plane_distance(near, Vec3::new(0.0, 0.0, -3.0)) - 2.0).abs() < 1e-4);
    }

    #[test]
    fn aabb_inside_outside_and_straddling() {
        let f = looking_down_neg_z();
        // Entirely inside.
        assert!(f.intersects_aabb(Vec3::new(-1.0, -1.0, -6.0), Vec3::new(1.0, 1.0, -4.0)));
        // Entirely behind the camera.
        assert!(!f.intersects_aabb(Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, 1.0, 4.0)));
        // Entirely to the right of the right plane.
        assert!(!f.intersects_aabb(Vec3::new(20.0, -1.0, -6.0), Vec3::new(22.0, 1.0, -4.0)));
        // Straddling the right plane (x = 5 at z = -5): no corner inside, but it intersects.
        let (lo, hi) = (Vec3::new(4.0, -1.0, -5.5), Vec3::new(30.0, 1.0, -4.5));
        assert!(f.intersects_aabb(lo, hi));
        // Straddling the near plane, and a box containing the whole frustum.
        assert!(f.intersects_aabb(Vec3::new(-0.1, -0.1, -2.0), Vec3::new(0.1, 0.1, 2.0)));
        assert!(f.intersects_aabb(Vec3::splat(-1000.0), Vec3::splat(1000.0)));
        // min / max given the other way round.
        assert!(f.intersects_aabb(Vec3::new(1.0, 1.0, -4.0), Vec3::new(-1.0, -1.0, -6.0)));
    }

    #[test]
    fn non_finite_matrix_rejects_nothing() {
        let f = Frustum::from_view_proj(Mat4::from_cols_array(&[f32::NAN; 16]));
        assert!(f.contains_point(Vec3::ZERO));
        assert!(f.intersects_aabb(Vec3::ZERO, Vec3::ONE));
    }

    /// Reverse-Z with an infinite far plane (what Bevy and most engines use): the planes
    /// z >= 0 and z <= w swap roles, the far one degenerates to "always inside", and the
    /// frustum is the same as forward depth's up to the far plane.
    #[test]
    fn reverse_z_and_infinite_far_planes_cull_like_forward_depth() {
        use glam::camera::rh::proj::directx;
        let view = glam::camera::rh::view::look_to_mat4(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y);
        let fov = 90f32.to_radians();
        let forward = looking_down_neg_z();
        let reverse =
            Frustum::from_view_proj(directx::perspective_infinite_reverse(fov, 1.0, 1.0) * view);
        let infinite = Frustum::from_view_proj(directx::perspective_infinite(fov, 1.0, 1.0) * view);
        for f in [&reverse, &infinite] {
            for plane in f.planes() {
                assert!(plane.is_finite(), "{plane}");
            }
            // Inside the finite frustum: inside these too.
            assert!(f.contains_point(Vec3::new(0.0, 0.0, -10.0)));
            assert!(f.contains_point(Vec3::new(4.9, -4.9, -5.0)));
            // Beyond any finite far plane: still inside.
            assert!(f.contains_point(Vec3::new(0.0, 0.0, -1.0e7)));
            // Behind the camera, before the near plane, outside a side plane.
            assert!(!f.contains_point(Vec3::new(0.0, 0.0, 10.0)));
            assert!(!f.contains_point(Vec3::new(0.0, 0.0, -0.5)));
            assert!(!f.contains_point(Vec3::new(5.1, 0.0, -5.0)));
            assert!(!f.intersects_aabb(Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, 1.0, 4.0)));
            assert!(f.intersects_aabb(Vec3::new(-1.0, -1.0, -6.0), Vec3::new(1.0, 1.0, -4.0)));
        }
        assert!(!forward.contains_point(Vec3::new(0.0, 0.0, -1.0e7)));
    }
}
