//! Every public query answers in time bounded by the map, not by the input: property tests
//! over the whole finite f32 range (and NaN / infinities), far outside the map, bodies far
//! below and above the ground, huge distances and radii, tiny and huge texel sizes. Each call
//! must return (a value or an error) within [`LIMIT`]; the answers that have a meaning are
//! checked too (finite heights within the field's bounds, unit normals, hits on the surface).
//!
//! The defects these found: a horizontal ray with a huge maximum distance walked cells
//! practically forever; a sphere far below the ground visited (2 depth / texel)^2 cells;
//! huge coordinates overflowed integer cell indices (a debug panic, a release wrap).

mod common;

use glam::{Vec2, Vec3};
use proptest::prelude::*;
use std::time::{Duration, Instant};
use terrain_core::{CoarseMap, Grid, HeightEncoding};
use terrain_physics::{
    BoundedGround, CameraBody, CollisionWindow, DeformationBound, GroundQuery, HeightfieldCollider,
    PendingDeformation, SphereBody,
};

/// The longest one query may take (a 64^2 field: the worst bounded query visits at most its
/// 4 096 cells, well under a millisecond; the limit leaves room for a loaded machine).
const LIMIT: Duration = Duration::from_millis(250);

/// Times `f`; fails the case if it took longer than [`LIMIT`].
fn timed<T>(what: &str, f: impl FnOnce() -> T) -> Result<T, TestCaseError> {
    let t = Instant::now();
    let out = f();
    let took = t.elapsed();
    prop_assert!(took <= LIMIT, "{what} took {took:?}");
    Ok(out)
}

/// Any f32 bit pattern: every finite value (tiny, huge, subnormal, negative zero) with NaN and
/// the infinities among them, plus values near the map so ordinary cases are covered too.
fn any_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        3 => any::<u32>().prop_map(f32::from_bits),
        2 => -100.0f32..100.0,
        1 => prop_oneof![
            Just(f32::MAX),
            Just(f32::MIN),
            Just(f32::MIN_POSITIVE),
            Just(-0.0f32),
            Just(1e30f32),
            Just(-1e30f32),
        ],
    ]
}

