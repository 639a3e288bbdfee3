//! Raycasts against the heightfield: a validated [`Ray`], the local-space cell walk
//! ([`HeightField::cast_local_ray`]) and its [`RayHit`].
//!
//! The walk visits every cell the ray's horizontal projection crosses, in order (a 2D DDA over
//! the texel grid, Amanatides & Woo), and intersects the ray exactly with each cell's bilinear
//! patch: along the ray the patch height is a quadratic in the distance, so each cell costs one
//! quadratic solve. Nothing is sampled, so no thin ridge is stepped over.

use crate::error::{PhysicsError, check_finite, check_finite3};
use crate::field::{HeightField, Patch};
use glam::{DVec3, Vec2, Vec3};

/// A ray: an origin and a unit direction, both finite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    origin: Vec3,
    dir: Vec3,
}

impl Ray {
    /// A ray from `origin` along `dir` (normalised here). Fails on a non-finite component or a
    /// zero (or denormal-small) direction.
    pub fn new(origin: Vec3, dir: Vec3) -> Result<Self, PhysicsError> {
        check_finite3("ray origin", origin)?;
        check_finite3("ray direction", dir)?;
        let Some(unit) = dir.try_normalize() else {
            return Err(PhysicsError::ZeroDirection { dir });
        };
        Ok(Self { origin, dir: unit })
    }

    /// The origin.
    pub fn origin(&self) -> Vec3 {
        self.origin
    }

    /// The unit direction.
    pub fn dir(&self) -> Vec3 {
        self.dir
    }

    /// The point `distance` metres along the ray.
    pub fn at(&self, distance: f32) -> Vec3 {
        self.origin + self.dir * distance
    }
}

/// Where a ray met the surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayHit {
    /// The point on the surface.
    pub point: Vec3,
    /// Distance from the ray's origin, in metres (0 when the origin is at or below the surface).
    pub distance: f32,
    /// Unit surface normal at the point (Y up).
    pub normal: Vec3,
}

/// Checks a maximum ray distance: finite and not negative.
pub(crate) fn check_max_dist(max_dist: f32) -> Result<(), PhysicsError> {
    check_finite("ray maximum distance", max_dist)?;
    if max_dist < 0.0 {
        return Err(PhysicsError::OutOfRange {
            what: "ray maximum distance",
            value: f64::from(max_dist),
            expected: "at least 0 metres",
        });
    }
    Ok(())
}

