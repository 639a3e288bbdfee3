//! The `parry` feature: tiled parry heightfields against the crate's own bilinear surface (the
//! bound of the module docs), tile rebuilds per dirty rect, wrap, and input errors.
#![cfg(feature = "parry")]

mod common;

use glam::{IVec2, UVec2, Vec2, Vec3};
use std::sync::Arc;
use terrain_core::{CoarseMap, Grid, HeightEncoding, Rect};
use terrain_physics::{
    CollisionMirror, HeightField, MAX_PARRY_TILE_SIZE, ParryTerrain, PhysicsError, Ray, read_region,
};

/// splitmix64: a seeded, dependency-free random source.
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in `[lo, hi)`.
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        let u = (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        lo + (hi - lo) * u
    }
}

/// A rough map: independent random heights 0..8 m per texel (large twists in every cell),
/// `w x h` texels at 0.5 m.
fn rough(w: u32, h: u32, seed: u64) -> CoarseMap {
    let enc = HeightEncoding::spanning::<u16>(0.0, 20.0).expect("encoding");
    let mut rng = Rng(seed);
    let g =
        Grid::from_fn(w, h, |_, _| enc.to_raw(rng.range(0.0, 8.0)).round() as u16).expect("grid");
    CoarseMap::coarse(g, enc, 0.5).expect("map")
}

fn field(map: &CoarseMap) -> HeightField {
    HeightField::from_map(map).expect("field")
}

/// `|h00 - h10 - h01 + h11| / 4` of the cell holding world `(x, z)`, from the field's samples.
fn cell_bound(f: &HeightField, p: Vec2) -> f32 {
    let ts = f.texel_size();
    let (w, h) = (f.size().x as i64, f.size().y as i64);
    let ix = (p.x / ts).floor() as i64;
    let iz = (p.y / ts).floor() as i64;
    let m = |x: i64, z: i64| {
        let raw = f
            .heights()
            .get(x.rem_euclid(w) as u32, z.rem_euclid(h) as u32)
            .expect("inside");
        f64::from(f.encoding().to_metres(f64::from(raw)))
    };
    let d = m(ix, iz) - m(ix + 1, iz) - m(ix, iz + 1) + m(ix + 1, iz + 1);
    (d.abs() / 4.0) as f32
}

/// The field's surface moved up by `dy` metres (same samples, shifted encoding).
fn shifted(f: &HeightField, dy: f32) -> HeightField {
    let e = f.encoding();
    let enc = HeightEncoding::new(e.scale, e.offset + dy).expect("encoding");
    HeightField::new(f.heights().clone(), enc, f.texel_size()).expect("field")
}

#[test]
fn tiles_share_their_borders_and_carry_the_wrapped_texels() {
    // 10 x 7 texels in tiles of 4 cells: 3 x 2 tiles, the last ones 2 and 3 cells wide.
    let map = rough(10, 7, 1);
    let f = field(&map);
    let t = ParryTerrain::new(&f, 4).expect("terrain");
    assert_eq!(t.tile_count(), UVec2::new(3, 2));
    assert_eq!(t.tiles().len(), 6);
    let last = t.tile(UVec2::new(2, 1)).expect("tile");
    assert_eq!(last.cells(), Rect::new(IVec2::new(8, 4), UVec2::new(2, 3)));
    assert!(t.tile(UVec2::new(3, 0)).is_none());
    for tile in t.tiles() {
        let c = tile.cells();
        let hf = tile.shape();
        assert_eq!(
            (hf.ncols(), hf.nrows()),
            (c.size.x as usize, c.size.y as usize)
        );
        // Centred on its pose: its local box spans half its size each way.
        let centre = (c.min.as_vec2() + c.size.as_vec2() * 0.5) * 0.5;
        assert!((tile.translation() - Vec3::new(centre.x, 0.0, centre.y)).length() < 1e-6);
        for j in 0..=c.size.x {
            for i in 0..=c.size.y {
                let (x, z) = (
                    (c.min.x as u32 + j) % map.size().x,
                    (c.min.y as u32 + i) % map.size().y,
                );
                let want = map.height_m(x, z).expect("texel");
                let got = hf.heights()[(i as usize, j as usize)];
                assert!((got - want).abs() < 1e-5, "tile {c:?} vertex ({j}, {i})");
            }
        }
    }
}