fn any_vec3() -> impl Strategy<Value = Vec3> {
    (any_f32(), any_f32(), any_f32()).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

/// A 64^2 rolling field at texel size `ts` (tiny to huge).
fn field(ts: f32) -> HeightfieldCollider {
    let base = common::hills(64);
    let map = CoarseMap::coarse(base.grid().clone(), base.encoding(), ts).expect("map");
    HeightfieldCollider::from_map(&map).expect("collider")
}

fn texel_size() -> impl Strategy<Value = f32> {
    prop_oneof![Just(1e-4f32), Just(0.5f32), Just(3.0f32), Just(1e4f32)]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    #[test]
    fn height_and_normal_answer_quickly_everywhere(ts in texel_size(), x in any_f32(), z in any_f32()) {
        let c = field(ts);
        let (lo, hi) = c.field().height_bounds();
        let p = Vec2::new(x, z);
        if let Ok(h) = timed("height", || c.height(p))? {
            prop_assert!(h.is_finite() && h >= lo - 1e-3 && h <= hi + 1e-3, "height {h} at {p}");
        }
        if let Ok(n) = timed("normal", || c.normal(p))? {
            prop_assert!(n.is_finite() && (n.length() - 1.0).abs() < 1e-3 && n.y > 0.0, "normal {n}");
        }
    }

    #[test]
    fn raycasts_answer_quickly_for_any_ray_and_distance(
        ts in texel_size(),
        origin in any_vec3(),
        dir in any_vec3(),
        max_dist in any_f32(),
    ) {
        let c = field(ts);
        if let Ok(Some(hit)) = timed("raycast", || c.raycast(origin, dir, max_dist))? {
            prop_assert!(hit.distance >= 0.0 && hit.distance <= max_dist, "{hit:?}");
            prop_assert!(hit.normal.is_finite());
        }
        // Horizontal rays inside the height range never meet a wall to stop them: the walk
        // must still end.
        let (lo, hi) = c.field().height_bounds();
        let inside = Vec3::new(origin.x, 0.5 * (lo + hi), origin.z);
        let flat = Vec3::new(dir.x, 0.0, dir.z);
        timed("horizontal raycast", || c.raycast(inside, flat, f32::MAX))?.ok();
        timed("grazing raycast", || c.raycast(inside, flat + Vec3::new(0.0, -1e-30, 0.0), f32::MAX))?.ok();
    }

    #[test]
    fn sphere_contacts_answer_quickly_far_below_far_above_and_for_huge_radii(
        ts in texel_size(),
        center in any_vec3(),
        radius in any_f32(),
    ) {
        let c = field(ts);
        if let Ok(Some(contact)) = timed("sphere contact", || c.sphere_contact(center, radius))? {
            prop_assert!(contact.depth.is_finite() || radius.abs() > 1e30 || center.y.abs() > 1e30);
        }
        // Far below the ground with a small radius: the case that visited (2 depth / ts)^2 cells.
        let deep = Vec3::new(center.x, -1e30, center.z);
        timed("deep sphere", || c.sphere_contact(deep, 0.5))?.ok();
    }

    #[test]
    fn bounded_ground_and_bodies_answer_quickly(
        ts in texel_size(),
        pos in any_vec3(),
        vel in any_vec3(),
        force in any_vec3(),
        dt in any_f32(),
        radius in any_f32(),
    ) {
        let c = field(ts);
        let pending = [PendingDeformation {
            rect: terrain_core::Rect::new(glam::IVec2::new(60, -3), glam::UVec2::new(9, 9)),
            bound: DeformationBound::new(0.5, 0.25).expect("bound"),
        }];
        let ground = BoundedGround::new(&c, &pending, &[]);
        let xz = Vec2::new(pos.x, pos.z);
        timed("bounded height", || ground.ground_height(xz))?.ok();
        timed("bounded normal", || ground.ground_normal(xz))?.ok();
        timed("bounded contact", || ground.ground_contact(pos, radius))?.ok();
        timed("height interval", || ground.height_interval(xz))?.ok();
        timed("raise under", || ground.raise_under(pos, radius))?.ok();
        let mut camera = CameraBody::new(pos);
        camera.velocity = vel;
        timed("camera step", || camera.step(dt, force, &ground))?.ok();
        if let Ok(mut sphere) = SphereBody::new(pos, radius.abs().clamp(1e-3, 1e6)) {
            sphere.velocity = vel;
            timed("sphere step", || sphere.step(dt, force, &ground))?.ok();
        }
    }

    #[test]
    fn collision_window_answers_quickly_for_any_centre(x in any_f32(), z in any_f32(), qx in any_f32(), qz in any_f32()) {
        let enc = HeightEncoding::new(0.01, 0.0).expect("enc");
        let mut w = CollisionWindow::new(64, glam::UVec2::new(4096, 4096), enc, 0.5).expect("window");
        let fill = |r: terrain_core::Rect, out: &mut Grid<u16>| -> Result<(), std::convert::Infallible> {
            for (i, v) in out.as_mut_slice().iter_mut().enumerate() {
                *v = (i as i32 + r.min.x) as u16;
            }
            Ok(())
        };
        timed("window recenter", || w.recenter(Vec2::new(x, z), fill))?.ok();
        if let Ok(Some(h)) = timed("window height", || w.height(Vec2::new(qx, qz)))? {
            prop_assert!(h.is_finite());
        }
    }
}

#[test]
fn the_worst_cases_found_answer_within_the_limit() {
    let c = field(0.5);
    let (lo, hi) = c.field().height_bounds();
    let mid = 0.5 * (lo + hi);
    type Case<'a> = (&'static str, Box<dyn Fn() + 'a>);
    let cases: Vec<Case<'_>> = vec![
        (
            "horizontal ray, f32::MAX distance",
            Box::new(|| {
                c.raycast(
                    Vec3::new(1.0, mid, 1.0),
                    Vec3::new(1.0, 0.0, 0.37),
                    f32::MAX,
                )
                .ok();
            }),
        ),
        (
            "sphere 1e30 m below the ground",
            Box::new(|| {
                c.sphere_contact(Vec3::new(3.0, -1e30, 4.0), 0.5).ok();
            }),
        ),
        (
            "sphere of radius 1e30",
            Box::new(|| {
                c.sphere_contact(Vec3::new(3.0, 10.0, 4.0), 1e30).ok();
            }),
        ),
        (
            "queries at f32::MAX",
            Box::new(|| {
                c.height(Vec2::splat(f32::MAX)).ok();
                c.normal(Vec2::new(f32::MIN, f32::MAX)).ok();
                c.raycast(Vec3::splat(f32::MAX), Vec3::new(-1.0, -1.0, -1.0), f32::MAX)
                    .ok();
                c.sphere_contact(Vec3::new(f32::MIN, 0.0, f32::MAX), 2.0)
                    .ok();
            }),
        ),
    ];
    for (what, f) in cases {
        let t = Instant::now();
        f();
        let took = t.elapsed();
        assert!(took <= LIMIT, "{what} took {took:?}");
    }
    // Far from the origin, whole periods away, a query means the same as near it (where f32
    // still holds the position to a fraction of a texel).
    let period = 64.0 * 0.5;
    let near = c.height(Vec2::new(3.25, 7.5)).expect("near");
    let far = c
        .height(Vec2::new(3.25 + period * 1024.0, 7.5 - period * 512.0))
        .expect("far");
    assert!((near - far).abs() < 1e-2, "{near} vs {far}");
    let hit_near = c
        .raycast(Vec3::new(3.0, 40.0, 7.0), Vec3::new(0.2, -1.0, 0.1), 100.0)
        .expect("ray")
        .expect("hit");
    let hit_far = c
        .raycast(
            Vec3::new(3.0 + period * 4096.0, 40.0, 7.0 - period * 2048.0),
            Vec3::new(0.2, -1.0, 0.1),
            100.0,
        )
        .expect("ray")
        .expect("hit");
    assert!((hit_near.distance - hit_far.distance).abs() < 1e-3);
    assert!((hit_far.point.x - hit_near.point.x - period * 4096.0).abs() < 1e-2);
    // A sphere under the surface is in contact, pushed out to the nearest surface point (no
    // farther than straight up), near the surface or far below it.
    let p = Vec2::new(5.0, 5.0);
    let h = c.height(p).expect("h");
    let contact = c
        .sphere_contact(Vec3::new(p.x, h - 2.0, p.y), 0.5)
        .expect("ok")
        .expect("touching");
    assert!(
        contact.depth > 0.5 && contact.depth <= 2.5 + 1e-3,
        "{contact:?}"
    );
    let deep = c
        .sphere_contact(Vec3::new(p.x, h - 1e6, p.y), 0.5)
        .expect("ok")
        .expect("touching");
    assert!(deep.depth >= 1e6 - 20.0 && deep.normal.y > 0.9, "{deep:?}");
}

