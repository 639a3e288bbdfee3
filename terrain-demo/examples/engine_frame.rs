//! The frame an engine runs, on its own device and in its own render pass, with the library
//! crates alone (no demo code): a streamed world (terrain-cache's RAM and VRAM pools filling
//! terrain-gpu's tile atlas), deformed on the GPU where the tiles are resident (craters and
//! footprints through terrain-cache's `TileStamps`, the changed rects read back into RAM and
//! collision without a stall), a walker colliding with a window of the world around it
//! (terrain-physics), the clipmap placed and culled (terrain-lod) and drawn with the sky into
//! the engine's pass (terrain-gpu). At the end the last readbacks land, the deformed tiles are
//! written back into the world and the last frame is saved.
//!
//! ```sh
//! cargo run --release -p terrain-demo --example engine_frame -- [OUT_DIR] [FRAMES]
//! ```

use anyhow::{Context, Result};
use glam::{UVec2, Vec2, Vec3};
use std::sync::Arc;
use std::time::Duration;
use terrain_cache::{
    CameraState, Layer, Manifest, ObjectTileStore, PoolConfig, ProceduralSource, RamPool,
    SphericalSelection, TileDeformer, TileGrid, TileStamps, TileStore, VramConfig, VramPool,
    WindowFill, build_world, rebuild_ancestors,
};
use terrain_core::{
    Blend, CoarseMap, GaussianStamp, Grid, HeightEncoding, Rect, StampPlacement, TerrainParams,
    TextureStamp, WrapMode, apply_stamp,
};
use terrain_gpu::{
    AtlasConfig, AtlasStamp, AtlasStampOp, AtlasStamper, Camera, ClipmapRenderer, ClipmapSurface,
    ClipmapView, DepthConvention, GpuTextureStamp, GpuTileAtlas, SkyColors, SkyPass, TargetFormat,
    TerrainStyle, TileSlot, wgpu,
};
use terrain_lod::{ClipmapLayout, Frustum};
use terrain_physics::{CameraBody, CollisionWindow};

const WORLD: u32 = 1024;
const TILE: u32 = 128;
const TEXEL: f32 = 0.5;
const SLOTS: u32 = 64;
const FRAME: UVec2 = UVec2::new(480, 270);
const DT: f32 = 1.0 / 30.0;

/// The deformations of this game: what `TileStamps` carries to each tile.
#[derive(Debug, Clone, Copy)]
enum Kind {
    Crater,
    Footprint,
}

/// The stamps of each `Kind` (GPU and CPU) and the stamper that adds them to atlas tiles.
struct TileGpu {
    stamper: AtlasStamper,
    crater: GaussianStamp,
    foot: TextureStamp,
    foot_gpu: GpuTextureStamp,
}

/// Applies a `Kind` to one tile: in its atlas slot on the GPU (the changed rects requested
/// back through the stamper's ring), or in RAM on the CPU with the same stamps' references.
struct Deformer<'a> {
    device: &'a wgpu::Device,
    queue: &'a wgpu::Queue,
    atlas: &'a GpuTileAtlas,
    t: &'a mut TileGpu,
}

