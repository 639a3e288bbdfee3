//! Tile atlas uploads (Fikkan 2013, sec. 5.3 budgets transfers per frame): one 256^2 tile of u16
//! heights into a `GpuTileAtlas` slot (packed two to a u32 word, `queue.write_buffer`,
//! submitted and waited for), beside a plain `queue.write_buffer` of the same 256 KiB already widened, and a
//! plain CPU copy of those bytes.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::UVec2;
use std::hint::black_box;
use std::time::Duration;
use terrain_core::{Grid, HeightEncoding, TileLayout, TileUploadTarget, WrapMode};
use terrain_gpu::{AtlasConfig, GpuContext, GpuTileAtlas};

fn bench(c: &mut Criterion) {
    let ctx = GpuContext::new_headless().expect("a GPU adapter (lavapipe: mesa-vulkan-drivers)");
    let r = ctx.report();
    eprintln!("adapter: {} ({}, {})", r.name, r.backend, r.device_type);
    let (device, queue) = (&ctx.device, &ctx.queue);
    let layout = TileLayout {
        world_size: UVec2::splat(4096),
        tile_size: 256,
        levels: 5,
        texel_size: 1.0,
        encoding: HeightEncoding::new(0.01, 0.0).expect("encoding"),
        wrap: WrapMode::Clamp,
        fill: 0,
    };
    let config = AtlasConfig {
        slots: 64,
        world: layout,
    };
    let mut atlas = GpuTileAtlas::new(device, queue, &config).expect("atlas");
    let tile = Grid::from_fn(256, 256, |x, y| (x * 31 + y * 17) as u16).expect("tile");
    let widened: Vec<u32> = tile.as_slice().iter().map(|&v| u32::from(v)).collect();
    let bytes: &[u8] = bytemuck::cast_slice(&widened);
    let plain = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("plain copy target"),
        size: bytes.len() as u64,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut cpu_copy = vec![0u8; bytes.len()];
    let wait = || {
        queue.submit([]);
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .expect("poll");
    };

    let mut group = c.benchmark_group("atlas");
    group.sample_size(30);
    group.warm_up_time(Duration::from_millis(500));
    group.measurement_time(Duration::from_secs(3));
    group.throughput(Throughput::Bytes(bytes.len() as u64));
    let mut slot = 0u32;
    group.bench_function("upload_tile/256", |b| {
        b.iter(|| {
            slot = (slot + 1) % config.slots;
            let n = atlas
                .upload(slot, 0, UVec2::new(slot % 16, slot / 16), &tile)
                .expect("upload");
            wait();
            black_box(n)
        })
    });
    group.bench_function("plain_write_buffer_u32/256", |b| {
        b.iter(|| {
            queue.write_buffer(&plain, 0, bytes);
            wait();
        })
    });
    group.bench_function("plain_cpu_copy_u32/256", |b| {
        b.iter(|| {
            cpu_copy.copy_from_slice(black_box(bytes));
            black_box(&cpu_copy);
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
