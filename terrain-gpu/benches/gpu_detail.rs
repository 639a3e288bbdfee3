//! The detail layer on the GPU, beside Flower 2010's tables 4.6-4.9: loading a detail tile into
//! its slot (upload, submit and wait; the thesis's bus copy of a 2048^2 tile took 24.7 ms, of
//! its 47.1 ms load) and reading one back (the write-back before an unload; the same 24.7 ms
//! bus copy of its 160.7 ms unload), at 256^2 and 2048^2;
//! and the frame cost of the same view drawn without detail, with the detail's composite
//! normals only, with parallax occlusion mapping, and with refined geometry (`RefinePass`, sec.
//! 2.4.3; the thesis: tessellated 9.82 ms,
//! parallax 2.33 ms), at 1024 x 768 over a 2048 x 2048 coarse-map at 0.1 m with footprints in
//! front of the camera. Timestamp queries where the adapter has them, else wall time. Also one
//! footprint stamped on the detail tiles, clipped and spilled into the coarse-map.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use glam::{UVec2, Vec2, Vec3};
use std::time::{Duration, Instant};
use terrain_core::detail::{DetailLayer, DetailLayout};
use terrain_core::{Blend, GaussianStamp, Grid, HeightEncoding, Rect, StampPlacement};
use terrain_core::{TerrainParams, generate_coarse_map};
use terrain_gpu::{
    Camera, ClipmapRenderer, ClipmapSurface, ClipmapView, DetailShading, GpuContext,
    GpuDerivativeMap, GpuDetailTiles, GpuHeightMap, GpuStamp, GpuTimer, NormalPass,
    OffscreenTarget, RefineDraw, RefinePass, RefineRenderer, SkyColors, SkyPass, SpillPass,
    StampOp, StampPass, TerrainStyle,
};
use terrain_lod::{ClipmapLayout, Frustum};

fn tiles(c: &mut Criterion, ctx: &GpuContext) {
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut group = c.benchmark_group("gpu_detail_tiles");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(200));
    group.measurement_time(Duration::from_secs(2));
    for side in [256u32, 2048] {
        let layout = DetailLayout::new(UVec2::splat(2048), 0.1, 3, side).expect("layout");
        let mut gpu = GpuDetailTiles::new(device, layout, 2).expect("slots");
        let texels =
            Grid::from_fn(side, side, |x, y| ((x * 7 + y * 13) % 251) as u8).expect("tile");
        let tile = UVec2::new(1, 1);
        group.bench_function(BenchmarkId::new("load", side), |b| {
            b.iter_custom(|iters| {
                let t = Instant::now();
                for _ in 0..iters {
                    gpu.load(queue, tile, Some(&texels)).expect("load");
                    queue.submit([]);
                    device
                        .poll(wgpu::PollType::wait_indefinitely())
                        .expect("poll");
                }
                t.elapsed()
            })
        });
        let all = Rect::from_size(UVec2::splat(side));
        group.bench_function(BenchmarkId::new("read_back", side), |b| {
            b.iter(|| gpu.read(device, queue, tile, all).expect("read"))
        });
    }
    group.finish();
}

