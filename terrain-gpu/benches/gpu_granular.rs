//! GPU time of each granular step (penetration, jump flooding, closest-seed displacement,
//! 10 scatter slope iterations) and of the whole step over one active area of about 3 774, 15 100, 60 398 and
//! 241 591 columns on maps of 512 to 4096 a side (the setting of seed 001 table 5.4), as the
//! wall time of submit + wait measured by `GpuTimer`; then whole steps with 1 to 8 vehicles,
//! active areas versus the full map (table 5.7). Prints the adapter first.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use glam::{Affine3A, Vec3};
use glam::{IVec2, UVec2, Vec2};
use std::time::Duration;
use terrain_core::granular::{
    AreaMode, DisplacementMethod, GranularObject, GranularParams, NO_OBJECT, SlopeMethod, TriMesh,
};
use terrain_core::{FixedPointMap, Grid, Rect};
use terrain_gpu::granular::{
    DisplacePass, GpuGranularMap, GpuGranularStep, GranularScratch, JumpFloodPass, PenetrationPass,
    SlopePass,
};
use terrain_gpu::{GpuContext, GpuTimer};

/// (map side, active-area side): sides of 61, 123, 246 and 492 give 3 721, 15 129, 60 516 and
/// 242 064 columns.
const CASES: [(u32, u32); 4] = [(512, 61), (1024, 123), (2048, 246), (4096, 492)];

fn bench(c: &mut Criterion) {
    let ctx = GpuContext::new_headless().expect("a GPU adapter (lavapipe: mesa-vulkan-drivers)");
    let r = ctx.report();
    eprintln!("adapter: {} ({}, {})", r.name, r.backend, r.device_type);
    let (device, queue) = (&ctx.device, &ctx.queue);
    let timer = GpuTimer::new(device, queue);
    let params = GranularParams::snow();
    let pen_pass = PenetrationPass::new(device).expect("pen");
    let jfa = JumpFloodPass::new(device).expect("jfa");
    let displace = DisplacePass::new(device).expect("displace");
    let slope = SlopePass::new(device).expect("slope");

    let mut group = c.benchmark_group("gpu_granular");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(200));
    group.measurement_time(Duration::from_secs(1));
    for (map_side, side) in CASES {
        let grid = Grid::new(map_side, map_side, 10_000u32).expect("grid");
        let map = FixedPointMap::fixed_point(grid, 10_000, 0.1).expect("map");
        let gmap = GpuGranularMap::from_map(device, queue, &map).expect("upload");
        let min = IVec2::splat(((map_side - side) / 2) as i32);
        let area = Rect::new(min, UVec2::splat(side));
        // An object sinking 0.05 m into the middle third of the area.
        let centre = Vec2::splat(side as f32 * 0.5);
        let depth = Grid::from_fn(side, side, |i, j| {
            if (Vec2::new(i as f32, j as f32) - centre).length() < side as f32 / 6.0 {
                9_500
            } else {
                NO_OBJECT
            }
        })
        .expect("depth");
        let depth_buf = PenetrationPass::upload_depth(device, &depth);
        let scratch = GranularScratch::new(device, area.area()).expect("scratch");
        let thresholds = params.slope_thresholds_units(0.1, 10_000.0);
        let label = format!("{map_side}/{}", area.area());
        // Times one recorded closure as wall time of submit + wait.
        let time = |b: &mut criterion::Bencher<'_>,
                    work: &dyn Fn(
            &mut wgpu::CommandEncoder,
        ) -> Result<(), terrain_gpu::GpuError>| {
            b.iter_custom(|iters| {
                (0..iters)
                    .map(|_| {
                        let t = timer
                            .time(device, queue, |enc| work(enc))
                            .expect("gpu work");
                        Duration::from_secs_f64(t.ms / 1e3)
                    })
                    .sum()
            })
        };
        // Each step on its own (the steps before it ran once, so its inputs are in place).
        let penetrate = |enc: &mut wgpu::CommandEncoder| {
            pen_pass.encode(device, enc, &gmap, &depth_buf, area, 5000, &scratch)
        };
        let flood = |enc: &mut wgpu::CommandEncoder| {
            jfa.encode(
                device,
                enc,
                gmap.size(),
                area,
                params.metric,
                params.jfa_extra_pass,
                &scratch,
            )
            .map(|_| ())
        };
        let mut seeds = 0;
        timer
            .time(device, queue, |enc| {
                penetrate(enc)?;
                seeds = jfa.encode(
                    device,
                    enc,
                    gmap.size(),
                    area,
                    params.metric,
                    params.jfa_extra_pass,
                    &scratch,
                )?;
                Ok(())
            })
            .expect("prepare");
        let displace_closest = |enc: &mut wgpu::CommandEncoder| {
            displace.encode(
                device,
                enc,
                &gmap,
                area,
                DisplacementMethod::ClosestSeed,
                params.keep_q15(),
                seeds,
                &scratch,
            )
        };
        let slopes = |enc: &mut wgpu::CommandEncoder| {
            slope.encode(
                device,
                enc,
                &gmap,
                area,
                SlopeMethod::Scatter,
                thresholds,
                params.roughness_q15(),
                params.num_iterations_even_out_slopes,
                &scratch,
            )
        };
        group.bench_function(BenchmarkId::new("penetration", &label), |b| {
            time(b, &penetrate)
        });
        group.bench_function(BenchmarkId::new("jump_flooding", &label), |b| {
            time(b, &flood)
        });
        group.bench_function(BenchmarkId::new("displace_closest_seed", &label), |b| {
            time(b, &displace_closest)
        });
        group.bench_function(BenchmarkId::new("slopes_scatter10", &label), |b| {
            time(b, &slopes)
        });
        group.bench_function(BenchmarkId::new("step", &label), |b| {
            time(b, &|enc| {
                penetrate(enc)?;
                let s = jfa.encode(
                    device,
                    enc,
                    gmap.size(),
                    area,
                    params.metric,
                    params.jfa_extra_pass,
                    &scratch,
                )?;
                displace.encode(
                    device,
                    enc,
                    &gmap,
                    area,
                    DisplacementMethod::ClosestSeed,
                    params.keep_q15(),
                    s,
                    &scratch,
                )?;
                slopes(enc)
            })
        });
    }
    group.finish();
    vehicles(c, &ctx);
    ctx.check().expect("validation");
}

