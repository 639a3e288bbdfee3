//! Classes of the bodies: `CameraBody` and `SphereBody` steps over the collider and over a
//! `BoundedGround`, with states, time steps and forces of any finite value.

use crate::REACH_TEXELS;
use crate::bounded::pending;
use crate::fields::Ctx;
use crate::inputs::{any_f32, any_pos, check_contact, near_height, near_pos, timed};
use glam::Vec3;
use terrain_physics::{BoundedGround, CameraBody, GroundClamp, SphereBody};
use terrain_test_support::fuzz::{Case, finite_f32};

/// A camera of random state (any finite values, some invalid: negative mass, friction or
/// gravity) stepping by any time step under any force over the collider (no loop in the
/// height query, so the whole range).
pub(crate) fn camera_body(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let p = any_pos(f, rng);
    let mut cam = CameraBody::new(Vec3::new(p.x, near_height(f, p.x, p.y, 8.0, rng), p.y));
    cam.velocity =
        Vec3::new(any_f32(rng), any_f32(rng), any_f32(rng)) * rng.pick(&[0.0, 1e-3, 1.0]);
    if rng.chance(1, 3) {
        cam.eye_height = any_f32(rng);
    }
    if rng.chance(1, 3) {
        cam.mass = any_f32(rng);
    }
    if rng.chance(1, 3) {
        cam.friction = any_f32(rng);
    }
    if rng.chance(1, 3) {
        cam.gravity = any_f32(rng);
    }
    cam.gravity_enabled = rng.chance(3, 4);
    cam.clamp = if rng.chance(1, 2) {
        GroundClamp::OffsetOnly
    } else {
        GroundClamp::OffsetAndStop
    };
    let dt = match rng.below(3) {
        0 => 1.0 / 60.0,
        1 => any_f32(rng),
        _ => rng.f32_edge().abs(),
    };
    let force = Vec3::new(any_f32(rng), any_f32(rng), any_f32(rng)) * rng.pick(&[0.0, 1.0]);
    case.show(|| {
        format!(
            "field {}, camera {cam:?}, dt {dt:e}, force {force:?}",
            f.label
        )
    });
    let before = cam;
    let r = timed("CameraBody::step", || {
        let mut c = before;
        let r = c.step(dt, force, &f.collider);
        (r, c)
    })?;
    match r {
        (Err(_), after) if format!("{after:?}") != format!("{before:?}") => Err(format!(
            "a failed step changed the camera: {before:?} -> {after:?}"
        )),
        (Ok(_), after) if !after.position.is_finite() => {
            case.note(|| format!("a step returned Ok with the camera at {}: {before:?}, dt {dt:e}, force {force}", after.position));
            Ok(())
        }
        _ => Ok(()),
    }
}

/// A camera over a BoundedGround near the map: small steps, so that it stays near.
pub(crate) fn camera_bounded_ground(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let pend = pending(rng, f);
    let p = near_pos(f, rng);
    let mut cam = CameraBody::new(Vec3::new(p.x, near_height(f, p.x, p.y, 8.0, rng), p.y));
    cam.gravity_enabled = rng.chance(1, 2);
    cam.velocity = Vec3::new(
        rng.uniform(-4.0, 4.0) as f32,
        0.0,
        rng.uniform(-4.0, 4.0) as f32,
    ) * f.ts as f32;
    let dt = rng.pick(&[0.0, 1.0 / 240.0, 1.0 / 60.0, 0.25]);
    let moved = cam.position + cam.velocity * dt * 2.0;
    if f.is_far(moved.x, moved.z) || f.is_far(cam.position.x, cam.position.z) {
        case.skipped = true;
        return Ok(());
    }
    case.show(|| {
        format!(
            "field {}, pending {pend:?}, camera {cam:?}, dt {dt}",
            f.label
        )
    });
    let g = BoundedGround::new(&f.collider, &pend, &[]);
    let before = cam;
    let (r, after) = timed("CameraBody::step", || {
        let mut c = before;
        (c.step(dt, Vec3::ZERO, &g), c)
    })?;
    if r.is_err() && format!("{after:?}") != format!("{before:?}") {
        return Err(format!(
            "a failed step changed the camera: {before:?} -> {after:?}"
        ));
    }
    Ok(())
}

