//! terrain-gpu in an engine that owns its device: the engine makes its own wgpu instance,
//! adapter, device and a swap-chain-like colour target (`Bgra8UnormSrgb`, 4x MSAA, its own depth
//! buffer); terrain-gpu stamps a crater and a ridge into a coarse-map, regenerates the normals,
//! and draws the sky and the clipmap, shaded with materials, into the engine's render pass.
//! The frame is written as PNG.
//!
//! ```sh
//! cargo run -p terrain-gpu --example own_device -- [OUT.png]
//! ```

#[path = "../tests/common/engine.rs"]
mod engine;

use glam::{UVec2, Vec2, Vec3};
use terrain_core::{
    Blend, GaussianStamp, HeightEncoding, StampPlacement, TerrainParams, TextureStamp,
    generate_coarse_map,
};
use terrain_gpu::{
    Camera, ClipmapRenderer, ClipmapSurface, ClipmapView, DeformableMap, GpuStamp, GpuTextureStamp,
    MapUse, SkyColors, SkyPass, StampOp, SurfaceShading, TerrainStyle, wgpu,
};
use terrain_lod::{ClipmapLayout, Frustum};

const MAP: u32 = 256;
const TEXEL: f32 = 0.5;
const FRAME: UVec2 = UVec2::new(480, 270);

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args()
        .nth(1)
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join("terrain_own_device.png"));

    // --- The engine's side: its own instance, adapter and device. ---
    let backends =
        wgpu::Backends::from_env().unwrap_or(wgpu::Backends::VULKAN | wgpu::Backends::GL);
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
        backends,
        ..wgpu::InstanceDescriptor::new_without_display_handle()
    });
    let adapter = pollster::block_on(instance.request_adapter(&Default::default()))?;
    // Ask for what terrain-gpu needs for this map size (the storage binding grows with it).
    let limits = terrain_gpu::required_limits(
        UVec2::splat(MAP),
        MapUse::Coarse,
        wgpu::Limits::downlevel_defaults(),
    )?;
    terrain_gpu::check_limits(&adapter.limits(), UVec2::splat(MAP), MapUse::Coarse)?;
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("engine device"),
        required_features: adapter.features() & terrain_gpu::OPTIONAL_FEATURES,
        required_limits: limits,
        ..Default::default()
    }))?;
    println!("engine device on {}", adapter.get_info().name);

    // The engine's frame: an sRGB colour target with 4x MSAA and its own depth buffer (made in
    // tests/common/engine.rs, which the render test shares to check this path).
    let format = engine::FORMAT;
    let targets = engine::EngineTargets::new(&device, FRAME);

    // --- terrain-gpu: built once. ---
    let params = TerrainParams {
        size: UVec2::splat(MAP),
        seed: 7,
        ..TerrainParams::default()
    };
    let map = generate_coarse_map(&params, HeightEncoding::spanning::<u16>(0.0, 30.0)?, TEXEL)?;
    // The map on the GPU with its normals, and the passes that deform it.
    let mut ground = DeformableMap::new(&device, &queue, &map)?;
    let layout = ClipmapLayout::new(63, 4)?;
    let mut renderer = ClipmapRenderer::new(&device, &format, &layout)?;
    let sky = SkyPass::new(&device, &format)?;
    let ridge = GpuTextureStamp::new(&device, &TextureStamp::from_values(ridge_profile()?)?)?;

    // --- One frame: deform, regenerate normals, draw into the engine's pass. ---
    let centre = Vec2::splat(MAP as f32 * TEXEL * 0.5);
    let mut encoder = device.create_command_encoder(&Default::default());
    let gauss = GaussianStamp::default();
    let crater = StampPlacement::new(centre + Vec2::new(8.0, 4.0), Vec2::splat(10.0), -4.0)?;
    let mut dirty = ground.encode_stamp(
        &device,
        &queue,
        &mut encoder,
        &StampOp {
            stamp: GpuStamp::Gaussian(&gauss),
            placement: crater,
            blend: Blend::Add,
        },
    )?;
    let wall = StampPlacement::new(centre + Vec2::new(-6.0, 10.0), Vec2::new(20.0, 3.0), 2.0)?;
    dirty.extend(ground.encode_stamp(
        &device,
        &queue,
        &mut encoder,
        &StampOp {
            stamp: GpuStamp::Texture(&ridge),
            placement: wall,
            blend: Blend::Add,
        },
    )?);
    // The normals of the stamped rects only, after every stamp (they read neighbours).
    ground.encode_normals(&device, &queue, &mut encoder, &dirty)?;

    let eye_xz = centre - Vec2::new(18.0, 18.0);
    let eye_ground = terrain_core::bilinear(&map, eye_xz)?;
    let camera = Camera::looking(
        Vec3::new(eye_xz.x, eye_ground + 12.0, eye_xz.y),
        Vec3::new(1.0, -0.45, 1.0),
    );
    let aspect = FRAME.x as f32 / FRAME.y as f32;
    let frame = layout.place(
        Vec2::new(camera.position.x, camera.position.z),
        TEXEL,
        (0.0, 30.0),
        Some(&Frustum::from_view_proj(camera.view_proj_world(aspect))),
    )?;
    // Shaded with the procedural materials (an engine passes its own images to
    // `GpuMaterials::new` and `renderer.set_materials`).
    let style = TerrainStyle {
        ramp: (0.0, 30.0),
        shading: SurfaceShading::Materials,
        ..TerrainStyle::default()
    };
    sky.prepare(
        &queue,
        camera.view_proj_relative(aspect),
        &SkyColors::default(),
    )?;
    renderer.prepare(
        &device,
        &queue,
        &ClipmapView {
            surface: ClipmapSurface::Coarse {
                map: ground.heights(),
                normals: ground.normals(),
            },
            frame: &frame,
            camera: &camera,
            style: &style,
            target_size: FRAME,
        },
    )?;
    {
        let mut pass = targets.begin_pass(&mut encoder);
        sky.draw(&mut pass);
        renderer.draw(&mut pass);
        // ... the engine would draw its own objects into the same pass here.
    }

    queue.submit([encoder.finish()]);
    // The submit carried every recorded dispatch: their uniform slots are free again.
    ground.recall();
    // Read the "swap chain" back (an engine would present it instead).
    let image = terrain_gpu::read_texture_rgba8(&device, &queue, &targets.resolved)?;
    terrain_core::io::write_png_rgba8(&out, &image)?;
    println!(
        "stamped {} dirty rect(s), drew {} triangles into the engine's pass; wrote {}",
        dirty.len(),
        frame.triangle_count(layout.mesh()),
        out.display()
    );
    Ok(())
}

/// A 32 x 8 ridge: a tent profile across, constant along.
fn ridge_profile() -> Result<terrain_core::Grid<f32>, terrain_core::CoreError> {
    let (w, h) = (32u32, 8u32);
    let values = (0..h)
        .flat_map(|y| {
            let t = (y as f32 + 0.5) / h as f32;
            std::iter::repeat_n(1.0 - (2.0 * t - 1.0).abs(), w as usize)
        })
        .collect();
    terrain_core::Grid::from_vec(w, h, values)
}
