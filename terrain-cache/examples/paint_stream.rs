//! Paints a crater's dirt into a world's material tiles and streams the paint beside the
//! heights, as an engine does: a RAM and a VRAM pool of heights, an `OverlayStream` of paint
//! with the same selection and slots, and CPU atlases standing in for the GPU's
//! (`terrain_gpu::GpuTileAtlas` and `GpuOverlayAtlas` take the same calls). It prints, frame
//! by frame, the tiles still missing and the paint the atlas shows at the crater.
//!
//! `cargo run -p terrain-cache --release --example paint_stream -- DIR [FRAMES]` (a world
//! `build_world` wrote into DIR; its paint is rewritten).

use glam::{DVec2, IVec2, UVec2, Vec2, Vec3};
use std::sync::Arc;
use std::time::Duration;
use terrain_cache::{
    CameraState, FsStore, Layer, OverlayStream, PoolConfig, RamPool, SphericalSelection, TileGrid,
    TileStore, VramConfig, VramPool, World, read_paint, write_paint,
};
use terrain_core::{
    MaterialEffect, OverlayAtlas, Rect, StampPlacement, TileAtlas, WrapMode, apply_material_effect,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir = args.next().ok_or("usage: paint_stream DIR [FRAMES]")?;
    let frames: u32 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(40);
    let store: Arc<dyn TileStore> = Arc::new(FsStore::open(&dir)?);
    let world = World::open(store)?;
    let m = *world.manifest();

    // A crater's dirt (material 1) over a 24 m disc near the camera, written into the level-0
    // tiles it touches and the coarser tiles above them.
    let centre = Vec2::splat(40.0);
    let rect = Rect::new(
        (centre / m.texel_size).as_ivec2() - IVec2::splat(32),
        UVec2::splat(64),
    );
    let mut paint = read_paint(&world, rect)?;
    let local = StampPlacement::new(Vec2::splat(32.0 * m.texel_size), Vec2::splat(24.0), -1.0)?;
    let dirt = MaterialEffect::new(1, 0.9)?;
    apply_material_effect(&mut paint, WrapMode::Clamp, m.texel_size, &local, &dirt)?;
    let written = write_paint(&world, rect, &paint)?;
    println!(
        "paint written: {} tiles over {} levels",
        written.len(),
        m.levels
    );

    // Heights and paint with one selection (RAM reaching further than VRAM) and one slot count.
    let selection = || {
        let mut s = SphericalSelection::for_grid(&TileGrid::from_manifest(&m, Layer::Height));
        s.lod0_range *= 3.0;
        s.view_distance *= 3.0;
        Box::new(s)
    };
    let tile = u64::from(m.tile_size).pow(2);
    let mut ram = RamPool::with_policy(
        world.clone(),
        PoolConfig::new(Layer::Height, 64 * tile * 2),
        selection(),
    )?;
    let slots = 40;
    let config = VramConfig::new(&m, slots);
    let mut vram = VramPool::new(config.clone())?;
    let mut heights = TileAtlas::new(m.tile_layout(), slots)?;
    let mut stream =
        OverlayStream::new(world, Layer::Material, 64 * tile * 4, selection(), config)?;
    let mut colours = OverlayAtlas::new(m.tile_layout(), slots)?;

    for frame in 0..frames {
        let camera = CameraState {
            forward: Vec3::new(1.0, -0.3, 0.4),
            ..CameraState::at(Vec3::new(centre.x - 20.0, 30.0, centre.y - 10.0))
        };
        ram.update(&camera)?;
        let h = vram.update(&camera, &ram, &mut heights)?;
        let (_, p) = stream.update(&camera, &mut colours)?;
        let at = (centre / m.texel_size).as_dvec2();
        let shown = colours.sample(DVec2::new(at.x, at.y), false);
        println!(
            "frame {frame:2}: height tiles missing {:2}, paint tiles missing {:2}, dirt at the \
             crater {:.2}",
            h.tiles_missing, p.tiles_missing, shown.y
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    stream.shutdown(Duration::from_secs(10))?;
    ram.shutdown(Duration::from_secs(10))?;
    Ok(())
}
