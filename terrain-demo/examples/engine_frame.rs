//! The frame an engine runs, on its own device and render pass, with the library crates alone,
//! every kind of deformation on one streamed world. Stream: terrain-cache's `StreamedWorld`
//! (its RAM and VRAM pools) fills terrain-gpu's tile atlas. Deform: craters and a shockwave on
//! the resident tiles on the GPU (the world's stamps through `AtlasDeformer`, the rects read
//! back without a stall), footprints in detail tiles streamed by band regions (`DetailCache`,
//! `GpuDetailStream`), a sledge's volume-preserving granular trail (`GranularTrails` stepping a
//! `FieldStepper`, each window moved on without a wait). Collide: a walker on a window of the
//! world, refilled where coarser data stood in (`WindowFill`). Select LOD and draw: the
//! clipmap placed and culled over the atlas and its detail, drawn with the sky into the
//! engine's pass. At the end every readback lands, the trail's volume is checked, the deformed
//! tiles go back into the world, and the last frame is saved.
//!
//! ```sh
//! cargo run --release -p terrain-demo --example engine_frame -- [OUT_DIR] [FRAMES]
//! ```

use anyhow::{Result, ensure};
use glam::{Affine3A, UVec2, Vec2, Vec3};
use std::sync::Arc;
use std::time::Duration;
use terrain_cache::detail::{DetailCache, detail_manifest_layout};
use terrain_cache::{
    BandSelection, CameraState, GranularTrails, Manifest, ObjectTileStore, ProceduralSource,
    StreamedWorld, TileStore, TrailConfig, WindowFill, build_world,
};
use terrain_core::detail::DetailLayout;
use terrain_core::granular::{GranularObject, GranularParams, TriMesh};
use terrain_core::{
    GaussianStamp, HeightEncoding, Shockwave, ShockwaveParams, StampPlacement, TerrainParams,
    TileStamp, WrapMode,
};
use terrain_gpu::granular::FieldStepper;
use terrain_gpu::{
    AtlasConfig, AtlasDeformer, AtlasStamper, Camera, ClipmapRenderer, ClipmapSurface, ClipmapView,
    DepthConvention, DetailShading, GpuDetailStream, GpuStamp, GpuTileAtlas, MapUse, SkyColors,
    SkyPass, TargetFormat, TerrainStyle, wgpu,
};
use terrain_lod::{ClipmapLayout, Frustum};
use terrain_physics::{CameraBody, CollisionWindow};

