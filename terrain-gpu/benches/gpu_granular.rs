//! GPU time of each granular step (penetration, jump flooding, closest-seed displacement,
//! 10 scatter slope iterations) and of the whole step over one active area of about 3 774, 15 100, 60 398 and
//! 241 591 columns on maps of 512 to 4096 a side (the setting of Persson 2019, table 5.4), as the
//! wall time of submit + wait measured by `GpuTimer`; then whole steps with 1 to 8 vehicles,
//! active areas versus the full map (table 5.7); then a streamed world's granular window moving
//! on, shifted on the GPU or stopped and started again. Prints the adapter first.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use glam::{Affine3A, Vec3};
use glam::{IVec2, UVec2, Vec2};
use std::time::Duration;
use terrain_core::granular::{
    AreaMode, DisplacementMethod, GranularObject, GranularParams, NO_OBJECT, SlopeMethod, TriMesh,
};
use terrain_core::{FixedPointMap, Grid, Rect};
use terrain_gpu::granular::{
    DisplacePass, GpuGranularStep, GranularArea, GranularField, GranularScratch, JumpFloodPass,
    PenetrationPass, SlopePass, SlopeSettings,
};
use terrain_gpu::{GpuContext, GpuError, GpuHeightMap, GpuTimer};

/// (map side, active-area side): sides of 61, 123, 246 and 492 give 3 721, 15 129, 60 516 and
/// 242 064 columns.
const CASES: [(u32, u32); 4] = [(512, 61), (1024, 123), (2048, 246), (4096, 492)];

/// The integer passes, built once for every case.
struct Passes {
    penetration: PenetrationPass,
    jfa: JumpFloodPass,
    displace: DisplacePass,
    slope: SlopePass,
}

impl Passes {
    fn recall(&mut self) {
        self.penetration.recall();
        self.jfa.recall();
        self.displace.recall();
        self.slope.recall();
    }
}

/// Times `work`, recorded into a fresh encoder per iteration, as the wall time of submit +
/// wait; the passes recall after each submit.
fn time(
    b: &mut criterion::Bencher<'_>,
    ctx: &GpuContext,
    timer: &GpuTimer,
    passes: &mut Passes,
    mut work: impl FnMut(&mut Passes, &mut wgpu::CommandEncoder) -> Result<(), GpuError>,
) {
    b.iter_custom(|iters| {
        (0..iters)
            .map(|_| {
                let t = timer
                    .time(&ctx.device, &ctx.queue, |enc| work(passes, enc))
                    .expect("gpu work");
                passes.recall();
                Duration::from_secs_f64(t.ms / 1e3)
            })
            .sum()
    })
}

fn bench(c: &mut Criterion) {
    let ctx = GpuContext::new_headless().expect("a GPU adapter (lavapipe: mesa-vulkan-drivers)");
    let r = ctx.report();
    eprintln!("adapter: {} ({}, {})", r.name, r.backend, r.device_type);
    let (device, queue) = (&ctx.device, &ctx.queue);
    let timer = GpuTimer::new(device, queue);
    let params = GranularParams::snow();
    let mut passes = Passes {
        penetration: PenetrationPass::new(device).expect("pen"),
        jfa: JumpFloodPass::new(device).expect("jfa"),
        displace: DisplacePass::new(device).expect("displace"),
        slope: SlopePass::new(device).expect("slope"),
    };

    let mut group = c.benchmark_group("gpu_granular");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(200));
    group.measurement_time(Duration::from_secs(1));
    for (map_side, side) in CASES {
        let grid = Grid::new(map_side, map_side, 10_000u32).expect("grid");
        let map = FixedPointMap::fixed_point(grid, 10_000, 0.1).expect("map");
        let gmap = GpuHeightMap::from_map(device, queue, &map).expect("upload");
        let min = IVec2::splat(((map_side - side) / 2) as i32);
        let rect = Rect::new(min, UVec2::splat(side));
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
        let scratch = GranularScratch::new(device, rect.area()).expect("scratch");
        let area = GranularArea::new(device, &gmap, rect, &scratch).expect("area");
        let slopes = SlopeSettings::from_params(&params, 0.1, 10_000.0);
        let label = format!("{map_side}/{}", rect.area());
        // The depth goes up once; each step is timed on its own (the steps before it ran once,
        // so its inputs are in place).
        let mut flooded = None;
        timer
            .time(device, queue, |enc| {
                let p = &mut passes;
                p.penetration
                    .upload_depth(device, queue, enc, &area, &depth)?;
                p.penetration.encode(device, queue, enc, &area, 5000)?;
                flooded = Some(p.jfa.encode(
                    device,
                    queue,
                    enc,
                    &area,
                    params.metric,
                    params.jfa_extra_pass,
                )?);
                Ok(())
            })
            .expect("prepare");
        passes.recall();
        let flooded = flooded.expect("flooded");
        group.bench_function(BenchmarkId::new("penetration", &label), |b| {
            time(b, &ctx, &timer, &mut passes, |p, enc| {
                p.penetration.encode(device, queue, enc, &area, 5000)
            })
        });
        group.bench_function(BenchmarkId::new("jump_flooding", &label), |b| {
            time(b, &ctx, &timer, &mut passes, |p, enc| {
                p.jfa
                    .encode(
                        device,
                        queue,
                        enc,
                        &area,
                        params.metric,
                        params.jfa_extra_pass,
                    )
                    .map(|_| ())
            })
        });
        group.bench_function(BenchmarkId::new("displace_closest_seed", &label), |b| {
            time(b, &ctx, &timer, &mut passes, |p, enc| {
                p.displace.encode(
                    device,
                    queue,
                    enc,
                    &flooded,
                    DisplacementMethod::ClosestSeed,
                    params.keep_q15(),
                )
            })
        });
        group.bench_function(BenchmarkId::new("slopes_scatter10", &label), |b| {
            time(b, &ctx, &timer, &mut passes, |p, enc| {
                p.slope
                    .encode(device, queue, enc, &area, SlopeMethod::Scatter, &slopes)
            })
        });
        group.bench_function(BenchmarkId::new("step", &label), |b| {
            time(b, &ctx, &timer, &mut passes, |p, enc| {
                p.penetration.encode(device, queue, enc, &area, 5000)?;
                let flooded = p.jfa.encode(
                    device,
                    queue,
                    enc,
                    &area,
                    params.metric,
                    params.jfa_extra_pass,
                )?;
                p.displace.encode(
                    device,
                    queue,
                    enc,
                    &flooded,
                    DisplacementMethod::ClosestSeed,
                    params.keep_q15(),
                )?;
                p.slope
                    .encode(device, queue, enc, &area, SlopeMethod::Scatter, &slopes)
            })
        });
    }
    group.finish();
    vehicles(c, &ctx);
    window_moves(c, &ctx);
    ctx.check().expect("validation");
}

