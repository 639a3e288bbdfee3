//! Footprints on a streamed world with the library crates alone (Flower 2010, sec. 2.3-2.4, over
//! Fikkan 2013's tile cache): a walker crosses a world of tiles and presses a footprint into
//! its detail layer every stride. terrain-cache's `DetailCache` holds the band regions of
//! tiles around the camera (read and written back on its threads), terrain-gpu stamps the
//! footprints into its detail slots and brings the stamped rects back to the cache without a
//! wait (`GpuDetailStream`), and the clipmap draws the world's atlas with the detail layer
//! (`ClipmapSurface::AtlasDetail`). At the end the last rects land, the cache writes the
//! deformed tiles into the world, and the tiles still in RAM are checked against the same
//! footprints stamped on the CPU (`DetailLayer`).
//!
//! ```sh
//! cargo run --release -p terrain-demo --example world_footprints -- [OUT_DIR] [FRAMES]
//! ```

use anyhow::{Context, Result, ensure};
use glam::{UVec2, Vec2, Vec3};
use std::sync::Arc;
use std::time::Duration;
use terrain_cache::detail::{DetailCache, detail_manifest_layout};
use terrain_cache::{
    BandSelection, Layer, Manifest, ObjectTileStore, ProceduralSource, TileId, TileStore,
    build_world,
};
use terrain_core::detail::{DetailLayer, DetailLayout};
use terrain_core::{
    Blend, GaussianStamp, HeightEncoding, StampPlacement, TerrainParams, TileUploadTarget, WrapMode,
};
use terrain_gpu::{
    AtlasConfig, Camera, ClipmapRenderer, ClipmapSurface, ClipmapView, DetailShading, GpuContext,
    GpuDetailStream, GpuStamp, GpuTileAtlas, OffscreenTarget, SkyColors, SkyPass, TargetFormat,
    TerrainStyle,
};
use terrain_lod::{ClipmapLayout, Frustum};

