//! Bodies: the camera of Flower 2010, sec. 3.2.5 (exact Euler steps, gravity switch, friction decay,
//! ground clamp) and the sphere that rests on flat ground and rolls down a slope.

mod common;

use glam::{Vec2, Vec3};
use terrain_physics::{
    CameraBody, GroundClamp, HeightfieldCollider, PhysicsError, SOLID_SPHERE_ROLLING_FACTOR,
    SphereBody,
};

fn flat_ground(height: f32) -> HeightfieldCollider {
    HeightfieldCollider::from_map(&common::flat(64, height)).expect("collider")
}

#[test]
fn camera_euler_step_is_exact_for_a_constant_force() {
    let ground = flat_ground(0.0);
    let mut cam = CameraBody::new(Vec3::new(1.0, 30.0, 2.0));
    cam.gravity_enabled = false;
    cam.friction = 0.0;
    cam.mass = 2.0;
    let force = Vec3::new(1.0, 0.5, -2.0);
    let dt = 0.125; // exact in binary
    let a = force / cam.mass;
    let p0 = cam.position;
    for n in 1..=16u32 {
        assert!(!cam.step(dt, force, &ground).expect("step"));
        // v_n = n a dt; p_n = p0 + sum_{i=1..n} v_i dt = p0 + a dt^2 n (n + 1) / 2.
        let nf = n as f32;
        let v = a * nf * dt;
        let p = p0 + a * dt * dt * nf * (nf + 1.0) * 0.5;
        assert!(
            (cam.velocity - v).length() < 1e-5,
            "step {n}: {} vs {v}",
            cam.velocity
        );
        assert!(
            (cam.position - p).length() < 1e-4,
            "step {n}: {} vs {p}",
            cam.position
        );
    }
}

#[test]
fn camera_gravity_can_be_switched_off() {
    let ground = flat_ground(0.0);
    let mut floating = CameraBody::new(Vec3::new(5.0, 20.0, 5.0));
    floating.gravity_enabled = false;
    let mut falling = floating;
    falling.gravity_enabled = true;
    falling.friction = 0.0;
    for _ in 0..10 {
        floating.step(0.01, Vec3::ZERO, &ground).expect("step");
        falling.step(0.01, Vec3::ZERO, &ground).expect("step");
    }
    assert_eq!(floating.position, Vec3::new(5.0, 20.0, 5.0));
    assert_eq!(floating.velocity, Vec3::ZERO);
    assert!((falling.velocity.y + 9.81 * 0.1).abs() < 1e-4);
    assert!(falling.position.y < 20.0 - 0.04);
}

#[test]
fn camera_friction_decays_velocity_geometrically() {
    let ground = flat_ground(0.0);
    let mut cam = CameraBody::new(Vec3::new(0.0, 10.0, 0.0));
    cam.gravity_enabled = false;
    cam.friction = 3.0;
    cam.mass = 1.5;
    cam.velocity = Vec3::new(4.0, 0.0, -2.0);
    let dt = 0.02;
    let k = 1.0 - cam.friction * dt / cam.mass;
    for n in 1..=50 {
        cam.step(dt, Vec3::ZERO, &ground).expect("step");
        let want = Vec3::new(4.0, 0.0, -2.0) * k.powi(n);
        assert!((cam.velocity - want).length() < 1e-4, "step {n}");
    }
    assert!(cam.velocity.length() < 4.5 * 0.2);
}

