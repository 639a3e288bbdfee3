//! [`DetailGround`]: the collision surface of Flower 2010's two layers, coarse + detail. Any
//! [`GroundQuery`] (a collider over the mirrored coarse-map, or the [`crate::BoundedGround`]
//! over it) plus a CPU detail layer ([`terrain_core::detail::DetailLayer`]), so a body steps
//! into a footprint that only the detail tiles hold.
//!
//! Heights add; normals are the composite normal of eq. 3.4 (the gradients add). A sphere
//! meets the coarse surface shifted by the detail height under its centre: exact where the
//! detail is level under the sphere, and off by no more than the detail's slope across the
//! sphere elsewhere (a detail mark is at most 1 m deep).

use crate::collider::{GroundQuery, check_radius};
use crate::contact::Contact;
use crate::error::{PhysicsError, check_finite2, check_finite3};
use glam::{Vec2, Vec3};
use terrain_core::composite_normal;
use terrain_core::detail::DetailLayer;

/// A ground and a detail layer over it (both in the same world metres).
#[derive(Debug, Clone, Copy)]
pub struct DetailGround<'a, G: GroundQuery> {
    base: &'a G,
    detail: &'a DetailLayer,
}

impl<'a, G: GroundQuery> DetailGround<'a, G> {
    /// `base` with `detail` added.
    pub fn new(base: &'a G, detail: &'a DetailLayer) -> Self {
        Self { base, detail }
    }
}

/// The gradient whose normal `normalize(-dx, 1, -dz)` is `n` (an upward unit normal).
fn gradient_of(n: Vec3) -> Vec2 {
    -Vec2::new(n.x, n.z) / n.y.max(1e-6)
}

