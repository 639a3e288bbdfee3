//! Classes of the camera rigs: `CameraPath` (orbit, flyover) built from maps and shapes of any
//! f32 value, posed at any time, and `CameraRig` stepping (a path camera and a follower) by
//! any time step over the collider. Construction refuses what is not finite or out of range;
//! what it accepts poses at finite points; every call returns within the call limit.

use crate::fields::Ctx;
use crate::inputs::{any_f32, any_pos, timed};
use glam::Vec2;
use terrain_physics::{CameraPath, CameraRig, FollowShape, GroundQuery, MapFrame, PathParams};
use terrain_test_support::fuzz::{Case, Rng};

/// Mostly sensible, sometimes any f32 (NaN and infinities included).
fn value(rng: &mut Rng, sensible: f32) -> f32 {
    match rng.below(4) {
        0 => any_f32(rng),
        1 => rng.f32_edge(),
        _ => sensible * rng.uniform(0.0, 2.0) as f32,
    }
}

/// A path from a map frame and a shape of any values, posed at any time, then a rig on it
/// stepping over the collider.
pub(crate) fn camera_path(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let frame = MapFrame {
        extent: Vec2::new(value(rng, 2000.0), value(rng, 2000.0)),
        low: value(rng, -50.0),
        high: value(rng, 800.0),
    };
    let params = PathParams {
        orbit_pitch: value(rng, 0.6),
        orbit_period_s: value(rng, 40.0),
        flyover_period_s: value(rng, 30.0),
        flyover_height: value(rng, 0.08),
        flyover_pitch: value(rng, 0.4),
    };
    let orbit = rng.chance(1, 2);
    let t = value(rng, 100.0);
    let dt = value(rng, 1.0 / 30.0);
    case.show(|| {
        format!(
            "field {}, {frame:?}, {params:?}, orbit {orbit}, t {t:e}, dt {dt:e}",
            f.label
        )
    });
    let path = timed("CameraPath::new", || match orbit {
        true => CameraPath::orbit(frame, params),
        false => CameraPath::flyover(frame, params),
    })?;
    let finite = frame.extent.is_finite()
        && frame.low.is_finite()
        && frame.high.is_finite()
        && [
            params.orbit_pitch,
            params.orbit_period_s,
            params.flyover_period_s,
            params.flyover_height,
            params.flyover_pitch,
        ]
        .iter()
        .all(|v| v.is_finite());
    let path = match path {
        Ok(_) if !finite => return Err("a path of non-finite inputs was accepted".into()),
        Ok(p) => p,
        Err(_) => return Ok(()),
    };
    let ground = |p: Vec2| f.collider.ground_height(p).unwrap_or(0.0);
    let pose = timed("CameraPath::pose", || path.pose(t, ground))?;
    if !pose.eye.is_finite() || !pose.look_at.is_finite() {
        return Err(format!("an accepted path posed at {pose:?}"));
    }
    if !path.view_radius().is_finite() || !path.clearance().is_finite() {
        return Err("an accepted path has non-finite distances".into());
    }
    let mut rig = CameraRig::on_path(path, ground);
    let before = rig.eye();
    let stepped = timed("CameraRig::step (path)", || {
        rig.step((Vec2::ZERO, Vec2::X), dt, &f.collider, ground)
    })?;
    if stepped.is_ok() && !(dt.is_finite() && dt >= 0.0) {
        return Err(format!("a step of dt {dt} was accepted"));
    }
    if stepped.is_err() && rig.eye() != before {
        return Err(format!(
            "a failed path step moved the eye {before} -> {}",
            rig.eye()
        ));
    }
    if let Ok(view) = stepped
        && !(view.pose.eye.is_finite() && view.pose.look_at.is_finite())
    {
        return Err(format!("a path step gave {view:?}"));
    }
    Ok(())
}

/// A follower of any shape, standing anywhere, following a subject anywhere.
pub(crate) fn camera_follower(ctx: &Ctx, case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let f = ctx.field(rng);
    let start = any_pos(f, rng);
    let shape = FollowShape {
        eye_height: value(rng, 3.0),
        behind: value(rng, 9.0),
        ahead: value(rng, 12.0),
    };
    let subject = (any_pos(f, rng), Vec2::new(value(rng, 1.0), value(rng, 1.0)));
    let dt = value(rng, 1.0 / 30.0);
    case.show(|| {
        format!(
            "field {}, start {start}, {shape:?}, subject {subject:?}, dt {dt:e}",
            f.label
        )
    });
    let ground_y = f.collider.ground_height(start).unwrap_or(0.0);
    let Ok(mut rig) = timed("CameraRig::follower", || {
        CameraRig::follower(start, ground_y, shape)
    })?
    else {
        return Ok(());
    };
    let look = |p: Vec2| f.collider.ground_height(p).unwrap_or(0.0);
    let before = rig.eye();
    let stepped = timed("CameraRig::step (follower)", || {
        rig.step(subject, dt, &f.collider, look)
    })?;
    if stepped.is_err() && rig.eye() != before {
        return Err(format!(
            "a failed step moved the rig: {before} -> {}",
            rig.eye()
        ));
    }
    let valid = dt.is_finite() && dt >= 0.0 && subject.0.is_finite() && subject.1.is_finite();
    if stepped.is_ok() && !valid {
        return Err("a follower step of non-finite input or negative dt was accepted".into());
    }
    if let Ok(view) = stepped
        && !(view.pose.eye.is_finite() && view.pose.look_at.is_finite())
    {
        return Err(format!("a follower step gave {view:?}"));
    }
    Ok(())
}