#[test]
fn vertical_rays_agree_within_the_bound_of_their_cell() {
    for (map, tile) in [
        (rough(40, 33, 7), 8),
        (common::hills(64), 16),
        (rough(17, 17, 9), 64),
    ] {
        let f = field(&map);
        let t = ParryTerrain::new(&f, tile).expect("terrain");
        let extent = f.extent_m();
        let mut rng = Rng(42);
        let mut worst = 0.0_f32;
        for _ in 0..4000 {
            // Include positions outside the first period: the adapter wraps.
            let p = Vec2::new(
                rng.range(-extent.x, 2.0 * extent.x),
                rng.range(-extent.y, 2.0 * extent.y),
            );
            let hit = t
                .cast_ray(Vec3::new(p.x, 40.0, p.y), Vec3::NEG_Y, 100.0)
                .expect("cast")
                .expect("a vertical ray hits");
            let bilinear = f.height_local(p);
            let bound = cell_bound(&f, p);
            let diff = (hit.point.y - bilinear).abs();
            assert!(
                diff <= bound + 1e-4,
                "at {p}: parry {} bilinear {bilinear} bound {bound}",
                hit.point.y
            );
            assert!(diff <= t.max_deviation() + 1e-4);
            assert!((hit.point.x - p.x).abs() < 1e-3 && (hit.point.z - p.y).abs() < 1e-3);
            assert!(hit.normal.y > 0.0 && (hit.normal.length() - 1.0).abs() < 1e-4);
            worst = worst.max(diff);
        }
        // The bound is attained (up to sampling) on rough maps: it is not loose.
        assert!(worst <= t.max_deviation() + 1e-4);
    }
}

#[test]
fn vertical_rays_on_cell_edges_agree_exactly() {
    let map = rough(24, 24, 3);
    let f = field(&map);
    let t = ParryTerrain::new(&f, 8).expect("terrain");
    let mut rng = Rng(5);
    for i in 0..500 {
        // On a cell edge along X (z on a texel row) or along Z.
        let a = rng.range(0.0, 12.0);
        let b = (rng.range(0.0, 24.0).floor()) * 0.5;
        let p = if i % 2 == 0 {
            Vec2::new(a, b)
        } else {
            Vec2::new(b, a)
        };
        let hit = t
            .cast_ray(Vec3::new(p.x, 30.0, p.y), Vec3::NEG_Y, 100.0)
            .expect("cast")
            .expect("hit");
        assert!((hit.point.y - f.height_local(p)).abs() < 1e-3, "at {p}");
    }
}

#[test]
fn any_ray_hits_between_the_bilinear_surface_raised_and_lowered_by_the_bound() {
    for (map, tile) in [
        (rough(32, 32, 11), 8),
        (common::hills(48), 13),
        (rough(20, 20, 12), 1),
    ] {
        let f = field(&map);
        let t = ParryTerrain::new(&f, tile).expect("terrain");
        // f32 slack: heights around 10 m, distances up to ~100 m.
        let delta = t.max_deviation() + 2e-3;
        let (hi, lo) = (shifted(&f, delta), shifted(&f, -delta));
        let extent = f.extent_m();
        let mut rng = Rng(99);
        let (mut hits, mut misses) = (0, 0);
        for _ in 0..3000 {
            let o = Vec3::new(
                rng.range(-extent.x, 2.0 * extent.x),
                rng.range(25.0, 40.0),
                rng.range(-extent.y, 2.0 * extent.y),
            );
            // Anything from straight down to nearly horizontal, any heading.
            let dir = Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, -0.02),
                rng.range(-1.0, 1.0),
            );
            let max = rng.range(5.0, 150.0);
            let ray = Ray::new(o, dir).expect("ray");
            let upper = hi.cast_local_ray(&ray, max).expect("cast");
            let lower = lo.cast_local_ray(&ray, max).expect("cast");
            match t.cast_ray(o, dir, max).expect("cast") {
                Some(p) => {
                    hits += 1;
                    let u = upper.expect("the raised surface is hit no later");
                    assert!(u.distance <= p.distance + 1e-3, "{u:?} vs {p:?}");
                    if let Some(l) = lower {
                        assert!(p.distance <= l.distance + 1e-3, "{p:?} vs {l:?}");
                    }
                    // The hit point lies within the bound of the bilinear surface.
                    let b = f.height_local(Vec2::new(p.point.x, p.point.z));
                    assert!((p.point.y - b).abs() <= delta, "{p:?}: bilinear {b}");
                }
                None => {
                    misses += 1;
                    assert!(
                        lower.is_none(),
                        "parry missed, the lowered surface is hit: {o} {dir} {max} {lower:?} {upper:?}"
                    );
                }
            }
        }
        assert!(hits > 500 && misses > 100, "{hits} hits, {misses} misses");
    }
}