/// A descending ray that meets the surface only after many laps around the field is either
/// hit correctly or refused as undecided, never reported as a miss (the walk is capped).
#[test]
fn a_capped_walk_never_reports_a_false_miss() {
    let enc = HeightEncoding::new(0.01, 0.0).expect("enc");
    let mut g = Grid::new(64, 64, 0u16).expect("grid");
    *g.get_mut(40, 40).expect("texel") = 10_000; // one 100 m spike off the ray's rows
    let map = CoarseMap::coarse(g, enc, 1.0).expect("map");
    let c = HeightfieldCollider::from_map(&map).expect("collider");
    // 1 m down per km: the ray reaches the ground (0 m) after 50 km, about 780 laps.
    let r = c.raycast(Vec3::new(0.5, 50.0, 0.5), Vec3::new(1000.0, -1.0, 0.0), 1e6);
    match r {
        Ok(Some(hit)) => assert!(hit.point.y.abs() < 1e-2 && hit.distance > 4e4, "{hit:?}"),
        Ok(None) => panic!("a descending ray that reaches the ground reported a miss"),
        Err(e) => assert!(
            matches!(e, terrain_physics::PhysicsError::RayTooLong { .. }),
            "{e}"
        ),
    }
    // A short cast of the same ray is decided: no hit within 1 km.
    assert_eq!(
        c.raycast(
            Vec3::new(0.5, 50.0, 0.5),
            Vec3::new(1000.0, -1.0, 0.0),
            1000.0
        )
        .expect("decided"),
        None
    );
}

