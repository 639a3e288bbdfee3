//! [`CameraRig`]: a camera as a physics body ([`CameraBody`]) standing on the collision ground,
//! never below it. A follower walks behind a moving subject, pulled by a critically damped
//! spring on X/Z under gravity, at eye height, looking ahead of the subject; a path camera is
//! moved along a [`CameraPath`] (each step's velocity takes it to the path's next point), the
//! ground clamp keeping it at least the path's clearance above the terrain and above
//! deformations still on their way back from the GPU (a [`GroundQuery`] with bounds).

use crate::camera_path::{CameraPath, Pose};
use crate::error::{check_finite, check_finite2};
use crate::{CameraBody, GroundQuery, PhysicsError};
use glam::{Vec2, Vec3};

/// Spring stiffness per unit mass on X/Z (1/s^2); friction is set for critical damping.
const STIFFNESS: f32 = 30.0;
/// Physics substeps per follower step.
const SUBSTEPS: u32 = 8;
/// Near and far planes of the follower.
const FOLLOW_NEAR: f32 = 0.25;
const FOLLOW_FAR: f32 = 30_000.0;

/// Where a follower stands relative to its subject (metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowShape {
    /// Eye height above the ground.
    pub eye_height: f32,
    /// How far behind the subject the camera walks.
    pub behind: f32,
    /// How far ahead of the subject it looks.
    pub ahead: f32,
}

/// What the rig sees after a step: eye, the point looked at and the depth planes (near and
/// far, metres) that suit the view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigView {
    /// The eye and the point it looks at.
    pub pose: Pose,
    /// Near plane distance.
    pub near: f32,
    /// Far plane distance.
    pub far: f32,
}

/// A camera that stands on the ground (see the module docs).
#[derive(Debug, Clone)]
pub struct CameraRig {
    body: CameraBody,
    /// The path of a path camera, and the time along it; `None` for a follower.
    path: Option<(CameraPath, f32)>,
    shape: FollowShape,
}

impl CameraRig {
    /// A follower standing at `xz` on ground of height `ground_y`, shaped by `shape`.
    pub fn follower(xz: Vec2, ground_y: f32, shape: FollowShape) -> Result<Self, PhysicsError> {
        check_finite2("follower position", xz)?;
        check_finite("follower ground height", ground_y)?;
        for (what, v) in [
            ("eye height", shape.eye_height),
            ("distance behind", shape.behind),
            ("distance ahead", shape.ahead),
        ] {
            check_finite(what, v)?;
            if v < 0.0 {
                return Err(PhysicsError::OutOfRange {
                    what,
                    value: f64::from(v),
                    expected: "at least 0 m",
                });
            }
        }
        let eye_y = ground_y + shape.eye_height;
        check_finite("follower eye height above the origin", eye_y)?;
        let mut body = CameraBody::new(Vec3::new(xz.x, eye_y, xz.y));
        body.eye_height = shape.eye_height;
        body.mass = 1.0;
        body.friction = 2.0 * STIFFNESS.sqrt();
        body.gravity_enabled = true;
        Ok(Self {
            body,
            path: None,
            shape,
        })
    }

    /// A camera on `path`, starting at its first pose (`ground` gives the terrain's height).
    pub fn on_path(path: CameraPath, ground: impl Fn(Vec2) -> f32) -> Self {
        let start = path.pose(0.0, &ground);
        let mut body = CameraBody::new(start.eye);
        body.eye_height = path.clearance();
        // Moved kinematically: no gravity or friction acts on the velocity each step sets.
        body.gravity_enabled = false;
        body.friction = 0.0;
        body.mass = 1.0;
        Self {
            body,
            path: Some((path, 0.0)),
            shape: FollowShape {
                eye_height: 0.0,
                behind: 0.0,
                ahead: 0.0,
            },
        }
    }

    /// The path of a path camera.
    pub fn path(&self) -> Option<&CameraPath> {
        self.path.as_ref().map(|(p, _)| p)
    }

    /// How far (metres, horizontally) the view must reach: a path camera's
    /// [`CameraPath::view_radius`]; `None` for a follower.
    pub fn view_radius(&self) -> Option<f32> {
        self.path.map(|(p, _)| p.view_radius())
    }