/// Seed 001 table 5.7 setting, as terrain-core's CPU bench: a 2048 map over 300 m, box cars
/// sinking 0.1 m into 1 m of snow, closest seed + scatter, one slope iteration; whole steps
/// (depth rasterised on the CPU and uploaded) over the merged active areas, and over the full
/// map for 1 and 8 cars.
fn vehicles(c: &mut Criterion, ctx: &GpuContext) {
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut g = c.benchmark_group("gpu_granular_vehicles_2048");
    g.sample_size(10);
    g.warm_up_time(Duration::from_millis(200));
    g.measurement_time(Duration::from_secs(1));
    let texel = 300.0 / 2048.0;
    let params = GranularParams {
        num_iterations_even_out_slopes: 1,
        active_area_margin: 40,
        ..GranularParams::default()
    };
    let car = TriMesh::cuboid(Vec3::new(2.0, 0.8, 4.0)).expect("car");
    let snow = FixedPointMap::fixed_point(
        Grid::new(2048, 2048, 10_000u32).expect("grid"),
        10_000,
        texel,
    )
    .expect("map");
    let gmap = GpuGranularMap::from_map(device, queue, &snow).expect("upload");
    for cars in 1..=8u32 {
        let objs: Vec<GranularObject<'_>> = (0..cars)
            .map(|i| {
                GranularObject::new(
                    &car,
                    Affine3A::from_translation(Vec3::new(30.0 + 33.0 * i as f32, 1.7, 150.0)),
                )
            })
            .collect();
        let modes: &[AreaMode] = if cars == 1 || cars == 8 {
            &[AreaMode::ActiveAreas, AreaMode::FullMap]
        } else {
            &[AreaMode::ActiveAreas]
        };
        for &mode in modes {
            let mut step = GpuGranularStep::new(device, params).expect("step");
            step.area_mode = mode;
            let name = match mode {
                AreaMode::ActiveAreas => "active_areas",
                AreaMode::FullMap => "full_map",
            };
            g.bench_function(BenchmarkId::new(name, cars), |b| {
                b.iter_custom(|iters| {
                    (0..iters)
                        .map(|_| {
                            let t = std::time::Instant::now();
                            step.step(device, queue, &gmap, &objs).expect("gpu step");
                            t.elapsed()
                        })
                        .sum()
                })
            });
            // Restore the snow so every case starts from the same field.
            gmap.write(queue, &snow).expect("reset");
        }
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
