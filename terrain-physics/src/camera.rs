//! `CameraBody`: the camera as a Newtonian point (Flower 2010, sec. 3.2.5): user forces, switchable
//! gravity, friction proportional to velocity, Euler integration, and a ground clamp at eye
//! height.

use crate::collider::GroundQuery;
use crate::error::{PhysicsError, check_finite, check_finite3};
use glam::{Vec2, Vec3};

/// Standard gravity, m/s^2.
pub const STANDARD_GRAVITY: f32 = 9.81;

/// What the ground clamp does when the body is below eye height over the ground.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum GroundClamp {
    /// Flower 2010, sec. 3.2.5 as written: the position is offset up to the ground and "this
    /// collision response method does not alter velocity in any way". A resting camera then
    /// keeps the downward velocity gravity gives it (up to the terminal `m g / friction`), and
    /// drops at that speed when it walks off an edge.
    OffsetOnly,
    /// The position is offset up, and the velocity's downward component is removed, so a
    /// camera standing on the ground does not accumulate a fall speed (the default).
    #[default]
    OffsetAndStop,
}

/// The camera: a point at eye height over the ground, moved by forces.
///
/// Each [`CameraBody::step`] (Flower 2010, sec. 3.2.5): the force is the user force, plus gravity
/// `-mass * gravity * Y` if enabled, plus friction `-friction * velocity`; it is integrated into
/// the velocity (`v += F / m * dt`), and the new velocity into the position (`p += v * dt`:
/// forces, then velocity, then position, as the seed describes it, which is the semi-implicit
/// Euler step). Then the ground height under the new position is looked up, and if the eye is
/// below `ground + eye_height` it is offset up to it ([`GroundClamp`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraBody {
    /// Eye position, metres.
    pub position: Vec3,
    /// Velocity, m/s.
    pub velocity: Vec3,
    /// Height of the eye over the ground, metres (listing 3.2's `EYE_HEIGHT`).
    pub eye_height: f32,
    /// Mass, kg (> 0).
    pub mass: f32,
    /// Friction coefficient, N s/m (>= 0): the friction force is `-friction * velocity`.
    pub friction: f32,
    /// Whether gravity acts ("can be toggled off and on").
    pub gravity_enabled: bool,
    /// Gravity, m/s^2 (>= 0), acting along -Y.
    pub gravity: f32,
    /// The ground clamp's response.
    pub clamp: GroundClamp,
}

impl CameraBody {
    /// A camera at rest at `position`, with eye height 1.7 m, mass 1 kg (forces are then
    /// accelerations), friction 1 N s/m, gravity on at [`STANDARD_GRAVITY`].
    pub fn new(position: Vec3) -> Self {
        Self {
            position,
            velocity: Vec3::ZERO,
            eye_height: 1.7,
            mass: 1.0,
            friction: 1.0,
            gravity_enabled: true,
            gravity: STANDARD_GRAVITY,
            clamp: GroundClamp::default(),
        }
    }

    /// Checks the body's state and parameters.
    pub fn validate(&self) -> Result<(), PhysicsError> {
        check_finite3("camera position", self.position)?;
        check_finite3("camera velocity", self.velocity)?;
        check_finite("camera eye height", self.eye_height)?;
        positive("camera mass", self.mass)?;
        non_negative("camera friction", self.friction)?;
        non_negative("gravity", self.gravity)
    }

    /// Advances the body by `dt` seconds (>= 0) under the user `force` (newtons), against
    /// `ground`. Returns whether the ground clamp acted. On error the body is unchanged.
    pub fn step<G: GroundQuery + ?Sized>(
        &mut self,
        dt: f32,
        force: Vec3,
        ground: &G,
    ) -> Result<bool, PhysicsError> {
        self.validate()?;
        check_dt(dt)?;
        check_finite3("camera force", force)?;
        let mut total = force - self.friction * self.velocity;
        if self.gravity_enabled {
            total.y -= self.mass * self.gravity;
        }
        let mut velocity = self.velocity + total / self.mass * dt;
        let mut position = self.position + velocity * dt;
        check_finite3("camera position after the step", position)?;
        let floor = ground.ground_height(Vec2::new(position.x, position.z))? + self.eye_height;
        let clamped = position.y < floor;
        if clamped {
            position.y = floor;
            if self.clamp == GroundClamp::OffsetAndStop {
                velocity.y = velocity.y.max(0.0);
            }
        }
        self.position = position;
        self.velocity = velocity;
        Ok(clamped)
    }
}

/// Checks a time step: finite and not negative.
pub(crate) fn check_dt(dt: f32) -> Result<(), PhysicsError> {
    non_negative("time step", dt)
}

pub(crate) fn non_negative(what: &'static str, v: f32) -> Result<(), PhysicsError> {
    check_finite(what, v)?;
    if v < 0.0 {
        return Err(PhysicsError::OutOfRange {
            what,
            value: f64::from(v),
            expected: "at least 0",
        });
    }
    Ok(())
}

pub(crate) fn positive(what: &'static str, v: f32) -> Result<(), PhysicsError> {
    check_finite(what, v)?;
    if v <= 0.0 {
        return Err(PhysicsError::OutOfRange {
            what,
            value: f64::from(v),
            expected: "greater than 0",
        });
    }
    Ok(())
}