impl HeightField {
    /// The first point within `max_dist` metres where `ray` (in the field's local space) meets
    /// the surface, or `None`.
    ///
    /// The ground is solid: a ray whose origin is at or below the surface hits at distance 0
    /// with the normal there, unless the origin is over a hole. Cells cut away
    /// ([`HeightField::with_holes`]) have no surface: rays pass through them, and a ray that
    /// enters the ground beside a hole from below its surface is stopped where it enters
    /// (solid ground, as for an origin below the surface). Below the field's lowest height
    /// there is nothing to hit. Otherwise the hit is the first crossing of the bilinear
    /// surface, found exactly cell by cell. Rays cross the map's edges freely (the surface repeats).
    /// `max_dist` must be finite and not negative ([`HeightfieldCollider::raycast`] checks it);
    /// the walk costs one step per cell crossed within the field's height bounds, at most
    /// `4 (width + height) + 4096` cells (four times around the repeating field, and a fixed allowance): a ray still
    /// undecided by then is [`PhysicsError::RayTooLong`], so every cast is bounded by the map's
    /// size whatever the distance and the origin, and `None` always means no hit.
    ///
    /// [`HeightfieldCollider::raycast`]: crate::HeightfieldCollider::raycast
    pub fn cast_local_ray(&self, ray: &Ray, max_dist: f32) -> Result<Option<RayHit>, PhysicsError> {
        if !(max_dist >= 0.0 && max_dist.is_finite()) {
            return Ok(None);
        }
        let ts = f64::from(self.texel_size());
        let d = ray.dir().as_dvec3();
        let max_dist = f64::from(max_dist);
        // The field repeats: walk from the origin moved into the first period, and move the
        // hit back. Cell indices stay small however far the origin is.
        let (px, pz) = self.period_m();
        let o_world = ray.origin().as_dvec3();
        let (ox, shift_x) = crate::field::reduce(o_world.x, px);
        let (oz, shift_z) = crate::field::reduce(o_world.z, pz);
        let o = DVec3::new(ox, o_world.y, oz);
        let shift = DVec3::new(shift_x, 0.0, shift_z);

        // At or below the surface at the origin: solid ground, hit at 0.
        let o_xz = Vec2::new(ox as f32, oz as f32);
        let h0 = f64::from(self.height_local(o_xz));
        if o.y <= h0 && !self.is_hole_local(o_xz) {
            let normal = self.normal_local(o_xz);
            return Ok(Some(RayHit {
                point: ray.origin(),
                distance: 0.0,
                normal,
            }));
        }

        // Only the stretch of the ray between the field's height bounds can hit.
        let (lo, hi) = self.height_bounds();
        let (lo, hi) = (f64::from(lo) - 1e-6, f64::from(hi) + 1e-6);
        let (mut t_start, mut t_end) = (0.0_f64, max_dist);
        if d.y < 0.0 {
            if o.y > hi {
                t_start = (o.y - hi) / -d.y;
            }
            t_end = t_end.min((o.y - lo) / -d.y);
        } else if o.y > hi {
            return Ok(None);
        } else if d.y > 0.0 {
            t_end = t_end.min((hi - o.y) / d.y);
        }
        if t_start > t_end {
            return Ok(None);
        }
        // Walk from where the stretch starts, moved into the first period too: a ray from far
        // above that descends slowly starts its stretch far away.
        let start = o + d * t_start;
        let (sx, start_x) = crate::field::reduce(start.x, px);
        let (sz, start_z) = crate::field::reduce(start.z, pz);
        let from = DVec3::new(sx, start.y, sz);
        let back = shift + DVec3::new(start_x, 0.0, start_z);
        Ok(walk(self, from, d, ts, t_end - t_start)?.map(|hit| RayHit {
            point: (hit.point.as_dvec3() + back).as_vec3(),
            distance: (f64::from(hit.distance) + t_start) as f32,
            ..hit
        }))
    }
}

/// The most cells one cast walks: four times around the repeating field along each axis, and
/// a fixed allowance.
/// Stopping there bounds every cast by the map's size, not by the distance asked for; a ray
/// still undecided then is refused with [`PhysicsError::RayTooLong`] (never a false miss).
fn max_walk_cells(field: &HeightField) -> u64 {
    let s = field.size();
    // Plus a fixed allowance, so small fields answer ordinary rays too.
    4 * (u64::from(s.x) + u64::from(s.y)) + MIN_WALK_CELLS
}

/// The walk's allowance on top of four times around the field.
const MIN_WALK_CELLS: u64 = 4096;

