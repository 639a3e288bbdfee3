//! Tests that pin the values the queries return, not only that they return something: ray hit
//! points lie on the surface and carry its normal (non-unit texel sizes, terrain below y = 0),
//! a sphere centred on a curved surface gets that surface's normal, and the small getters.
//! Each one was written against a mutant (cargo-mutants) that survived; see docs/testing.md.

use glam::{Vec2, Vec3};
use terrain_core::{Grid, HeightEncoding};
use terrain_physics::{HeightField, Ray};

fn hash(v: u32) -> u32 {
    let s = v.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let w = ((s >> ((s >> 28) + 4)) ^ s).wrapping_mul(277_803_737);
    (w >> 22) ^ w
}

/// Random in `[0, 1)` from a counter.
fn unit(k: u32) -> f32 {
    (hash(k) % 1_000_000) as f32 / 1_000_000.0
}

/// Rough ground: random heights `offset + 0.01 * (0..2000)` metres over `w x h` texels.
fn rough(w: u32, h: u32, texel: f32, offset: f32, salt: u32) -> HeightField {
    let g = Grid::from_fn(w, h, |x, y| (hash(x ^ hash(y ^ salt)) % 2_000) as u16).expect("grid");
    HeightField::new(g, HeightEncoding::new(0.01, offset).expect("enc"), texel).expect("field")
}

/// Whether `p` lies within `eps` texels of a cell edge (where the normal is discontinuous).
fn near_edge(p: Vec3, texel: f32, eps: f32) -> bool {
    let f = |v: f32| {
        let t = v / texel;
        (t - t.round()).abs() < eps
    };
    f(p.x) || f(p.z)
}

#[test]
fn ray_hits_lie_on_the_surface_with_its_normal() {
    for (k, (texel, offset)) in [(0.5f32, -30.0f32), (2.0, -5.0), (0.37, -12.5), (1.0, 3.0)]
        .into_iter()
        .enumerate()
    {
        let f = rough(32, 24, texel, offset, k as u32);
        let (lo, hi) = f.height_bounds();
        assert!(lo >= offset && hi <= offset + 20.0);
        let extent = f.extent_m();
        let mut hits = 0;
        for i in 0..60u32 {
            let s = 1000 * k as u32 + 4 * i;
            let origin = Vec3::new(
                unit(s) * extent.x,
                hi + 1.0 + 5.0 * unit(s + 1),
                unit(s + 2) * extent.y,
            );
            // Steep to shallow, in every direction.
            let a = unit(s + 3) * std::f32::consts::TAU;
            let down = 0.3 + 3.0 * unit(s + 3 + 7919);
            let dir = Vec3::new(a.cos(), -down, a.sin());
            let ray = Ray::new(origin, dir).expect("ray");
            let Some(hit) = f.cast_local_ray(&ray, 500.0).expect("bounded") else {
                continue;
            };
            hits += 1;
            let xz = Vec2::new(hit.point.x, hit.point.z);
            let ground = f.height_local(xz);
            assert!(
                (hit.point.y - ground).abs() < 2e-3,
                "texel {texel}: {hit:?} is {} m off the surface",
                hit.point.y - ground
            );
            assert!(
                (hit.point - ray.at(hit.distance)).length() < 2e-3,
                "{hit:?} is not at its distance along {ray:?}"
            );
            assert!(hit.distance > 0.0);
            if !near_edge(hit.point, texel, 1e-3) {
                let n = f.normal_local(xz);
                assert!(
                    (hit.normal - n).length() < 1e-3,
                    "texel {texel}: hit normal {} but the surface's is {n} at {xz}",
                    hit.normal
                );
            }
            assert!((hit.normal.length() - 1.0).abs() < 1e-5);
        }
        assert!(hits > 50, "texel {texel}: only {hits} hits");
        // Straight down: the distance is exactly the height above the ground.
        for i in 0..20u32 {
            let xz = Vec2::new(unit(7 * i + 1) * extent.x, unit(7 * i + 2) * extent.y);
            let origin = Vec3::new(xz.x, hi + 2.0, xz.y);
            let ray = Ray::new(origin, Vec3::NEG_Y).expect("ray");
            let hit = f
                .cast_local_ray(&ray, 100.0)
                .expect("bounded")
                .expect("hit");
            let ground = f.height_local(xz);
            assert!((hit.distance - (origin.y - ground)).abs() < 1e-3, "{hit:?}");
            assert!((hit.point.y - ground).abs() < 1e-3, "{hit:?}");
        }
    }
}

