//! Holes (`terrain_core::holes`) in collision: rays pass through the cells cut away, spheres
//! find no contact over them, bodies fall through them and rest beside them, the mirror keeps
//! them across height updates, and parry's tiles remove the same cells.

use glam::{Vec2, Vec3};
use std::sync::Arc;
use terrain_core::{
    CoarseMap, GROUND, Grid, HeightEncoding, HoleOp, Rect, StampPlacement, WrapMode,
    apply_hole_stamp,
};
use terrain_physics::{
    CameraBody, CollisionMirror, GroundQuery, HeightField, HeightfieldCollider, PhysicsError,
    SphereBody,
};

/// Flat ground 10 m high, 64 x 64 texels of 0.5 m, and its mask with a 6 m disc cut at
/// (16, 16) m.
fn ground_with_hole() -> (CoarseMap, Arc<Grid<u8>>) {
    let enc = HeightEncoding::spanning::<u16>(0.0, 50.0).expect("range");
    let grid = Grid::new(64, 64, enc.to_raw(10.0).round() as u16).expect("grid");
    let map = CoarseMap::coarse(grid, enc, 0.5).expect("map");
    let mut mask = Grid::new(64, 64, GROUND).expect("mask");
    let disc = StampPlacement::new(Vec2::new(16.0, 16.0), Vec2::splat(6.0), -1.0).expect("disc");
    apply_hole_stamp(&mut mask, WrapMode::Repeat, 0.5, &disc, HoleOp::Cut).expect("cut");
    (map, Arc::new(mask))
}

fn collider() -> HeightfieldCollider {
    let (map, mask) = ground_with_hole();
    let field = HeightField::from_map(&map)
        .expect("field")
        .with_holes(Some(mask))
        .expect("same size");
    HeightfieldCollider::new(Arc::new(field))
}

#[test]
fn a_ray_through_a_hole_misses_and_beside_it_hits() {
    let c = collider();
    assert!(c.is_hole(Vec2::new(16.0, 16.0)).expect("finite"));
    assert!(!c.is_hole(Vec2::new(22.0, 16.0)).expect("finite"));
    // Straight down through the hole: nothing (the map is one layer of ground).
    let down = c.raycast(Vec3::new(16.0, 30.0, 16.0), Vec3::NEG_Y, 100.0);
    assert_eq!(down.expect("valid"), None);
    // Beside it: the ground, 20 m down.
    let hit = c
        .raycast(Vec3::new(22.0, 30.0, 16.0), Vec3::NEG_Y, 100.0)
        .expect("valid")
        .expect("hit");
    assert!((hit.distance - 20.0).abs() < 1e-3, "{hit:?}");
    // Slanting down through the hole, the ray goes on below the (flat) ground: nothing there.
    let slant = c.raycast(
        Vec3::new(16.0, 10.5, 16.0),
        Vec3::new(1.0, -0.2, 0.0),
        100.0,
    );
    assert_eq!(slant.expect("valid"), None);
    // Slanting down beside it, it meets the ground.
    let beside = c
        .raycast(
            Vec3::new(19.5, 10.5, 16.0),
            Vec3::new(1.0, -0.2, 0.0),
            100.0,
        )
        .expect("valid")
        .expect("hit");
    assert!((beside.point.x - 22.0).abs() < 1e-3, "{beside:?}");
    // An origin below the surface over the hole is not inside solid ground.
    let up = c.raycast(Vec3::new(16.0, 5.0, 16.0), Vec3::Y, 100.0);
    assert_eq!(up.expect("valid"), None);
    // The same origin beside the hole is.
    let inside = c
        .raycast(Vec3::new(22.0, 5.0, 16.0), Vec3::Y, 100.0)
        .expect("valid")
        .expect("solid");
    assert_eq!(inside.distance, 0.0);
}

#[test]
fn spheres_find_no_contact_over_a_hole_and_bodies_fall_through() {
    let c = collider();
    assert_eq!(
        c.sphere_contact(Vec3::new(16.0, 10.2, 16.0), 0.5)
            .expect("valid"),
        None
    );
    // Well below the surface over the hole's middle: no ground within reach, no contact.
    assert_eq!(
        c.sphere_contact(Vec3::new(16.0, 5.0, 16.0), 0.5)
            .expect("valid"),
        None
    );
    // Beside the hole the ground is there.
    let beside = c
        .sphere_contact(Vec3::new(22.0, 10.2, 16.0), 0.5)
        .expect("valid")
        .expect("contact");
    assert!((beside.depth - 0.3).abs() < 1e-4, "{beside:?}");
    // A sphere over the rim touches the rim's ground, not the hole.
    let rim = c
        .sphere_contact(Vec3::new(19.2, 10.3, 16.0), 0.5)
        .expect("valid")
        .expect("rim contact");
    assert!(rim.point.x >= 19.0 - 1e-4, "{rim:?}");

    // A ball dropped over the hole falls through; one beside it comes to rest on the ground.
    let mut falling = SphereBody::new(Vec3::new(16.0, 11.0, 16.0), 0.4).expect("ball");
    let mut resting = SphereBody::new(Vec3::new(24.0, 11.0, 16.0), 0.4).expect("ball");
    for _ in 0..120 {
        falling.step(1.0 / 60.0, Vec3::ZERO, &c).expect("step");
        resting.step(1.0 / 60.0, Vec3::ZERO, &c).expect("step");
    }
    assert!(falling.center.y < 0.0, "fell through: {}", falling.center);
    assert!(
        (resting.center.y - 10.4).abs() < 0.01,
        "rests: {}",
        resting.center
    );

    // The camera's ground over a hole is -inf: it falls too.
    assert_eq!(
        c.ground_height(Vec2::new(16.0, 16.0)).expect("valid"),
        f32::NEG_INFINITY
    );
    let mut camera = CameraBody::new(Vec3::new(16.0, 11.7, 16.0));
    for _ in 0..60 {
        camera.step(1.0 / 60.0, Vec3::ZERO, &c).expect("step");
    }
    assert!(camera.position.y < 10.0, "{}", camera.position);
    // Heights still describe the surface the hole was cut from.
    assert!((c.height(Vec2::new(16.0, 16.0)).expect("valid") - 10.0).abs() < 1e-3);
}

