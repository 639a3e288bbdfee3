//! A streamed world driven once per frame, as an engine drives it: a crater's dirt painted
//! into the world's material tiles, the crater stamped into its height tiles, and
//! `StreamedWorld` streaming both (a RAM and a VRAM pool of heights, the paint's stream with
//! the same selection and slots) into CPU atlases standing in for the GPU's
//! (`terrain_gpu::GpuTileAtlas` and `GpuOverlayAtlas` take the same calls). It prints, frame
//! by frame, the tiles still missing and the crater's depth and dirt as the atlases show them,
//! and at the end writes the deformed tiles back.
//!
//! `cargo run -p terrain-cache --release --example streamed_world -- DIR [FRAMES]` (a world
//! `build_world` wrote into DIR; its paint and heights are rewritten).

use glam::{IVec2, UVec2, Vec2, Vec3};
use std::sync::Arc;
use std::time::Duration;
use terrain_cache::{
    CameraState, FsStore, StreamedWorld, TileStore, World, read_paint, write_paint,
};
use terrain_core::{
    GaussianStamp, MaterialEffect, OverlayAtlas, Rect, StampPlacement, TileAtlas, TileStamp,
    WrapMode, apply_material_effect,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir = args.next().ok_or("usage: streamed_world DIR [FRAMES]")?;
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

    // The world driven once per frame as an engine drives it: its heights in a RAM pool that
    // reaches further than the VRAM pool, and the paint streamed with the same selection and
    // slots; CPU atlases stand in for the GPU's.
    let tile = u64::from(m.tile_size).pow(2);
    let slots = 40;
    let mut streamed = StreamedWorld::open(world, 64 * tile * 2)?;
    streamed.enable_gpu(slots, true, false)?;
    let mut heights = TileAtlas::new(m.tile_layout(), slots)?;
    let mut colours = OverlayAtlas::new(m.tile_layout(), slots)?;
    // The crater itself: stamped into each tile it touches once the tile is in RAM (here on
    // the CPU; with a GPU, `deform` stamps the slots and the rects come back by readback).
    let crater = StampPlacement::new(centre, Vec2::splat(24.0), -2.0)?;
    streamed.push(TileStamp::Gaussian(GaussianStamp::default()), crater)?;

    let at = (centre / m.texel_size).as_ivec2();
    for frame in 0..frames {
        let camera = CameraState {
            forward: Vec3::new(1.0, -0.3, 0.4),
            ..CameraState::at(Vec3::new(centre.x - 20.0, 30.0, centre.y - 10.0))
        };
        streamed.update(&camera)?;
        let h = streamed
            .upload(&camera, &mut heights)?
            .ok_or("no VRAM pool")?;
        let p = streamed.upload_paint(&camera, &mut colours)?;
        let p = p.ok_or("no paint stream")?;
        let stamped = streamed.deform_in_ram()?;
        let shown = colours.sample(at.as_dvec2(), false);
        println!(
            "frame {frame:2}: height tiles missing {:2}, paint tiles missing {:2}, tiles \
             stamped {}, at the crater {:.2} m and dirt {:.2}",
            h.tiles_missing,
            p.tiles_missing,
            stamped.cpu_tiles,
            heights.height_at(at),
            shown.y
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    let (written, _) = streamed.finish(Duration::from_secs(10))?;
    println!(
        "{} tiles written back, {} stamped straight into the files",
        written.written_back, written.stamped_at_finish
    );
    Ok(())
}
