//! Stamp + normal regeneration over square regions of 100 to 2000 texels a side (Flower 2010
//! table 4.3 deforms 10 to 200 m at 0.1 m per texel), beside plain copies of the region's u16
//! heights (out of the map into a buffer of their own, and in place into a second map's rows),
//! and the stores alone of the normals' output.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use glam::{IVec2, UVec2, Vec2};
use std::hint::black_box;
use terrain_core::{
    Blend, CoarseMap, DERIVATIVE_APRON, DerivativeMap, GaussianStamp, Grid, HeightEncoding, Rect,
    StampPlacement, TerrainParams, TextureStamp, apply_stamp, apply_stamp_reference,
    generate_coarse_map,
};

const MAP: u32 = 4096;
const TEXEL: f32 = 0.1;
const SIDES: [u32; 5] = [100, 200, 500, 1000, 2000];

fn map() -> CoarseMap {
    let params = TerrainParams {
        size: UVec2::splat(MAP),
        ..TerrainParams::default()
    };
    let enc = HeightEncoding::spanning::<u16>(0.0, 100.0).expect("valid encoding");
    generate_coarse_map(&params, enc, TEXEL).expect("valid terrain")
}

fn bench(c: &mut Criterion) {
    let mut map = map();
    let mut normals = DerivativeMap::from_map(&map);
    let mut group = c.benchmark_group("stamp_normals");
    group.sample_size(10);
    group.warm_up_time(std::time::Duration::from_millis(500));
    group.measurement_time(std::time::Duration::from_secs(2));
    let centre = Vec2::splat(MAP as f32 * TEXEL * 0.5);
    for side in SIDES {
        group.throughput(Throughput::Elements(u64::from(side) * u64::from(side)));
        let scale = Vec2::splat(side as f32 * TEXEL);
        // Alternate raise and lower so repeated runs never drift into the encoding's clamp.
        let mut sign = 1.0;
        let mut next = move || {
            sign = -sign;
            StampPlacement::new(centre, scale, sign).expect("valid placement")
        };
        let mut gauss = GaussianStamp::default();
        group.bench_function(BenchmarkId::new("stamp", side), |b| {
            b.iter(|| apply_stamp(&mut map, &mut gauss, &next(), Blend::Add).expect("stamp"))
        });
        // The per-texel evaluation stamps used before (slow: the small sizes only).
        if side <= 500 {
            group.bench_function(BenchmarkId::new("stamp_reference", side), |b| {
                b.iter(|| {
                    apply_stamp_reference(&mut map, &mut gauss, &next(), Blend::Add).expect("stamp")
                })
            });
        }
        // A rotated, non-square Gaussian (the cross factor), a rotated texture stamp and the
        // min / max blends.
        let rotated = move |p: StampPlacement| {
            StampPlacement {
                scale: Vec2::new(p.scale.x, p.scale.y * 0.5),
                ..p
            }
            .with_rotation(0.6)
            .expect("valid rotation")
        };
        group.bench_function(BenchmarkId::new("stamp_gaussian_rotated", side), |b| {
            b.iter(|| {
                apply_stamp(&mut map, &mut gauss, &rotated(next()), Blend::Add).expect("stamp")
            })
        });
        let mut tex = TextureStamp::from_gray8(
            &Grid::from_fn(64, 64, |x, y| ((x * 7 + y * 13) % 256) as u8).expect("image"),
        );
        group.bench_function(BenchmarkId::new("stamp_texture_rotated", side), |b| {
            b.iter(|| apply_stamp(&mut map, &mut tex, &rotated(next()), Blend::Add).expect("stamp"))
        });
        let mut flip = false;
        group.bench_function(BenchmarkId::new("stamp_min_max", side), |b| {
            b.iter(|| {
                flip = !flip;
                let blend = if flip {
                    Blend::Min { base_m: 50.0 }
                } else {
                    Blend::Max { base_m: 50.0 }
                };
                apply_stamp(&mut map, &mut gauss, &next(), blend).expect("stamp")
            })
        });
        let rect = Rect::new(
            (centre / TEXEL).as_ivec2() - IVec2::splat(side as i32 / 2),
            UVec2::splat(side),
        );
        group.bench_function(BenchmarkId::new("normals", side), |b| {
            b.iter(|| normals.update_rect(&map, black_box(rect)).expect("normals"))
        });
        group.bench_function(BenchmarkId::new("stamp_and_normals", side), |b| {
            b.iter(|| {
                for r in apply_stamp(&mut map, &mut gauss, &next(), Blend::Add).expect("stamp") {
                    normals.update_rect(&map, r).expect("normals");
                }
            })
        });
        // The same bytes where they live: the region's rows of the 4096^2 map copied into the
        // same rows of a second map-sized buffer (a stamp's reads and writes are strided like
        // this, through a map too large for the caches nearest the core).
        let mut other = vec![0u16; (MAP * MAP) as usize];
        let (x0, y0) = (rect.min.x as usize, rect.min.y as usize);
        let (n, stride) = (side as usize, MAP as usize);
        group.bench_function(BenchmarkId::new("memcpy_in_map", side), |b| {
            b.iter(|| {
                let src = black_box(map.grid().as_slice());
                for y in y0..y0 + n {
                    let row = y * stride + x0..y * stride + x0 + n;
                    other[row.clone()].copy_from_slice(&src[row]);
                }
            })
        });
        // What the normals' writes cost alone: a plain loop storing a value into each texel
        // the normals regenerate (8 bytes, rows 32 KiB apart in a second map-sized grid).
        let mut gradients = vec![Vec2::ZERO; (MAP * MAP) as usize];
        let m = n + 2 * DERIVATIVE_APRON as usize;
        let (gx, gy) = (
            x0 - DERIVATIVE_APRON as usize,
            y0 - DERIVATIVE_APRON as usize,
        );
        group.bench_function(BenchmarkId::new("normals_stores", side), |b| {
            b.iter(|| {
                for y in gy..gy + m {
                    let row = black_box(&mut gradients[y * stride + gx..y * stride + gx + m]);
                    for (i, v) in row.iter_mut().enumerate() {
                        *v = Vec2::new(i as f32, 1.0);
                    }
                }
            })
        });
        // The baseline: a plain copy of the region's u16 heights (side^2 texels, its rows read
        // from the map) into a buffer of their own.
        let mut dst = vec![0u16; n * n];
        group.bench_function(BenchmarkId::new("memcpy", side), |b| {
            b.iter(|| {
                let src = black_box(map.grid().as_slice());
                for (j, out) in dst.chunks_exact_mut(n).enumerate() {
                    let at = (y0 + j) * stride + x0;
                    out.copy_from_slice(&src[at..at + n]);
                }
                black_box(&dst);
            })
        });
    }
    group.finish();
}

