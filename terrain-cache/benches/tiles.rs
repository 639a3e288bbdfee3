//! Tile files of 256^2 and 2048^2 height tiles: load to RAM (store read + decode) and write-back
//! (encode + atomic write with fsync) of `.tile` files (raw, the heights' codec, and LZ4) and of
//! the PNG16 files of version-1 worlds, beside plain handling of the same samples measured in
//! the same run: `plain_read_copy` (`std::fs::read` of a warm file of the raw samples, then a
//! copy of its bytes into a `u16` buffer, what any load must at least do), memcpy, and a plain
//! file read / write without fsync. Compare with Flower 2010, tables 4.7 / 4.6's disk side
//! ("System and Hdd": 22.4 ms to load a 2048^2 8-bit detail tile, 134.0 ms to write one; their
//! 47.1 / 160.7 ms totals add the GPU bus copy). Fikkan 2013, graph 6.2's 1.6 ms per 256^2 block
//! is an average over 1 000 random cold reads of texture and heights: these warm reads of one
//! file do not measure the disk.
//!
//! `TERRAIN_BENCH_QUICK=1` measures 256^2 only, briefly.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::UVec2;
use std::hint::black_box;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;
use terrain_cache::tile_file::{self, TileCodec};
use terrain_cache::{
    FsStore, Layer, Manifest, ProceduralSource, TileData, TileFormat, TileId, TileSource,
    TileStore, World,
};
use terrain_core::{Grid, HeightEncoding, Rect, TerrainParams, WrapMode};

/// A world of `format` in `dir` with tiles of `side`.
fn world(dir: &Path, side: u32, format: TileFormat) -> World {
    let _ = std::fs::remove_dir_all(dir);
    let store: Arc<dyn TileStore> = Arc::new(FsStore::open(dir).expect("store"));
    let enc = HeightEncoding::spanning::<u16>(0.0, 500.0).expect("encoding");
    let mut m =
        Manifest::new(UVec2::splat(side * 2), side, 0.5, enc, WrapMode::Repeat).expect("manifest");
    m.tile_format = format;
    m.format_version = format.format_version();
    World::create(store, m).expect("world")
}

/// The raw samples as a file, and a read of it with the copy every load makes.
fn plain_read_copy(path: &Path, samples: usize) -> Vec<u16> {
    let bytes = std::fs::read(path).expect("read");
    let mut out = vec![0u16; samples];
    bytemuck::cast_slice_mut::<u16, u8>(&mut out).copy_from_slice(&bytes);
    out
}

fn bench(c: &mut Criterion) {
    let quick = std::env::var_os("TERRAIN_BENCH_QUICK").is_some();
    let mut group = c.benchmark_group("tile");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(if quick { 200 } else { 500 }));
    group.measurement_time(Duration::from_secs(if quick { 1 } else { 2 }));
    let base = TerrainParams {
        size: UVec2::splat(256),
        ..TerrainParams::default()
    };
    let sides: &[u32] = if quick { &[256] } else { &[256, 2048] };
    for &side in sides {
        let root =
            std::env::temp_dir().join(format!("terrain-cache-bench-{side}-{}", std::process::id()));
        let tile_world = world(&root.join("tile"), side, TileFormat::Tile);
        let lz4_world = world(&root.join("lz4"), side, TileFormat::Tile);
        let png_world = world(&root.join("png"), side, TileFormat::Png);
        let src = ProceduralSource::new(UVec2::splat(side * 2), &base, 4, 0.02).expect("source");
        let grid: Grid<u16> = src
            .region(Rect::new(glam::IVec2::ZERO, UVec2::splat(side)))
            .expect("region");
        let data = TileData::U16(grid.clone());
        let id = TileId::new(0, 0, 0);
        let raw_file = tile_file::encode_u16(&grid, TileCodec::Raw);
        let lz4_file = tile_file::encode_u16(&grid, TileCodec::Lz4);
        let png = png_world.encode_tile(Layer::Height, &data).expect("encode");
        tile_world
            .write_tile(Layer::Height, id, &data)
            .expect("write");
        png_world
            .write_tile(Layer::Height, id, &data)
            .expect("write");
        // The heights' codec is raw; an LZ4 file at the same key reads the same (the header
        // names the codec), which measures what loading LZ4 heights would cost.
        lz4_world
            .store()
            .write(&lz4_world.manifest().tile_key(Layer::Height, id), &lz4_file)
            .expect("write");
        let raw = data.as_bytes().to_vec();
        let raw_path = root.join("raw.bin");
        std::fs::write(&raw_path, &raw).expect("raw");
        eprintln!(
            "tile {side}^2: {} raw bytes; .tile raw {} bytes, .tile LZ4 {} bytes ({:.0} %), PNG16 {} \
             bytes ({:.0} %)",
            raw.len(),
            raw_file.len(),
            lz4_file.len(),
            100.0 * lz4_file.len() as f64 / raw.len() as f64,
            png.len(),
            100.0 * png.len() as f64 / raw.len() as f64
        );
        group.throughput(Throughput::Bytes(raw.len() as u64));

        let n = (side * side) as usize;
        group.bench_function(format!("plain_read_copy/{side}"), |b| {
            b.iter(|| plain_read_copy(black_box(&raw_path), n))
        });
        for (name, w) in [
            ("tile", &tile_world),
            ("tile_lz4", &lz4_world),
            ("png16", &png_world),
        ] {
            group.bench_function(format!("load_to_ram/{name}/{side}"), |b| {
                b.iter(|| w.load_tile(Layer::Height, black_box(id)).expect("load"))
            });
        }
        for (name, bytes) in [
            ("tile", &raw_file),
            ("tile_lz4", &lz4_file),
            ("png16", &png),
        ] {
            let w = if name == "png16" {
                &png_world
            } else {
                &tile_world
            };
            group.bench_function(format!("decode/{name}/{side}"), |b| {
                b.iter(|| {
                    w.decode_tile(Layer::Height, id, black_box(bytes))
                        .expect("decode")
                })
            });
        }
        group.bench_function(format!("encode/tile/{side}"), |b| {
            b.iter(|| tile_file::encode_u16(black_box(&grid), TileCodec::Raw))
        });
        group.bench_function(format!("encode/tile_lz4/{side}"), |b| {
            b.iter(|| tile_file::encode_u16(black_box(&grid), TileCodec::Lz4))
        });
        group.bench_function(format!("encode/png16/{side}"), |b| {
            b.iter(|| {
                png_world
                    .encode_tile(Layer::Height, black_box(&data))
                    .expect("encode")
            })
        });
        for (name, w) in [("tile", &tile_world), ("png16", &png_world)] {
            group.bench_function(format!("write_back_fsync/{name}/{side}"), |b| {
                b.iter(|| {
                    w.write_tile(Layer::Height, black_box(id), &data)
                        .expect("write")
                })
            });
        }
        group.bench_function(format!("plain_memcpy/{side}"), |b| {
            b.iter(|| black_box(&raw).clone())
        });
        group.bench_function(format!("plain_file_read/{side}"), |b| {
            b.iter(|| std::fs::read(black_box(&raw_path)).expect("read"))
        });
        group.bench_function(format!("plain_file_write/{side}"), |b| {
            b.iter(|| std::fs::write(black_box(&raw_path), &raw).expect("write"))
        });
        let _ = std::fs::remove_dir_all(&root);
    }
    group.finish();
}