#[test]
fn camera_ground_clamp_offsets_to_eye_height() {
    let map = common::hills(64);
    let ground = HeightfieldCollider::from_map(&map).expect("collider");
    let at = Vec2::new(7.3, 11.1);
    let h = ground.height(at).expect("h");
    // OffsetOnly: position up to ground + eye, velocity untouched (sec. 3.2.5).
    let mut cam = CameraBody::new(Vec3::new(at.x, h - 3.0, at.y));
    cam.gravity_enabled = false;
    cam.friction = 0.0;
    cam.clamp = GroundClamp::OffsetOnly;
    cam.velocity = Vec3::new(0.0, -1.0, 0.0);
    assert!(cam.step(0.0, Vec3::ZERO, &ground).expect("step"));
    assert!((cam.position.y - (h + cam.eye_height)).abs() < 1e-4);
    assert_eq!(cam.velocity, Vec3::new(0.0, -1.0, 0.0));
    // OffsetAndStop (default) also removes the downward velocity; upward motion is kept.
    let mut stop = CameraBody::new(Vec3::new(at.x, h, at.y));
    stop.velocity = Vec3::new(0.5, -2.0, 0.0);
    stop.step(0.0, Vec3::ZERO, &ground).expect("step");
    assert_eq!(stop.velocity, Vec3::new(0.5, 0.0, 0.0));
    // With gravity on and the default clamp, a camera walking on hills never goes under.
    let mut walker = CameraBody::new(Vec3::new(1.0, 30.0, 1.0));
    for _ in 0..600 {
        walker
            .step(1.0 / 60.0, Vec3::new(3.0, 0.0, 1.0), &ground)
            .expect("step");
        let g = ground
            .height(Vec2::new(walker.position.x, walker.position.z))
            .expect("h");
        assert!(walker.position.y >= g + walker.eye_height - 1e-4);
    }
    assert!(walker.velocity.y.abs() < 20.0);
}

#[test]
fn sphere_rests_on_flat_ground_without_drifting() {
    let ground = flat_ground(10.0);
    let start = Vec3::new(7.25, 10.0 + 0.4, 3.5);
    let mut ball = SphereBody::new(start, 0.4).expect("ball");
    for _ in 0..2000 {
        ball.step(1.0 / 120.0, Vec3::ZERO, &ground).expect("step");
    }
    assert!(
        (ball.center - start).length() < 1e-5,
        "{} drifted from {start}",
        ball.center
    );
    assert!(ball.velocity.length() < 1e-5);
}

#[test]
fn sphere_dropped_lands_and_settles_on_the_surface() {
    let ground = flat_ground(10.0);
    let mut ball = SphereBody::new(Vec3::new(3.0, 14.0, 3.0), 0.5).expect("ball");
    for _ in 0..600 {
        ball.step(1.0 / 120.0, Vec3::ZERO, &ground).expect("step");
        assert!(ball.center.y >= 10.5 - 1e-4);
    }
    assert!((ball.center.y - 10.5).abs() < 2e-3, "{}", ball.center);
    assert!(ball.velocity.length() < 1e-3);
}

#[test]
fn sphere_rolls_down_a_slope_at_five_sevenths_of_g_sin_theta() {
    // A plane rising 0.25 m per metre along +X; the ball starts uphill and rolls towards -X.
    let slope = 0.25f32;
    let ground = HeightfieldCollider::from_map(&common::ramp(256, slope)).expect("collider");
    let r = 0.5;
    let x0 = 80.0;
    let theta = slope.atan();
    let n = Vec3::new(-theta.sin(), theta.cos(), 0.0);
    let surface = Vec3::new(x0, x0 * slope, 20.0);
    let mut ball = SphereBody::new(surface + n * r, r).expect("ball");
    let dt = 1.0 / 240.0;
    let steps = 480; // 2 s
    for _ in 0..steps {
        ball.step(dt, Vec3::ZERO, &ground).expect("step");
        // Stays on the plane: the centre is r from it along the normal.
        let above = (ball.center - Vec3::new(0.0, 0.0, ball.center.z)).dot(n);
        assert!((above - r).abs() < 2e-3, "left the surface: {above}");
    }
    let t = steps as f32 * dt;
    // 5/7 written out (not the constant): a solid ball's `1 / (1 + I / (m r^2))`, I = 2/5 m r^2.
    assert!((SOLID_SPHERE_ROLLING_FACTOR - 5.0 / 7.0).abs() < 1e-7);
    let a = 5.0 / 7.0 * 9.81 * theta.sin();
    let speed = ball.velocity.length();
    assert!(
        (speed - a * t).abs() < 0.02 * a * t,
        "speed {speed} vs {}",
        a * t
    );
    assert!(
        ball.velocity.x < 0.0 && ball.velocity.y < 0.0,
        "{}",
        ball.velocity
    );
    assert!(ball.velocity.z.abs() < 1e-4);
    let travelled = (surface + n * r - ball.center).length();
    assert!((travelled - 0.5 * a * t * t).abs() < 0.03 * 0.5 * a * t * t);
    // Rolling without slipping: |w| r = |v|, about the axis n x v (here +Z turning... -X motion).
    assert!((ball.angular_velocity.length() * r - speed).abs() < 1e-3 * speed.max(1.0));
    assert!(ball.angular_velocity.z > 0.0);
}