/// One footprint-sized detail stamp (0.6 x 0.3 m over a 4-tile corner, 1.5 m deep) on a
/// detail layer refined x3 over the 4096^2 map, clipped at the tiles' range and spilled into
/// the coarse-map (Flower 2010's detail layer; `terrain_core::detail_spill`).
fn detail(c: &mut Criterion) {
    use terrain_core::detail::{DetailLayer, DetailLayout};
    let mut map = map();
    let layout = DetailLayout::new(UVec2::splat(MAP), TEXEL, 3, 1024).expect("layout");
    let mut layer = DetailLayer::new(layout).expect("layer");
    let corner = Vec2::splat(1024.0 * layout.detail_texel_m());
    let p = StampPlacement::new(corner, Vec2::new(0.6, 0.3), -1.5).expect("placement");
    let mut g = GaussianStamp::default();
    let mut group = c.benchmark_group("detail_stamp");
    group.sample_size(10);
    group.bench_function("clip", |b| {
        b.iter(|| layer.apply_stamp(&mut g, &p, Blend::Add).expect("stamp"))
    });
    group.bench_function("spill", |b| {
        b.iter(|| {
            layer
                .apply_stamp_spilling(&mut map, &mut g, &p, Blend::Add)
                .expect("stamp")
        })
    });
    group.finish();
}

criterion_group!(benches, bench, detail);
criterion_main!(benches);