#[test]
fn steep_rays_agree_in_distance_within_delta_over_k() {
    let map = common::hills(64);
    let f = field(&map);
    let t = ParryTerrain::new(&f, 16).expect("terrain");
    // g: the largest height step between neighbouring texels, per metre.
    let (w, h) = (map.size().x, map.size().y);
    let mut g = 0.0_f32;
    for z in 0..h {
        for x in 0..w {
            let c = map.height_m(x, z).expect("texel");
            let r = map.height_m((x + 1) % w, z).expect("texel");
            let d = map.height_m(x, (z + 1) % h).expect("texel");
            g = g.max((r - c).abs()).max((d - c).abs());
        }
    }
    let g = g / map.texel_size();
    let delta = t.max_deviation();
    let mut rng = Rng(3);
    let mut tested = 0;
    for _ in 0..3000 {
        let o = Vec3::new(rng.range(0.0, 32.0), 30.0, rng.range(0.0, 32.0));
        let dir = Vec3::new(rng.range(-0.3, 0.3), -1.0, rng.range(-0.3, 0.3)).normalize();
        let k = -dir.y - g * (dir.x.abs() + dir.z.abs());
        if k <= 0.05 {
            continue;
        }
        tested += 1;
        let ray = Ray::new(o, dir).expect("ray");
        let b = f.cast_local_ray(&ray, 100.0).expect("cast").expect("hit");
        let p = t.cast_ray(o, dir, 100.0).expect("cast").expect("hit");
        assert!(
            (b.distance - p.distance).abs() <= delta / k + 2e-3,
            "k {k}: bilinear {} parry {} bound {}",
            b.distance,
            p.distance,
            delta / k
        );
    }
    assert!(tested > 400, "{tested}");
}

#[test]
fn rays_cross_the_wrap_seam_and_far_copies() {
    let map = rough(16, 16, 21);
    let f = field(&map);
    let t = ParryTerrain::new(&f, 8).expect("terrain");
    let period = f.extent_m(); // 8 m
    let base = Vec3::new(3.1, 20.0, 5.7);
    let dir = Vec3::new(0.9, -0.4, 0.3);
    let a = t.cast_ray(base, dir, 200.0).expect("cast").expect("hit");
    for k in [-1000.0_f32, -3.0, 1.0, 250.0] {
        let shift = Vec3::new(k * period.x, 0.0, -k * period.y);
        let b = t
            .cast_ray(base + shift, dir, 200.0)
            .expect("cast")
            .expect("hit");
        assert!((a.distance - b.distance).abs() < 2e-3, "copy {k}");
        assert!((a.point + shift - b.point).length() < 2e-2, "copy {k}");
    }
    // A shallow ray crosses several seams before it comes down.
    let shallow = Vec3::new(1.0, -0.02, 0.7);
    let p = t
        .cast_ray(Vec3::new(-1.0, 9.0, 7.9), shallow, 400.0)
        .expect("cast");
    let b = shifted(&f, t.max_deviation() + 2e-3)
        .cast_local_ray(
            &Ray::new(Vec3::new(-1.0, 9.0, 7.9), shallow).expect("ray"),
            400.0,
        )
        .expect("cast");
    if let Some(p) = p {
        assert!(b.expect("raised surface hit").distance <= p.distance + 1e-3);
    }
}

