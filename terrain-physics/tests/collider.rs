//! Collider queries against independent references: listing 3.2 written out literally,
//! finite differences, dense sampling along rays, and a brute-force closest-point search.

mod common;

use glam::{Vec2, Vec3};
use proptest::prelude::*;
use terrain_core::{CoarseMap, bilinear};
use terrain_physics::{HeightfieldCollider, PhysicsError};

/// Flower 2010, listing 3.2, literally (positions in texel units, inside the map).
fn listing_3_2(map: &CoarseMap, p_texels: Vec2) -> f32 {
    let n = map.size().x as i32;
    let h = |x: i32, z: i32| map.height_m(x as u32, z as u32).expect("inside the map") as f64;
    let x0 = p_texels.x as i32;
    let z0 = p_texels.y as i32;
    let fx = f64::from(p_texels.x - x0 as f32);
    let fz = f64::from(p_texels.y - z0 as f32);
    let x1 = if x0 < n - 1 { x0 + 1 } else { 0 };
    let z1 = if z0 < n - 1 { z0 + 1 } else { 0 };
    let top = (1.0 - fx) * h(x0, z0) + fx * h(x1, z0);
    let bot = (1.0 - fx) * h(x0, z1) + fx * h(x1, z1);
    ((1.0 - fz) * top + fz * bot) as f32
}

#[test]
fn height_follows_listing_3_2_including_the_wrapped_last_column_and_row() {
    let map = common::hills(32);
    let c = HeightfieldCollider::from_map(&map).expect("collider");
    let ts = map.texel_size();
    for i in 0..=400 {
        for j in [0, 7, 31 * 13, 400] {
            // Texel coordinates in [0, 32): the last column / row interpolate with texel 0.
            let p = Vec2::new(i as f32 * 0.08, j as f32 * 0.08).min(Vec2::splat(31.999));
            let want = listing_3_2(&map, p);
            let got = c.height(p * ts).expect("finite");
            assert!((got - want).abs() < 1e-4, "at texel {p}: {got} vs {want}");
            // And a whole period away (negative positions too) gives the same height.
            let shifted = c.height(p * ts - Vec2::new(16.0, -32.0)).expect("finite");
            assert!((shifted - want).abs() < 1e-3, "wrapped at {p}");
        }
    }
}

fn cell_interior(v: f32) -> f32 {
    // Keep finite differences inside one cell: fractions in [0.05, 0.95].
    v.floor() + 0.05 + 0.9 * (v - v.floor())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn normal_matches_finite_differences(x in -40.0f32..80.0, z in -40.0f32..80.0) {
        let map = common::hills(32);
        let c = HeightfieldCollider::from_map(&map).expect("collider");
        let ts = map.texel_size();
        let p = Vec2::new(cell_interior(x / ts), cell_interior(z / ts)) * ts;
        let eps = 0.01 * ts;
        let dx = (c.height(p + Vec2::X * eps).expect("h") - c.height(p - Vec2::X * eps).expect("h"))
            / (2.0 * eps);
        let dz = (c.height(p + Vec2::Y * eps).expect("h") - c.height(p - Vec2::Y * eps).expect("h"))
            / (2.0 * eps);
        let want = Vec3::new(-dx, 1.0, -dz).normalize();
        let got = c.normal(p).expect("normal");
        prop_assert!((got - want).length() < 2e-3, "{got} vs {want} at {p}");
        prop_assert!((got.length() - 1.0).abs() < 1e-5);
    }
}

/// First distance (to within `step`) at which dense samples along the ray are at or below the
/// surface, by terrain-core's own bilinear lookup.
fn brute_first_below(map: &CoarseMap, o: Vec3, d: Vec3, max_dist: f32, step: f32) -> Option<f32> {
    let n = (max_dist / step).ceil() as u32;
    (0..=n).map(|i| (i as f32 * step).min(max_dist)).find(|&t| {
        let p = o + d * t;
        p.y <= bilinear(map, Vec2::new(p.x, p.z)).expect("finite")
    })
}

