//! The CPU side of collision streaming (Flower 2010, table 4.5: a full 4096 x 4096 u16 readback
//! took 60.5 ms, 51 ms of it the system-memory copy with u16 -> f32 conversion): applying a full
//! 4096^2 region to the mirror beside converting it to f32 and a plain memcpy; a 256 x 256
//! dirty-region apply; one million height queries; a thousand raycasts and sphere contacts;
//! with `--features parry`, building parry tiles over a 2048^2 map, a one-tile update, and a
//! thousand parry raycasts.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use glam::{IVec2, UVec2, Vec2, Vec3};
use std::hint::black_box;
use std::time::Duration;
use terrain_core::{CoarseMap, Grid, HeightEncoding, Rect};
use terrain_physics::CollisionMirror;

const MAP: u32 = 4096;
const TEXEL: f32 = 0.1; // Flower 2010, sec. 3.3: 4096 texels span 409.6 m

fn encoding() -> HeightEncoding {
    HeightEncoding::spanning::<u16>(0.0, 100.0).expect("valid encoding")
}

/// Rolling hills over the whole map (periodic, so the wrap edge is smooth).
fn heights(size: u32, phase: f32) -> Grid<u16> {
    let enc = encoding();
    let tau = std::f32::consts::TAU / size as f32;
    Grid::from_fn(size, size, |x, y| {
        let (u, v) = (x as f32 * tau, y as f32 * tau);
        let h = 50.0
            + 20.0 * (u * 3.0 + phase).sin() * (v * 2.0).cos()
            + 8.0 * (u * 11.0 + v * 7.0).sin()
            + 2.0 * (u * 40.0).cos() * (v * 37.0).sin();
        enc.to_raw(h).round() as u16
    })
    .expect("grid")
}

/// A small deterministic generator for query positions.
struct Lcg(u64);

impl Lcg {
    fn next_f32(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
}

fn configure<'a>(
    c: &'a mut Criterion,
    name: &str,
) -> criterion::BenchmarkGroup<'a, criterion::measurement::WallTime> {
    let mut g = c.benchmark_group(name);
    g.sample_size(10);
    g.warm_up_time(Duration::from_millis(300));
    g.measurement_time(Duration::from_secs(2));
    g
}

fn streaming(c: &mut Criterion) {
    let enc = encoding();
    let base = heights(MAP, 0.0);
    let map = CoarseMap::coarse(base.clone(), enc, TEXEL).expect("map");
    let mirror = CollisionMirror::from_map(&map).expect("mirror");
    let full = Rect::from_size(UVec2::splat(MAP));
    let other = heights(MAP, 1.0);
    let texels = u64::from(MAP) * u64::from(MAP);

    let mut g = configure(c, "mirror");
    g.throughput(Throughput::Bytes(texels * 2));
    let updates = [&base, &other];
    let mut i = 0;
    g.bench_function(BenchmarkId::new("apply_full", MAP), |b| {
        b.iter(|| {
            i ^= 1;
            mirror
                .apply_next(full, black_box(updates[i]))
                .expect("apply")
        })
    });
    let side = 256;
    let region = Rect::new(IVec2::new(1000, 2000), UVec2::splat(side));
    let patch = heights(side, 0.5);
    g.throughput(Throughput::Bytes(u64::from(side * side) * 2));
    g.bench_function(BenchmarkId::new("apply_region", side), |b| {
        b.iter(|| {
            mirror
                .apply_next(black_box(region), black_box(&patch))
                .expect("apply")
        })
    });
    // The same region across the map's corner: four pieces.
    let corner = Rect::new(IVec2::splat(MAP as i32 - 128), UVec2::splat(side));
    g.bench_function(BenchmarkId::new("apply_region_wrapped", side), |b| {
        b.iter(|| {
            mirror
                .apply_next(black_box(corner), black_box(&patch))
                .expect("apply")
        })
    });
    g.finish();

    // For comparison: what Flower 2010 did on every update (u16 -> f32 metres), and a plain copy.
    let src = other.as_slice();
    let mut metres = vec![0.0f32; src.len()];
    let mut g = configure(c, "convert_u16_to_f32");
    g.throughput(Throughput::Bytes(texels * 2));
    g.bench_function(BenchmarkId::from_parameter(MAP), |b| {
        b.iter(|| {
            let (off, scale) = (enc.offset, enc.scale);
            for (m, &s) in metres.iter_mut().zip(black_box(src)) {
                *m = off + scale * f32::from(s);
            }
            black_box(&metres);
        })
    });
    g.finish();
    let mut copy = vec![0u16; src.len()];
    let mut g = configure(c, "memcpy");
    g.throughput(Throughput::Bytes(texels * 2));
    g.bench_function(BenchmarkId::from_parameter(MAP), |b| {
        b.iter(|| {
            copy.copy_from_slice(black_box(src));
            black_box(&copy);
        })
    });
    g.finish();
}