#[test]
fn the_mirror_keeps_holes_across_height_updates() {
    let (map, mask) = ground_with_hole();
    let mirror = CollisionMirror::from_map(&map).expect("mirror");
    let version = mirror.version();
    mirror.set_holes(Some(mask.clone())).expect("same size");
    assert_eq!(mirror.version(), version, "a hole is no height update");
    assert!(
        mirror
            .collider()
            .is_hole(Vec2::new(16.0, 16.0))
            .expect("finite")
    );
    // A height update elsewhere (and twice, through both buffers) keeps the holes.
    for v in 1..=2u16 {
        let heights = Grid::new(4, 4, 20_000 + v).expect("grid");
        mirror
            .apply_next(
                Rect::new(glam::IVec2::new(40, 40), glam::UVec2::splat(4)),
                &heights,
            )
            .expect("update");
        let c = mirror.collider();
        assert!(c.is_hole(Vec2::new(16.0, 16.0)).expect("finite"));
        assert_eq!(c.field().heights().get(41, 41), Some(20_000 + v));
    }
    // A mask of another size is refused and changes nothing; `None` fills every hole.
    let small = Arc::new(Grid::new(8, 8, 255u8).expect("grid"));
    assert!(matches!(
        mirror.set_holes(Some(small)),
        Err(PhysicsError::SizeMismatch { .. })
    ));
    assert!(
        mirror
            .collider()
            .is_hole(Vec2::new(16.0, 16.0))
            .expect("finite")
    );
    mirror.set_holes(None).expect("no holes");
    assert!(
        !mirror
            .collider()
            .is_hole(Vec2::new(16.0, 16.0))
            .expect("finite")
    );
    let field = HeightField::from_map(&map).expect("field");
    let wrong = Arc::new(Grid::new(63, 64, 0u8).expect("grid"));
    assert!(field.with_holes(Some(wrong)).is_err());
}

#[cfg(feature = "parry")]
#[test]
fn parry_tiles_remove_the_hole_cells() {
    let c = collider();
    let terrain = terrain_physics::ParryTerrain::new(c.field(), 16).expect("terrain");
    let through = terrain
        .cast_ray(Vec3::new(16.0, 30.0, 16.0), Vec3::NEG_Y, 100.0)
        .expect("valid");
    assert_eq!(through, None);
    let beside = terrain
        .cast_ray(Vec3::new(22.0, 30.0, 16.0), Vec3::NEG_Y, 100.0)
        .expect("valid")
        .expect("hit");
    assert!((beside.distance - 20.0).abs() < 1e-3);
}

#[test]
fn a_collision_window_takes_the_holes_of_its_rect() {
    // A 256 x 256 world of flat ground at 10 m, 1 m texels; a 64-texel window around (100, 70).
    let enc = HeightEncoding::spanning::<u16>(0.0, 50.0).expect("range");
    let raw = enc.to_raw(10.0).round() as u16;
    let mut window = terrain_physics::CollisionWindow::new(64, glam::UVec2::splat(256), enc, 1.0)
        .expect("window");
    let holes = Grid::new(8, 8, 255u8).expect("mask");
    assert!(window.set_holes(Some(&holes)).is_err(), "no window yet");
    window
        .recenter(Vec2::new(100.0, 70.0), |_, out| {
            out.as_mut_slice().fill(raw);
            Ok::<(), ()>(())
        })
        .expect("fill");
    let rect = window.window().expect("placed");
    // The world's mask (as read_holes gives the window's rect): a 6 m disc at (100, 70).
    let mut world = Grid::new(256, 256, GROUND).expect("mask");
    let disc = StampPlacement::new(Vec2::new(100.0, 70.0), Vec2::splat(6.0), -1.0).expect("disc");
    apply_hole_stamp(&mut world, WrapMode::Clamp, 1.0, &disc, HoleOp::Cut).expect("cut");
    let mask = world.copy_rect(rect).expect("inside");
    assert!(window.set_holes(Some(&holes)).is_err(), "another size");
    window.set_holes(Some(&mask)).expect("holes");
    let c = window.collider();
    let down = |x: f32, z: f32| {
        c.raycast(Vec3::new(x, 30.0, z), Vec3::NEG_Y, 100.0)
            .expect("ray")
    };
    assert_eq!(down(100.5, 70.5), None, "through the hole");
    assert!(down(106.5, 70.5).is_some(), "beside it");
    assert!(down(100.5, 76.5).is_some(), "beside it");
    window.set_holes(None).expect("none");
    assert!(
        window
            .collider()
            .raycast(Vec3::new(100.5, 30.0, 70.5), Vec3::NEG_Y, 100.0)
            .expect("ray")
            .is_some()
    );
}