#[test]
fn bad_body_input_returns_errors() {
    let ground = flat_ground(0.0);
    let mut cam = CameraBody::new(Vec3::new(0.0, 5.0, 0.0));
    let before = cam;
    assert!(matches!(
        cam.step(f32::NAN, Vec3::ZERO, &ground),
        Err(PhysicsError::NonFinite {
            what: "time step",
            ..
        })
    ));
    assert!(matches!(
        cam.step(-0.1, Vec3::ZERO, &ground),
        Err(PhysicsError::OutOfRange {
            what: "time step",
            ..
        })
    ));
    assert!(
        cam.step(0.1, Vec3::new(f32::NAN, 0.0, 0.0), &ground)
            .is_err()
    );
    assert_eq!(cam, before);
    cam.position.x = f32::NAN;
    assert!(matches!(
        cam.step(0.1, Vec3::ZERO, &ground),
        Err(PhysicsError::NonFinite {
            what: "camera position",
            ..
        })
    ));
    let mut heavy = CameraBody::new(Vec3::ZERO);
    heavy.mass = 0.0;
    assert!(heavy.step(0.1, Vec3::ZERO, &ground).is_err());
    let mut sticky = CameraBody::new(Vec3::ZERO);
    sticky.friction = -1.0;
    assert!(sticky.step(0.1, Vec3::ZERO, &ground).is_err());

    assert!(matches!(
        SphereBody::new(Vec3::ZERO, -1.0),
        Err(PhysicsError::NegativeRadius { radius }) if radius == -1.0
    ));
    assert!(SphereBody::new(Vec3::ZERO, 0.0).is_err());
    assert!(SphereBody::new(Vec3::new(0.0, f32::INFINITY, 0.0), 1.0).is_err());
    let mut ball = SphereBody::new(Vec3::new(0.0, 3.0, 0.0), 1.0).expect("ball");
    assert!(ball.step(f32::INFINITY, Vec3::ZERO, &ground).is_err());
    ball.radius = -2.0;
    assert!(matches!(
        ball.step(0.1, Vec3::ZERO, &ground),
        Err(PhysicsError::NegativeRadius { .. })
    ));
}

/// In the air a sphere follows `F / m` (mass 2 kg here) and its orientation integrates its
/// angular velocity: a quarter turn about +Z in half a second at pi rad/s.
#[test]
fn sphere_in_the_air_integrates_force_over_mass_and_its_spin() {
    let ground = flat_ground(0.0);
    let mut ball = SphereBody::new(Vec3::new(10.0, 20.0, 10.0), 0.5).expect("ball");
    ball.gravity_enabled = false;
    ball.mass = 2.0;
    ball.angular_velocity = Vec3::new(0.0, 0.0, std::f32::consts::PI);
    for _ in 0..50 {
        ball.step(0.01, Vec3::new(4.0, 0.0, 0.0), &ground)
            .expect("step");
    }
    assert!(
        (ball.velocity - Vec3::new(1.0, 0.0, 0.0)).length() < 1e-5,
        "{}",
        ball.velocity
    );
    let x = ball.orientation * Vec3::X;
    assert!((x - Vec3::Y).length() < 1e-4, "{x}");
}
