//! Tile decode, encode, load-to-RAM (store read + decode) and write-back (encode + atomic write
//! with fsync) of 256^2 and 2048^2 height tiles, each beside a plain copy of the same bytes
//! (memcpy, and a plain file read / write without fsync). Compare with Fikkan 2013, graph 6.2
//! (1.6 ms per 256^2 block from SSD) and Flower 2010, tables 4.6 / 4.7 (160.7 ms to page a 2048^2
//! detail tile out, 47.1 ms projected to load one).

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::UVec2;
use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;
use terrain_cache::{
    FsStore, Layer, Manifest, ProceduralSource, TileData, TileId, TileSource, TileStore, World,
};
use terrain_core::{HeightEncoding, Rect, TerrainParams, WrapMode};

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("tile");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(300));
    group.measurement_time(Duration::from_secs(2));
    let base = TerrainParams {
        size: UVec2::splat(256),
        ..TerrainParams::default()
    };
    for side in [256u32, 2048] {
        let dir =
            std::env::temp_dir().join(format!("terrain-cache-bench-{side}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let store: Arc<dyn TileStore> = Arc::new(FsStore::open(&dir).expect("store"));
        let enc = HeightEncoding::spanning::<u16>(0.0, 500.0).expect("encoding");
        let m = Manifest::new(UVec2::splat(side * 2), side, 0.5, enc, WrapMode::Repeat)
            .expect("manifest");
        let world = World::create(store.clone(), m).expect("world");
        let src = ProceduralSource::new(UVec2::splat(side * 2), &base, 4, 0.02).expect("source");
        let grid = src
            .region(Rect::new(glam::IVec2::ZERO, UVec2::splat(side)))
            .expect("region");
        let data = TileData::U16(grid);
        let id = TileId::new(0, 0, 0);
        let png = world.encode_tile(Layer::Height, &data).expect("encode");
        world.write_tile(Layer::Height, id, &data).expect("write");
        let raw = data.as_bytes().to_vec();
        let raw_path = dir.join("raw.bin");
        std::fs::write(&raw_path, &raw).expect("raw");
        eprintln!(
            "tile {side}^2: {} raw bytes, PNG16 {} bytes ({:.0} %)",
            raw.len(),
            png.len(),
            100.0 * png.len() as f64 / raw.len() as f64
        );
        group.throughput(Throughput::Bytes(raw.len() as u64));

        group.bench_function(format!("decode_png16/{side}"), |b| {
            b.iter(|| {
                world
                    .decode_tile(Layer::Height, id, black_box(&png))
                    .expect("decode")
            })
        });
        group.bench_function(format!("encode_png16/{side}"), |b| {
            b.iter(|| {
                world
                    .encode_tile(Layer::Height, black_box(&data))
                    .expect("encode")
            })
        });
        group.bench_function(format!("load_to_ram/{side}"), |b| {
            b.iter(|| world.load_tile(Layer::Height, black_box(id)).expect("load"))
        });
        group.bench_function(format!("write_back_fsync/{side}"), |b| {
            b.iter(|| {
                world
                    .write_tile(Layer::Height, black_box(id), &data)
                    .expect("write")
            })
        });
        group.bench_function(format!("plain_memcpy/{side}"), |b| {
            b.iter(|| black_box(&raw).clone())
        });
        group.bench_function(format!("plain_file_read/{side}"), |b| {
            b.iter(|| std::fs::read(black_box(&raw_path)).expect("read"))
        });
        group.bench_function(format!("plain_file_write/{side}"), |b| {
            b.iter(|| std::fs::write(black_box(&raw_path), &raw).expect("write"))
        });
        let _ = std::fs::remove_dir_all(&dir);
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
