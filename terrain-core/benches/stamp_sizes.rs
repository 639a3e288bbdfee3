//! One CPU stamp at the footprints a game places most (64^2 and 256^2 texels) on a 2048^2 u16
//! map: the Gaussian, the texture (a 64^2 image) and both rotated (non-square footprint), with
//! the add blend, and the Gaussian with min / max. Servers without a GPU run exactly this.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use glam::{UVec2, Vec2};
use terrain_core::{
    Blend, CoarseMap, GaussianStamp, Grid, HeightEncoding, StampPlacement, TerrainParams,
    TextureStamp, apply_stamp, generate_coarse_map,
};

const MAP: u32 = 2048;
const TEXEL: f32 = 0.5;
const SIDES: [u32; 2] = [64, 256];

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
    let mut group = c.benchmark_group("stamp_sizes");
    group.sample_size(20);
    group.warm_up_time(std::time::Duration::from_millis(300));
    group.measurement_time(std::time::Duration::from_secs(1));
    // Off the texel grid, so the local frame has no special values.
    let centre = Vec2::splat(MAP as f32 * TEXEL * 0.5 + 0.37);
    let mut tex = TextureStamp::from_gray8(
        &Grid::from_fn(64, 64, |x, y| ((x * 7 + y * 13) % 256) as u8).expect("image"),
    );
    let mut gauss = GaussianStamp::default();
    for side in SIDES {
        group.throughput(Throughput::Elements(u64::from(side) * u64::from(side)));
        let scale = Vec2::splat(side as f32 * TEXEL);
        // Alternate raise and lower so repeated runs never drift into the encoding's clamp.
        let mut sign = 1.0;
        let mut next = move || {
            sign = -sign;
            StampPlacement::new(centre, scale, sign * 2.0).expect("valid placement")
        };
        let rotated = move |p: StampPlacement| {
            StampPlacement {
                scale: Vec2::new(p.scale.x, p.scale.y * 0.5),
                ..p
            }
            .with_rotation(0.6)
            .expect("valid rotation")
        };
        group.bench_function(BenchmarkId::new("gaussian", side), |b| {
            b.iter(|| apply_stamp(&mut map, &mut gauss, &next(), Blend::Add).expect("stamp"))
        });
        group.bench_function(BenchmarkId::new("gaussian_rotated", side), |b| {
            b.iter(|| {
                apply_stamp(&mut map, &mut gauss, &rotated(next()), Blend::Add).expect("stamp")
            })
        });
        let mut flip = false;
        group.bench_function(BenchmarkId::new("gaussian_min_max", side), |b| {
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
        group.bench_function(BenchmarkId::new("texture", side), |b| {
            b.iter(|| apply_stamp(&mut map, &mut tex, &next(), Blend::Add).expect("stamp"))
        });
        group.bench_function(BenchmarkId::new("texture_rotated", side), |b| {
            b.iter(|| apply_stamp(&mut map, &mut tex, &rotated(next()), Blend::Add).expect("stamp"))
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