#[test]
fn a_rect_rebuilds_exactly_the_tiles_holding_its_texels() {
    let map = rough(64, 48, 4);
    let f = field(&map);
    let t = ParryTerrain::new(&f, 16).expect("terrain"); // 4 x 3 tiles
    let r = |x, y, w, h| Rect::new(IVec2::new(x, y), UVec2::new(w, h));
    let u = |x, y| UVec2::new(x, y);
    // Strictly inside tile (1, 1).
    assert_eq!(t.tiles_touched(&[r(20, 20, 5, 5)]).expect("ok"), [u(1, 1)]);
    // Texel 16 is the border shared by tiles 0 and 1 along X.
    assert_eq!(
        t.tiles_touched(&[r(16, 20, 1, 1)]).expect("ok"),
        [u(0, 1), u(1, 1)]
    );
    // Texel (32, 32): a corner of four tiles.
    assert_eq!(
        t.tiles_touched(&[r(32, 32, 1, 1)]).expect("ok"),
        [u(1, 1), u(2, 1), u(1, 2), u(2, 2)]
    );
    // Texel 0 is also the wrapped last vertex of the last tile.
    assert_eq!(
        t.tiles_touched(&[r(0, 20, 1, 1)]).expect("ok"),
        [u(0, 1), u(3, 1)]
    );
    // Texel 15 (last cell of tile 0 ends at texel 16): only tile 0.
    assert_eq!(t.tiles_touched(&[r(15, 20, 1, 1)]).expect("ok"), [u(0, 1)]);
    // A rect crossing the map's corner wraps onto all four corner tiles.
    assert_eq!(
        t.tiles_touched(&[r(62, 46, 4, 4)]).expect("ok"),
        [u(0, 0), u(3, 0), u(0, 2), u(3, 2)]
    );
    // The same rect given from the other side of the wrap.
    assert_eq!(
        t.tiles_touched(&[r(-2, -2, 4, 4)]).expect("ok"),
        t.tiles_touched(&[r(62, 46, 4, 4)]).expect("ok")
    );
    // The whole map, and nothing.
    assert_eq!(
        t.tiles_touched(&[Rect::from_size(map.size())])
            .expect("ok")
            .len(),
        12
    );
    assert!(t.tiles_touched(&[]).expect("ok").is_empty());
    // Overlapping rects count a tile once.
    assert_eq!(
        t.tiles_touched(&[r(20, 20, 2, 2), r(21, 21, 3, 3)])
            .expect("ok"),
        [u(1, 1)]
    );
}

#[test]
fn update_rebuilds_only_the_touched_tiles_and_matches_a_fresh_build() {
    let mut map = rough(64, 64, 8);
    let mirror = CollisionMirror::from_map(&map).expect("mirror");
    let mut t = ParryTerrain::new(&mirror.snapshot(), 16).expect("terrain");
    let before: Vec<_> = t.tiles().cloned().collect();
    // Raise a 3 x 3 patch across the corner of tiles (0..1, 1..2) at texel (16, 16)..
    let rect = Rect::new(IVec2::new(15, 15), UVec2::new(3, 3));
    for y in 15..18 {
        for x in 15..18 {
            *map.grid_mut().get_mut(x, y).expect("texel") = 60_000;
        }
    }
    mirror
        .apply_next(rect, &read_region(&map, rect).expect("region"))
        .expect("apply");
    let snap = mirror.snapshot();
    let rebuilt = t.update(&snap, &[rect]).expect("update");
    assert_eq!(
        rebuilt,
        [
            UVec2::new(0, 0),
            UVec2::new(1, 0),
            UVec2::new(0, 1),
            UVec2::new(1, 1)
        ]
    );
    assert_eq!(t.version(), 1);
    let fresh = ParryTerrain::new(&snap, 16).expect("fresh");
    for ((now, old), want) in t.tiles().zip(&before).zip(fresh.tiles()) {
        // Every tile equals a fresh build of the new snapshot...
        assert_eq!(now.shape().heights().data(), want.shape().heights().data());
        assert_eq!(now.max_deviation(), want.max_deviation());
        // ...and only the rebuilt ones carry the new version.
        let was_rebuilt = rebuilt.contains(&now.index());
        assert_eq!(now.version(), if was_rebuilt { 1 } else { 0 });
        if !was_rebuilt {
            assert_eq!(now.shape().heights().data(), old.shape().heights().data());
        }
    }
    assert_eq!(t.max_deviation(), fresh.max_deviation());
    // The raised texels are hit by parry now.
    let hit = t
        .cast_ray(Vec3::new(8.0, 40.0, 8.0), Vec3::NEG_Y, 100.0)
        .expect("cast")
        .expect("hit");
    assert!((hit.point.y - snap.height_local(Vec2::splat(8.0))).abs() < 1e-3);
    // No rects: nothing rebuilt, the version follows.
    assert!(t.update(&snap, &[]).expect("update").is_empty());
    t.rebuild_all(&snap).expect("rebuild");
}

