//! Ground between a deformation and its readback: [`DeformationBound`] (how far a deformation
//! can move the surface, known from the deformation itself) and [`BoundedGround`], which raises
//! the mirrored surface by the bounds still pending so no body is ever below ground.
//!
//! Flower 2010, sec. 3.2.1: until the streamed heights arrive "the player will momentarily be
//! underground. The CPU can account for this using collision heuristics that have prior
//! knowledge regarding the geometry of the deformation". The heuristic here: a deformation
//! reports the rect it changed and the most it can raise (or lower) the surface there; until a
//! readback requested after it has been applied, bodies collide with the mirror raised by the
//! largest pending `raise` over the texels their query touches. The body may float by at most
//! that bound over the true surface for the few frames of the gap, and never sinks below it.

use crate::collider::{GroundQuery, HeightfieldCollider};
use crate::contact::Contact;
use crate::error::{PhysicsError, check_finite, check_finite2, check_finite3};
use glam::{UVec2, Vec2, Vec3};
use terrain_core::{HeightEncoding, Rect};

/// How far a deformation can move the surface inside its rect, in metres (both >= 0).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DeformationBound {
    /// The most the surface can rise.
    pub raise: f32,
    /// The most the surface can sink.
    pub lower: f32,
}

impl DeformationBound {
    /// A bound from its parts; both must be finite and not negative.
    pub fn new(raise: f32, lower: f32) -> Result<Self, PhysicsError> {
        for (what, v) in [
            ("deformation raise bound", raise),
            ("deformation lower bound", lower),
        ] {
            check_finite(what, v)?;
            if v < 0.0 {
                return Err(PhysicsError::OutOfRange {
                    what,
                    value: f64::from(v),
                    expected: "at least 0 metres",
                });
            }
        }
        Ok(Self { raise, lower })
    }

    /// The bound of an additive stamp (`Blend::Add`) of `intensity` metres whose values lie in
    /// `[0, 1]` (texture and Gaussian stamps): a positive intensity raises by at most
    /// `intensity`, a negative one lowers by at most `|intensity|`, plus one stored unit of
    /// `encoding` for rounding.
    pub fn additive(intensity: f32, encoding: HeightEncoding) -> Result<Self, PhysicsError> {
        check_finite("stamp intensity", intensity)?;
        check_finite("height scale", encoding.scale)?;
        let unit = encoding.scale.abs();
        Self::new(intensity.max(0.0) + unit, (-intensity).max(0.0) + unit)
    }
}

/// A deformation not yet covered by an applied readback.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PendingDeformation {
    /// The texels it changed (it may wrap, as the dirty rects of stamps do).
    pub rect: Rect,
    /// How far it can move the surface there.
    pub bound: DeformationBound,
}

impl PendingDeformation {
    /// Whether a bilinear lookup in cell `(x0, z0)` (taps `x0..=x0 + 1`, `z0..=z0 + 1`) reads
    /// one of the rect's texels, on a toroidal map of `map_size`.
    pub fn touches_cell(&self, x0: i64, z0: i64, map_size: UVec2) -> bool {
        self.touches_cells(x0, x0, z0, z0, map_size)
    }

    /// Whether bilinear lookups in cells `x_lo..=x_hi` by `z_lo..=z_hi` read one of the rect's
    /// texels, on a toroidal map of `map_size`.
    pub fn touches_cells(
        &self,
        x_lo: i64,
        x_hi: i64,
        z_lo: i64,
        z_hi: i64,
        map_size: UVec2,
    ) -> bool {
        // Cells lo..=hi read texels lo..=hi + 1.
        overlaps(
            x_lo,
            x_hi.saturating_sub(x_lo).saturating_add(2),
            self.rect.min.x,
            self.rect.size.x,
            map_size.x,
        ) && overlaps(
            z_lo,
            z_hi.saturating_sub(z_lo).saturating_add(2),
            self.rect.min.y,
            self.rect.size.y,
            map_size.y,
        )
    }
}