fn check_ray(map: &CoarseMap, o: Vec3, dir: Vec3, max_dist: f32) -> Result<(), TestCaseError> {
    let c = HeightfieldCollider::from_map(map).expect("collider");
    let d = dir.normalize();
    let hit = c.raycast(o, dir, max_dist).expect("valid ray");
    let step = 0.002;
    let brute = brute_first_below(map, o, d, max_dist, step);
    match (hit, brute) {
        (None, None) => {}
        (None, Some(tb)) => {
            return Err(TestCaseError::fail(format!(
                "missed a crossing at {tb} ({o} {d})"
            )));
        }
        (Some(h), brute) => {
            prop_assert!(h.distance >= 0.0 && h.distance <= max_dist + 1e-4);
            prop_assert!((h.point - (o + d * h.distance)).length() < 1e-3);
            let surface = bilinear(map, Vec2::new(h.point.x, h.point.z)).expect("finite");
            if h.distance > 0.0 {
                prop_assert!(
                    (h.point.y - surface).abs() < 2e-3,
                    "hit {h:?} off the surface {surface}"
                );
            } else {
                prop_assert!(o.y <= surface + 1e-4);
            }
            // No sample before the hit is below ground (the hit is the first crossing), and
            // where sampling finds a crossing the hit is no later.
            if let Some(tb) = brute {
                prop_assert!(
                    h.distance <= tb + 1e-3,
                    "hit at {} after crossing at {tb}",
                    h.distance
                );
                prop_assert!(tb <= h.distance + step + 1e-3 || tb >= h.distance - 1e-3);
            }
            let before = brute_first_below(map, o, d, (h.distance - 2e-3).max(0.0), step);
            if h.distance > 2e-3 {
                prop_assert!(
                    before.is_none(),
                    "sampled crossing at {before:?} before hit {h:?}"
                );
            }
            prop_assert!((h.normal.length() - 1.0).abs() < 1e-4 && h.normal.y > 0.0);
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    /// Random rays, most starting within one map of the origin (the map is 16 m wide, so many
    /// cross the wrap edges), downward, level or upward, some ending before the ground.
    #[test]
    fn raycast_agrees_with_dense_sampling(
        ox in -20.0f32..36.0, oy in 4.0f32..24.0, oz in -20.0f32..36.0,
        dx in -1.0f32..1.0, dy in -1.0f32..0.3, dz in -1.0f32..1.0,
        max_dist in 0.5f32..40.0,
    ) {
        let dir = Vec3::new(dx, dy, dz);
        prop_assume!(dir.length() > 0.05);
        check_ray(&common::hills(32), Vec3::new(ox, oy, oz), dir, max_dist)?;
    }

    /// Rays starting just inside the map's last column / row heading out across the edge.
    #[test]
    fn raycast_across_the_wrap_edge_agrees_with_dense_sampling(
        ox in 14.0f32..16.0, oy in 12.0f32..20.0, oz in 0.0f32..16.0,
        dx in 0.2f32..1.0, dy in -0.6f32..-0.05, dz in -0.5f32..0.5,
    ) {
        check_ray(&common::hills(32), Vec3::new(ox, oy, oz), Vec3::new(dx, dy, dz), 30.0)?;
    }
}

#[test]
fn a_ray_that_would_hit_beyond_its_maximum_distance_misses() {
    let map = common::hills(32);
    let c = HeightfieldCollider::from_map(&map).expect("collider");
    let o = Vec3::new(3.0, 40.0, 5.0);
    let ground = c.height(Vec2::new(3.0, 5.0)).expect("h");
    let gap = 40.0 - ground;
    assert!(c.raycast(o, Vec3::NEG_Y, gap - 0.01).expect("ok").is_none());
    let hit = c
        .raycast(o, Vec3::NEG_Y, gap + 0.01)
        .expect("ok")
        .expect("hit");
    assert!((hit.distance - gap).abs() < 1e-3);
    // A shallow ray across the whole map: crosses the wrap edge, hits a hill on the far side.
    let hit = c
        .raycast(Vec3::new(15.9, 13.0, 4.0), Vec3::new(1.0, -0.05, 0.1), 40.0)
        .expect("ok")
        .expect("hit");
    assert!(hit.point.x > 16.0, "{hit:?}");
    check_ray(
        &map,
        Vec3::new(15.9, 13.0, 4.0),
        Vec3::new(1.0, -0.05, 0.1),
        40.0,
    )
    .expect("agrees with sampling");
}

/// The closest surface point by brute force over a dense grid (spacing `s`) around `c`.
fn brute_closest(map: &CoarseMap, c: Vec3, reach: f32, s: f32) -> (f32, Vec3) {
    let n = (reach / s).ceil() as i32;
    let mut best = (f32::INFINITY, Vec3::ZERO);
    for j in -n..=n {
        for i in -n..=n {
            let q = Vec2::new(c.x + i as f32 * s, c.z + j as f32 * s);
            let p = Vec3::new(q.x, bilinear(map, q).expect("finite"), q.y);
            let d = (p - c).length();
            if d < best.0 {
                best = (d, p);
            }
        }
    }
    best
}

/// The steepest texel-to-texel slope of a map (metres per metre).
fn max_slope(map: &CoarseMap) -> f32 {
    let size = map.size();
    let mut m = 0.0f32;
    for y in 0..size.y {
        for x in 0..size.x {
            let h = map.height_m(x, y).expect("inside");
            let hx = map.height_m((x + 1) % size.x, y).expect("inside");
            let hy = map.height_m(x, (y + 1) % size.y).expect("inside");
            m = m.max((hx - h).abs()).max((hy - h).abs());
        }
    }
    m / map.texel_size()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Centres from 1 m below to 1.5 m above the surface, radii 0.2 to 1.5 m, anywhere
    /// (including across the wrap edges of the 64 m map; slopes up to about 2.7).
    #[test]
    fn sphere_contact_agrees_with_brute_force_closest_point(
        x in -10.0f32..70.0, z in -10.0f32..70.0, above in -1.0f32..1.5, r in 0.2f32..1.5,
    ) {
        let map = common::hills(128);
        let c = HeightfieldCollider::from_map(&map).expect("collider");
        let h = c.height(Vec2::new(x, z)).expect("h");
        let centre = Vec3::new(x, h + above, z);
        let s = 0.5 / 48.0;
        let (bd, bp) = brute_closest(&map, centre, r.max(above.abs()) + 0.1, s);
        let below = above < 0.0;
        // The grid misses the true closest point by at most half a diagonal horizontally, and
        // by the slope times that vertically.
        let tol = s * std::f32::consts::FRAC_1_SQRT_2 * (1.0 + max_slope(&map)) + 1e-4;
        let contact = c.sphere_contact(centre, r).expect("valid sphere");
        match contact {
            None => {
                prop_assert!(!below);
                prop_assert!(bd >= r - tol, "no contact but brute distance {bd} < r {r}");
            }
            Some(k) => {
                // The distance it reports, from its depth.
                let d = if below { k.depth - r } else { r - k.depth };
                prop_assert!(d >= -1e-4);
                prop_assert!(d <= bd + 1e-4, "contact distance {d} worse than brute {bd}");
                prop_assert!(d >= bd - tol, "contact distance {d} far below brute {bd} at {bp}");
                // Its point is on the surface at that distance; the normal moves the sphere out.
                let surface = bilinear(&map, Vec2::new(k.point.x, k.point.z)).expect("finite");
                prop_assert!((k.point.y - surface).abs() < 1e-3);
                prop_assert!(((k.point - centre).length() - d).abs() < 1e-3);
                prop_assert!((k.normal.length() - 1.0).abs() < 1e-4);
                let moved = centre + k.normal * k.depth;
                prop_assert!(((moved - k.point).length() - r).abs() < 2e-3);
                if !below {
                    prop_assert!(bd < r + tol);
                }
            }
        }
    }
}

#[test]
fn bad_query_input_returns_errors() {
    let c = HeightfieldCollider::from_map(&common::hills(16)).expect("collider");
    assert!(matches!(
        c.height(Vec2::new(f32::NAN, 1.0)),
        Err(PhysicsError::NonFinite {
            what: "query position",
            ..
        })
    ));
    assert!(matches!(
        c.normal(Vec2::new(1.0, f32::NEG_INFINITY)),
        Err(PhysicsError::NonFinite { .. })
    ));
    assert!(matches!(
        c.raycast(Vec3::ONE, Vec3::ZERO, 5.0),
        Err(PhysicsError::ZeroDirection { dir }) if dir == Vec3::ZERO
    ));
    assert!(matches!(
        c.raycast(Vec3::new(0.0, f32::NAN, 0.0), Vec3::X, 5.0),
        Err(PhysicsError::NonFinite {
            what: "ray origin",
            ..
        })
    ));
    assert!(matches!(
        c.raycast(Vec3::ONE, Vec3::new(f32::INFINITY, 0.0, 0.0), 5.0),
        Err(PhysicsError::NonFinite {
            what: "ray direction",
            ..
        })
    ));
    assert!(matches!(
        c.raycast(Vec3::ONE, Vec3::X, -2.0),
        Err(PhysicsError::OutOfRange { .. })
    ));
    assert!(matches!(
        c.sphere_contact(Vec3::ONE, -1.0),
        Err(PhysicsError::NegativeRadius { radius }) if radius == -1.0
    ));
    assert!(matches!(
        c.sphere_contact(Vec3::new(f32::NAN, 0.0, 0.0), 1.0),
        Err(PhysicsError::NonFinite {
            what: "sphere centre",
            ..
        })
    ));
}
