//! Granular trails on a streamed world with terrain-cache alone, without a GPU (a server): a
//! sledge crosses a 512^2 world of tiles (0.5 m texels, in memory) and ploughs volume-preserving
//! granular material (Persson 2019, ch. 4) in a `GranularTrails` window that follows it. Each
//! frame the window steps on the CPU and hands the changed areas back into the RAM tiles; when
//! the sledge nears its edge it is released (its volume checked against the tiles) and taken
//! again ahead. At the end the tiles are written back into the world.
//!
//! `cargo run -p terrain-cache --release --example granular_trails -- [FRAMES]`

use glam::{Affine3A, UVec2, Vec2, Vec3};
use std::sync::Arc;
use std::time::{Duration, Instant};
use terrain_cache::{
    CameraState, CpuOnly, GranularTrails, Layer, Manifest, ObjectTileStore, PoolConfig,
    ProceduralSource, RamPool, TileStore, TrailConfig, build_world,
};
use terrain_core::granular::{GranularObject, GranularParams, TriMesh};
use terrain_core::{HeightEncoding, TerrainParams, WrapMode};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let frames: u32 = std::env::args().nth(1).map_or(Ok(300), |n| n.parse())?;
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory()?);
    let base = TerrainParams {
        size: UVec2::splat(128),
        seed: 3,
        ..TerrainParams::default()
    };
    let source = ProceduralSource::new(UVec2::splat(512), &base, 2, 0.004)?;
    let encoding = HeightEncoding::spanning::<u16>(0.0, 40.0)?;
    let manifest = Manifest::new(UVec2::splat(512), 128, 0.5, encoding, WrapMode::Clamp)?;
    let (world, _) = build_world(store, manifest, &source, &|_| true)?;
    let mut pool = RamPool::new(world, PoolConfig::new(Layer::Height, 64 << 20))?;
    let config = TrailConfig::default();
    let mut trails = GranularTrails::new(&manifest, GranularParams::snow(), config)?;
    let runner = TriMesh::wheel(0.6, 0.4, 16)?;
    let (mut stepped, mut changed, started) = (0u32, 0u64, Instant::now());
    for frame in 0..frames {
        // 6 m/s at 30 frames a second, from (20, 128) m eastwards, bouncing at the far side.
        let x = 20.0 + (frame as f32 * 0.2) % 200.0;
        let sledge = Vec2::new(x, 128.0);
        let camera = CameraState::at(Vec3::new(x, 20.0, 128.0));
        pool.update(&camera)?;
        let ahead = sledge + Vec2::X * 16.0;
        let cpu = None::<&mut CpuOnly>;
        let mut trail = trails.follow(&mut pool, cpu, &[sledge], ahead, &camera, false)?;
        let Some((local, ground)) = trails.ground_at(sledge) else {
            continue;
        };
        // The runner's bottom 0.15 m under the ground the window was taken with.
        let y = ground + 0.45;
        let pose = Affine3A::from_translation(Vec3::new(local.x, y, local.y));
        let objects = [GranularObject::new(&runner, pose)];
        let cpu = None::<&mut CpuOnly>;
        trails.step(&mut pool, cpu, &objects, u64::from(frame), &mut trail)?;
        if trail.volume != trail.volume_taken {
            return Err(format!("frame {frame}: the window's volume changed").into());
        }
        stepped += 1;
        changed += trail.changed.iter().map(|(r, _)| r.area()).sum::<u64>();
    }
    trails.release(&mut pool, None::<&mut CpuOnly>)?;
    let written = pool.flush();
    pool.shutdown(Duration::from_secs(30))?;
    println!(
        "{stepped} steps in {:.0} ms on the CPU: {} windows released with their volume exact, \
         {changed} texels handed back into the tiles, {written} tiles written back",
        started.elapsed().as_secs_f64() * 1e3,
        trails.windows_released(),
    );
    Ok(())
}
