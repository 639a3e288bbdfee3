//! Readback for collision (Flower 2010, table 4.5: a full 4096 x 4096 u16 readback took 60.5 ms,
//! 51 ms of it the system copy with u16 -> f32 conversion): the full map and a 256 x 256 dirty
//! region through `RegionReadback`, each as u16 rows (what the collision mirror keeps) and
//! converted to f32 metres, from request to rows in hand.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::{IVec2, UVec2};
use std::hint::black_box;
use std::time::Duration;
use terrain_core::{CoarseMap, Grid, HeightEncoding, Rect};
use terrain_gpu::{GpuContext, GpuHeightMap, RegionReadback};

fn bench(c: &mut Criterion) {
    let ctx = GpuContext::new_headless().expect("a GPU adapter (lavapipe: mesa-vulkan-drivers)");
    let r = ctx.report();
    eprintln!("adapter: {} ({}, {})", r.name, r.backend, r.device_type);
    let (device, queue) = (&ctx.device, &ctx.queue);
    let grid = Grid::from_fn(4096, 4096, |x, y| (x ^ y) as u16).expect("grid");
    let map =
        CoarseMap::coarse(grid, HeightEncoding::new(0.01, 0.0).expect("enc"), 0.1).expect("map");
    let gpu = GpuHeightMap::from_map(device, queue, &map).expect("upload");
    let mut readback = RegionReadback::new(device, 2).expect("ring");

    let mut group = c.benchmark_group("gpu_readback");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(300));
    group.measurement_time(Duration::from_secs(3));
    let full = Rect::from_size(UVec2::splat(4096));
    let region = Rect::new(IVec2::new(1000, 2000), UVec2::splat(256));
    // As the collision mirror reads: converted straight from the staging buffer.
    let mut read = |rect: Rect, metres: bool| {
        let mut encoder = device.create_command_encoder(&Default::default());
        readback
            .request(device, &mut encoder, &gpu, rect)
            .expect("request");
        queue.submit([encoder.finish()]);
        let mut arrived = readback
            .wait_with(device, |r| {
                if metres {
                    (None, Some(r.to_metres().expect("metres")))
                } else {
                    (Some(r.to_u16().expect("u16")), None)
                }
            })
            .expect("wait");
        arrived.pop().expect("one region")
    };
    group.bench_function("full_4096_u16", |b| b.iter(|| black_box(read(full, false))));
    group.bench_function("full_4096_f32_metres", |b| {
        b.iter(|| black_box(read(full, true)))
    });
    group.bench_function("region_256_u16", |b| {
        b.iter(|| black_box(read(region, false)))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
