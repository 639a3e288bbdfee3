//! GPU time of rendering the geometry clipmap (sky + terrain) at 1024 x 768 for 3, 5, 7, 9 and
//! 11 levels of N = 255 (Flower 2010, table 4.4), and of the default 5 levels at the five
//! viewport sizes of table 4.2, over a 4096 x 4096 coarse-map at 0.1 m per texel, with frustum
//! culling. Timestamp queries where the adapter has them, else wall time.

use criterion::measurement::WallTime;
use criterion::{BenchmarkGroup, BenchmarkId, Criterion, criterion_group, criterion_main};
use glam::{UVec2, Vec2, Vec3};
use std::time::Duration;
use terrain_core::{HeightEncoding, TerrainParams};
use terrain_gpu::{
    Camera, ClipmapRenderer, ClipmapSurface, ClipmapView, GpuContext, GpuDerivativeMap,
    GpuHeightMap, GpuTimer, NormalPass, OffscreenTarget, SkyColors, SkyPass, TerrainStyle,
};
use terrain_lod::{ClipmapLayout, Frustum};

const LEVELS: [u32; 5] = [3, 5, 7, 9, 11];

/// Flower 2010, table 4.2's viewports.
const VIEWPORTS: [(u32, u32); 5] = [
    (640, 480),
    (800, 600),
    (1024, 768),
    (1440, 900),
    (1920, 1080),
];

/// What every timed frame draws with.
struct Scene<'a> {
    ctx: &'a GpuContext,
    timer: &'a GpuTimer,
    map: &'a GpuHeightMap<u16>,
    normals: &'a GpuDerivativeMap,
    camera: &'a Camera,
    style: &'a TerrainStyle,
    xz: Vec2,
}

impl Scene<'_> {
    /// Benchmarks one frame of `levels` clipmap levels at `size` as `id`.
    fn bench(
        &self,
        group: &mut BenchmarkGroup<'_, WallTime>,
        id: BenchmarkId,
        levels: u32,
        size: UVec2,
    ) {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let target = OffscreenTarget::new(device, size).expect("target");
        let sky = SkyPass::new(device, &target.format()).expect("sky");
        let aspect = size.x as f32 / size.y as f32;
        let layout = ClipmapLayout::new(255, levels).expect("layout");
        let mut renderer =
            ClipmapRenderer::new(device, &target.format(), &layout).expect("renderer");
        let frame = layout
            .place(
                self.xz,
                0.1,
                (0.0, 60.0),
                Some(&Frustum::from_view_proj(
                    self.camera.view_proj_world(aspect),
                )),
            )
            .expect("placement");
        eprintln!(
            "{levels} levels at {}x{}: {} triangles drawn, {} parts culled",
            size.x,
            size.y,
            frame.triangle_count(layout.mesh()),
            frame.culled
        );
        sky.prepare(
            queue,
            self.camera.view_proj_relative(aspect),
            &SkyColors::default(),
        )
        .expect("sky uniforms");
        let view = ClipmapView {
            surface: ClipmapSurface::Coarse {
                map: self.map,
                normals: self.normals,
            },
            frame: &frame,
            camera: self.camera,
            style: self.style,
            target_size: size,
        };
        let mut frame_time = || {
            let t = self.timer.time(device, queue, |encoder| {
                // Per frame: write the uniforms and instances, record the draws.
                renderer.prepare(device, queue, &view)?;
                let mut pass = target.begin_pass(encoder, wgpu::Color::BLACK);
                sky.draw(&mut pass);
                renderer.draw(&mut pass);
                Ok(())
            });
            Duration::from_secs_f64(t.expect("render").ms / 1e3)
        };
        group.bench_function(id, |b| {
            b.iter_custom(|iters| (0..iters).map(|_| frame_time()).sum())
        });
    }
}

fn bench(c: &mut Criterion) {
    let ctx = GpuContext::new_headless().expect("a GPU adapter (lavapipe: mesa-vulkan-drivers)");
    let r = ctx.report();
    eprintln!("adapter: {} ({}, {})", r.name, r.backend, r.device_type);
    let (device, queue) = (&ctx.device, &ctx.queue);
    let params = TerrainParams {
        size: UVec2::splat(4096),
        ..TerrainParams::default()
    };
    let enc = HeightEncoding::spanning::<u16>(0.0, 60.0).expect("encoding");
    let map = terrain_core::generate_coarse_map(&params, enc, 0.1).expect("terrain");
    let gpu_map = GpuHeightMap::from_map(device, queue, &map).expect("upload");
    let normals = GpuDerivativeMap::for_map(device, &gpu_map).expect("normals");
    let mut encoder = device.create_command_encoder(&Default::default());
    NormalPass::new(device)
        .expect("normal pass")
        .encode_full(device, queue, &mut encoder, &gpu_map, &normals)
        .expect("normals");
    queue.submit([encoder.finish()]);
    let timer = GpuTimer::new(device, queue);
    eprintln!(
        "GPU timestamps available: {} (wall time of submit + wait is measured)",
        timer.has_timestamps()
    );
    let xz = Vec2::new(204.8, 204.8);
    let eye = Vec3::new(
        xz.x,
        terrain_core::bilinear(&map, xz).expect("height") + 2.0,
        xz.y,
    );
    let camera = Camera::looking(eye, Vec3::new(1.0, -0.15, 0.3));
    let style = TerrainStyle {
        ramp: (0.0, 60.0),
        ..TerrainStyle::default()
    };
    let scene = Scene {
        ctx: &ctx,
        timer: &timer,
        map: &gpu_map,
        normals: &normals,
        camera: &camera,
        style: &style,
        xz,
    };

    let mut group = c.benchmark_group("gpu_clipmap_render");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(200));
    group.measurement_time(Duration::from_secs(3));
    for levels in LEVELS {
        let id = BenchmarkId::new("1024x768_levels", levels);
        scene.bench(&mut group, id, levels, UVec2::new(1024, 768));
    }
    for (w, h) in VIEWPORTS {
        let id = BenchmarkId::new("viewport_5_levels", format!("{w}x{h}"));
        scene.bench(&mut group, id, 5, UVec2::new(w, h));
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
