//! Density maps of 1M to 8M height samples with each curvature filter, beside Cervin 2012, table
//! 4.1 (Xeon X5650: 0.14 s to 11.04 s per 1M to 8M samples), and the dirty-rect update after a
//! crater.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use glam::{IVec2, UVec2};
use std::hint::black_box;
use terrain_core::{HeightEncoding, Rect, TerrainParams, generate_coarse_map};
use terrain_lod::{CurvatureFilter, DensityMap, DensityParams};

/// Sides of square maps of about 1M, 2M, 3M, 4M and 8M samples (table 4.1's rows).
const SIDES: [(u32, &str); 5] = [
    (1024, "1M"),
    (1448, "2M"),
    (1732, "3M"),
    (2048, "4M"),
    (2896, "8M"),
];

fn bench(c: &mut Criterion) {
    let quick = std::env::var_os("TERRAIN_BENCH_QUICK").is_some();
    let mut group = c.benchmark_group("density");
    group.sample_size(10);
    group.warm_up_time(std::time::Duration::from_millis(300));
    group.measurement_time(std::time::Duration::from_secs(if quick { 1 } else { 3 }));
    let enc = HeightEncoding::spanning::<u16>(0.0, 100.0).expect("valid encoding");
    for (side, label) in SIDES {
        if quick && side > 2048 {
            continue;
        }
        let params = TerrainParams {
            size: UVec2::splat(side),
            ..TerrainParams::default()
        };
        let map = generate_coarse_map(&params, enc, 0.1).expect("valid terrain");
        group.throughput(Throughput::Elements(u64::from(side) * u64::from(side)));
        for filter in CurvatureFilter::ALL {
            let p = DensityParams {
                filter,
                ..DensityParams::default()
            };
            group.bench_function(BenchmarkId::new(filter.name(), label), |b| {
                b.iter(|| DensityMap::from_map(black_box(&map), p).expect("density"))
            });
        }
        // A plain copy of the heights' bytes, the memory bound of one pass over them.
        group.bench_function(BenchmarkId::new("copy", label), |b| {
            b.iter(|| black_box(map.grid().as_slice().to_vec()))
        });
        if side == 2048 {
            // After a 20 m crater (200 texels at 0.1 m): only its samples are recomputed.
            let mut dm = DensityMap::from_map(&map, DensityParams::default()).expect("density");
            let rect = Rect::new(IVec2::splat(900), UVec2::splat(200));
            group.throughput(Throughput::Elements(rect.area()));
            group.bench_function(BenchmarkId::new("update_rect_mean", "200x200"), |b| {
                b.iter(|| dm.update_rect(black_box(&map), rect).expect("update"))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