fn render(c: &mut Criterion, ctx: &GpuContext) {
    let (device, queue) = (&ctx.device, &ctx.queue);
    let params = TerrainParams {
        size: UVec2::splat(2048),
        ..TerrainParams::default()
    };
    let enc = HeightEncoding::spanning::<u16>(0.0, 60.0).expect("encoding");
    let map = generate_coarse_map(&params, enc, 0.1).expect("terrain");
    let gpu_map = GpuHeightMap::from_map(device, queue, &map).expect("upload");
    let normals = GpuDerivativeMap::for_map(device, &gpu_map).expect("normals");
    let mut encoder = device.create_command_encoder(&Default::default());
    NormalPass::new(device)
        .expect("normal pass")
        .encode_full(device, queue, &mut encoder, &gpu_map, &normals)
        .expect("normals");
    queue.submit([encoder.finish()]);

    // Footprints 12 cm deep every 0.6 m along 12 m in front of the camera, as the demo's.
    let layout = DetailLayout::new(map.size(), 0.1, 3, 256).expect("layout");
    let mut layer = DetailLayer::new(layout).expect("layer");
    let mut foot = GaussianStamp::default();
    for i in 0..20 {
        let side = if i % 2 == 0 { -0.2 } else { 0.2 };
        let c = Vec2::new(102.4 + side, 104.0 + 0.6 * i as f32);
        let p = StampPlacement::new(c, Vec2::new(0.45, 1.1), -0.12).expect("placement");
        layer.apply_stamp(&mut foot, &p, Blend::Add).expect("stamp");
    }
    let mut detail = GpuDetailTiles::new(device, layout, 32).expect("slots");
    let wanted = layout
        .tiles_within(Vec2::new(102.4, 110.0), 30.0)
        .expect("band");
    detail.stream_from(queue, &layer, &wanted).expect("stream");

    let size = UVec2::new(1024, 768);
    let target = OffscreenTarget::new(device, size).expect("target");
    let sky = SkyPass::new(device, &target.format()).expect("sky");
    let timer = GpuTimer::new(device, queue);
    eprintln!("GPU timestamps available: {}", timer.has_timestamps());
    let xz = Vec2::new(102.4, 101.0);
    let eye = Vec3::new(
        xz.x,
        terrain_core::bilinear(&map, xz).expect("height") + 1.7,
        xz.y,
    );
    let camera = Camera::looking(eye, Vec3::new(0.0, -0.5, 1.0));
    let aspect = size.x as f32 / size.y as f32;
    let style = TerrainStyle {
        ramp: (0.0, 60.0),
        ..TerrainStyle::default()
    };
    let clipmap = ClipmapLayout::new(255, 5).expect("layout");
    let mut renderer = ClipmapRenderer::new(device, &target.format(), &clipmap).expect("renderer");
    let frame = clipmap
        .place(
            xz,
            0.1,
            (0.0, 60.0),
            Some(&Frustum::from_view_proj(camera.view_proj_world(aspect))),
        )
        .expect("placement");
    sky.prepare(
        queue,
        camera.view_proj_relative(aspect),
        &SkyColors::default(),
    )
    .expect("sky uniforms");
    let normals_only = DetailShading {
        parallax_steps: 0,
        ..DetailShading::default()
    };
    let parallax = DetailShading::default();
    let coarse = ClipmapSurface::Coarse {
        map: &gpu_map,
        normals: &normals,
    };
    let with = |shading| ClipmapSurface::Detail {
        map: &gpu_map,
        normals: &normals,
        detail: &detail,
        shading,
    };
    let mut group = c.benchmark_group("gpu_detail_render");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(200));
    group.measurement_time(Duration::from_secs(3));
    for (name, surface) in [
        ("none", coarse),
        ("composite_normals", with(&normals_only)),
        ("parallax", with(&parallax)),
    ] {
        let view = ClipmapView {
            surface,
            frame: &frame,
            camera: &camera,
            style: &style,
            target_size: size,
        };
        let mut frame_time = || {
            let t = timer.time(device, queue, |encoder| {
                renderer.prepare(device, queue, &view)?;
                let mut pass = target.begin_pass(encoder, wgpu::Color::BLACK);
                sky.draw(&mut pass);
                renderer.draw(&mut pass);
                Ok(())
            });
            Duration::from_secs_f64(t.expect("render").ms / 1e3)
        };
        group.bench_function(BenchmarkId::new("1024x768", name), |b| {
            b.iter_custom(|iters| (0..iters).map(|_| frame_time()).sum())
        });
    }
    // Refined geometry within 9 m (the demo's `--detail refine`): the refine pass, the clipmap
    // shading the rest with the composite normals, the refined triangles drawn indirectly.
    let mut refine = RefinePass::new(device, 91).expect("refine pass");
    let mut refined = RefineRenderer::new(device, &target.format()).expect("refine renderer");
    let draw = RefineDraw {
        surface: ClipmapSurface::Detail {
            map: &gpu_map,
            normals: &normals,
            detail: &detail,
            shading: &normals_only,
        },
        radius_m: 9.0,
        camera: &camera,
        style: &style,
        target_size: size,
    };
    let view = ClipmapView {
        surface: with(&normals_only),
        frame: &frame,
        camera: &camera,
        style: &style,
        target_size: size,
    };
    group.bench_function(BenchmarkId::new("1024x768", "refine"), |b| {
        b.iter_custom(|iters| {
            (0..iters)
                .map(|_| {
                    let t = timer
                        .time(device, queue, |encoder| {
                            let v = refine.encode(device, queue, encoder, &draw)?;
                            refined.prepare(device, queue, &draw, &refine)?;
                            renderer.exclude(Some(v.region()));
                            renderer.prepare(device, queue, &view)?;
                            let mut pass = target.begin_pass(encoder, wgpu::Color::BLACK);
                            sky.draw(&mut pass);
                            renderer.draw(&mut pass);
                            refined.draw(&mut pass, &refine);
                            Ok(())
                        })
                        .expect("render");
                    Duration::from_secs_f64(t.ms / 1e3)
                })
                .sum()
        })
    });
    let (count, _) = refine.read_count(device, queue).expect("count");
    eprintln!("refined triangles: {count}");
    group.finish();
}