/// The walk's cap is four times around the field plus a fixed allowance: on a 64 x 64 field
/// (4 * 128 + 4096 = 4608 cells) a ray that meets the flat ground after 4400 cells, more than
/// once around plus the allowance, is answered, not refused. A 50 m spike away from the ray's
/// row keeps the field's top above the ray, so the walk starts at its origin.
#[test]
fn a_walk_of_four_laps_and_the_allowance_is_answered() {
    let enc = HeightEncoding::new(0.01, 0.0).expect("enc");
    let grid =
        Grid::from_fn(64, 64, |x, y| if (x, y) == (32, 32) { 5000u16 } else { 0 }).expect("grid");
    let map = CoarseMap::coarse(grid, enc, 1.0).expect("map");
    let c = HeightfieldCollider::from_map(&map).expect("collider");
    let hit = c
        .raycast(Vec3::new(0.5, 44.0, 0.5), Vec3::new(1.0, -0.01, 0.0), 1e4)
        .expect("within the cap")
        .expect("reaches the ground");
    assert!(
        (hit.point.x - 4400.5).abs() < 0.05 && hit.point.y.abs() < 1e-3,
        "{hit:?}"
    );
}

/// The one-period search of a sphere far below ground is exact: its depth equals the distance
/// to the nearest surface point found by brute force over several periods, for centres at
/// every fraction of a cell (the window once missed nearer copies at its edges).
#[test]
fn deep_sphere_contacts_are_exact_on_a_tiny_repeating_field() {
    let enc = HeightEncoding::new(0.01, 0.0).expect("enc");
    let g = Grid::from_fn(4, 4, |x, y| ((x * 7 + y * 3) % 5 * 40) as u16).expect("grid");
    let map = CoarseMap::coarse(g, enc, 1.0).expect("map");
    let c = HeightfieldCollider::from_map(&map).expect("collider");
    for (fx, fz) in [(0.1, 0.2), (0.9, 0.5), (0.5, 0.95), (0.99, 0.01)] {
        let centre = Vec3::new(1.0 + fx, -3.0, 2.0 + fz);
        let contact = c
            .sphere_contact(centre, 0.25)
            .expect("ok")
            .expect("below ground: in contact");
        // Brute force: the surface sampled finely over three periods each way.
        let mut best = f32::MAX;
        let steps = 240;
        for i in 0..=steps {
            for j in 0..=steps {
                let p = Vec2::new(
                    -4.0 + 12.0 * i as f32 / steps as f32,
                    -4.0 + 12.0 * j as f32 / steps as f32,
                );
                let h = c.height(p).expect("h");
                best = best.min(Vec3::new(p.x, h, p.y).distance(centre));
            }
        }
        let dist = contact.depth - 0.25;
        assert!(
            dist <= best + 1e-3,
            "centre {centre}: {dist} vs brute force {best}"
        );
        assert!(
            dist >= best - 0.06,
            "centre {centre}: {dist} vs brute force {best}"
        );
    }
}
