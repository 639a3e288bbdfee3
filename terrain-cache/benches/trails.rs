//! Granular trails on a streamed world without a GPU (what a server runs): one frame of
//! `GranularTrails` (`follow` with the window in place, and a CPU step of four wheels with the
//! changed areas handed back into the RAM tiles), and a window move (the release with its
//! volume check and the take of the next window from the tiles), on a 128^2 window (64 m at
//! 0.5 m) of a 512^2 world in RAM (granular deformation: Persson 2019, ch. 4).

use criterion::{Criterion, criterion_group, criterion_main};
use glam::{Affine3A, Quat, UVec2, Vec2, Vec3};
use std::sync::Arc;
use std::time::{Duration, Instant};
use terrain_cache::{
    CameraState, CpuOnly, GranularTrails, Layer, Manifest, ObjectTileStore, PoolConfig,
    ProceduralSource, RamPool, TileId, TileStore, TrailConfig, build_world,
};
use terrain_core::granular::{GranularObject, GranularParams, TriMesh};
use terrain_core::{HeightEncoding, TerrainParams, WrapMode};

const WORLD: u32 = 512;
const TILE: u32 = 128;
const TEXEL: f32 = 0.5;

fn pool() -> RamPool {
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().expect("store"));
    let base = TerrainParams {
        size: UVec2::splat(128),
        seed: 5,
        ..TerrainParams::default()
    };
    let source = ProceduralSource::new(UVec2::splat(WORLD), &base, 2, 0.004).expect("source");
    let enc = HeightEncoding::spanning::<u16>(0.0, 60.0).expect("encoding");
    let m = Manifest::new(UVec2::splat(WORLD), TILE, TEXEL, enc, WrapMode::Clamp).expect("m");
    let (world, _) = build_world(store, m, &source, &|_| true).expect("world");
    let mut pool = RamPool::new(world, PoolConfig::new(Layer::Height, 256 << 20)).expect("pool");
    let camera = CameraState::at(Vec3::new(128.0, 5.0, 128.0));
    let deadline = Instant::now() + Duration::from_secs(60);
    let tiles = WORLD / TILE;
    while !(0..tiles * tiles).all(|i| pool.tile(TileId::new(0, i % tiles, i / tiles)).is_some()) {
        assert!(Instant::now() < deadline, "level 0 never loaded");
        pool.update(&camera).expect("update");
        std::thread::sleep(Duration::from_millis(2));
    }
    pool
}

/// The four wheels of a truck at `centre` heading +X, on the window's ground.
fn wheels<'a>(
    trails: &GranularTrails,
    wheel: &'a TriMesh,
    centre: Vec2,
) -> Vec<GranularObject<'a>> {
    let (ground, window) = (
        trails.ground().expect("ground"),
        trails.window().expect("window"),
    );
    let corner = window.min.as_vec2() * TEXEL;
    [(2.0f32, 1.3f32), (2.0, -1.3), (-2.0, 1.3), (-2.0, -1.3)]
        .iter()
        .map(|&(along, across)| {
            let local = centre + Vec2::new(along, across) - corner;
            let y = terrain_core::bilinear(ground, local).unwrap_or(0.0) - 0.35 + 0.9;
            let pose = Affine3A::from_rotation_translation(
                Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
                Vec3::new(local.x, y, local.y),
            );
            GranularObject::new(wheel, pose)
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let mut pool = pool();
    let camera = CameraState::at(Vec3::new(128.0, 5.0, 128.0));
    let wheel = TriMesh::wheel(0.9, 0.5, 24).expect("wheel");
    let config = TrailConfig::default();
    let mut trails = GranularTrails::new(pool.world().manifest(), GranularParams::snow(), config)
        .expect("trails");
    let mut group = c.benchmark_group("granular_trails");
    group.sample_size(20);
    // A frame: the truck drives 0.5 m a frame back and forth inside one window.
    let mut x = 0.0f32;
    group.bench_function("frame_128", |b| {
        b.iter(|| {
            x = (x + 0.5) % 16.0;
            let centre = Vec2::new(120.0 + x, 128.0);
            let ahead = Vec2::new(128.0, 128.0);
            let mut frame = (trails)
                .follow(
                    &mut pool,
                    None::<&mut CpuOnly>,
                    &[centre],
                    ahead,
                    &camera,
                    false,
                )
                .expect("follow");
            let objects = wheels(&trails, &wheel, centre);
            trails
                .step(&mut pool, None::<&mut CpuOnly>, &objects, 0, &mut frame)
                .expect("step");
            frame.changed.len()
        })
    });
    // A move: release (hand-backs done, volume checked) and take the next window.
    let mut flip = false;
    group.bench_function("move_128", |b| {
        b.iter(|| {
            flip = !flip;
            let centre = Vec2::new(if flip { 200.0 } else { 128.0 }, 128.0);
            let moved = trails
                .follow(
                    &mut pool,
                    None::<&mut CpuOnly>,
                    &[centre],
                    centre,
                    &camera,
                    false,
                )
                .expect("move");
            assert_eq!(moved.move_waited, Some(false), "no move");
            moved.changed.len()
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
