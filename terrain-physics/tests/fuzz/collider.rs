//! Classes of `HeightfieldCollider`'s queries: height and normal, non-finite inputs, rays
//! (near the map, over the whole range, long walks, far origins) and sphere contacts (near the
//! surface, over the whole range, deep below, huge radii, far centres).

use crate::fields::Ctx;
use crate::inputs::{
    any_f32, any_pos, check_contact, check_hit, direction, local_overflow_refused, max_distance,
    near_coord, near_height, near_pos, sphere_reach, timed, walk_cap, walk_cells,
};
use crate::{FAR_TEXELS, REACH_TEXELS, WALK_CELLS};
use glam::{IVec2, UVec2, Vec2, Vec3};
use terrain_core::Rect;
use terrain_physics::{
    BoundedGround, CameraBody, DeformationBound, GroundQuery, PendingDeformation, SphereBody,
};
use terrain_test_support::fuzz::{Case, Rng, finite_f32};

/// Height and normal anywhere in the finite range.
pub(crate) fn height_normal(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let f = ctx.field(&mut case.rng);
    let p = any_pos(f, &mut case.rng);
    case.show(|| format!("field {}, pos {p:?}", f.label));
    let h = timed("height", || f.collider.height(p))?;
    let n = timed("normal", || f.collider.normal(p))?;
    let p3 = Vec3::new(p.x, 0.0, p.y);
    if f.overflows(p3) {
        // Out of every query's reach: an error is the right answer, a value (NaN) is noted.
        if !local_overflow_refused(f, p3, &h, case) {
            case.note(|| format!("height at {p:?} on field {} is {h:?}", f.label));
        }
        return Ok(());
    }
    let h = h.map_err(|e| format!("height at {p}: finite input refused: {e}"))?;
    let n = n.map_err(|e| format!("normal at {p}: finite input refused: {e}"))?;
    if !h.is_finite() && f.lo.abs() < 1e38 && f.hi.abs() < 1e38 {
        case.note(|| format!("height at {p:?} on field {} is {h}", f.label));
    }
    if !n.is_finite() {
        case.note(|| format!("normal at {p:?} on field {} is {n}", f.label));
    }
    Ok(())
}

/// NaN or an infinity in one input of any query: always an error.
pub(crate) fn non_finite_inputs(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let bad = rng.f32_non_finite();
    let p = near_pos(f, rng);
    let v3 = |rng: &mut Rng| {
        let mut v = Vec3::new(p.x, near_height(f, p.x, p.y, 4.0, rng), p.y);
        let i = rng.index(3);
        v[i] = bad;
        v
    };
    let mut v2 = p;
    v2[rng.index(2)] = bad;
    let pending = [PendingDeformation {
        rect: Rect::new(IVec2::ZERO, UVec2::splat(4)),
        bound: DeformationBound::new(1.0, 1.0).expect("bound"),
    }];
    let ground = BoundedGround::new(&f.collider, &pending, &[]);
    let which = rng.below(12);
    // Each query's result, formatted: it must be an error.
    let shown = match which {
        0 => format!("{:?}", f.collider.height(v2)),
        1 => format!("{:?}", f.collider.normal(v2)),
        2 => {
            let o = v3(rng);
            format!("{:?}", f.collider.raycast(o, Vec3::NEG_Y, 1.0))
        }
        3 => {
            let mut d = Vec3::NEG_Y;
            d[rng.index(3)] = bad;
            format!("{:?}", f.collider.raycast(Vec3::new(p.x, 0.0, p.y), d, 1.0))
        }
        4 => format!(
            "{:?}",
            f.collider
                .raycast(Vec3::new(p.x, 0.0, p.y), Vec3::NEG_Y, bad)
        ),
        5 => {
            let c = v3(rng);
            format!("{:?}", f.collider.sphere_contact(c, 1.0))
        }
        6 => format!(
            "{:?}",
            f.collider.sphere_contact(Vec3::new(p.x, 0.0, p.y), bad)
        ),
        7 => format!("{:?}", ground.raise_at(v2)),
        8 => {
            let c = v3(rng);
            format!("{:?}", ground.ground_contact(c, 1.0))
        }
        9 => format!("{:?}", ground.height_interval(v2)),
        10 => {
            let mut cam = CameraBody::new(Vec3::new(p.x, 0.0, p.y));
            match rng.below(4) {
                0 => cam.velocity.y = bad,
                1 => cam.eye_height = bad,
                2 => cam.mass = bad,
                _ => cam.position.x = bad,
            }
            let before = format!("{cam:?}");
            let r = cam.step(1.0 / 60.0, Vec3::ZERO, &f.collider);
            if format!("{cam:?}") != before {
                return Err(format!(
                    "a failed step changed the camera: {before} -> {cam:?}"
                ));
            }
            format!("{r:?}")
        }
        _ => {
            let mut s =
                SphereBody::new(Vec3::new(p.x, 0.0, p.y), 1.0).map_err(|e| e.to_string())?;
            let (dt, force) = match rng.below(3) {
                0 => (bad, Vec3::ZERO),
                1 => (1.0 / 60.0, Vec3::new(bad, 0.0, 0.0)),
                _ => {
                    s.velocity.z = bad;
                    (1.0 / 60.0, Vec3::ZERO)
                }
            };
            let before = format!("{s:?}");
            let r = s.step(dt, force, &f.collider);
            if format!("{s:?}") != before {
                return Err(format!("a failed step changed the ball: {before} -> {s:?}"));
            }
            format!("{r:?}")
        }
    };
    if shown.starts_with("Err(") {
        Ok(())
    } else {
        Err(format!(
            "query {which} with a {bad} input on field {} returned {shown}",
            f.label
        ))
    }
}