/// Persson 2019, table 5.7 setting, as terrain-core's CPU bench: a 2048 map over 300 m, box cars
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
    let gmap = GpuHeightMap::from_map(device, queue, &snow).expect("upload");
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

/// A streamed world's granular window (128^2, a wheel's step just submitted) moving on, as the
/// frame thread sees it: `GranularField::shift` (the shared columns copied on the GPU, nothing
/// waited for) against stopping the map (`finish`, which waits for the step's readbacks) and
/// starting the next from its passes. Only the move is timed; the drains after it are not.
fn window_moves(c: &mut Criterion, ctx: &GpuContext) {
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut g = c.benchmark_group("gpu_granular_window_move_128");
    g.sample_size(10);
    g.warm_up_time(Duration::from_millis(200));
    g.measurement_time(Duration::from_secs(2));
    let map =
        FixedPointMap::fixed_point(Grid::new(128, 128, 10_000u32).expect("grid"), 10_000, 0.5)
            .expect("map");
    let wheel = TriMesh::wheel(0.6, 0.3, 24).expect("wheel");
    let at = Affine3A::from_translation(Vec3::new(40.0, 1.5, 32.0));
    let objs = [GranularObject::new(&wheel, at)];
    let params = GranularParams::snow();
    let mut field = Some(GranularField::new(device, queue, &map, params, None).expect("field"));
    // Each move drains both maps after it; with `recycle` the retired field is handed back, so
    // the next shift writes into its buffers and the replaced normals instead of allocating.
    for (name, recycle) in [("shift", false), ("shift_recycled", true)] {
        g.bench_function(name, |b| {
            b.iter_custom(|iters| {
                let f = field.as_mut().expect("field");
                (0..iters)
                    .map(|i| {
                        f.step(device, queue, &objs, i).expect("step");
                        let t = std::time::Instant::now();
                        let (mut retired, _) = f
                            .shift(device, queue, &map, IVec2::new(32, 0), u64::MAX)
                            .expect("shift");
                        let spent = t.elapsed();
                        retired.drain(device, queue).expect("drain retired");
                        if recycle {
                            let kept = f.recycle(retired).is_none();
                            assert!(kept, "a drained field is taken back");
                        }
                        f.drain(device, queue).expect("drain");
                        spent
                    })
                    .sum()
            })
        });
    }
    g.bench_function("stop_and_start", |b| {
        b.iter_custom(|iters| {
            (0..iters)
                .map(|i| {
                    let mut f = field.take().expect("field");
                    f.step(device, queue, &objs, i).expect("step");
                    let t = std::time::Instant::now();
                    let (_, passes) = f.finish(device, queue).expect("finish");
                    let next = GranularField::new(device, queue, &map, params, Some(passes));
                    let spent = t.elapsed();
                    field = Some(next.expect("field"));
                    spent
                })
                .sum()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