#[test]
fn ray_getters() {
    let ray = Ray::new(Vec3::new(1.0, 2.0, 3.0), Vec3::new(0.0, 3.0, 4.0)).expect("ray");
    assert_eq!(ray.origin(), Vec3::new(1.0, 2.0, 3.0));
    assert!((ray.dir() - Vec3::new(0.0, 0.6, 0.8)).length() < 1e-6);
    assert!((ray.at(10.0) - Vec3::new(1.0, 8.0, 11.0)).length() < 1e-5);
    assert!((ray.at(-5.0) - Vec3::new(1.0, -1.0, -1.0)).length() < 1e-5);
    assert_eq!(ray.at(0.0), ray.origin());
}

#[test]
fn field_extent() {
    let f = rough(32, 24, 0.5, 0.0, 1);
    assert_eq!(f.extent_m(), Vec2::new(16.0, 12.0));
    assert_eq!(f.size(), glam::UVec2::new(32, 24));
    let f = rough(5, 7, 2.5, 0.0, 1);
    assert_eq!(f.extent_m(), Vec2::new(12.5, 17.5));
}

#[test]
fn mirror_and_collider_getters() {
    let mirror = terrain_physics::CollisionMirror::new(rough(16, 12, 0.75, 0.0, 2));
    assert_eq!(mirror.texel_size(), 0.75);
    let patch = Grid::new(2, 2, 7u16).expect("grid");
    let rect = terrain_core::Rect::new(glam::IVec2::new(3, 4), glam::UVec2::new(2, 2));
    let v0 = mirror.version();
    for k in 1..=3 {
        assert_eq!(mirror.apply_next(rect, &patch).expect("apply"), v0 + k);
        assert_eq!(mirror.collider().version(), v0 + k);
    }
}

/// Only the stretch of a ray between the field's height bounds is walked: a ray from 1 km up
/// descending at 1 in 20 (tens of thousands of cells away horizontally, far beyond the walk's
/// cell limit) hits, and one climbing slowly out of the bounds misses at once, for any
/// maximum distance.
#[test]
fn only_the_stretch_between_the_height_bounds_is_walked() {
    let f = rough(32, 24, 0.5, 0.0, 3);
    let (_, hi) = f.height_bounds();
    let ray = Ray::new(Vec3::new(4.0, hi + 1000.0, 3.0), Vec3::new(1.0, -0.05, 0.3)).expect("ray");
    let hit = f
        .cast_local_ray(&ray, 1e6)
        .expect("walks only near the surface")
        .expect("hits");
    let ground = f.height_local(Vec2::new(hit.point.x, hit.point.z));
    assert!(
        (hit.point.y - ground).abs() < 1e-2,
        "{hit:?} vs ground {ground}"
    );
    let flat = HeightField::new(
        Grid::new(16, 16, 500u16).expect("grid"),
        HeightEncoding::new(0.01, 0.0).expect("enc"),
        1.0,
    )
    .expect("field");
    let climb = Ray::new(Vec3::new(3.0, 5.000_000_5, 3.0), Vec3::new(1.0, 1e-3, 0.0)).expect("ray");
    assert_eq!(flat.cast_local_ray(&climb, 1e6).expect("bounded"), None);
}