/// Walks the cells the ray crosses from its origin to `t_end` and returns the first hit.
fn walk(
    field: &HeightField,
    o: DVec3,
    d: DVec3,
    ts: f64,
    t_end: f64,
) -> Result<Option<RayHit>, PhysicsError> {
    // Texel-space position and direction (per metre of ray).
    let (px, pz) = (o.x / ts, o.z / ts);
    let (dx, dz) = (d.x / ts, d.z / ts);
    let ray = GridRay {
        o,
        d,
        px,
        pz,
        dx,
        dz,
    };
    let mut ix = px.floor() as i64;
    let mut iz = pz.floor() as i64;
    let step_x: i64 = if dx > 0.0 { 1 } else { -1 };
    let step_z: i64 = if dz > 0.0 { 1 } else { -1 };
    // Distance along the ray to the next cell boundary on each axis, and between boundaries.
    let next_boundary = |p: f64, i: i64, dp: f64| -> (f64, f64) {
        if dp == 0.0 {
            (f64::INFINITY, f64::INFINITY)
        } else {
            let b = if dp > 0.0 { (i + 1) as f64 } else { i as f64 };
            ((b - p) / dp, 1.0 / dp.abs())
        }
    };
    let (mut t_max_x, delta_x) = next_boundary(px, ix, dx);
    let (mut t_max_z, delta_z) = next_boundary(pz, iz, dz);
    let mut t_in = 0.0;
    // Every cell crossed costs one step; bound the loop by the cells the segment can cross.
    let span = t_end.max(0.0);
    let max_steps = (span * (dx.abs() + dz.abs())).ceil() + 4.0;
    let max_steps = if max_steps.is_finite() {
        (max_steps as u64).min(max_walk_cells(field))
    } else {
        0
    };
    let capped = max_steps == max_walk_cells(field);
    for _ in 0..=max_steps {
        let t_out = t_max_x.min(t_max_z).min(t_end);
        // A hole's cell has no surface: the ray passes through it.
        if t_out >= t_in && !field.hole_cell(ix, iz) {
            let patch = field.patch(ix, iz);
            if let Some(t) = hit_in_cell(&patch, &ray, t_in, t_out) {
                let p = o + d * t;
                let (u, v) = (
                    (p.x / ts - ix as f64).clamp(0.0, 1.0),
                    (p.z / ts - iz as f64).clamp(0.0, 1.0),
                );
                return Ok(Some(RayHit {
                    point: p.as_vec3(),
                    distance: t as f32,
                    normal: patch.normal(u, v, ts).as_vec3(),
                }));
            }
        }
        if t_out >= t_end {
            return Ok(None);
        }
        t_in = t_in.max(t_out);
        if t_max_x < t_max_z {
            ix += step_x;
            t_max_x += delta_x;
        } else {
            iz += step_z;
            t_max_z += delta_z;
        }
    }
    if capped {
        return Err(PhysicsError::RayTooLong { cells: max_steps });
    }
    Ok(None)
}

/// A ray in world units (`o`, `d`) and in texel units over the grid (`px`, `pz` the origin,
/// `dx`, `dz` the direction).
#[derive(Debug, Clone, Copy)]
struct GridRay {
    o: DVec3,
    d: DVec3,
    px: f64,
    pz: f64,
    dx: f64,
    dz: f64,
}

/// The first distance in `[t_in, t_out]` where the ray meets the cell's patch.
#[inline]
fn hit_in_cell(patch: &Patch, ray: &GridRay, t_in: f64, t_out: f64) -> Option<f64> {
    let GridRay {
        o,
        d,
        px,
        pz,
        dx,
        dz,
    } = *ray;
    // Quick rejection: the patch lies within its corner heights, the ray segment within its
    // end heights.
    let (y_in, y_out) = (o.y + d.y * t_in, o.y + d.y * t_out);
    if y_in.min(y_out) > patch.max {
        return None;
    }
    // Along the ray from t_in: u(s) = u0 + dx s, v(s) = v0 + dz s, y(s) = y_in + d.y s, and
    // f(s) = y(s) - h(u(s), v(s)) = qa s^2 + qb s + qc.
    let u0 = px + dx * t_in - patch.ix as f64;
    let v0 = pz + dz * t_in - patch.iz as f64;
    let qa = -patch.d * dx * dz;
    let qb = d.y - patch.b * dx - patch.c * dz - patch.d * (u0 * dz + dx * v0);
    let qc = y_in - patch.height(u0, v0);
    let len = t_out - t_in;
    if qc <= 0.0 {
        return Some(t_in);
    }
    first_root(qa, qb, qc, len).map(|s| t_in + s)
}