    /// Advances `dt` seconds: a follower follows the subject at `subject.0` heading along
    /// `subject.1` (a direction, of any length); a path camera moves to the path's next pose. Both stand on `ground` (the
    /// collision ground, with the bounds of pending deformations). `look_height` gives the
    /// terrain's height at a point (where the follower looks, what the flyover clears).
    pub fn step(
        &mut self,
        subject: (Vec2, Vec2),
        dt: f32,
        ground: &impl GroundQuery,
        look_height: impl Fn(Vec2) -> f32,
    ) -> Result<RigView, PhysicsError> {
        check_finite("camera time step", dt)?;
        if dt < 0.0 {
            return Err(PhysicsError::OutOfRange {
                what: "camera time step",
                value: f64::from(dt),
                expected: "at least 0 s",
            });
        }
        // The body moves on a copy, kept only when every step succeeded: a failed step leaves
        // the rig as it was.
        let mut body = self.body;
        if let Some((path, t)) = self.path.as_mut() {
            // Time within the loop (the poses repeat): an f32 that kept growing would stop
            // advancing after days of running.
            let at = (*t + dt).rem_euclid(path.period());
            let Pose { eye, look_at } = path.pose(at, &look_height);
            if dt > 0.0 {
                // The velocity that reaches the path's point in one step; the ground clamp
                // then lifts the eye if the terrain (or a deformation pending readback) is
                // closer than the clearance.
                body.velocity = (eye - body.position) / dt;
                body.step(dt, Vec3::ZERO, ground)?;
                check_eye(body.position)?;
            }
            (self.body, *t) = (body, at);
            let (near, far) = planes(path);
            let pose = Pose {
                eye: body.position,
                look_at,
            };
            return Ok(RigView { pose, near, far });
        }
        let (pos, heading) = subject;
        check_finite2("subject position", pos)?;
        check_finite2("subject heading", heading)?;
        // A direction: `behind` and `ahead` are metres whatever the heading's length (scaled
        // first so a huge or tiny heading normalises in f32).
        let heading =
            (heading / heading.abs().max_element().max(f32::MIN_POSITIVE)).normalize_or_zero();
        let target = pos - heading * self.shape.behind;
        let h = dt / SUBSTEPS as f32;
        for _ in 0..SUBSTEPS {
            let xz = Vec2::new(body.position.x, body.position.z);
            let pull = (target - xz) * STIFFNESS * body.mass;
            body.step(h, Vec3::new(pull.x, 0.0, pull.y), ground)?;
        }
        check_eye(body.position)?;
        let ahead = pos + heading * self.shape.ahead;
        let look_at = Vec3::new(ahead.x, look_height(ahead), ahead.y);
        for v in look_at.to_array() {
            check_finite("the point the follower looks at", v)?;
        }
        self.body = body;
        let pose = Pose {
            eye: self.body.position,
            look_at,
        };
        Ok(RigView {
            pose,
            near: FOLLOW_NEAR,
            far: FOLLOW_FAR,
        })
    }

    /// The eye position.
    pub fn eye(&self) -> Vec3 {
        self.body.position
    }
}

/// The body's position after a step: finite, or the step is refused (a ground clamp at an
/// absurd height can leave f32).
fn check_eye(eye: Vec3) -> Result<(), PhysicsError> {
    for v in eye.to_array() {
        check_finite("camera eye after the step", v)?;
    }
    Ok(())
}

