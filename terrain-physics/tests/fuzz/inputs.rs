//! Generators and checks shared by the classes: coordinates and heights near a field or
//! anywhere, ray directions and distances within the walk bound, sphere reaches, the timing of
//! one call, and what a hit or a contact must satisfy.

use crate::fields::Field;
use crate::{CALL_LIMIT, WALK_CELLS};
use glam::{Vec2, Vec3};
use std::time::Instant;
use terrain_test_support::fuzz::{Case, Rng, finite_f32};

/// Any finite f32: random bits (every exponent alike), edge values, or modest numbers (within
/// 1e3).
pub(crate) fn any_f32(rng: &mut Rng) -> f32 {
    rng.f32_any(1e3)
}

/// A world coordinate along `axis` within a few map periods of the field, often on a cell
/// edge or a texel exactly.
pub(crate) fn near_coord(f: &Field, axis: usize, rng: &mut Rng) -> f32 {
    let n = f64::from(if axis == 0 { f.size.x } else { f.size.y });
    let t = match rng.below(3) {
        0 => rng.uniform(-3.0 * n, 4.0 * n),
        1 => rng.range_u32(0, 7 * n as u32) as f64 - 3.0 * n,
        _ => rng.range_u32(0, 7 * n as u32) as f64 - 3.0 * n + rng.pick(&[0.5, 1e-9, -1e-9]),
    };
    let origin = if axis == 0 {
        f.translation.x
    } else {
        f.translation.z
    };
    finite_f32(t * f.ts + f64::from(origin))
}

/// A world height: near the surface at `(x, z)` (within `reach` texels), inside the field's
/// height band, or anywhere.
pub(crate) fn near_height(f: &Field, x: f32, z: f32, reach: f64, rng: &mut Rng) -> f32 {
    match rng.below(4) {
        0 | 1 => finite_f32(f.surface(x, z) + rng.uniform(-reach, reach) * f.ts),
        2 => finite_f32(rng.uniform(f.lo, f.hi)),
        _ => any_f32(rng),
    }
}

pub(crate) fn near_pos(f: &Field, rng: &mut Rng) -> Vec2 {
    Vec2::new(near_coord(f, 0, rng), near_coord(f, 1, rng))
}

/// A position anywhere: near the map, or any finite value per axis.
pub(crate) fn any_pos(f: &Field, rng: &mut Rng) -> Vec2 {
    let axis = |a: usize, rng: &mut Rng| {
        if rng.chance(1, 2) {
            near_coord(f, a, rng)
        } else {
            any_f32(rng)
        }
    };
    Vec2::new(axis(0, rng), axis(1, rng))
}

/// Runs one call of the code under test, timed. A call over [`CALL_LIMIT`] is run twice
/// more and fails only if every run is over: a loaded machine stalls a call now and then, a
/// slow input is slow every time.
pub(crate) fn timed<T>(what: &str, mut call: impl FnMut() -> T) -> Result<T, String> {
    let mut took = Vec::new();
    for _ in 0..3 {
        let t = Instant::now();
        let r = call();
        let d = t.elapsed();
        if d <= CALL_LIMIT {
            return Ok(r);
        }
        took.push(format!("{:.1} ms", d.as_secs_f64() * 1e3));
    }
    Err(format!(
        "{what} took {} (limit {} ms)",
        took.join(", then "),
        CALL_LIMIT.as_millis()
    ))
}

/// A unit-ish direction: uniform on the sphere, along an axis, near horizontal, or random
/// bits per component (the collider normalises; a zero one is an error).
pub(crate) fn direction(rng: &mut Rng) -> Vec3 {
    match rng.below(4) {
        0 => loop {
            let v = Vec3::new(
                rng.uniform(-1.0, 1.0) as f32,
                rng.uniform(-1.0, 1.0) as f32,
                rng.uniform(-1.0, 1.0) as f32,
            );
            if v.length_squared() > 1e-6 {
                break v;
            }
        },
        1 => rng.pick(&[
            Vec3::X,
            Vec3::NEG_X,
            Vec3::Y,
            Vec3::NEG_Y,
            Vec3::Z,
            Vec3::NEG_Z,
        ]),
        2 => {
            let a = rng.uniform(0.0, std::f64::consts::TAU);
            let dy = rng.pick(&[0.0f32, 1e-6, -1e-6, 1e-3, -1e-3, -1e-30, 1e-30]);
            Vec3::new(a.cos() as f32, dy, a.sin() as f32)
        }
        _ => Vec3::new(any_f32(rng), any_f32(rng), any_f32(rng)),
    }
}