/// Whether spans `[a, a + a_len)` and `[b, b + b_len)` overlap on a circle of length `n`.
fn overlaps(a: i64, a_len: i64, b: i32, b_len: u32, n: u32) -> bool {
    // i128: `a` may be a saturated cast (i64::MIN or MAX), and `b - a` must not overflow.
    let (a, a_len) = (i128::from(a), i128::from(a_len));
    let (b, b_len, n) = (i128::from(b), i128::from(b_len), i128::from(n));
    if a_len <= 0 || b_len <= 0 {
        return false;
    }
    a_len >= n || b_len >= n || (b - a).rem_euclid(n) < a_len || (a - b).rem_euclid(n) < b_len
}

/// The mirrored ground raised by the pending deformations' bounds: what bodies collide with
/// between a deformation and its readback. Build it with
/// [`ReadbackScheduler::ground`](crate::ReadbackScheduler::ground) or [`BoundedGround::new`].
#[derive(Debug, Clone, Copy)]
pub struct BoundedGround<'a> {
    collider: &'a HeightfieldCollider,
    pending: &'a [PendingDeformation],
    extra: &'a [PendingDeformation],
}

impl<'a> BoundedGround<'a> {
    /// The ground of `collider` raised by the bounds of `pending` (two lists, for callers that
    /// keep them apart; pass `&[]` for an unused one).
    pub fn new(
        collider: &'a HeightfieldCollider,
        pending: &'a [PendingDeformation],
        extra: &'a [PendingDeformation],
    ) -> Self {
        Self {
            collider,
            pending,
            extra,
        }
    }

    /// The collider underneath.
    pub fn collider(&self) -> &HeightfieldCollider {
        self.collider
    }

    fn deformations(&self) -> impl Iterator<Item = &PendingDeformation> {
        self.pending.iter().chain(self.extra)
    }

    /// The pending raise that a height lookup at world `pos` reads: the sum of the bounds of
    /// every pending deformation there (overlapping deformations add up), 0 if none.
    pub fn raise_at(&self, pos: Vec2) -> Result<f32, PhysicsError> {
        check_finite2("query position", pos)?;
        let field = self.collider.field();
        let p = self.collider.to_local2(pos) / field.texel_size();
        let (x0, z0) = (p.x.floor() as i64, p.y.floor() as i64);
        let size = field.size();
        Ok(self
            .deformations()
            .filter(|d| d.touches_cell(x0, z0, size))
            .fold(0.0, |m: f32, d| (m + d.bound.raise).min(f32::MAX)))
    }

    /// The pending raise over the cells under a sphere: the sum of the bounds of every pending
    /// deformation touching them (0 if none).
    pub fn raise_under(&self, center: Vec3, radius: f32) -> Result<f32, PhysicsError> {
        check_finite3("sphere centre", center)?;
        check_finite("sphere radius", radius)?;
        let field = self.collider.field();
        let ts = field.texel_size();
        let c = self.collider.to_local2(Vec2::new(center.x, center.z));
        let r = radius.max(0.0);
        let lo = ((c - Vec2::splat(r)) / ts).floor();
        let hi = ((c + Vec2::splat(r)) / ts).floor();
        let size = field.size();
        Ok(self
            .deformations()
            .filter(|d| d.touches_cells(lo.x as i64, hi.x as i64, lo.y as i64, hi.y as i64, size))
            .fold(0.0, |m: f32, d| (m + d.bound.raise).min(f32::MAX)))
    }

    /// The interval `(lowest, highest)` the true ground height at world `pos` lies in: the
    /// mirrored height less the pending `lower` bounds there, plus the pending `raise` bounds
    /// (each summed: overlapping deformations add up).
    pub fn height_interval(&self, pos: Vec2) -> Result<(f32, f32), PhysicsError> {
        let h = self.collider.height(pos)?;
        let field = self.collider.field();
        let p = self.collider.to_local2(pos) / field.texel_size();
        let (x0, z0) = (p.x.floor() as i64, p.y.floor() as i64);
        let size = field.size();
        let (mut lower, mut raise) = (0.0_f32, 0.0_f32);
        for d in self.deformations().filter(|d| d.touches_cell(x0, z0, size)) {
            lower = (lower + d.bound.lower).min(f32::MAX);
            raise = (raise + d.bound.raise).min(f32::MAX);
        }
        Ok((h - lower, h + raise))
    }
}

