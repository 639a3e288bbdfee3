//! PNG16 encode / decode (in memory and through files) and procedural terrain generation at 4096 x 4096, each beside a plain
//! copy of the same 32 MiB of heights.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::UVec2;
use std::hint::black_box;
use terrain_core::io::{ReadLimits, decode_png16, encode_png16};
use terrain_core::{TerrainParams, generate_heights};

const SIDE: u32 = 4096;

fn bench(c: &mut Criterion) {
    let params = TerrainParams {
        size: UVec2::splat(SIDE),
        ..TerrainParams::default()
    };
    let bytes = u64::from(SIDE) * u64::from(SIDE) * 2;

    let mut group = c.benchmark_group("io_and_generation");
    group.sample_size(10);
    group.warm_up_time(std::time::Duration::from_millis(500));
    group.measurement_time(std::time::Duration::from_secs(5));
    group.throughput(Throughput::Bytes(bytes));

    let map = terrain_core::generate_coarse_map(
        &params,
        terrain_core::HeightEncoding::spanning::<u16>(0.0, 100.0).expect("encoding"),
        0.1,
    )
    .expect("terrain");
    let png = encode_png16(map.grid()).expect("encode");
    let limits = ReadLimits::default();

    group.bench_function("png16_encode/4096", |b| {
        b.iter(|| encode_png16(black_box(map.grid())).expect("encode"))
    });
    group.bench_function("png16_decode/4096", |b| {
        b.iter(|| decode_png16(black_box(&png), &limits).expect("decode"))
    });
    // Files in the system's temp folder: write includes the fsync of the atomic write.
    let dir = std::env::temp_dir().join(format!("terrain-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("map.png");
    group.bench_function("png16_write_file/4096", |b| {
        b.iter(|| terrain_core::io::write_png16(&path, black_box(map.grid())).expect("write"))
    });
    group.bench_function("png16_read_file/4096", |b| {
        b.iter(|| terrain_core::io::read_png16(&path, &limits).expect("read"))
    });
    let _ = std::fs::remove_dir_all(&dir);
    group.bench_function("terrain_generate/4096", |b| {
        b.iter(|| generate_heights(black_box(&params)).expect("terrain"))
    });
    let src = map.grid().as_slice().to_vec();
    let mut dst = vec![0u16; src.len()];
    group.bench_function("memcpy/4096", |b| {
        b.iter(|| dst.copy_from_slice(black_box(&src)))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