/// A sphere whose bottom dips a fraction of a micrometre below the field's highest point
/// touches it (the early exit for spheres above the field keeps its tolerance above).
#[test]
fn a_sphere_just_touching_the_highest_point_is_in_contact() {
    let mut g = Grid::new(8, 8, 0u16).expect("grid");
    *g.get_mut(4, 4).expect("texel") = 1; // 1 cm
    let f = HeightField::new(g, HeightEncoding::new(0.01, 0.0).expect("enc"), 1.0).expect("field");
    let (r, dip) = (0.001f32, 5e-7f32);
    let c = f
        .contact_local_sphere(Vec3::new(4.0, 0.01 + r - dip, 4.0), r)
        .expect("touches");
    assert!((c.depth - dip).abs() < 1e-7, "{c:?}");
    let above = Vec3::new(4.0, 0.01 + r + dip, 4.0);
    assert!(f.contact_local_sphere(above, r).is_none());
}

/// A curved field whose heights, positions and patch values are exact in binary: scale 0.25,
/// texel 0.5, raw heights 0..40.
fn dyadic_field() -> HeightField {
    let g = Grid::from_fn(16, 16, |x, y| (hash(x * 31 + y * 17 + 5) % 41) as u16).expect("grid");
    HeightField::new(g, HeightEncoding::new(0.25, 0.0).expect("enc"), 0.5).expect("field")
}

#[test]
fn sphere_centred_on_a_curved_surface_gets_its_normal() {
    let f = dyadic_field();
    let mut curved = 0;
    for i in 0..40u32 {
        // Positions at quarter texels (never on a cell edge).
        let x = (f64::from(hash(i) % 16) + 0.25 + 0.5 * f64::from(hash(i + 100) % 2)) * 0.5;
        let z = (f64::from(hash(i + 200) % 16) + 0.25 + 0.5 * f64::from(hash(i + 300) % 2)) * 0.5;
        let xz = Vec2::new(x as f32, z as f32);
        let h = f.height_local(xz);
        let n = f.normal_local(xz);
        // Is the patch curved here (the normal varies within the cell)?
        let n2 = f.normal_local(xz + Vec2::new(0.125, 0.125));
        if (n - n2).length() > 1e-3 {
            curved += 1;
        }
        // Exactly on the surface: the contact's normal is the surface's.
        let c = f
            .contact_local_sphere(Vec3::new(xz.x, h, xz.y), 0.3)
            .expect("contact");
        assert!((c.normal - n).length() < 1e-6, "{c:?} vs {n}");
        assert!((c.depth - 0.3).abs() < 1e-6, "{c:?}");
        assert!(
            (c.point - Vec3::new(xz.x, h, xz.y)).length() < 1e-6,
            "{c:?}"
        );
        // Just above it along the normal: the same normal, depth radius - 1 mm.
        let p = Vec3::new(xz.x, h, xz.y) + n * 1e-3;
        let c = f.contact_local_sphere(p, 0.3).expect("contact");
        assert!((c.normal - n).length() < 1e-3, "{c:?} vs {n}");
        assert!((c.depth - 0.299).abs() < 1e-4, "{c:?}");
        // Just below it: pushed out along the normal, depth radius + 1 mm.
        let p = Vec3::new(xz.x, h, xz.y) - n * 1e-3;
        let c = f.contact_local_sphere(p, 0.3).expect("contact");
        assert!((c.normal - n).length() < 1e-3, "{c:?} vs {n}");
        assert!((c.depth - 0.301).abs() < 1e-4, "{c:?}");
    }
    assert!(curved > 20, "only {curved} curved samples");
}

#[test]
fn ray_with_a_non_finite_or_negative_maximum_distance_misses() {
    // `cast_local_ray` answers `None` for a maximum distance the collider would refuse.
    let f = rough(16, 16, 0.5, 0.0, 3);
    let ray = Ray::new(Vec3::new(3.1, 30.0, 2.9), Vec3::NEG_Y).expect("ray");
    assert!(f.cast_local_ray(&ray, 100.0).expect("bounded").is_some());
    for bad in [f32::INFINITY, f32::NAN, -1.0] {
        assert_eq!(f.cast_local_ray(&ray, bad).expect("bounded"), None, "{bad}");
    }
}