/// A ball resting, rolling or falling near the surface: radius and steps small enough that
/// both of its contact queries stay within [`REACH_TEXELS`].
pub(crate) fn sphere_body_near(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let p = near_pos(f, rng);
    let r = finite_f32(rng.uniform(0.05, 8.0) * f.ts);
    let y = finite_f32(f.surface(p.x, p.y) + rng.uniform(-2.0, 16.0) * f.ts);
    let Ok(mut ball) = SphereBody::new(Vec3::new(p.x, y, p.y), r) else {
        return Ok(()); // a radius that rounded to 0 or below
    };
    ball.velocity = Vec3::new(
        rng.uniform(-8.0, 8.0) as f32,
        rng.uniform(-8.0, 8.0) as f32,
        rng.uniform(-8.0, 8.0) as f32,
    ) * f.ts as f32;
    ball.gravity_enabled = rng.chance(1, 2);
    ball.damping = rng.uniform(0.0, 2.0) as f32;
    let dt = rng.pick(&[0.0, 1.0 / 240.0, 1.0 / 60.0]);
    // Both contact queries of the step stay within REACH_TEXELS if the highest texel under
    // where the step can take the ball is within it of the lowest centre: the box spans the
    // centre, the centre moved by the velocity, slack for the acceleration over the step,
    // the radius, and the rounding of world to local f32 coordinates.
    let lc = (ball.center - f.translation).as_dvec3();
    let step = (ball.velocity * dt).as_dvec3();
    let accel =
        f64::from(ball.damping) * f64::from(ball.velocity.length()) + f64::from(ball.gravity);
    let magnitude = ball.center.abs().max(f.translation.abs()).max_element();
    let tol = f64::from(ball.radius) + f64::from(terrain_physics::CONTACT_TOLERANCE);
    let slack = 2.0 * accel * f64::from(dt) * f64::from(dt)
        + tol
        + 4.0 * f64::from(magnitude) * f64::from(f32::EPSILON);
    let (a, b) = (lc, lc + step);
    let lowest = a.y.min(b.y) - slack;
    let bounded = f
        .max_surface_box(
            a.x.min(b.x) - slack,
            a.x.max(b.x) + slack,
            a.z.min(b.z) - slack,
            a.z.max(b.z) + slack,
        )
        .is_some_and(|top| (top - lowest) / f.ts <= REACH_TEXELS && tol / f.ts <= REACH_TEXELS);
    if !bounded {
        case.skipped = true;
        return Ok(()); // the domain of sphere_body_whole_range
    }
    case.show(|| format!("field {}, ball {ball:?}, dt {dt}", f.label));
    let before = ball;
    let (res, after) = timed("SphereBody::step", || {
        let mut b = before;
        (b.step(dt, Vec3::ZERO, &f.collider), b)
    })?;
    match res {
        Err(_) if format!("{after:?}") != format!("{before:?}") => Err(format!(
            "a failed step changed the ball: {before:?} -> {after:?}"
        )),
        Ok(c) => check_contact("SphereBody::step", Ok(c), case),
        Err(_) => Ok(()),
    }
}

/// A ball of any state (centre, velocity, radius over the finite range) stepping by any time
/// step: its contact queries can take any reach (defects 2 and 3).
pub(crate) fn sphere_body_whole_range(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let p = any_pos(f, rng);
    let c = Vec3::new(p.x, any_f32(rng), p.y);
    let Ok(mut ball) = SphereBody::new(c, any_f32(rng).abs()) else {
        return Ok(());
    };
    ball.velocity = Vec3::new(any_f32(rng), any_f32(rng), any_f32(rng));
    let dt = any_f32(rng).abs();
    let force = Vec3::new(any_f32(rng), any_f32(rng), any_f32(rng));
    case.show(|| {
        format!(
            "field {}, ball {ball:?}, dt {dt:e}, force {force:?}",
            f.label
        )
    });
    let before = ball;
    let (res, after) = timed("SphereBody::step", || {
        let mut b = before;
        (b.step(dt, force, &f.collider), b)
    })?;
    match res {
        Err(_) if format!("{after:?}") != format!("{before:?}") => Err(format!(
            "a failed step changed the ball: {before:?} -> {after:?}"
        )),
        _ => Ok(()),
    }
}