#[test]
fn sphere_contact_agrees_with_the_crate_within_the_bound() {
    let map = common::hills(64);
    let f = Arc::new(field(&map));
    let t = ParryTerrain::new(&f, 16).expect("terrain");
    let collider = terrain_physics::HeightfieldCollider::new(f.clone());
    let mut rng = Rng(17);
    let mut n = 0;
    for _ in 0..300 {
        let p = Vec2::new(rng.range(-10.0, 42.0), rng.range(-10.0, 42.0));
        let ground = f.height_local(p);
        let center = Vec3::new(p.x, ground + rng.range(0.2, 0.9), p.y);
        let radius = 1.0;
        let ours = collider.sphere_contact(center, radius).expect("contact");
        let theirs = t.sphere_contact(center, radius).expect("contact");
        if let (Some(a), Some(b)) = (ours, theirs) {
            n += 1;
            // Distances to surfaces within delta of each other differ by at most delta.
            assert!(
                (a.depth - b.depth).abs() <= t.max_deviation() + 2e-3,
                "{a:?} vs {b:?}"
            );
            // (The normals need not agree: a facet and a curved patch.)
            assert!(b.normal.y > 0.0, "{b:?}");
        }
    }
    assert!(n > 250, "{n}");
    // A sphere far above touches nothing.
    assert!(
        t.sphere_contact(Vec3::new(3.0, 60.0, 3.0), 1.0)
            .expect("contact")
            .is_none()
    );
}

#[test]
fn bad_input_is_an_error_never_a_panic() {
    let map = rough(32, 32, 2);
    let f = field(&map);
    for bad in [0, MAX_PARRY_TILE_SIZE + 1, u32::MAX] {
        assert!(matches!(
            ParryTerrain::new(&f, bad),
            Err(PhysicsError::OutOfRange { .. })
        ));
    }
    // Too many tiles: 4096 x 2048 texels in tiles of 1 cell.
    let wide = HeightField::new(
        Grid::new(4096, 2048, 0u16).expect("grid"),
        f.encoding(),
        0.5,
    )
    .expect("field");
    assert!(matches!(
        ParryTerrain::new(&wide, 1),
        Err(PhysicsError::OutOfRange { .. })
    ));
    // A tile larger than the map: one tile.
    let big = ParryTerrain::new(&f, MAX_PARRY_TILE_SIZE).expect("terrain");
    assert_eq!(big.tile_count(), UVec2::ONE);
    let mut t = ParryTerrain::new(&f, 8).expect("terrain");
    let nan = Vec3::new(f32::NAN, 1.0, 0.0);
    assert!(matches!(
        t.cast_ray(nan, Vec3::NEG_Y, 1.0),
        Err(PhysicsError::NonFinite { .. })
    ));
    assert!(matches!(
        t.cast_ray(Vec3::ZERO, Vec3::ZERO, 1.0),
        Err(PhysicsError::ZeroDirection { .. })
    ));
    assert!(t.cast_ray(Vec3::ZERO, Vec3::NEG_Y, -1.0).is_err());
    assert!(t.cast_ray(Vec3::ZERO, Vec3::NEG_Y, f32::NAN).is_err());
    assert!(matches!(
        t.cast_ray(Vec3::new(0.0, 5.0, 0.0), Vec3::X, 1e9),
        Err(PhysicsError::RayTooLong { .. })
    ));
    assert!(t.sphere_contact(nan, 1.0).is_err());
    assert!(matches!(
        t.sphere_contact(Vec3::ZERO, -1.0),
        Err(PhysicsError::NegativeRadius { .. })
    ));
    assert!(t.sphere_contact(Vec3::ZERO, f32::INFINITY).is_err());
    // A sphere larger than many periods of the map.
    assert!(t.sphere_contact(Vec3::ZERO, 1000.0).is_err());
    // Rects: empty, off the map, larger than the map; nothing changes on failure.
    let r = |x, y, w, h| Rect::new(IVec2::new(x, y), UVec2::new(w, h));
    for bad in [
        r(0, 0, 0, 3),
        r(100, 0, 2, 2),
        r(0, 0, 33, 1),
        r(-40, 0, 1, 1),
    ] {
        assert!(matches!(
            t.update(&f, &[r(1, 1, 1, 1), bad]),
            Err(PhysicsError::RegionOffMap { .. })
        ));
    }
    assert_eq!(t.version(), 0);
    // Snapshots that do not fit.
    let other = field(&rough(16, 32, 2));
    assert!(matches!(
        t.update(&other, &[]),
        Err(PhysicsError::SizeMismatch { .. })
    ));
    let coarse = HeightField::new(f.heights().clone(), f.encoding(), 1.0).expect("field");
    assert!(matches!(
        t.update(&coarse, &[]),
        Err(PhysicsError::SnapshotMismatch {
            what: "texel size",
            ..
        })
    ));
    assert!(matches!(
        t.update(&shifted(&f, 1.0), &[]),
        Err(PhysicsError::SnapshotMismatch { .. })
    ));
    // An older snapshot than the one held.
    let mirror = CollisionMirror::from_map(&map).expect("mirror");
    let old = mirror.snapshot();
    let one = r(0, 0, 1, 1);
    mirror
        .apply_next(one, &read_region(&map, one).expect("region"))
        .expect("apply");
    t.update(&mirror.snapshot(), &[one]).expect("update");
    assert!(matches!(
        t.update(&old, &[]),
        Err(PhysicsError::StaleVersion { .. })
    ));
}