/// Rays near the map, any direction, within [`WALK_CELLS`] cells.
pub(crate) fn ray_near_map(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let p = near_pos(f, rng);
    let o = Vec3::new(p.x, near_height(f, p.x, p.y, 64.0, rng), p.y);
    if f.is_far(o.x, o.z) {
        case.skipped = true;
        return Ok(()); // a large translation rounded it far: the domain of ray_far_origin
    }
    let d = direction(rng);
    let max_dist = max_distance(f, rng).min(walk_cap(f, d));
    case.show(|| {
        format!(
            "field {}, origin {o:?}, dir {d:?}, max_dist {max_dist:e}",
            f.label
        )
    });
    let r = timed("raycast", || f.collider.raycast(o, d, max_dist))?;
    if d.try_normalize().is_none() {
        return match r {
            Err(_) => Ok(()),
            Ok(h) => Err(format!("a zero direction {d:?} gave {h:?}")),
        };
    }
    check_hit("raycast", r, max_dist, case)
}

/// Rays from anywhere in the finite range (not far, see [`FAR_TEXELS`]), any direction and
/// max distance within [`WALK_CELLS`] cells.
pub(crate) fn ray_whole_range(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let mut p = any_pos(f, rng);
    if f.is_far(p.x, p.y) {
        p = near_pos(f, rng);
    }
    if f.is_far(p.x, p.y) {
        case.skipped = true;
        return Ok(()); // a large translation rounded it far: the domain of ray_far_origin
    }
    let o = Vec3::new(p.x, any_f32(rng), p.y);
    let d = direction(rng);
    let max_dist = any_f32(rng).abs().min(walk_cap(f, d));
    case.show(|| {
        format!(
            "field {}, origin {o:?}, dir {d:?}, max_dist {max_dist:e}",
            f.label
        )
    });
    let r = timed("raycast", || f.collider.raycast(o, d, max_dist))?;
    if d.try_normalize().is_none() {
        return r.map(|_| ()).or(Ok(()));
    }
    check_hit("raycast", r, max_dist, case)
}