fn queries(c: &mut Criterion) {
    let map = CoarseMap::coarse(heights(MAP, 0.0), encoding(), TEXEL).expect("map");
    let mirror = CollisionMirror::from_map(&map).expect("mirror");
    let collider = mirror.collider();
    let extent = MAP as f32 * TEXEL;
    let mut rng = Lcg(7);
    let positions: Vec<Vec2> = (0..1_000_000)
        .map(|_| Vec2::new(rng.next_f32(), rng.next_f32()) * extent)
        .collect();
    let mut g = configure(c, "collider");
    g.throughput(Throughput::Elements(positions.len() as u64));
    g.bench_function(BenchmarkId::new("height_queries", positions.len()), |b| {
        b.iter(|| {
            let mut sum = 0.0f32;
            for &p in black_box(&positions) {
                sum += collider.height(p).expect("finite");
            }
            sum
        })
    });
    // The same number of queries in raster order over a 100 m square: what bodies moving
    // over the ground do (the random ones above mostly measure cache misses on a 32 MiB map).
    let coherent: Vec<Vec2> = (0..1000)
        .flat_map(|j| (0..1000).map(move |i| Vec2::new(i as f32, j as f32) * 0.1 + 150.0))
        .collect();
    g.bench_function(
        BenchmarkId::new("height_queries_coherent", coherent.len()),
        |b| {
            b.iter(|| {
                let mut sum = 0.0f32;
                for &p in black_box(&coherent) {
                    sum += collider.height(p).expect("finite");
                }
                sum
            })
        },
    );
    // Rays from 2 m above the ground, 5 to 30 degrees down, up to 200 m.
    let rays: Vec<(Vec3, Vec3)> = (0..1000)
        .map(|_| {
            let p = Vec2::new(rng.next_f32(), rng.next_f32()) * extent;
            let o = Vec3::new(p.x, collider.height(p).expect("finite") + 2.0, p.y);
            let yaw = rng.next_f32() * std::f32::consts::TAU;
            let pitch = (5.0 + 25.0 * rng.next_f32()).to_radians();
            let d = Vec3::new(
                yaw.cos() * pitch.cos(),
                -pitch.sin(),
                yaw.sin() * pitch.cos(),
            );
            (o, d)
        })
        .collect();
    g.throughput(Throughput::Elements(rays.len() as u64));
    g.bench_function(BenchmarkId::new("raycast", rays.len()), |b| {
        b.iter(|| {
            let mut hits = 0;
            for &(o, d) in black_box(&rays) {
                hits += usize::from(collider.raycast(o, d, 200.0).expect("valid").is_some());
            }
            hits
        })
    });
    let spheres: Vec<Vec3> = (0..1000)
        .map(|_| {
            let p = Vec2::new(rng.next_f32(), rng.next_f32()) * extent;
            Vec3::new(p.x, collider.height(p).expect("finite") + 0.3, p.y)
        })
        .collect();
    g.bench_function(
        BenchmarkId::new("sphere_contact_r0.5", spheres.len()),
        |b| {
            b.iter(|| {
                let mut n = 0;
                for &s in black_box(&spheres) {
                    n += usize::from(collider.sphere_contact(s, 0.5).expect("valid").is_some());
                }
                n
            })
        },
    );
    g.finish();
}

/// The `parry` feature: building 64-texel parry tiles over a 2048 x 2048 map from scratch,
/// against rebuilding the one tile a small deformation touched, and a thousand parry raycasts.
#[cfg(feature = "parry")]
fn parry_tiles(c: &mut Criterion) {
    use terrain_physics::ParryTerrain;
    const SIDE: u32 = 2048;
    let map = CoarseMap::coarse(heights(SIDE, 0.0), encoding(), TEXEL).expect("map");
    let mirror = CollisionMirror::from_map(&map).expect("mirror");
    let snapshot = mirror.snapshot();
    let mut g = configure(c, "parry");
    g.bench_function(BenchmarkId::new("full_build_64", SIDE), |b| {
        b.iter(|| ParryTerrain::new(black_box(&snapshot), 64).expect("terrain"))
    });
    let mut terrain = ParryTerrain::new(&snapshot, 64).expect("terrain");
    // An 8 x 8 crater strictly inside tile (10, 10).
    let rect = Rect::new(IVec2::new(650, 650), UVec2::new(8, 8));
    g.bench_function(BenchmarkId::new("one_tile_update_64", SIDE), |b| {
        b.iter(|| {
            let rebuilt = terrain
                .update(black_box(&snapshot), &[rect])
                .expect("update");
            assert_eq!(rebuilt.len(), 1);
        })
    });
    let extent = SIDE as f32 * TEXEL;
    let mut rng = Lcg(11);
    let rays: Vec<(Vec3, Vec3)> = (0..1000)
        .map(|_| {
            let o = Vec3::new(rng.next_f32() * extent, 120.0, rng.next_f32() * extent);
            let d = Vec3::new(rng.next_f32() - 0.5, -1.0, rng.next_f32() - 0.5);
            (o, d)
        })
        .collect();
    g.throughput(Throughput::Elements(rays.len() as u64));
    g.bench_function(BenchmarkId::new("raycasts", rays.len()), |b| {
        b.iter(|| {
            let mut hits = 0;
            for &(o, d) in black_box(&rays) {
                hits += usize::from(terrain.cast_ray(o, d, 500.0).expect("cast").is_some());
            }
            hits
        })
    });
    g.finish();
}