impl<G: GroundQuery> GroundQuery for DetailGround<'_, G> {
    /// The base height plus the detail height there.
    fn ground_height(&self, pos: Vec2) -> Result<f32, PhysicsError> {
        check_finite2("ground position", pos)?;
        Ok(self.base.ground_height(pos)? + self.detail.height_m(pos))
    }

    /// Eq. 3.4: the base's gradient plus the detail's.
    fn ground_normal(&self, pos: Vec2) -> Result<Vec3, PhysicsError> {
        check_finite2("ground position", pos)?;
        let base = gradient_of(self.base.ground_normal(pos)?);
        Ok(composite_normal(base, self.detail.gradient_m(pos)))
    }

    /// The base's contact with the sphere moved down by the detail height under its centre,
    /// moved back up, with the composite normal at the contact point.
    fn ground_contact(&self, center: Vec3, radius: f32) -> Result<Option<Contact>, PhysicsError> {
        check_finite3("sphere centre", center)?;
        check_radius(radius)?;
        let lift = Vec3::new(
            0.0,
            self.detail.height_m(Vec2::new(center.x, center.z)),
            0.0,
        );
        let Some(c) = self.base.ground_contact(center - lift, radius)? else {
            return Ok(None);
        };
        let point = c.point + lift;
        // The push-out direction stays the base's where the sphere's centre is below the
        // surface (its normal then points from the centre to the surface's outside).
        let normal = if c.normal.y > 0.0 {
            self.ground_normal(Vec2::new(point.x, point.z))?
        } else {
            c.normal
        };
        Ok(Some(Contact {
            point,
            normal,
            depth: c.depth,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::HeightfieldCollider;
    use glam::UVec2;
    use terrain_core::detail::DetailLayout;
    use terrain_core::{Blend, CoarseMap, GaussianStamp, Grid, HeightEncoding, StampPlacement};

    /// Flat coarse ground 2 m high, 64 x 64 texels of 0.25 m, and a detail layer refined x4
    /// over it with a 0.2 m deep mark at (8, 8).
    fn scene() -> (HeightfieldCollider, DetailLayer) {
        let g = Grid::new(64, 64, 200u16).unwrap();
        let map = CoarseMap::coarse(g, HeightEncoding::new(0.01, 0.0).unwrap(), 0.25).unwrap();
        let collider = HeightfieldCollider::from_map(&map).unwrap();
        let layout = DetailLayout::new(UVec2::splat(64), 0.25, 4, 32).unwrap();
        let mut layer = DetailLayer::new(layout).unwrap();
        let p = StampPlacement::new(Vec2::splat(8.0), Vec2::splat(2.0), -0.2).unwrap();
        layer
            .apply_stamp(&mut GaussianStamp::default(), &p, Blend::Add)
            .unwrap();
        (collider, layer)
    }

    #[test]
    fn heights_add_and_normals_compose() {
        let (collider, layer) = scene();
        let ground = DetailGround::new(&collider, &layer);
        for pos in [Vec2::splat(8.0), Vec2::new(8.4, 7.7), Vec2::new(3.0, 12.0)] {
            let h = ground.ground_height(pos).unwrap();
            let want = collider.ground_height(pos).unwrap() + layer.height_m(pos);
            assert!((h - want).abs() < 1e-6, "{pos}: {h} vs {want}");
            let n = ground.ground_normal(pos).unwrap();
            let want = composite_normal(Vec2::ZERO, layer.gradient_m(pos));
            assert!(
                (n - want).abs().max_element() < 1e-5,
                "{pos}: {n} vs {want}"
            );
        }
        // In the mark the ground is lower; its walls lean towards its centre.
        let centre = ground.ground_height(Vec2::splat(8.0)).unwrap();
        assert!(centre < 2.0 - 0.15, "{centre}");
        let wall = ground.ground_normal(Vec2::new(8.5, 8.0)).unwrap();
        assert!(wall.x < -0.05, "{wall}");
        assert!((ground.ground_height(Vec2::new(3.0, 3.0)).unwrap() - 2.0).abs() < 1e-6);
    }

    #[test]
    fn a_sphere_sinks_into_the_mark_and_rests_on_the_flat_elsewhere() {
        let (collider, layer) = scene();
        let ground = DetailGround::new(&collider, &layer);
        let r = 0.1;
        // Resting on the coarse surface at the mark's centre: it is 0.2 m above the detail
        // surface there, no contact.
        assert!(
            ground
                .ground_contact(Vec3::new(8.0, 2.0 + r, 8.0), r)
                .unwrap()
                .is_none()
        );
        // 5 cm into the detail surface: a contact about 5 cm deep, pushing up.
        let h = ground.ground_height(Vec2::splat(8.0)).unwrap();
        let c = ground
            .ground_contact(Vec3::new(8.0, h + r - 0.05, 8.0), r)
            .unwrap()
            .expect("contact");
        assert!((c.depth - 0.05).abs() < 1e-3, "{}", c.depth);
        assert!(c.normal.y > 0.99, "{}", c.normal);
        assert!((c.point.y - h).abs() < 1e-3);
        // Away from the mark: as the base.
        let at = Vec3::new(3.0, 2.0 + r - 0.02, 3.0);
        assert_eq!(
            ground.ground_contact(at, r).unwrap(),
            collider.ground_contact(at, r).unwrap()
        );
    }

    #[test]
    fn bad_input_is_refused() {
        let (collider, layer) = scene();
        let ground = DetailGround::new(&collider, &layer);
        assert!(ground.ground_height(Vec2::new(f32::NAN, 0.0)).is_err());
        assert!(ground.ground_normal(Vec2::new(0.0, f32::INFINITY)).is_err());
        assert!(
            ground
                .ground_contact(Vec3::new(0.0, f32::NAN, 0.0), 0.1)
                .is_err()
        );
        assert!(ground.ground_contact(Vec3::ZERO, -1.0).is_err());
        // Far away: the layer and the map repeat.
        let far = Vec2::new(8.0 + 16.0 * 1000.0, 8.0);
        let h = ground.ground_height(far).unwrap();
        assert!((h - ground.ground_height(Vec2::splat(8.0)).unwrap()).abs() < 1e-3);
    }
}