/// The first `s` in `[0, len]` where `f(s) = qa s^2 + qb s + qc` (with `f(0) = qc > 0`)
/// reaches 0: the closed-form roots, or bisection where rounding lost the root that
/// `f(len) <= 0` proves.
fn first_root(qa: f64, qb: f64, qc: f64, len: f64) -> Option<f64> {
    let f = |s: f64| (qa * s + qb) * s + qc;
    let mut best: Option<f64> = None;
    let mut consider = |s: f64| {
        if s.is_finite() && (0.0..=len).contains(&s) && best.is_none_or(|b| s < b) {
            best = Some(s);
        }
    };
    let scale = qa.abs().max(qb.abs()).max(qc.abs());
    if qa.abs() <= 1e-14 * scale.max(f64::MIN_POSITIVE) {
        if qb != 0.0 {
            consider(-qc / qb);
        }
    } else {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc >= 0.0 {
            // The numerically stable pair of roots.
            let q = -0.5 * (qb + qb.signum() * disc.sqrt());
            consider(q / qa);
            if q != 0.0 {
                consider(qc / q);
            }
        }
    }
    if best.is_some() {
        return best;
    }
    // Rounding can lose a root that the end value proves: bisect for it.
    if f(len) <= 0.0 {
        let (mut a, mut b) = (0.0, len);
        for _ in 0..60 {
            let m = 0.5 * (a + b);
            if f(m) > 0.0 {
                a = m;
            } else {
                b = m;
            }
        }
        return Some(b);
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use terrain_core::{Grid, HeightEncoding};

    fn flat(raw: u16) -> HeightField {
        let g = Grid::new(8, 8, raw).expect("grid");
        HeightField::new(g, HeightEncoding::new(0.01, 0.0).expect("enc"), 1.0).expect("field")
    }

    #[test]
    fn straight_down_onto_flat_ground() {
        let f = flat(500); // 5 m
        let ray = Ray::new(Vec3::new(3.3, 10.0, 2.7), Vec3::NEG_Y).expect("ray");
        let hit = f
            .cast_local_ray(&ray, 100.0)
            .expect("bounded")
            .expect("hit");
        assert!((hit.distance - 5.0).abs() < 1e-5);
        assert!((hit.point - Vec3::new(3.3, 5.0, 2.7)).length() < 1e-5);
        assert!((hit.normal - Vec3::Y).length() < 1e-6);
        assert!(f.cast_local_ray(&ray, 4.9).expect("bounded").is_none());
    }

    #[test]
    fn horizontal_and_upward_rays_above_ground_miss() {
        let f = flat(500);
        let up = Ray::new(Vec3::new(1.0, 6.0, 1.0), Vec3::new(0.3, 1.0, 0.2)).expect("ray");
        assert!(f.cast_local_ray(&up, 1e6).expect("bounded").is_none());
        let flat_ray = Ray::new(Vec3::new(1.0, 6.0, 1.0), Vec3::X).expect("ray");
        assert!(
            f.cast_local_ray(&flat_ray, 1000.0)
                .expect("bounded")
                .is_none()
        );
    }

    #[test]
    fn origin_below_ground_hits_at_zero() {
        let f = flat(500);
        let ray = Ray::new(Vec3::new(1.0, 4.0, 1.0), Vec3::Y).expect("ray");
        let hit = f.cast_local_ray(&ray, 10.0).expect("bounded").expect("hit");
        assert_eq!(hit.distance, 0.0);
    }

    #[test]
    fn a_one_texel_spike_is_not_stepped_over() {
        let mut g = Grid::new(16, 16, 0u16).expect("grid");
        *g.get_mut(7, 5).expect("texel") = 1000; // a 10 m spike
        let f =
            HeightField::new(g, HeightEncoding::new(0.01, 0.0).expect("enc"), 1.0).expect("field");
        let ray = Ray::new(Vec3::new(0.0, 5.0, 5.0), Vec3::X).expect("ray");
        let hit = f.cast_local_ray(&ray, 15.0).expect("bounded").expect("hit");
        // The patch between texel 6 (0 m) and 7 (10 m) on row 5 reaches 5 m at x = 6.5.
        assert!((hit.distance - 6.5).abs() < 1e-5, "{hit:?}");
        assert!((f.height_local(Vec2::new(6.5, 5.0)) - 5.0).abs() < 1e-5);
    }

    #[test]
    fn bad_rays_are_errors() {
        assert!(matches!(
            Ray::new(Vec3::ZERO, Vec3::ZERO),
            Err(PhysicsError::ZeroDirection { .. })
        ));
        assert!(matches!(
            Ray::new(Vec3::new(f32::NAN, 0.0, 0.0), Vec3::X),
            Err(PhysicsError::NonFinite { .. })
        ));
        assert!(check_max_dist(-1.0).is_err());
        assert!(check_max_dist(f32::INFINITY).is_err());
    }

    /// Where the ray meets a flat patch the crossing is linear (`-qc / qb`): straight down
    /// from 2 m onto 0 m meets it 2 m on, also when that distance is a whole multiple of the
    /// slope.
    #[test]
    fn a_linear_crossing_is_found_where_it_is() {
        let f = flat(0);
        let patch = f.patch(3, 3);
        let ray = GridRay {
            o: DVec3::new(3.5, 2.0, 3.5),
            d: DVec3::NEG_Y,
            px: 3.5,
            pz: 3.5,
            dx: 0.0,
            dz: 0.0,
        };
        assert_eq!(hit_in_cell(&patch, &ray, 0.0, 5.0), Some(2.0));
        assert_eq!(hit_in_cell(&patch, &ray, 0.5, 5.0), Some(2.0));
        assert_eq!(hit_in_cell(&patch, &ray, 0.0, 1.5), None);
    }

    /// A ray over a patch that falls away a little faster than it descends: it stays above
    /// the patch to the cell's far side (its end height below the patch's highest corner, so
    /// the quick rejection does not decide) and meets the patch's extension only beyond it:
    /// no hit in this cell.
    #[test]
    fn a_crossing_beyond_the_cell_is_not_this_cells() {
        let g = Grid::from_fn(8, 8, |x, _| if x <= 3 { 100u16 } else { 0 }).expect("grid");
        let f =
            HeightField::new(g, HeightEncoding::new(0.01, 0.0).expect("enc"), 1.0).expect("field");
        let patch = f.patch(3, 3);
        let d = DVec3::new(1.0, -1.05, 0.0).normalize();
        let (t_in, t_out) = (0.5, 0.5 + 1.0 / d.x);
        let o = DVec3::new(3.0, 1.1, 3.5) - d * t_in;
        let ray = GridRay {
            o,
            d,
            px: o.x,
            pz: o.z,
            dx: d.x,
            dz: d.z,
        };
        assert_eq!(hit_in_cell(&patch, &ray, t_in, t_out), None);
        // It comes down in the next cell, which is flat at 0 m.
        assert!(hit_in_cell(&f.patch(4, 3), &ray, t_out, t_out + 1.0 / d.x).is_some());
    }

    /// A quadratic term too small for the closed form (treated as linear, whose root lies
    /// just past the end) still decides the crossing: bisection finds it.
    #[test]
    fn bisection_finds_a_root_the_closed_form_misses() {
        let (qa, qb, qc, len) = (-1e-15, -1e-3, 1.0, 1000.0 - 1e-7);
        let f = |s: f64| (qa * s + qb) * s + qc;
        assert!(f(len) <= 0.0 && -qc / qb > len);
        let s = first_root(qa, qb, qc, len).expect("a root");
        assert!(s > 999.99 && s <= len, "{s}");
        assert!(f(s) <= 0.0 && f(s - 1e-9) > 0.0, "{s}: not the crossing");
        // No crossing when the end stays above, nor on a patch the ray rises away from.
        assert_eq!(first_root(qa, qb, qc, 900.0), None);
        assert_eq!(first_root(0.0, 1.0, 0.5, 2.0), None);
        // Roots 1e-8 and 1e8: the stable pair of roots keeps the small one exact.
        let s = first_root(1.0, -1e8, 1.0, 1.0).expect("a root");
        assert!((s - 1e-8).abs() < 1e-15, "{s}");
    }
}