/// Near and far planes for a path camera: the far plane past the farthest point of the map
/// (and never nearer than the follower's), the near plane a ten-thousandth of the subject's
/// distance (depth precision follows the ratio), at most half the clearance.
fn planes(path: &CameraPath) -> (f32, f32) {
    let d = path.subject_distance();
    let near = (d * 1e-4).clamp(FOLLOW_NEAR, path.clearance() * 0.5);
    let far = (2.0 * path.view_radius() + d).max(FOLLOW_FAR);
    (near, far)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera_path::{MapFrame, PathParams};

    use crate::HeightfieldCollider;
    use terrain_core::{CoarseMap, Grid, HeightEncoding, WrapMode};

    /// Flat ground at `h` metres (a multiple of the encoding's step), for the rig to stand on.
    fn flat(h: f32) -> HeightfieldCollider {
        let enc = HeightEncoding::spanning::<u16>(0.0, 655.35).unwrap();
        let level = (h * 100.0).round() as u16;
        let grid = Grid::new(64, 64, level).unwrap();
        let map = CoarseMap::new(grid, enc, 1.0, WrapMode::Repeat).unwrap();
        HeightfieldCollider::from_map(&map).unwrap()
    }

    const SHAPE: FollowShape = FollowShape {
        eye_height: 3.0,
        behind: 9.0,
        ahead: 12.0,
    };

    #[test]
    fn the_follower_settles_behind_its_subject_at_eye_height() {
        let mut rig = CameraRig::follower(Vec2::ZERO, 5.0, SHAPE).unwrap();
        let subject = (Vec2::new(40.0, 0.0), Vec2::X);
        let mut view = None;
        for _ in 0..300 {
            view = Some(rig.step(subject, 1.0 / 30.0, &flat(5.0), |_| 5.0).unwrap());
        }
        let view = view.unwrap();
        let xz = Vec2::new(view.pose.eye.x, view.pose.eye.z);
        assert!(xz.distance(Vec2::new(31.0, 0.0)) < 0.05, "{xz}");
        assert!((view.pose.eye.y - 8.0).abs() < 1e-3, "{}", view.pose.eye.y);
        assert_eq!(view.pose.look_at, Vec3::new(52.0, 5.0, 0.0));
        assert!(rig.view_radius().is_none() && rig.path().is_none());
    }

    #[test]
    fn a_path_camera_never_goes_below_its_clearance() {
        let frame = MapFrame {
            extent: Vec2::splat(200.0),
            low: 0.0,
            high: 10.0,
        };
        let path = CameraPath::flyover(frame, PathParams::default()).unwrap();
        let mut rig = CameraRig::on_path(path, |_| 0.0);
        // The ground rose far above what the path was told: the clamp lifts the eye.
        for _ in 0..60 {
            let view = rig.step((Vec2::ZERO, Vec2::X), 1.0 / 30.0, &flat(500.0), |_| 0.0);
            let view = view.unwrap();
            assert!(view.pose.eye.y >= 500.0 + path.clearance() - 1e-3);
            assert!(view.near > 0.0 && view.near < view.far);
        }
        assert_eq!(rig.view_radius(), Some(path.view_radius()));
    }

    #[test]
    fn a_path_camera_keeps_moving_after_any_time() {
        let frame = MapFrame {
            extent: Vec2::splat(200.0),
            low: 0.0,
            high: 10.0,
        };
        let path = CameraPath::orbit(frame, PathParams::default()).unwrap();
        let mut rig = CameraRig::on_path(path, |_| 0.0);
        let ground = flat(0.0);
        // A billion seconds in: one f32 step there is 64 s, so a clock that kept the whole
        // time would stand still.
        rig.step((Vec2::ZERO, Vec2::X), 1e9, &ground, |_| 0.0)
            .unwrap();
        let before = rig.eye();
        let after = (rig
            .step((Vec2::ZERO, Vec2::X), 1.0, &ground, |_| 0.0)
            .unwrap())
        .pose;
        assert!(
            (after.eye - before).length() > 1e-3,
            "{before} {}",
            after.eye
        );
    }

    #[test]
    fn bad_input_is_refused() {
        let bad = FollowShape {
            eye_height: -1.0,
            ..SHAPE
        };
        assert!(CameraRig::follower(Vec2::ZERO, 0.0, bad).is_err());
        assert!(CameraRig::follower(Vec2::NAN, 0.0, SHAPE).is_err());
        let mut rig = CameraRig::follower(Vec2::ZERO, 0.0, SHAPE).unwrap();
        let nan = (Vec2::new(f32::NAN, 0.0), Vec2::X);
        assert!(rig.step(nan, 0.1, &flat(0.0), |_| 0.0).is_err());
        let ok = (Vec2::ZERO, Vec2::X);
        assert!(rig.step(ok, f32::INFINITY, &flat(0.0), |_| 0.0).is_err());
        assert!(rig.step(ok, -0.1, &flat(0.0), |_| 0.0).is_err());
        // A subject so far that the pull leaves f32 on the way: refused, the rig unchanged.
        let eye = rig.eye();
        let far = (Vec2::splat(3.0e38), Vec2::X);
        assert!(rig.step(far, 1.0, &flat(0.0), |_| 0.0).is_err());
        assert_eq!(rig.eye(), eye);
        assert!(rig.step(ok, 0.1, &flat(0.0), |_| f32::NAN).is_err());
        assert_eq!(rig.eye(), eye);
        // A heading of any length is a direction: the distances stay the shape's metres.
        let mut unit = rig.clone();
        let huge = (Vec2::ZERO, Vec2::splat(1e38));
        let a = rig.step(huge, 0.1, &flat(0.0), |_| 0.0).unwrap();
        let b = (unit.step((Vec2::ZERO, Vec2::ONE), 0.1, &flat(0.0), |_| 0.0)).unwrap();
        assert!((a.pose.eye - b.pose.eye).length() < 1e-4, "{a:?} {b:?}");
        assert!((a.pose.look_at - b.pose.look_at).length() < 1e-4);
        let tiny = (Vec2::ZERO, Vec2::splat(1e-30));
        let c = rig.step(tiny, 0.1, &flat(0.0), |_| 0.0).unwrap();
        assert!((c.pose.look_at - b.pose.look_at).length() < 1e-4);
        let high = FollowShape {
            eye_height: 3e38,
            ..SHAPE
        };
        assert!(CameraRig::follower(Vec2::ZERO, 3e38, high).is_err());
    }
}
