//! The adaptive tessellation pass (`TessellationPass`, Cervin 2012, sec. 2.3) on its own: the
//! compute work that refines every patch of a 1024 x 1024 coarse-map at 0.5 m for a 1024 x 768
//! view, from a camera close to the ground (deep refinement near it) and from high above
//! (shallow, many patches), with and without frustum culling: the time of the generator, not
//! of drawing its triangles, between GPU timestamps where the adapter has them, else the wall
//! time of submit and wait. Prints the triangle counts.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use glam::{UVec2, Vec2, Vec3};
use std::time::Duration;
use terrain_core::{HeightEncoding, TerrainParams, generate_coarse_map};
use terrain_gpu::{Camera, GpuContext, GpuTessellation, GpuTimer, TessellationPass};
use terrain_lod::{CdlodView, DensityMap, DensityParams, Frustum, TessConfig, TessHierarchy};

fn tessellation(c: &mut Criterion, ctx: &GpuContext) {
    let (device, queue) = (&ctx.device, &ctx.queue);
    let params = TerrainParams {
        size: UVec2::splat(1024),
        ..TerrainParams::default()
    };
    let enc = HeightEncoding::spanning::<u16>(0.0, 60.0).expect("encoding");
    let map = generate_coarse_map(&params, enc, 0.5).expect("terrain");
    let density = DensityMap::from_map(&map, DensityParams::default()).expect("density");
    let config = TessConfig {
        patch_size: 64,
        ..TessConfig::default()
    };
    let tess = TessHierarchy::from_map(&map, Some(&density), config).expect("hierarchy");
    let gpu = GpuTessellation::new(device, queue, &tess, 1 << 21).expect("upload");
    let mut pass = TessellationPass::new(device).expect("pass");
    let timer = GpuTimer::new(device, queue);
    eprintln!("GPU timestamps available: {}", timer.has_timestamps());
    let size = UVec2::new(1024, 768);
    let aspect = size.x as f32 / size.y as f32;
    let xz = Vec2::new(256.0, 256.0);
    let ground = terrain_core::bilinear(&map, xz).expect("height");
    let mut group = c.benchmark_group("gpu_tessellation");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(200));
    group.measurement_time(Duration::from_secs(3));
    for (name, eye, dir) in [
        (
            "ground",
            Vec3::new(xz.x, ground + 1.7, xz.y),
            Vec3::new(1.0, -0.2, 0.7),
        ),
        (
            "above",
            Vec3::new(256.0, 400.0, 256.0),
            Vec3::new(0.2, -1.0, 0.2),
        ),
    ] {
        let camera = Camera::looking(eye, dir);
        let frustum = Frustum::from_view_proj(camera.view_proj_world(aspect));
        for culled in [false, true] {
            let view = CdlodView {
                camera: camera.position,
                frustum: culled.then_some(&frustum),
                viewport_width: size.x as f32,
                hfov: 2.0 * ((camera.fov_y * 0.5).tan() * aspect).atan(),
            };
            let mut run = || {
                let t = timer
                    .time(device, queue, |encoder| {
                        pass.encode(device, queue, encoder, &gpu, &tess, &view)
                    })
                    .expect("tessellate");
                pass.recall();
                Duration::from_secs_f64(t.timestamp_ms.unwrap_or(t.ms) / 1e3)
            };
            run();
            let (tris, overflow) = gpu.read_triangles(device, queue).expect("read");
            eprintln!(
                "{name} culled={culled}: {} triangles (overflow: {overflow})",
                tris.len()
            );
            let id = format!("{name}{}", if culled { "_culled" } else { "" });
            group.bench_function(BenchmarkId::new("1024x768", id), |b| {
                b.iter_custom(|iters| (0..iters).map(|_| run()).sum())
            });
        }
    }
    group.finish();
}

fn bench(c: &mut Criterion) {
    let ctx = GpuContext::new_headless().expect("a GPU adapter (lavapipe: mesa-vulkan-drivers)");
    let r = ctx.report();
    eprintln!("adapter: {} ({}, {})", r.name, r.backend, r.device_type);
    tessellation(c, &ctx);
}

criterion_group!(benches, bench);
criterion_main!(benches);