/// A 2048^2 detail tile as deformation leaves it: the zero deformation (128) but for 40
/// footprint-like dents with sloped sides.
fn dented_detail(side: u32) -> Grid<u8> {
    let mut g = Grid::new(side, side, 128u8).expect("grid");
    for k in 0..40u32 {
        let (cx, cy) = ((k * 733) % side, (k * 1291) % side);
        let r = 20 + (k * 7) % 40;
        for y in cy.saturating_sub(r)..(cy + r).min(side) {
            for x in cx.saturating_sub(r)..(cx + r).min(side) {
                let d = f64::from((x as i32 - cx as i32).pow(2) + (y as i32 - cy as i32).pow(2));
                let depth = (1.0 - d.sqrt() / f64::from(r)).max(0.0) * 90.0;
                if let Some(v) = g.get_mut(x, y) {
                    *v = 128 - depth as u8;
                }
            }
        }
    }
    g
}

/// Detail tiles (u8): the LZ4 codec they are written with against raw.
fn bench_detail(c: &mut Criterion) {
    let quick = std::env::var_os("TERRAIN_BENCH_QUICK").is_some();
    let mut group = c.benchmark_group("detail_tile");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(if quick { 200 } else { 500 }));
    group.measurement_time(Duration::from_secs(if quick { 1 } else { 2 }));
    let side = if quick { 256 } else { 2048 };
    let grid = dented_detail(side);
    let data = TileData::U8(grid.clone());
    let dir =
        std::env::temp_dir().join(format!("terrain-cache-bench-detail-{}", std::process::id()));
    let w = world(&dir, 256, TileFormat::Tile);
    let mut w2 = w.clone();
    w2.update_manifest(|m| {
        let mut d = terrain_cache::DetailLayout::covering(m.extent_m().as_vec2(), side, 0.05)
            .expect("detail");
        d.tiles = UVec2::splat(1);
        m.detail = Some(d);
    })
    .expect("detail layer");
    group.throughput(Throughput::Bytes(u64::from(side * side)));
    for codec in [TileCodec::Raw, TileCodec::Lz4] {
        let bytes = tile_file::encode_u8(&grid, codec);
        eprintln!(
            "detail tile {side}^2, {codec:?}: {} bytes ({:.2} %)",
            bytes.len(),
            100.0 * bytes.len() as f64 / f64::from(side * side)
        );
        group.bench_function(format!("decode/{codec:?}/{side}"), |b| {
            b.iter(|| tile_file::decode(black_box(&bytes), Layer::Detail, side).expect("decode"))
        });
        group.bench_function(format!("encode/{codec:?}/{side}"), |b| {
            b.iter(|| tile_file::encode_u8(black_box(&grid), codec))
        });
    }
    let id = TileId::new(0, 0, 0);
    group.bench_function(format!("write_back_fsync/{side}"), |b| {
        b.iter(|| {
            w2.write_tile(Layer::Detail, id, black_box(&data))
                .expect("write")
        })
    });
    group.bench_function(format!("load_to_ram/{side}"), |b| {
        b.iter(|| w2.load_tile(Layer::Detail, black_box(id)).expect("load"))
    });
    let _ = std::fs::remove_dir_all(&dir);
    group.finish();
}

criterion_group!(benches, bench, bench_detail);
criterion_main!(benches);