/// Cells a ray walks at most: `max_dist * (|d.x| + |d.z|) / texel` for the normalised
/// direction (`None` if it does not normalise: the query is an error then).
pub(crate) fn walk_cells(f: &Field, dir: Vec3, max_dist: f32) -> Option<f64> {
    let d = dir.try_normalize()?;
    Some(f64::from(max_dist) * (f64::from(d.x.abs()) + f64::from(d.z.abs())) / f.ts)
}

/// The largest `max_dist` that keeps a ray within [`WALK_CELLS`] cells.
pub(crate) fn walk_cap(f: &Field, dir: Vec3) -> f32 {
    match dir.try_normalize() {
        Some(d) => {
            let across = f64::from(d.x.abs()) + f64::from(d.z.abs());
            if across == 0.0 {
                f32::MAX
            } else {
                finite_f32(WALK_CELLS * f.ts / across * 0.999)
            }
        }
        None => f32::MAX,
    }
}

/// A max distance: modest, edge, random bits, zero.
pub(crate) fn max_distance(f: &Field, rng: &mut Rng) -> f32 {
    match rng.below(4) {
        0 => finite_f32(rng.uniform(0.0, 200.0) * f.ts),
        1 => rng.f32_edge().abs(),
        2 => rng.f32_bits().abs(),
        _ => 0.0,
    }
}

/// Checks a raycast that returned.
pub(crate) fn check_hit(
    what: &str,
    r: Result<Option<terrain_physics::RayHit>, terrain_physics::PhysicsError>,
    max_dist: f32,
    case: &mut Case,
) -> Result<(), String> {
    match r {
        Ok(Some(hit)) => {
            if !(hit.distance >= 0.0 && hit.distance <= max_dist * (1.0 + 1e-5) + 1e-30) {
                return Err(format!(
                    "{what}: hit at distance {} of {max_dist}",
                    hit.distance
                ));
            }
            if !(hit.point.is_finite() && hit.normal.is_finite()) {
                case.note(|| format!("{what}: non-finite hit {hit:?}"));
            }
            Ok(())
        }
        Ok(None) => Ok(()),
        // A ray undecided after the bounded walk is refused by design (never a false miss).
        Err(terrain_physics::PhysicsError::RayTooLong { .. }) => Ok(()),
        Err(e) => Err(format!("{what}: finite input refused: {e}")),
    }
}

/// How far a sphere query searches, in texels (see [`REACH_TEXELS`]): from the centre in
/// the collider's local frame (`centre - translation` in f32, as the collider computes it).
pub(crate) fn sphere_reach(f: &Field, c: Vec3, r: f32) -> f64 {
    let lc = c - f.translation;
    if !lc.is_finite() {
        return 0.0; // the query is refused before any search
    }
    let h = f.surface_local(lc.x, lc.z);
    let y = f64::from(lc.y);
    let reach = if y < h {
        h - y
    } else {
        (y - h).min(f64::from(r))
    };
    if reach.is_nan() { 0.0 } else { reach / f.ts }
}

/// Whether the collider's local coordinates of world point `p` (`p - translation` in f32)
/// overflow: the query is then refused as non-finite although its input is finite (noted).
pub(crate) fn local_overflow_refused<T: std::fmt::Debug, E: std::fmt::Display>(
    f: &Field,
    p: Vec3,
    r: &Result<T, E>,
    case: &mut Case,
) -> bool {
    if !f.overflows(p) {
        return false;
    }
    if let Err(e) = r {
        case.note(|| {
            format!(
                "{p} on field {}: local coordinates overflow, refused: {e}",
                f.label
            )
        });
        return true;
    }
    false
}

/// Checks a sphere contact that returned.
pub(crate) fn check_contact(
    what: &str,
    r: Result<Option<terrain_physics::Contact>, terrain_physics::PhysicsError>,
    case: &mut Case,
) -> Result<(), String> {
    match r {
        Ok(Some(c)) => {
            if c.depth.is_nan() || c.depth < 0.0 {
                return Err(format!("{what}: contact of depth {}", c.depth));
            }
            if !(c.point.is_finite() && c.normal.is_finite() && c.depth.is_finite()) {
                case.note(|| format!("{what}: non-finite contact {c:?}"));
            }
            Ok(())
        }
        Ok(None) => Ok(()),
        Err(e) => Err(format!("{what}: finite input refused: {e}")),
    }
}