/// Defect 1: near-horizontal rays inside the height band with a huge max distance.
pub(crate) fn ray_long_walk(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let p = near_pos(f, rng);
    // Just above the ground under the origin, or anywhere in the band.
    let y = if rng.chance(1, 2) {
        finite_f32(f.surface(p.x, p.y) + 1e-3 * f.ts.min(1.0))
    } else {
        finite_f32(rng.uniform(f.lo, f.hi))
    };
    let o = Vec3::new(p.x, y, p.y);
    let a = rng.uniform(0.0, std::f64::consts::TAU);
    let dy = rng.pick(&[0.0f32, 1e-6, -1e-6, 1e-9, -1e-30]);
    let d = Vec3::new(a.cos() as f32, dy, a.sin() as f32);
    let cells = rng.pick(&[1e6, 1e8, 1e12, 1e20, 1e30]);
    let max_dist = if rng.chance(1, 4) {
        f32::MAX
    } else {
        finite_f32(cells * f.ts)
    };
    if walk_cells(f, d, max_dist).is_some_and(|c| c <= WALK_CELLS) {
        case.skipped = true;
        return Ok(()); // a texel size so large the walk is short: the enabled classes' domain
    }
    case.show(|| {
        format!(
            "field {}, origin {o:?}, dir {d:?}, max_dist {max_dist:e}",
            f.label
        )
    });
    let r = timed("raycast", || f.collider.raycast(o, d, max_dist))?;
    check_hit("raycast", r, max_dist, case)
}

/// Defect 3: rays from far outside the map (texel coordinates of 2^62 and more).
pub(crate) fn ray_far_origin(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let far = |rng: &mut Rng, axis: usize| {
        let origin = if axis == 0 {
            f.translation.x
        } else {
            f.translation.z
        };
        let t = FAR_TEXELS * rng.uniform(1.0, 64.0) * if rng.chance(1, 2) { 1.0 } else { -1.0 };
        if rng.chance(1, 3) {
            any_f32(rng)
        } else {
            finite_f32(t * f.ts + f64::from(origin))
        }
    };
    let mut p = near_pos(f, rng);
    match rng.below(3) {
        0 => p.x = far(rng, 0),
        1 => p.y = far(rng, 1),
        _ => p = Vec2::new(far(rng, 0), far(rng, 1)),
    }
    if !f.is_far(p.x, p.y) {
        case.skipped = true;
        return Ok(()); // a texel size so large the coordinate is not far
    }
    let o = Vec3::new(p.x, near_height(f, p.x, p.y, 64.0, rng), p.y);
    let d = direction(rng);
    let max_dist = max_distance(f, rng).min(walk_cap(f, d));
    case.show(|| {
        format!(
            "field {}, origin {o:?}, dir {d:?}, max_dist {max_dist:e}",
            f.label
        )
    });
    let r = timed("raycast", || f.collider.raycast(o, d, max_dist))?;
    if d.try_normalize().is_none() {
        return r.map(|_| ()).or(Ok(()));
    }
    if local_overflow_refused(f, o, &r, case) {
        return Ok(());
    }
    check_hit("raycast", r, max_dist, case)
}

/// Spheres near the surface, radius up to [`REACH_TEXELS`] texels.
pub(crate) fn sphere_near_surface(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let p = near_pos(f, rng);
    let c = Vec3::new(
        p.x,
        finite_f32(f.surface(p.x, p.y) + rng.uniform(-REACH_TEXELS, REACH_TEXELS) * f.ts),
        p.y,
    );
    let r = match rng.below(3) {
        0 => 0.0,
        1 => finite_f32(rng.uniform(0.0, 4.0) * f.ts),
        _ => finite_f32(rng.uniform(0.0, REACH_TEXELS) * f.ts),
    };
    if sphere_reach(f, c, r) > REACH_TEXELS || f.is_far(c.x, c.z) {
        case.skipped = true;
        return Ok(()); // rounding put it past a bound: the domain of another class
    }
    case.show(|| format!("field {}, centre {c:?}, radius {r:e}", f.label));
    let got = timed("sphere_contact", || f.collider.sphere_contact(c, r))?;
    check_contact("sphere_contact", got, case)
}

