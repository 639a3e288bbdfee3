//! `SphereBody`: a rigid ball that falls, rests and rolls on the ground (the demo's vehicles).

use crate::camera::{STANDARD_GRAVITY, check_dt, non_negative, positive};
use crate::collider::GroundQuery;
use crate::contact::Contact;
use crate::error::{PhysicsError, check_finite3};
use glam::{Quat, Vec3};

/// A sphere within this distance of the ground (metres) counts as resting on it.
pub const CONTACT_TOLERANCE: f32 = 1e-3;

/// For a solid ball rolling without slipping, the share of the tangential force that
/// accelerates it: `1 / (1 + I / (m r^2))` with `I = 2/5 m r^2`.
pub const SOLID_SPHERE_ROLLING_FACTOR: f32 = 5.0 / 7.0;

/// A solid ball of uniform density on the ground.
///
/// Each [`SphereBody::step`]:
/// 1. If the ball touches the ground (within [`CONTACT_TOLERANCE`]) and the applied
///    acceleration (gravity, user force, damping) presses it into the ground, the normal part
///    is cancelled by the ground and the tangential part is scaled by
///    [`SOLID_SPHERE_ROLLING_FACTOR`] (rolling without slipping). On flat ground gravity has no
///    tangential part, so a ball at rest stays exactly where it is.
/// 2. Semi-implicit Euler: `v += a dt`, `p += v dt`.
/// 3. Penetration is resolved along the contact normal and the velocity into the ground
///    removed (no bounce).
/// 4. While in contact, the angular velocity follows the rolling constraint `w = n x v / r`,
///    and the orientation integrates it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SphereBody {
    /// Centre, metres.
    pub center: Vec3,
    /// Velocity, m/s.
    pub velocity: Vec3,
    /// Angular velocity, rad/s (world axes).
    pub angular_velocity: Vec3,
    /// Orientation (for drawing the roll).
    pub orientation: Quat,
    /// Radius, metres (> 0).
    pub radius: f32,
    /// Mass, kg (> 0).
    pub mass: f32,
    /// Linear damping, N s/m (>= 0): force `-damping * velocity`.
    pub damping: f32,
    /// Whether gravity acts.
    pub gravity_enabled: bool,
    /// Gravity, m/s^2 (>= 0), along -Y.
    pub gravity: f32,
}

impl SphereBody {
    /// A ball at rest at `center` with `radius` (> 0), mass 1 kg, no damping, gravity on.
    pub fn new(center: Vec3, radius: f32) -> Result<Self, PhysicsError> {
        if radius < 0.0 {
            return Err(PhysicsError::NegativeRadius { radius });
        }
        let body = Self {
            center,
            velocity: Vec3::ZERO,
            angular_velocity: Vec3::ZERO,
            orientation: Quat::IDENTITY,
            radius,
            mass: 1.0,
            damping: 0.0,
            gravity_enabled: true,
            gravity: STANDARD_GRAVITY,
        };
        body.validate()?;
        Ok(body)
    }

    /// Checks the body's state and parameters.
    pub fn validate(&self) -> Result<(), PhysicsError> {
        check_finite3("sphere centre", self.center)?;
        check_finite3("sphere velocity", self.velocity)?;
        check_finite3("sphere angular velocity", self.angular_velocity)?;
        if self.radius < 0.0 {
            return Err(PhysicsError::NegativeRadius {
                radius: self.radius,
            });
        }
        positive("sphere radius", self.radius)?;
        positive("sphere mass", self.mass)?;
        non_negative("sphere damping", self.damping)?;
        non_negative("gravity", self.gravity)?;
        if !self.orientation.is_finite() {
            return Err(PhysicsError::NonFinite {
                what: "sphere orientation",
                value: f32::NAN,
            });
        }
        Ok(())
    }

    /// Advances the ball by `dt` seconds (>= 0) under the user `force` (newtons, through the
    /// centre) against `ground`. Returns the contact after the step, if any. On error the body
    /// is unchanged.
    pub fn step<G: GroundQuery + ?Sized>(
        &mut self,
        dt: f32,
        force: Vec3,
        ground: &G,
    ) -> Result<Option<Contact>, PhysicsError> {
        self.validate()?;
        check_dt(dt)?;
        check_finite3("sphere force", force)?;
        let r = self.radius;
        let mut accel = (force - self.damping * self.velocity) / self.mass;
        if self.gravity_enabled {
            accel.y -= self.gravity;
        }
        let resting = ground.ground_contact(self.center, r + CONTACT_TOLERANCE)?;
        if let Some(c) = resting {
            let pressing = accel.dot(c.normal);
            if pressing < 0.0 {
                let tangential = accel - pressing * c.normal;
                accel = tangential * SOLID_SPHERE_ROLLING_FACTOR;
            }
        }
        let mut velocity = self.velocity + accel * dt;
        let mut center = self.center + velocity * dt;
        check_finite3("sphere centre after the step", center)?;
        let contact = ground.ground_contact(center, r)?;
        if let Some(c) = contact {
            center += c.normal * c.depth;
            let into = velocity.dot(c.normal);
            if into < 0.0 {
                velocity -= into * c.normal;
            }
        }
        let mut angular = self.angular_velocity;
        if let Some(c) = contact.or(resting) {
            angular = c.normal.cross(velocity) / r;
        }
        let turn = Quat::from_scaled_axis(angular * dt);
        self.orientation = (turn * self.orientation).normalize();
        self.center = center;
        self.velocity = velocity;
        self.angular_velocity = angular;
        Ok(contact)
    }
}
