//! `HeightfieldCollider`: the world-space queries (height, normal, raycast, sphere contact) on
//! top of a [`HeightField`] snapshot's local-space ones, and the [`GroundQuery`] trait bodies
//! collide through.

use crate::contact::Contact;
use crate::error::{PhysicsError, check_finite2, check_finite3};
use crate::field::HeightField;
use crate::ray::{Ray, RayHit, check_max_dist};
use glam::{Vec2, Vec3};
use std::sync::Arc;
use terrain_core::CoarseMap;

/// What a body needs to know about the ground under it, in world space.
///
/// [`HeightfieldCollider`] answers with the mirrored surface; [`BoundedGround`] raises it by
/// the bounds of deformations whose readback has not arrived yet.
///
/// [`BoundedGround`]: crate::BoundedGround
pub trait GroundQuery {
    /// Ground height in metres at world `pos = (X, Z)`; `f32::NEG_INFINITY` where there is no
    /// ground (over a hole: a body there falls).
    fn ground_height(&self, pos: Vec2) -> Result<f32, PhysicsError>;
    /// Unit ground normal (Y up) at world `pos = (X, Z)`.
    fn ground_normal(&self, pos: Vec2) -> Result<Vec3, PhysicsError>;
    /// Contact of a sphere with the ground, or `None` if they do not touch.
    fn ground_contact(&self, center: Vec3, radius: f32) -> Result<Option<Contact>, PhysicsError>;
}

/// A heightfield placed in the world: a shared snapshot plus a translation.
///
/// World = local + `translation`; with the default zero translation, texel `(x, y)` stands at
/// world `(x * texel_size, height, y * texel_size)` (the workspace convention). Every query
/// checks its input and returns [`PhysicsError`] on NaN / infinite values, a zero ray direction
/// or a negative radius, then calls the local-space query of [`HeightField`].
#[derive(Debug, Clone)]
pub struct HeightfieldCollider {
    field: Arc<HeightField>,
    translation: Vec3,
}

impl HeightfieldCollider {
    /// A collider over `field` at the origin.
    pub fn new(field: Arc<HeightField>) -> Self {
        Self {
            field,
            translation: Vec3::ZERO,
        }
    }

    /// A collider over a copy of `map` (which must wrap) at the origin.
    pub fn from_map(map: &CoarseMap) -> Result<Self, PhysicsError> {
        Ok(Self::new(Arc::new(HeightField::from_map(map)?)))
    }

    /// The same collider moved so that local `(0, 0, 0)` is at world `translation`.
    pub fn with_translation(self, translation: Vec3) -> Result<Self, PhysicsError> {
        check_finite3("collider translation", translation)?;
        Ok(Self {
            translation,
            ..self
        })
    }

    /// The snapshot queried.
    pub fn field(&self) -> &Arc<HeightField> {
        &self.field
    }

    /// World position of local `(0, 0, 0)`.
    pub fn translation(&self) -> Vec3 {
        self.translation
    }

    /// The version of the mirror update the snapshot contains.
    pub fn version(&self) -> u64 {
        self.field.version()
    }

    /// Converts a world horizontal position to local.
    #[inline]
    pub(crate) fn to_local2(&self, pos: Vec2) -> Vec2 {
        pos - Vec2::new(self.translation.x, self.translation.z)
    }

    /// `to_local2`, refusing a position whose offset from the collider overflows f32.
    fn local2(&self, pos: Vec2) -> Result<Vec2, PhysicsError> {
        check_finite2("query position", pos)?;
        let local = self.to_local2(pos);
        check_finite2("query position relative to the collider", local)?;
        Ok(local)
    }

    /// A point in the collider's local space, refusing one whose offset overflows f32.
    fn local3(&self, what: &'static str, p: Vec3) -> Result<Vec3, PhysicsError> {
        check_finite3(what, p)?;
        let local = p - self.translation;
        check_finite3(what, local)?;
        Ok(local)
    }

    /// Height in metres at world `pos = (X, Z)` (bilinear, wrap addressing, listing 3.2): the
    /// surface's, over a hole too (see [`GroundQuery::ground_height`] for the ground's).
    pub fn height(&self, pos: Vec2) -> Result<f32, PhysicsError> {
        Ok(self.field.height_local(self.local2(pos)?) + self.translation.y)
    }

    /// Unit surface normal (Y up) at world `pos = (X, Z)`.
    pub fn normal(&self, pos: Vec2) -> Result<Vec3, PhysicsError> {
        Ok(self.field.normal_local(self.local2(pos)?))
    }

    /// Whether world `pos = (X, Z)` lies over a hole ([`HeightField::with_holes`]).
    pub fn is_hole(&self, pos: Vec2) -> Result<bool, PhysicsError> {
        Ok(self.field.is_hole_local(self.local2(pos)?))
    }

    /// The ground height at world `pos` for a body: [`HeightfieldCollider::height`], or
    /// `f32::NEG_INFINITY` over a hole.
    pub(crate) fn ground_height_at(&self, pos: Vec2) -> Result<f32, PhysicsError> {
        if self.is_hole(pos)? {
            return Ok(f32::NEG_INFINITY);
        }
        self.height(pos)
    }

