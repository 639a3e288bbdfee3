//! GPU density maps of 1M to 8M height samples with each curvature filter, beside Cervin 2012
//! table 4.1 (Xeon X5650 CPU: 0.14 s to 11.04 s) and terrain-lod's CPU `density` bench. Wall
//! time of submit + wait (timestamps where the adapter has them). Prints the adapter first.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use glam::UVec2;
use std::time::Duration;
use terrain_core::{HeightEncoding, TerrainParams};
use terrain_gpu::{DensityPass, GpuContext, GpuDensityMap, GpuHeightMap, GpuTimer};
use terrain_lod::{CurvatureFilter, DensityParams};

/// Sides of square maps of about 1M, 2M, 4M and 8M samples (table 4.1's rows).
const SIDES: [(u32, &str); 4] = [(1024, "1M"), (1448, "2M"), (2048, "4M"), (2896, "8M")];

fn bench(c: &mut Criterion) {
    let ctx = GpuContext::new_headless().expect("a GPU adapter (lavapipe: mesa-vulkan-drivers)");
    let r = ctx.report();
    eprintln!("adapter: {} ({}, {})", r.name, r.backend, r.device_type);
    let (device, queue) = (&ctx.device, &ctx.queue);
    let timer = GpuTimer::new(device, queue);
    let mut pass = DensityPass::new(device).expect("density pass");
    let enc = HeightEncoding::spanning::<u16>(0.0, 100.0).expect("encoding");
    let mut group = c.benchmark_group("gpu_density");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(300));
    group.measurement_time(Duration::from_secs(2));
    let quick = std::env::var_os("TERRAIN_BENCH_QUICK").is_some();
    for (side, label) in SIDES {
        if quick && side > 2048 {
            continue;
        }
        let params = TerrainParams {
            size: UVec2::splat(side),
            ..TerrainParams::default()
        };
        let map = terrain_core::generate_coarse_map(&params, enc, 0.1).expect("terrain");
        let gpu_map = GpuHeightMap::from_map(device, queue, &map).expect("upload");
        for filter in CurvatureFilter::ALL {
            let p = DensityParams {
                filter,
                ..DensityParams::default()
            };
            let out = GpuDensityMap::for_map(device, &gpu_map, p).expect("density map");
            let mut run = || -> Duration {
                let t = timer
                    .time(device, queue, |encoder| {
                        pass.encode_full(device, queue, encoder, &gpu_map, &out)
                    })
                    .expect("gpu work");
                pass.recall();
                Duration::from_secs_f64(t.ms / 1e3)
            };
            group.bench_function(BenchmarkId::new(filter.name(), label), |b| {
                b.iter_custom(|iters| (0..iters).map(|_| run()).sum())
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