#[test]
fn the_scheduler_reports_the_rects_that_bring_the_tiles_up_to_date() {
    use std::time::{Duration, Instant};
    use terrain_core::{Blend, GaussianStamp, StampPlacement, apply_stamp};
    use terrain_physics::{CpuRegionSource, DeformationBound, ReadbackScheduler, SchedulerConfig};

    let map = common::hills(128);
    let enc = map.encoding();
    let mirror = CollisionMirror::from_map(&map).expect("mirror");
    let mut terrain = ParryTerrain::new(&mirror.snapshot(), 32).expect("terrain");
    let mut source = CpuRegionSource::new(map);
    let mut scheduler =
        ReadbackScheduler::for_mirror(&mirror, SchedulerConfig::default()).expect("scheduler");
    let t0 = Instant::now();
    // Two craters, one across the wrap corner.
    for at in [Vec2::new(20.0, 20.0), Vec2::new(0.5, 63.5)] {
        let placement = StampPlacement::new(at, Vec2::splat(6.0), -2.0).expect("placement");
        let dirty = apply_stamp(
            source.map_mut(),
            &mut GaussianStamp::default(),
            &placement,
            Blend::Add,
        )
        .expect("stamp");
        for rect in dirty {
            scheduler
                .note_deformation(
                    rect,
                    DeformationBound::additive(2.0, enc).expect("bound"),
                    t0,
                )
                .expect("note");
        }
    }
    let mut rects = Vec::new();
    for ms in [25, 40, 60] {
        let report = scheduler
            .update(t0 + Duration::from_millis(ms), &mut source, &mirror)
            .expect("update");
        assert_eq!(report.applied.len(), report.applied_rects.len());
        rects.extend(report.applied_rects);
    }
    assert!(!rects.is_empty());
    let snap = mirror.snapshot();
    let rebuilt = terrain.update(&snap, &rects).expect("update");
    assert!(!rebuilt.is_empty() && rebuilt.len() < 16, "{rebuilt:?}");
    // The corner crater reaches the four corner tiles.
    for corner in [
        UVec2::new(0, 0),
        UVec2::new(3, 0),
        UVec2::new(0, 3),
        UVec2::new(3, 3),
    ] {
        assert!(rebuilt.contains(&corner), "{rebuilt:?}");
    }
    let fresh = ParryTerrain::new(&snap, 32).expect("fresh");
    for (a, b) in terrain.tiles().zip(fresh.tiles()) {
        assert_eq!(a.shape().heights().data(), b.shape().heights().data());
    }
}