const WORLD: u32 = 1024;
const TILE: u32 = 128;
const TEXEL: f32 = 0.5;
const SLOTS: u32 = 64;
const FRAME: UVec2 = UVec2::new(480, 270);
const DT: f32 = 1.0 / 30.0;

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let out = std::path::PathBuf::from(args.next().unwrap_or("terrain_engine_frame".into()));
    let frames: u32 = args.next().map_or(Ok(48), |n| n.parse())?;
    std::fs::create_dir_all(&out)?;

    // --- The engine's device and frame (as terrain-gpu's `own_device` example makes them). ---
    let backends =
        wgpu::Backends::from_env().unwrap_or(wgpu::Backends::VULKAN | wgpu::Backends::GL);
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
        backends,
        ..wgpu::InstanceDescriptor::new_without_display_handle()
    });
    let adapter = pollster::block_on(instance.request_adapter(&Default::default()))?;
    let base = wgpu::Limits::downlevel_defaults().using_resolution(adapter.limits());
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("engine device"),
        required_features: adapter.features() & terrain_gpu::OPTIONAL_FEATURES,
        // The trail's granular passes bind 7 storage buffers (downlevel defaults allow 4).
        required_limits: terrain_gpu::required_limits(UVec2::splat(128), MapUse::Granular, base)?,
        ..Default::default()
    }))?;
    let format = TargetFormat {
        color: wgpu::TextureFormat::Rgba8UnormSrgb,
        depth: wgpu::TextureFormat::Depth32Float,
        sample_count: 1,
        depth_convention: DepthConvention::Forward,
    };
    let target = |format, usage| {
        let size = wgpu::Extent3d {
            width: FRAME.x,
            height: FRAME.y,
            depth_or_array_layers: 1,
        };
        device.create_texture(&wgpu::TextureDescriptor {
            label: Some("engine target"),
            size,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        })
    };
    let usage = wgpu::TextureUsages::RENDER_ATTACHMENT;
    let color = target(format.color, usage | wgpu::TextureUsages::COPY_SRC);
    let depth = target(format.depth, usage);

    // --- The world: built once (here in memory; `FsStore::open` for a folder), with a detail
    // layer of 8 texels per world texel in 256^2 tiles (16 m). ---
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory()?);
    let base = TerrainParams {
        size: UVec2::splat(256),
        seed: 11,
        ..TerrainParams::default()
    };
    let source = ProceduralSource::new(UVec2::splat(WORLD), &base, 2, 0.004)?;
    let encoding = HeightEncoding::spanning::<u16>(0.0, 60.0)?;
    let size = UVec2::splat(WORLD);
    let mut manifest = Manifest::new(size, TILE, TEXEL, encoding, WrapMode::Clamp)?;
    let detail_layout = DetailLayout::new(size, TEXEL, 8, 256)?;
    manifest.detail = Some(detail_manifest_layout(&detail_layout)?);
    let (world, _) = build_world(store, manifest, &source, &|_| true)?;

    // --- Built once: pools, atlas, stamps, detail, trail, collision, renderer. ---
    // The world's RAM and VRAM pools and the stamps on its tiles, driven once per frame.
    let mut streamed = StreamedWorld::open(world.clone(), 64 << 20)?;
    streamed.enable_gpu(SLOTS, false, false)?;
    let atlas_config = AtlasConfig {
        slots: SLOTS,
        world: manifest.tile_layout(),
    };
    let mut atlas = GpuTileAtlas::new(&device, &queue, &atlas_config)?;
    let mut stamper = AtlasStamper::new(&device, 16)?;
    let crater = TileStamp::Gaussian(GaussianStamp::default());
    let mut shock = Shockwave::new(ShockwaveParams::default())?;
    let detail_world = terrain_cache::World::open(world.store().clone())?;
    let band = BandSelection::default();
    let mut detail = DetailCache::open(detail_world, detail_layout, band, 9 << 16)?;
    let mut detail_gpu = GpuDetailStream::new(&device, detail_layout, 13, 16)?;
    let foot = GaussianStamp::default();
    let trail = TrailConfig::default();
    let mut trails = GranularTrails::new(&manifest, GranularParams::snow(), trail)?;
    // The trail's GPU side: terrain-gpu's granular field, each window moved on without a wait.
    let mut snow = FieldStepper::new(&device, &queue);
    let runner = TriMesh::wheel(0.6, 0.4, 16)?;
    let mut window = CollisionWindow::new(256, manifest.world_size, encoding, TEXEL)?;
    let mut fill = WindowFill::new(&manifest);
    let layout = ClipmapLayout::new(127, 5)?;
    let mut renderer = ClipmapRenderer::new(&device, &format, &layout)?;
    let sky = SkyPass::new(&device, &format)?;
    let style = TerrainStyle {
        ramp: (0.0, 60.0),
        ..TerrainStyle::default()
    };
    let start = manifest.world_size.as_vec2() * TEXEL * 0.3;
    let mut walker = CameraBody::new(Vec3::new(start.x, 60.0, start.y));
    let heading = Vec2::new(1.0, 0.4).normalize();
    let aspect = FRAME.x as f32 / FRAME.y as f32;
    let (mut gpu_tiles, mut cpu_tiles, mut arrived_rects, mut missing) = (0, 0, 0, 0);
    let mut trail_texels = 0;

    for frame in 0..frames {
        // Stream: RAM around the walker (worker threads), the nearest tiles into the atlas.
        let xz = Vec2::new(walker.position.x, walker.position.z);
        let look = Vec3::new(heading.x, -0.25, heading.y);
        let camera = Camera::looking(walker.position + Vec3::Y * 6.0 - look * 12.0, look);
        let state = CameraState::at(camera.position).looking(look, camera.fov_y, aspect);
        streamed.update(&state)?;
        let uploaded = streamed.upload(&state, &mut atlas)?;

        // Deform the tiles: a crater ahead every 8th frame, the shockwave's change, both 50 m
        // aside, clear of the trail's window (a write there would break its volume).
        let aside = heading.perp() * 50.0;
        if frame % 8 == 0 {
            let p = StampPlacement::new(xz + heading * 25.0 + aside, Vec2::splat(10.0), -3.0)?;
            streamed.push(crater.clone(), p)?;
        }
        shock.step();
        let wave_at = start + heading * 60.0 + aside;
        let p = StampPlacement::new(wave_at, Vec2::splat(30.0), 1.5)?;
        streamed.push(TileStamp::Texture(Arc::new(shock.take_delta()?)), p)?;
        let mut deformer = AtlasDeformer {
            device: &device,
            queue: &queue,
            atlas: &atlas,
            stamper: &mut stamper,
            submit: None,
        };
        let report = streamed.deform(&mut deformer)?;
        (gpu_tiles, cpu_tiles) = (gpu_tiles + report.gpu_tiles, cpu_tiles + report.cpu_tiles);
        for (rect, heights) in &report.changed {
            window.apply(*rect, heights)?;
        }
        // The GPU's changed rects that have arrived (never waiting) go to RAM and collision.
        for a in stamper.poll(&device)? {
            let world_rect = streamed.receive(a.ticket, a.rect, &a.heights)?;
            window.apply(world_rect, &a.heights)?;
            arrived_rects += 1;
        }

        // A footprint under the walker, in the detail tiles of the band around the camera.
        let side = if frame % 2 == 0 { 0.3 } else { -0.3 };
        let step = StampPlacement::new(xz + heading.perp() * side, Vec2::new(0.3, 0.6), -0.1)?;
        let keep = detail_gpu.tiles_in_flight();
        let band = detail.update_for_stamps(Vec2::new(xz.x, xz.y), &[step], &keep, 4.0)?;
        ensure!(band.failed.is_empty(), "a detail tile could not be read");
        let load = band.load.iter().map(|&t| (t, detail.tile(t)));
        detail_gpu.follow(&queue, &band.unload, load)?;
        let mut encoder = device.create_command_encoder(&Default::default());
        let gpu_foot = GpuStamp::Gaussian(&foot);
        detail_gpu.encode_stamps(&device, &queue, &mut encoder, gpu_foot, &[step])?;
        queue.submit([encoder.finish()]);
        detail_gpu.recall();
        for (tile, rect, texels) in detail_gpu.poll(&device)? {
            detail.write_rect(tile, rect, &texels)?;
        }

        // The sledge beside the walker ploughs the snow; its window keeps clear of the stamps.
        let sledge = xz - heading.perp() * 6.0;
        let others = streamed.readbacks_in_flight() > 0;
        let ahead = sledge + heading * 8.0;
        let points = [sledge];
        let ram = streamed.ram_mut();
        let mut trail = trails.follow(ram, Some(&mut snow), &points, ahead, &state, others)?;
        if let Some((local, ground)) = trails.ground_at(sledge) {
            let pose = Affine3A::from_translation(Vec3::new(local.x, ground + 0.45, local.y));
            let objects = [GranularObject::new(&runner, pose)];
            trails.step(
                streamed.ram_mut(),
                Some(&mut snow),
                &objects,
                u64::from(frame),
                &mut trail,
            )?;
        }
        for (rect, heights) in &trail.changed {
            window.apply(*rect, heights)?;
            trail_texels += rect.area();
        }
        for m in &trail.measured {
            ensure!(Some(m.volume) == m.volume_taken, "step {}: volume", m.tag);
        }

        // Collide: the window follows the walker, refilled where coarser data stood in.
        window.follow(xz, &mut fill.over(streamed.ram()))?;
        walker.step(
            DT,
            Vec3::new(heading.x, 0.0, heading.y) * 6.0,
            &window.collider(),
        )?;
        let feet = Vec2::new(walker.position.x, walker.position.z);
        if let Some(ground) = window.height(feet)? {
            ensure!(walker.position.y >= ground, "frame {frame}: fell through");
        }

        // Select LOD and draw into the engine's pass.
        let eye = Vec2::new(camera.position.x, camera.position.z);
        let frustum = Frustum::from_view_proj(camera.view_proj_world(aspect));
        let placed = layout.place(eye, TEXEL, (0.0, 60.0), Some(&frustum))?;
        let sky_view = camera.view_proj_relative(aspect);
        sky.prepare(&queue, sky_view, &SkyColors::default())?;
        let surface = ClipmapSurface::AtlasDetail {
            atlas: &atlas,
            detail: detail_gpu.tiles(),
            shading: &DetailShading::default(),
        };
        let view = ClipmapView {
            surface,
            frame: &placed,
            camera: &camera,
            style: &style,
            target_size: FRAME,
        };
        renderer.prepare(&device, &queue, &view)?;
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let color_view = color.create_view(&Default::default());
            let depth_view = depth.create_view(&Default::default());
            // The engine's own pass: colour kept for the capture, depth for this frame only.
            let depth_ops = wgpu::Operations {
                load: wgpu::LoadOp::Clear(1.0),
                store: wgpu::StoreOp::Discard,
            };
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("engine main pass"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &color_view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &depth_view,
                    depth_ops: Some(depth_ops),
                    stencil_ops: None,
                }),
                ..Default::default()
            });
            sky.draw(&mut pass);
            renderer.draw(&mut pass);
            // ... the engine draws its own objects into the same pass here.
        }
        queue.submit([encoder.finish()]);
        // Tiles drawn from a coarser level after the first second (30 frames).
        let streamed_missing = uploaded.map_or(0, |u| u.tiles_missing);
        missing = missing.max(streamed_missing * usize::from(frame >= 30));
    }

    // The end: the last rects come back (bounded waits), the trail's window is released (its
    // volume checked), the detail and the dirty tiles go back into the world.
    for a in stamper.wait(&device)? {
        streamed.receive(a.ticket, a.rect, &a.heights)?;
        arrived_rects += 1;
    }
    trails.release(streamed.ram_mut(), Some(&mut snow))?;
    for (tile, rect, texels) in detail_gpu.flush(&device, &queue, Duration::from_secs(30))? {
        detail.write_rect(tile, rect, &texels)?;
    }
    let detail_tiles = detail.flush()?;
    // Every readback has landed (else this fails): the dirty tiles go back, and the stamps
    // whose tiles never became resident go straight into the files.
    let (written, _) = streamed.finish(Duration::from_secs(30))?;
    let image = terrain_gpu::read_texture_rgba8(&device, &queue, &color)?;
    let png = out.join("engine_frame.png");
    terrain_core::io::write_png_rgba8(&png, &image)?;
    println!(
        "{frames} frames on {}: {gpu_tiles} tile stamps on the GPU ({arrived_rects} rects read \
         back), {cpu_tiles} in RAM, {} written straight into the world; {detail_tiles} detail \
         tiles and a {trail_texels}-texel trail written back; at most {missing} tiles missing \
         after the first second; wrote {}",
        adapter.get_info().name,
        written.stamped_at_finish,
        png.display()
    );
    ensure!(
        gpu_tiles > 0 && trail_texels > 0,
        "no deformation on the GPU"
    );
    Ok(())
}