impl TileDeformer<Kind> for Deformer<'_> {
    type Error = anyhow::Error;

    fn stamp_slot(
        &mut self,
        slot: u32,
        kind: &Kind,
        placement: &StampPlacement,
    ) -> Result<Option<Vec<(u64, Rect)>>> {
        let stamp = match kind {
            Kind::Crater => AtlasStamp::Gaussian(&self.t.crater),
            Kind::Footprint => AtlasStamp::Uploaded(&self.t.foot_gpu),
        };
        let op = AtlasStampOp {
            tile: TileSlot { slot, level: 0 },
            placement: *placement,
            stamp,
        };
        Ok(self
            .t
            .stamper
            .stamp(self.device, self.queue, self.atlas, op)?)
    }

    fn stamp_ram(
        &mut self,
        kind: &Kind,
        tile: &mut CoarseMap,
        placement: &StampPlacement,
    ) -> Result<Vec<Rect>> {
        Ok(match kind {
            Kind::Crater => apply_stamp(tile, &mut self.t.crater, placement, Blend::Add)?,
            Kind::Footprint => apply_stamp(tile, &mut self.t.foot, placement, Blend::Add)?,
        })
    }
}

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let out = args
        .next()
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join("terrain_engine_frame"));
    let frames: u32 = match args.next() {
        Some(n) => n.parse().context("FRAMES: a number of frames")?,
        None => 48,
    };
    std::fs::create_dir_all(&out)?;

    // --- The engine's device and frame (as terrain-gpu's `own_device` example makes them). ---
    let backends =
        wgpu::Backends::from_env().unwrap_or(wgpu::Backends::VULKAN | wgpu::Backends::GL);
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
        backends,
        ..wgpu::InstanceDescriptor::new_without_display_handle()
    });
    let adapter = pollster::block_on(instance.request_adapter(&Default::default()))?;
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("engine device"),
        required_features: adapter.features() & terrain_gpu::OPTIONAL_FEATURES,
        required_limits: wgpu::Limits::downlevel_defaults().using_resolution(adapter.limits()),
        ..Default::default()
    }))?;
    let format = TargetFormat {
        color: wgpu::TextureFormat::Rgba8UnormSrgb,
        depth: wgpu::TextureFormat::Depth32Float,
        sample_count: 1,
        depth_convention: DepthConvention::Forward,
    };
    let target = |fmt, usage| {
        device.create_texture(&wgpu::TextureDescriptor {
            label: Some("engine target"),
            size: wgpu::Extent3d {
                width: FRAME.x,
                height: FRAME.y,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: fmt,
            usage,
            view_formats: &[],
        })
    };
    let color = target(
        format.color,
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
    );
    let depth = target(format.depth, wgpu::TextureUsages::RENDER_ATTACHMENT);

    // --- The world: built once (here in memory; `FsStore::open` for a folder). ---
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory()?);
    let base = TerrainParams {
        size: UVec2::splat(256),
        seed: 11,
        ..TerrainParams::default()
    };
    let source = ProceduralSource::new(UVec2::splat(WORLD), &base, 2, 0.004)?;
    let encoding = HeightEncoding::spanning::<u16>(0.0, 60.0)?;
    let manifest = Manifest::new(UVec2::splat(WORLD), TILE, TEXEL, encoding, WrapMode::Clamp)?;
    let (world, _) = build_world(store, manifest, &source, &|_| true)?;

    // --- Built once: pools, atlas, passes, renderer, collision. ---
    // RAM reaches further than the VRAM pool's frustum, so what the GPU wants next is in RAM
    // (Fikkan 2013, sec. 4.3).
    let mut spherical =
        SphericalSelection::for_grid(&TileGrid::from_manifest(&manifest, Layer::Height));
    spherical.lod0_range *= 3.0;
    spherical.view_distance *= 3.0;
    let config = PoolConfig::new(Layer::Height, 64 << 20);
    let mut ram = RamPool::with_policy(world.clone(), config, Box::new(spherical))?;
    let mut vram = VramPool::new(VramConfig::new(&manifest, SLOTS))?;
    let mut atlas = GpuTileAtlas::new(
        &device,
        &queue,
        &AtlasConfig {
            slots: SLOTS,
            world: manifest.tile_layout(),
        },
    )?;
    let layout = ClipmapLayout::new(127, 5)?;
    let mut renderer = ClipmapRenderer::new(&device, &format, &layout)?;
    let sky = SkyPass::new(&device, &format)?;
    let mut tile_stamps = TileStamps::<Kind>::new(&manifest)?;
    let foot = TextureStamp::from_values(Grid::from_fn(8, 16, |x, y| {
        let (u, v) = ((x as f32 + 0.5) / 4.0 - 1.0, (y as f32 + 0.5) / 8.0 - 1.0);
        -(1.0 - (u * u + v * v)).max(0.0)
    })?)?;
    let mut tiles = TileGpu {
        stamper: AtlasStamper::new(&device, 16)?,
        crater: GaussianStamp::default(),
        foot_gpu: GpuTextureStamp::new(&device, &foot)?,
        foot,
    };
    let mut window = CollisionWindow::new(256, manifest.world_size, encoding, TEXEL)?;
    let mut fill = WindowFill::new(&manifest);
    let extent = manifest.world_size.as_vec2() * TEXEL;
    let start = extent * 0.3;
    let mut walker = CameraBody::new(Vec3::new(start.x, 60.0, start.y));
    let style = TerrainStyle {
        ramp: (0.0, 60.0),
        ..TerrainStyle::default()
    };
    let heading = Vec2::new(1.0, 0.4).normalize();
    let (mut gpu_tiles, mut cpu_tiles, mut arrived_rects, mut missing) = (0, 0, 0, 0);

    for frame in 0..frames {
        // Stream: RAM around the walker (worker threads), the nearest tiles into the atlas.
        let xz = Vec2::new(walker.position.x, walker.position.z);
        let look = Vec3::new(heading.x, -0.25, heading.y);
        let camera = Camera::looking(walker.position + Vec3::Y * 6.0 - look * 12.0, look);
        let state = CameraState {
            position: camera.position,
            forward: look,
            fov_y: camera.fov_y,
            aspect: FRAME.x as f32 / FRAME.y as f32,
        };
        ram.update(&state)?;
        let streamed = vram.update(&state, &ram, &mut atlas)?;

        // Deform: a footprint under the walker every frame, a crater ahead every 8th.
        let side = if frame % 2 == 0 { 0.3 } else { -0.3 };
        let foot_at = xz + heading.perp() * side;
        let p = StampPlacement::new(foot_at, Vec2::new(0.3, 0.6), 0.15)?;
        tile_stamps.push(Kind::Footprint, p)?;
        if frame % 8 == 0 {
            let p = StampPlacement::new(xz + heading * 25.0, Vec2::splat(10.0), -3.0)?;
            tile_stamps.push(Kind::Crater, p)?;
        }
        let mut deformer = Deformer {
            device: &device,
            queue: &queue,
            atlas: &atlas,
            t: &mut tiles,
        };
        let report = tile_stamps.apply(&mut ram, Some(&mut vram), &mut deformer)?;
        (gpu_tiles, cpu_tiles) = (gpu_tiles + report.gpu_tiles, cpu_tiles + report.cpu_tiles);
        for (rect, heights) in &report.changed {
            window.apply(*rect, heights)?;
        }
        // The GPU's changed rects that have arrived (never waiting) go to RAM and collision.
        for a in tiles.stamper.poll(&device)? {
            let (_, world_rect) = tile_stamps.receive::<anyhow::Error>(
                &mut ram,
                Some(&mut vram),
                a.ticket,
                a.rect,
                &a.heights,
            )?;
            window.apply(world_rect, &a.heights)?;
            arrived_rects += 1;
        }

        // Collide: the window follows the walker; it walks on what the window holds.
        // What coarser data stood in for is filled again once its level-0 tile is in RAM.
        window.recenter(xz, |rect, out| fill.fill(&ram, rect, out))?;
        for rect in fill.ready(&ram, window.window()) {
            window.refresh(rect, |r, out| fill.fill(&ram, r, out))?;
        }
        let collider = window.collider();
        walker.step(DT, Vec3::new(heading.x, 0.0, heading.y) * 6.0, &collider)?;
        let feet = Vec2::new(walker.position.x, walker.position.z);
        if let Some(ground) = window.height(feet)? {
            anyhow::ensure!(
                walker.position.y >= ground,
                "frame {frame}: the walker fell through"
            );
        }

        // Select LOD and draw into the engine's pass.
        let aspect = FRAME.x as f32 / FRAME.y as f32;
        let placed = layout.place(
            Vec2::new(camera.position.x, camera.position.z),
            TEXEL,
            (0.0, 60.0),
            Some(&Frustum::from_view_proj(camera.view_proj_world(aspect))),
        )?;
        sky.prepare(
            &queue,
            camera.view_proj_relative(aspect),
            &SkyColors::default(),
        )?;
        renderer.prepare(
            &device,
            &queue,
            &ClipmapView {
                surface: ClipmapSurface::Atlas { atlas: &atlas },
                frame: &placed,
                camera: &camera,
                style: &style,
                target_size: FRAME,
            },
        )?;
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let (color_view, depth_view) = (
                color.create_view(&Default::default()),
                depth.create_view(&Default::default()),
            );
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
        missing = missing.max(streamed.tiles_missing * usize::from(frame >= 30));
    }

    // The end: the last rects come back (bounded wait), dirty tiles go back into the world.
    let deadline = std::time::Instant::now() + Duration::from_secs(30);
    while tile_stamps.in_flight() > 0 {
        anyhow::ensure!(
            std::time::Instant::now() < deadline,
            "tile readbacks never arrived"
        );
        for a in tiles.stamper.wait(&device)? {
            tile_stamps.receive::<anyhow::Error>(
                &mut ram,
                Some(&mut vram),
                a.ticket,
                a.rect,
                &a.heights,
            )?;
            arrived_rects += 1;
        }
    }
    ram.flush();
    ram.shutdown(Duration::from_secs(30))?;
    let mut deformer = Deformer {
        device: &device,
        queue: &queue,
        atlas: &atlas,
        t: &mut tiles,
    };
    let late = tile_stamps.finish_into_world(&world, &mut deformer)?;
    rebuild_ancestors(&world, &late)?;
    let image = terrain_gpu::read_texture_rgba8(&device, &queue, &color)?;
    let png = out.join("engine_frame.png");
    terrain_core::io::write_png_rgba8(&png, &image)?;
    println!(
        "{frames} frames on {}: {gpu_tiles} tile stamps on the GPU ({arrived_rects} rects read \
         back), {cpu_tiles} in RAM, {} written straight into the world; at most {missing} \
         tiles missing after the first second; wrote {}",
        adapter.get_info().name,
        late.len(),
        png.display()
    );
    anyhow::ensure!(gpu_tiles + cpu_tiles > 0, "nothing was deformed");
    Ok(())
}