/// Spheres anywhere in the finite range whose search stays within [`REACH_TEXELS`] and whose
/// centre is not far.
pub(crate) fn sphere_whole_range(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let mut p = any_pos(f, rng);
    if f.is_far(p.x, p.y) {
        p = near_pos(f, rng);
    }
    let c = Vec3::new(p.x, any_f32(rng), p.y);
    let r = any_f32(rng).abs();
    if sphere_reach(f, c, r) > REACH_TEXELS || f.is_far(c.x, c.z) {
        case.skipped = true;
        return Ok(()); // the domain of sphere_deep_below / sphere_huge_radius / sphere_far_center
    }
    case.show(|| format!("field {}, centre {c:?}, radius {r:e}", f.label));
    let got = timed("sphere_contact", || f.collider.sphere_contact(c, r))?;
    check_contact("sphere_contact", got, case)
}

/// Defect 2: sphere centres far below the ground.
pub(crate) fn sphere_deep_below(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let p = near_pos(f, rng);
    let depth = rng.pick(&[1e3, 1e4, 1e6, 1e12, 1e30]) * f.ts;
    let c = Vec3::new(p.x, finite_f32(f.surface(p.x, p.y) - depth), p.y);
    let r = finite_f32(rng.uniform(0.0, 4.0) * f.ts);
    if sphere_reach(f, c, r) <= REACH_TEXELS || f.is_far(c.x, c.z) {
        case.skipped = true;
        return Ok(());
    }
    case.show(|| format!("field {}, centre {c:?}, radius {r:e}", f.label));
    let got = timed("sphere_contact", || f.collider.sphere_contact(c, r))?;
    check_contact("sphere_contact", got, case)
}

/// Defect 2: sphere centres high above the ground with a radius reaching down to it.
pub(crate) fn sphere_huge_radius(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let p = near_pos(f, rng);
    let up = rng.pick(&[1e3, 1e4, 1e6, 1e12, 1e30]) * f.ts;
    let c = Vec3::new(p.x, finite_f32(f.surface(p.x, p.y) + up), p.y);
    let r = finite_f32(up * rng.uniform(1.0, 3.0));
    if sphere_reach(f, c, r) <= REACH_TEXELS || f.is_far(c.x, c.z) {
        case.skipped = true;
        return Ok(());
    }
    case.show(|| format!("field {}, centre {c:?}, radius {r:e}", f.label));
    let got = timed("sphere_contact", || f.collider.sphere_contact(c, r))?;
    check_contact("sphere_contact", got, case)
}

/// Defect 3: sphere centres far outside the map, small radius and near the ground height.
pub(crate) fn sphere_far_center(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let t = FAR_TEXELS * rng.uniform(1.0, 64.0);
    let x = if rng.chance(1, 3) {
        any_f32(rng)
    } else {
        let sign = if rng.chance(1, 2) { 1.0 } else { -1.0 };
        finite_f32(t * f.ts * sign + f64::from(f.translation.x))
    };
    let z = near_coord(f, 1, rng);
    let (x, z) = if rng.chance(1, 2) { (x, z) } else { (z, x) };
    if !f.is_far(x, z) {
        case.skipped = true;
        return Ok(());
    }
    // On or just above the ground there (as the collider finds it), or anywhere in the band.
    let y = if rng.chance(3, 4) {
        f.surface(x, z) + rng.uniform(0.0, 4.0) * f.ts
    } else {
        rng.uniform(f.lo, f.hi)
    };
    let c = Vec3::new(x, finite_f32(y), z);
    let r = finite_f32(rng.uniform(0.0, 4.0) * f.ts);
    if sphere_reach(f, c, r) > REACH_TEXELS {
        case.skipped = true;
        return Ok(());
    }
    case.show(|| format!("field {}, centre {c:?}, radius {r:e}", f.label));
    let got = timed("sphere_contact", || f.collider.sphere_contact(c, r))?;
    if local_overflow_refused(f, c, &got, case) {
        return Ok(());
    }
    check_contact("sphere_contact", got, case)
}