/// The `parry` feature: sphere contacts on a real DEM against parry's `HeightField` over the
/// same heights, the same queries in the same process. The DEM is the USGS elevation of the
/// Jacksboro fault, Tennessee (3 arc-seconds, 403 x 344, whole metres; matplotlib's sample
/// data, `benches/data/`), with square texels of 83 m (the geometric mean of its 74 x 93 m
/// cells). 20 000 spheres of 50 m at random places, centres 5 to 45 m above the ground under
/// them, so each touches. Parry is measured twice: the crate's `ParryTerrain` holding the
/// whole map in one `HeightField` (input checks and wrapping as the collider has them), and
/// parry's own `query::contact` on that shape alone.
#[cfg(feature = "parry")]
fn parry_dem_contacts(c: &mut Criterion) {
    use terrain_core::io::{ReadLimits, read_png16};
    use terrain_physics::ParryTerrain;
    use terrain_physics::parry3d::math::{Pose, Vector as PVec3};
    use terrain_physics::parry3d::query;
    use terrain_physics::parry3d::shape::Ball;
    const RADIUS: f32 = 50.0;
    const SPHERES: usize = 20_000;
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/benches/data/jacksboro_fault_dem.png"
    );
    let dem = read_png16(path, &ReadLimits::default()).expect("the DEM");
    let enc = HeightEncoding::new(1.0, 0.0).expect("encoding");
    let map = CoarseMap::coarse(dem, enc, 83.0).expect("map");
    let mirror = CollisionMirror::from_map(&map).expect("mirror");
    let collider = mirror.collider();
    let snapshot = mirror.snapshot();
    // One tile over the whole map: parry's single HeightField.
    let terrain = ParryTerrain::new(&snapshot, 4096).expect("terrain");
    let (pose, shape) = terrain.shapes().next().expect("one tile");
    let extent = map.size().as_vec2() * 83.0;
    let mut rng = Lcg(23);
    let spheres: Vec<Vec3> = (0..SPHERES)
        .map(|_| {
            let p = Vec2::new(rng.next_f32(), rng.next_f32()) * extent;
            let lift = RADIUS * (0.1 + 0.8 * rng.next_f32());
            Vec3::new(p.x, collider.height(p).expect("finite") + lift, p.y)
        })
        .collect();
    let ball = Ball::new(RADIUS);
    let mut g = configure(c, "dem_sphere_contact");
    g.throughput(Throughput::Elements(SPHERES as u64));
    g.bench_function(BenchmarkId::new("collider", SPHERES), |b| {
        b.iter(|| {
            let mut n = 0;
            for &s in black_box(&spheres) {
                n += usize::from(collider.sphere_contact(s, RADIUS).expect("valid").is_some());
            }
            n
        })
    });
    g.bench_function(BenchmarkId::new("parry_terrain", SPHERES), |b| {
        b.iter(|| {
            let mut n = 0;
            for &s in black_box(&spheres) {
                n += usize::from(terrain.sphere_contact(s, RADIUS).expect("valid").is_some());
            }
            n
        })
    });
    g.bench_function(BenchmarkId::new("parry_heightfield", SPHERES), |b| {
        b.iter(|| {
            let mut n = 0;
            for &s in black_box(&spheres) {
                let at = Pose::from_translation(PVec3::new(s.x, s.y, s.z));
                let found = query::contact(&at, &ball, &pose, shape, 0.0).expect("supported");
                n += usize::from(found.is_some_and(|c| c.dist < 0.0));
            }
            n
        })
    });
    g.finish();
}

#[cfg(not(feature = "parry"))]
fn parry_tiles(_: &mut Criterion) {}

#[cfg(not(feature = "parry"))]
fn parry_dem_contacts(_: &mut Criterion) {}

criterion_group!(benches, streaming, queries, parry_tiles, parry_dem_contacts);
criterion_main!(benches);
