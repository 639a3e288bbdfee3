//! GPU time of one granular step (penetration, jump flooding, closest-seed displacement and
//! 10 scatter slope iterations) over one active area of about 3 774, 15 100, 60 398 and
//! 241 591 columns on maps of 512 to 4096 a side (the setting of seed 001 table 5.4), as the
//! wall time of submit + wait measured by `GpuTimer`. Prints the adapter first.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use glam::{IVec2, UVec2, Vec2};
use std::time::Duration;
use terrain_core::granular::{DisplacementMethod, GranularParams, NO_OBJECT, SlopeMethod};
use terrain_core::{FixedPointMap, Grid, Rect};
use terrain_gpu::granular::{
    DisplacePass, GpuGranularMap, GranularScratch, JumpFloodPass, PenetrationPass, SlopePass,
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
        let id = BenchmarkId::new("step", format!("{map_side}/{}", area.area()));
        group.bench_function(id, |b| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    let t = timer
                        .time(device, queue, |enc| {
                            pen_pass
                                .encode(device, enc, &gmap, &depth_buf, area, 5000, &scratch)?;
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
                        })
                        .expect("step");
                    total += Duration::from_secs_f64(t.ms / 1e3);
                }
                total
            })
        });
    }
    group.finish();
    ctx.check().expect("validation");
}

criterion_group!(benches, bench);
criterion_main!(benches);