impl GroundQuery for BoundedGround<'_> {
    /// The mirrored height plus the pending raise there (`-inf` over a hole).
    fn ground_height(&self, pos: Vec2) -> Result<f32, PhysicsError> {
        Ok(self.collider.ground_height_at(pos)? + self.raise_at(pos)?)
    }

    /// The mirrored normal (a bound says nothing about the new slope).
    fn ground_normal(&self, pos: Vec2) -> Result<Vec3, PhysicsError> {
        self.collider.normal(pos)
    }

    /// The contact with the mirrored surface lifted by the largest pending raise under the
    /// sphere.
    fn ground_contact(&self, center: Vec3, radius: f32) -> Result<Option<Contact>, PhysicsError> {
        crate::collider::check_radius(radius)?;
        let raise = self.raise_under(center, radius)?;
        let lift = Vec3::new(0.0, raise, 0.0);
        Ok(self
            .collider
            .sphere_contact(center - lift, radius)?
            .map(|c| Contact {
                point: c.point + lift,
                ..c
            }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::IVec2;
    use terrain_core::{CoarseMap, Grid};

    /// Flat ground 1 m high, 16 x 16 texels of `texel` metres.
    fn collider_at(texel: f32) -> HeightfieldCollider {
        let g = Grid::new(16, 16, 100u16).expect("grid");
        let m =
            CoarseMap::coarse(g, HeightEncoding::new(0.01, 0.0).expect("enc"), texel).expect("map");
        HeightfieldCollider::from_map(&m).expect("collider")
    }

    fn collider() -> HeightfieldCollider {
        collider_at(1.0)
    }

    /// One pending deformation over `rect` that can raise the ground by 1 m.
    fn raising(rect: Rect) -> [PendingDeformation; 1] {
        [PendingDeformation {
            rect,
            bound: DeformationBound::new(1.0, 0.0).expect("bound"),
        }]
    }

    #[test]
    fn raise_applies_only_where_the_rect_is_read_including_across_the_wrap() {
        let c = collider();
        let d = [PendingDeformation {
            rect: Rect::new(IVec2::new(14, 3), UVec2::new(4, 2)), // columns 14, 15, 0, 1
            bound: DeformationBound::new(2.0, 0.0).expect("bound"),
        }];
        let g = BoundedGround::new(&c, &d, &[]);
        assert_eq!(g.raise_at(Vec2::new(15.5, 3.5)).expect("ok"), 2.0);
        assert_eq!(g.raise_at(Vec2::new(0.5, 4.5)).expect("ok"), 2.0);
        // Cell 13 reads texel 14; cell 2 reads texels 2 and 3: untouched.
        assert_eq!(g.raise_at(Vec2::new(13.5, 3.5)).expect("ok"), 2.0);
        assert_eq!(g.raise_at(Vec2::new(2.5, 3.5)).expect("ok"), 0.0);
        // Row 2 reads row 3; row 5 reads rows 5 and 6: untouched.
        assert_eq!(g.raise_at(Vec2::new(0.5, 2.5)).expect("ok"), 2.0);
        assert_eq!(g.raise_at(Vec2::new(0.5, 5.5)).expect("ok"), 0.0);
        assert!((g.ground_height(Vec2::new(15.5, 3.5)).expect("ok") - 3.0).abs() < 1e-6);
        assert!((g.ground_height(Vec2::new(5.5, 3.5)).expect("ok") - 1.0).abs() < 1e-6);
        // A sphere reaching into the rect is lifted.
        let contact = g
            .ground_contact(Vec3::new(2.5, 3.5, 3.5), 1.5)
            .expect("ok")
            .expect("contact");
        assert!((contact.depth - 1.0).abs() < 1e-4, "{contact:?}");
        // Its point is on the lifted surface, `radius - depth` from the centre.
        let p = contact.point;
        let under = c.height(Vec2::new(p.x, p.z)).expect("ok");
        assert!((p.y - (under + 2.0)).abs() < 1e-4, "{contact:?}");
        let centre = Vec3::new(2.5, 3.5, 3.5);
        assert!(((centre - p).length() - (1.5 - contact.depth)).abs() < 1e-4);
    }

    #[test]
    fn additive_bounds_and_bad_bounds() {
        let e = HeightEncoding::new(0.01, 0.0).expect("enc");
        let up = DeformationBound::additive(2.0, e).expect("bound");
        assert!((up.raise - 2.01).abs() < 1e-6 && (up.lower - 0.01).abs() < 1e-6);
        let down = DeformationBound::additive(-1.0, e).expect("bound");
        assert!((down.raise - 0.01).abs() < 1e-6 && (down.lower - 1.01).abs() < 1e-6);
        assert!(DeformationBound::new(-1.0, 0.0).is_err());
        assert!(DeformationBound::new(0.0, f32::NAN).is_err());
        assert!(DeformationBound::additive(f32::INFINITY, e).is_err());
    }

    /// A sphere far from a pending deformation gets none of its raise (the cell range under
    /// the sphere is its own, not one reaching back to the map's corner); overlapping
    /// deformations add their lower bounds as well as their raise bounds.
    #[test]
    fn raise_under_and_height_interval_sum_only_what_is_under_them() {
        let c = collider();
        let d = [
            PendingDeformation {
                rect: Rect::new(IVec2::new(0, 0), UVec2::new(3, 3)),
                bound: DeformationBound::new(1.0, 0.25).expect("bound"),
            },
            PendingDeformation {
                rect: Rect::new(IVec2::new(1, 1), UVec2::new(4, 4)),
                bound: DeformationBound::new(0.5, 0.5).expect("bound"),
            },
        ];
        let g = BoundedGround::new(&c, &d, &[]);
        assert_eq!(
            g.raise_under(Vec3::new(11.5, 3.0, 11.5), 1.0).expect("ok"),
            0.0
        );
        assert_eq!(
            g.raise_under(Vec3::new(1.5, 3.0, 1.5), 0.2).expect("ok"),
            1.5
        );
        let (lo, hi) = g.height_interval(Vec2::new(1.5, 1.5)).expect("ok");
        assert!(
            (lo - (1.0 - 0.75)).abs() < 1e-6 && (hi - (1.0 + 1.5)).abs() < 1e-6,
            "{lo} {hi}"
        );
        let (lo, hi) = g.height_interval(Vec2::new(9.5, 9.5)).expect("ok");
        assert_eq!((lo, hi), (1.0, 1.0));
        // Half-metre texels: a sphere over cells 9 and 10 is clear of cells 3 to 5.
        let c = collider_at(0.5);
        let d = raising(Rect::new(IVec2::new(3, 9), UVec2::new(3, 3)));
        let g = BoundedGround::new(&c, &d, &[]);
        let raise = |x: f32| g.raise_under(Vec3::new(x, 3.0, 5.0), 0.25).expect("ok");
        assert_eq!(raise(5.0), 0.0);
        assert_eq!(raise(2.0), 1.0);
        // A sphere whose cells (and their second taps) end right before the rect: clear of it;
        // one more cell and it reads the rect's first texel.
        let c = collider();
        let d = raising(Rect::new(IVec2::new(6, 0), UVec2::new(2, 16)));
        let g = BoundedGround::new(&c, &d, &[]);
        let raise = |x: f32| g.raise_under(Vec3::new(x, 3.0, 8.0), 0.5).expect("ok");
        assert_eq!(raise(4.0), 0.0); // cells 3 and 4 read texels 3 to 5
        assert_eq!(raise(4.6), 1.0); // cell 5 reads texel 6
        // The bounded ground's normal is the mirrored surface's.
        assert_eq!(g.ground_normal(Vec2::new(6.5, 8.5)).expect("ok"), Vec3::Y);
    }
}