/// One footprint-sized detail stamp (0.6 x 0.3 m over a 4-tile corner, 1.5 m deep) on the
/// demo's layout, clipped (`StampPass::encode_detail`) and spilled into the coarse-map
/// (`SpillPass::encode`): record, submit and wait.
fn stamp(c: &mut Criterion, ctx: &GpuContext) {
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut group = c.benchmark_group("gpu_detail_stamp");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(200));
    group.measurement_time(Duration::from_secs(2));
    let layout = DetailLayout::new(UVec2::splat(2048), 0.1, 3, 1024).expect("layout");
    let mut tiles = GpuDetailTiles::new(device, layout, 4).expect("slots");
    let enc = HeightEncoding::new(0.001, -30.0).expect("encoding");
    let coarse = terrain_core::HeightMap::new(
        Grid::new(2048, 2048, 30_000u16).expect("grid"),
        enc,
        0.1,
        terrain_core::WrapMode::Repeat,
    )
    .expect("map");
    let coarse = GpuHeightMap::from_map(device, queue, &coarse).expect("upload");
    let mut stamps = StampPass::new(device).expect("stamp pass");
    let mut spill = SpillPass::new(device, 256 * 256).expect("spill pass");
    let gauss = GaussianStamp::default();
    let corner = Vec2::splat(1024.0 * layout.detail_texel_m());
    let op = StampOp {
        stamp: GpuStamp::Gaussian(&gauss),
        placement: StampPlacement::new(corner, Vec2::new(0.6, 0.3), -1.5).expect("placement"),
        blend: Blend::Add,
    };
    let mut run = |spilling: bool| {
        let mut encoder = device.create_command_encoder(&Default::default());
        if spilling {
            spill
                .encode(
                    device,
                    queue,
                    &mut encoder,
                    &mut stamps,
                    terrain_gpu::SpillTargets {
                        tiles: &mut tiles,
                        coarse: &coarse,
                    },
                    &op,
                )
                .expect("spill");
        } else {
            stamps
                .encode_detail(device, queue, &mut encoder, &mut tiles, &op)
                .expect("stamp");
        }
        queue.submit([encoder.finish()]);
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .expect("poll");
        stamps.recall();
        spill.recall();
    };
    group.bench_function("clip", |b| b.iter(|| run(false)));
    group.bench_function("spill", |b| b.iter(|| run(true)));
    group.finish();
}

fn bench(c: &mut Criterion) {
    let ctx = GpuContext::new_headless().expect("a GPU adapter (lavapipe: mesa-vulkan-drivers)");
    let r = ctx.report();
    eprintln!("adapter: {} ({}, {})", r.name, r.backend, r.device_type);
    tiles(c, &ctx);
    stamp(c, &ctx);
    render(c, &ctx);
}

criterion_group!(benches, bench);
criterion_main!(benches);