    /// The first hit of the ray from world `origin` along `dir` (any non-zero length) within
    /// `max_dist` metres, or `None`. See [`HeightField::cast_local_ray`] for the surface model
    /// and the solid-ground rule.
    pub fn raycast(
        &self,
        origin: Vec3,
        dir: Vec3,
        max_dist: f32,
    ) -> Result<Option<RayHit>, PhysicsError> {
        let ray = Ray::new(origin, dir)?;
        check_max_dist(max_dist)?;
        let local = Ray::new(self.local3("ray origin", origin)?, ray.dir())?;
        Ok(self
            .field
            .cast_local_ray(&local, max_dist)?
            .map(|hit| RayHit {
                point: hit.point + self.translation,
                ..hit
            }))
    }

    /// The contact of a sphere at world `center` with `radius` (>= 0), or `None` if it does not
    /// touch the ground. See [`HeightField::contact_local_sphere`].
    pub fn sphere_contact(
        &self,
        center: Vec3,
        radius: f32,
    ) -> Result<Option<Contact>, PhysicsError> {
        check_radius(radius)?;
        let local = self.local3("sphere centre", center)?;
        Ok(self
            .field
            .contact_local_sphere(local, radius)
            .map(|c| Contact {
                point: c.point + self.translation,
                ..c
            }))
    }
}

/// Checks a sphere radius: finite and not negative.
pub(crate) fn check_radius(radius: f32) -> Result<(), PhysicsError> {
    if radius < 0.0 {
        return Err(PhysicsError::NegativeRadius { radius });
    }
    crate::error::check_finite("sphere radius", radius)
}

impl GroundQuery for HeightfieldCollider {
    fn ground_height(&self, pos: Vec2) -> Result<f32, PhysicsError> {
        self.ground_height_at(pos)
    }

    fn ground_normal(&self, pos: Vec2) -> Result<Vec3, PhysicsError> {
        self.normal(pos)
    }

    fn ground_contact(&self, center: Vec3, radius: f32) -> Result<Option<Contact>, PhysicsError> {
        self.sphere_contact(center, radius)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use terrain_core::{Grid, HeightEncoding};

    fn collider() -> HeightfieldCollider {
        let g = Grid::from_fn(8, 8, |x, y| (x * 100 + y * 10) as u16).expect("grid");
        let m =
            CoarseMap::coarse(g, HeightEncoding::new(0.01, 0.0).expect("enc"), 0.5).expect("map");
        HeightfieldCollider::from_map(&m).expect("collider")
    }

    #[test]
    fn translation_moves_every_query() {
        let c = collider();
        let t = Vec3::new(10.0, -2.0, 3.0);
        let m = c.clone().with_translation(t).expect("finite");
        let p = Vec2::new(1.3, 2.2);
        let pw = p + Vec2::new(t.x, t.z);
        assert!((m.height(pw).expect("h") - (c.height(p).expect("h") - 2.0)).abs() < 1e-5);
        assert!((m.normal(pw).expect("n") - c.normal(p).expect("n")).length() < 1e-6);
        let o = Vec3::new(1.3, 5.0, 2.2);
        let a = c.raycast(o, Vec3::NEG_Y, 10.0).expect("ok").expect("hit");
        let b = m
            .raycast(o + t, Vec3::NEG_Y, 10.0)
            .expect("ok")
            .expect("hit");
        assert!((a.distance - b.distance).abs() < 1e-4);
        assert!((a.point + t - b.point).length() < 1e-4);
        let s = c
            .sphere_contact(a.point, 0.3)
            .expect("ok")
            .expect("contact");
        let u = m
            .sphere_contact(a.point + t, 0.3)
            .expect("ok")
            .expect("contact");
        assert!((s.depth - u.depth).abs() < 1e-4);
        assert!((s.point + t - u.point).length() < 1e-4);
    }

    #[test]
    fn bad_input_is_an_error() {
        let c = collider();
        let nan = f32::NAN;
        assert!(matches!(
            c.height(Vec2::new(nan, 0.0)),
            Err(PhysicsError::NonFinite { .. })
        ));
        assert!(c.normal(Vec2::new(0.0, f32::INFINITY)).is_err());
        assert!(matches!(
            c.raycast(Vec3::ZERO, Vec3::ZERO, 1.0),
            Err(PhysicsError::ZeroDirection { .. })
        ));
        assert!(c.raycast(Vec3::new(nan, 0.0, 0.0), Vec3::X, 1.0).is_err());
        assert!(c.raycast(Vec3::ZERO, Vec3::X, nan).is_err());
        assert!(c.raycast(Vec3::ZERO, Vec3::X, -1.0).is_err());
        assert!(matches!(
            c.sphere_contact(Vec3::ZERO, -0.5),
            Err(PhysicsError::NegativeRadius { radius }) if radius == -0.5
        ));
        assert!(c.sphere_contact(Vec3::ZERO, nan).is_err());
        assert!(c.sphere_contact(Vec3::new(0.0, nan, 0.0), 1.0).is_err());
        assert!(c.clone().with_translation(Vec3::splat(nan)).is_err());
    }
}
