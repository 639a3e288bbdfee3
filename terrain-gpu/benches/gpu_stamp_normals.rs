//! GPU time of stamp + normal regeneration over square regions of 100 to 2000 texels a side on a
//! 4096 x 4096 coarse-map (Flower 2010, table 4.3), from timestamp queries where the adapter has
//! them, else wall time with a blocking poll. Prints the adapter first.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use glam::{UVec2, Vec2};
use std::time::Duration;
use terrain_core::{Blend, GaussianStamp, HeightEncoding, StampPlacement, TerrainParams};
use terrain_gpu::{
    GpuContext, GpuDerivativeMap, GpuHeightMap, GpuStamp, GpuTimer, NormalPass, StampOp, StampPass,
};

const MAP: u32 = 4096;
const TEXEL: f32 = 0.1;
const SIDES: [u32; 5] = [100, 200, 500, 1000, 2000];

fn bench(c: &mut Criterion) {
    let ctx = GpuContext::new_headless().expect("a GPU adapter (lavapipe: mesa-vulkan-drivers)");
    let r = ctx.report();
    eprintln!("adapter: {} ({}, {})", r.name, r.backend, r.device_type);
    let (device, queue) = (&ctx.device, &ctx.queue);
    let params = TerrainParams {
        size: UVec2::splat(MAP),
        ..TerrainParams::default()
    };
    let enc = HeightEncoding::spanning::<u16>(0.0, 100.0).expect("encoding");
    let map = terrain_core::generate_coarse_map(&params, enc, TEXEL).expect("terrain");
    let gpu_map = GpuHeightMap::from_map(device, queue, &map).expect("upload");
    let normals = GpuDerivativeMap::for_map(device, &gpu_map).expect("normals");
    let (mut stamps, mut normal_pass) = (
        StampPass::new(device).expect("stamp pass"),
        NormalPass::new(device).expect("normal pass"),
    );
    let timer = GpuTimer::new(device, queue);
    eprintln!(
        "GPU timestamps available: {} (wall time of submit + wait is measured)",
        timer.has_timestamps()
    );
    let gauss = GaussianStamp::default();
    let centre = Vec2::splat(MAP as f32 * TEXEL * 0.5);

    let mut group = c.benchmark_group("gpu_stamp_normals");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(300));
    group.measurement_time(Duration::from_secs(2));
    for side in SIDES {
        let scale = Vec2::splat(side as f32 * TEXEL);
        let mut sign = 1.0;
        // Normals alone are `stamp_and_normals` minus `stamp`.
        let mut run = |with_normals: bool| -> Duration {
            sign = -sign;
            let p = StampPlacement::new(centre, scale, sign).expect("placement");
            let t = timer
                .time(device, queue, |encoder| {
                    let rects = stamps.encode(
                        device,
                        queue,
                        encoder,
                        &gpu_map,
                        &StampOp {
                            stamp: GpuStamp::Gaussian(&gauss),
                            placement: p,
                            blend: Blend::Add,
                        },
                    )?;
                    if with_normals {
                        for r in rects {
                            normal_pass.encode(device, queue, encoder, &gpu_map, &normals, r)?;
                        }
                    }
                    Ok(())
                })
                .expect("gpu work");
            // The work was submitted: its uniform slots are free again.
            stamps.recall();
            normal_pass.recall();
            Duration::from_secs_f64(t.ms / 1e3)
        };
        group.bench_function(BenchmarkId::new("stamp", side), |b| {
            b.iter_custom(|iters| (0..iters).map(|_| run(false)).sum())
        });
        group.bench_function(BenchmarkId::new("stamp_and_normals", side), |b| {
            b.iter_custom(|iters| (0..iters).map(|_| run(true)).sum())
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