const WORLD: u32 = 512;
const TILE: u32 = 128;
const TEXEL: f32 = 0.5;
/// Detail texels per world texel, and the detail tiles' side (16 m).
const REFINE: u32 = 8;
const DETAIL_TILE: u32 = 256;
const FRAME: UVec2 = UVec2::new(480, 270);
const STRIDE_M: f32 = 0.7;

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let out = std::path::PathBuf::from(args.next().unwrap_or("target/world_footprints".into()));
    let frames: u32 = args.next().map_or(Ok(40), |a| a.parse())?;
    std::fs::create_dir_all(&out)?;
    let ctx =
        GpuContext::new_headless().context("a GPU adapter (lavapipe: mesa-vulkan-drivers)")?;
    let (device, queue) = (&ctx.device, &ctx.queue);

    // A world of 4 x 4 tiles in memory, with a detail layer over its level 0.
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory()?);
    let base = TerrainParams {
        size: UVec2::splat(256),
        seed: 5,
        ..TerrainParams::default()
    };
    let source = ProceduralSource::new(UVec2::splat(WORLD), &base, 2, 0.004)?;
    let encoding = HeightEncoding::spanning::<u16>(0.0, 40.0)?;
    let mut manifest = Manifest::new(UVec2::splat(WORLD), TILE, TEXEL, encoding, WrapMode::Clamp)?;
    let layout = DetailLayout::new(manifest.world_size, TEXEL, REFINE, DETAIL_TILE)?;
    manifest.detail = Some(detail_manifest_layout(&layout)?);
    let (world, _) = build_world(store.clone(), manifest, &source, &|_| true)?;

    // The world is small: every level-0 tile in the atlas (engine_frame streams them instead).
    let tiles_across = WORLD / TILE;
    let config = AtlasConfig {
        slots: tiles_across * tiles_across,
        world: manifest.tile_layout(),
    };
    let mut atlas = GpuTileAtlas::new(device, queue, &config)?;
    // Their heights stay on the CPU too, for the camera's height above the walk.
    let mut level0 = Vec::new();
    for slot in 0..config.slots {
        let t = UVec2::new(slot % tiles_across, slot / tiles_across);
        let data = world.load_tile(Layer::Height, TileId::new(0, t.x, t.y))?;
        let heights = data.as_u16().context("height tiles hold u16")?;
        atlas.upload(slot, 0, t, heights)?;
        atlas.map(0, t, Some(slot))?;
        level0.push(heights.clone());
    }
    let ground = |xz: Vec2| {
        let texel = (xz / TEXEL).as_uvec2().min(UVec2::splat(WORLD - 1));
        let tile = &level0[((texel.y / TILE) * tiles_across + texel.x / TILE) as usize];
        let stored = tile.get(texel.x % TILE, texel.y % TILE).unwrap_or(0);
        encoding.to_metres(f64::from(stored))
    };

    let mut cache = DetailCache::open(world, layout, BandSelection::default(), 9 << 16)?;
    let mut detail = GpuDetailStream::new(device, layout, 13, 16)?;
    let shading = DetailShading {
        fade_start_m: 8.0,
        fade_end_m: 12.0,
        ..DetailShading::default()
    };
    let mut cpu = DetailLayer::new(layout)?;
    let mut foot = GaussianStamp::default();

    let layout3d = ClipmapLayout::new(127, 5)?;
    let mut renderer = ClipmapRenderer::new(device, &TargetFormat::CAPTURE, &layout3d)?;
    let sky = SkyPass::new(device, &TargetFormat::CAPTURE)?;
    let target = OffscreenTarget::new(device, FRAME)?;
    let style = TerrainStyle {
        ramp: (0.0, 40.0),
        ..TerrainStyle::default()
    };
    let heading = Vec2::new(1.0, 0.35).normalize();
    let start = Vec2::splat(60.0);
    let aspect = FRAME.x as f32 / FRAME.y as f32;
    let (mut arrived, mut read_now) = (0, 0);

    for frame in 0..frames {
        // One footprint a frame, left and right in turn; the camera a few metres behind.
        let walked = start + heading * (STRIDE_M * frame as f32);
        let side = if frame % 2 == 0 { 0.15 } else { -0.15 };
        let rotation = heading.y.atan2(heading.x) - std::f32::consts::FRAC_PI_2;
        let p = StampPlacement::new(walked + heading.perp() * side, Vec2::new(0.22, 0.45), -0.1)?
            .with_rotation(rotation)?;
        let behind = walked - heading * 2.0;
        let eye = Vec3::new(behind.x, ground(behind) + 2.5, behind.y);
        let camera = Camera::looking(eye, Vec3::new(heading.x, -1.6, heading.y));

        // The band around the camera, plus the tiles this footprint and the rects still on
        // their way back need; the GPU's slots follow the cache.
        let keep = detail.tiles_in_flight();
        let band = cache.update_for_stamps(Vec2::new(eye.x, eye.z), &[p], &keep, 0.0)?;
        ensure!(band.failed.is_empty(), "a detail tile could not be read");
        read_now += band.read_now;
        let load = band.load.iter().map(|&t| (t, cache.tile(t)));
        detail.follow(queue, &band.unload, load)?;

        // The footprint on the GPU (the truth), its rects requested back after it; the CPU
        // reference stamps the same footprint for the check at the end.
        cpu.apply_stamp(&mut foot, &p, Blend::Add)?;
        let mut encoder = device.create_command_encoder(&Default::default());
        detail.encode_stamps(device, queue, &mut encoder, GpuStamp::Gaussian(&foot), &[p])?;

        let frustum = Frustum::from_view_proj(camera.view_proj_world(aspect));
        let placed = layout3d.place(Vec2::new(eye.x, eye.z), TEXEL, (0.0, 40.0), Some(&frustum))?;
        sky.prepare(
            queue,
            camera.view_proj_relative(aspect),
            &SkyColors::default(),
        )?;
        let surface = ClipmapSurface::AtlasDetail {
            atlas: &atlas,
            detail: detail.tiles(),
            shading: &shading,
        };
        let view = ClipmapView {
            surface,
            frame: &placed,
            camera: &camera,
            style: &style,
            target_size: FRAME,
        };
        renderer.prepare(device, queue, &view)?;
        {
            let mut pass = target.begin_pass(&mut encoder, wgpu::Color::BLACK);
            sky.draw(&mut pass);
            renderer.draw(&mut pass);
        }
        queue.submit([encoder.finish()]);
        detail.recall();
        for (t, rect, texels) in detail.poll(device)? {
            cache.write_rect(t, rect, &texels)?;
            arrived += 1;
        }
    }

    // The last rects land, every deformed tile goes into the world, and the tiles the cache
    // still holds are the CPU reference's, texel for texel.
    for (t, rect, texels) in detail.flush(device, queue, Duration::from_secs(60))? {
        cache.write_rect(t, rect, &texels)?;
        arrived += 1;
    }
    let image = target.read_rgba8(device, queue)?;
    terrain_core::io::write_png_rgba8(out.join("world_footprints.png"), &image)?;
    cache.flush()?;
    let mut checked = 0;
    for (t, _) in cache.loaded_tiles() {
        if let Some(held) = cache.tile(t) {
            ensure!(
                cpu.tile(t) == Some(held),
                "detail tile {t} differs from the CPU's"
            );
            checked += 1;
        }
    }
    let files = store.list(Layer::Detail.folder())?.len();
    ensure!(checked > 0 && files > 0, "no footprint reached the world");
    println!(
        "{frames} footprints: {arrived} rects read back, {read_now} tiles read on the frame \
         thread, {files} detail tiles in the world, {checked} in RAM equal to the CPU's stamps"
    );
    ctx.check()?;
    Ok(())
}
