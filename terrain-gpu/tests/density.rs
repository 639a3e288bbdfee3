//! `DensityPass` against terrain-lod's CPU `DensityMap`: every filter, both wrap modes, the
//! pyramid, and the dirty-rect update after a stamp on both sides.

use glam::{IVec2, UVec2, Vec2};
use terrain_core::{
    Blend, GaussianStamp, Grid, HeightEncoding, HeightMap, Rect, StampPlacement, WrapMode,
    apply_stamp,
};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{
    DensityPass, GpuContext, GpuDensityMap, GpuError, GpuHeightMap, GpuStamp, StampOp, StampPass,
};
use terrain_lod::{CurvatureFilter, DensityMap, DensityParams};

/// Largest difference between a GPU and a CPU density sample, in u8 steps. The raw maxima are
/// f32 sums and quotients whose last bits differ between the GPU's arithmetic (fused
/// multiply-adds, its own division, square root and `pow`) and the CPU's; a value within
/// rounding error of a step's middle may round the other way, never by more than one.
const DENSITY_BOUND: u8 = 1;
/// Largest relative difference of a raw (unquantised) sample.
const RAW_BOUND: f32 = 1e-4;

fn bumpy(w: u32, h: u32, wrap: WrapMode) -> HeightMap<u16> {
    let grid = Grid::from_fn(w, h, |x, y| {
        let v = (x.wrapping_mul(7919) ^ y.wrapping_mul(104_729)).wrapping_mul(2_654_435_761);
        let smooth = ((x as f32 * 0.11).sin() * 600.0 + (y as f32 * 0.07).cos() * 500.0) as i32;
        (30_000 + smooth + (v >> 30) as i32) as u16
    })
    .unwrap();
    HeightMap::new(grid, HeightEncoding::new(0.002, 0.0).unwrap(), 0.25, wrap).unwrap()
}

/// Compares every level and the raw samples; returns (largest level difference, samples that
/// differ).
fn compare(ctx: &GpuContext, gpu: &GpuDensityMap, cpu: &DensityMap, what: &str) -> (u8, usize) {
    let (device, queue) = (&ctx.device, &ctx.queue);
    let raw = gpu.read_raw(device, queue).unwrap();
    assert_eq!(raw.size(), cpu.raw().size());
    for (k, (a, b)) in raw.as_slice().iter().zip(cpu.raw().as_slice()).enumerate() {
        let tol = RAW_BOUND * b.abs().max(1e-3);
        assert!(
            (a - b).abs() <= tol,
            "{what}: raw sample {k}: GPU {a} CPU {b}"
        );
    }
    assert_eq!(gpu.level_count(), cpu.level_count(), "{what}");
    let (mut max, mut differ) = (0u8, 0usize);
    for k in 0..cpu.level_count() {
        let g = gpu.read_level(device, queue, k).unwrap().unwrap();
        let c = cpu.level(k).unwrap();
        assert_eq!(g.size(), c.size(), "{what}: level {k}");
        for (a, b) in g.as_slice().iter().zip(c.as_slice()) {
            let d = a.abs_diff(*b);
            max = max.max(d);
            differ += usize::from(d != 0);
        }
    }
    assert!(
        gpu.read_level(device, queue, cpu.level_count())
            .unwrap()
            .is_none()
    );
    ctx.check().expect("no GPU validation errors");
    (max, differ)
}

#[test]
fn density_maps_match_the_cpu_for_every_filter_and_wrap() {
    let Some(ctx) = context_or_skip("density_maps_match_the_cpu_for_every_filter_and_wrap") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut pass = DensityPass::new(device).unwrap();
    for (w, h, wrap) in [(130, 97, WrapMode::Repeat), (77, 64, WrapMode::Clamp)] {
        let map = bumpy(w, h, wrap);
        let gpu_map = GpuHeightMap::from_map(device, queue, &map).unwrap();
        for filter in CurvatureFilter::ALL {
            for exponent in [1.0, 2.5] {
                let params = DensityParams {
                    filter,
                    exponent,
                    tile_size: 8,
                    full_density_bend: 0.3,
                    ..Default::default()
                };
                let cpu = DensityMap::from_map(&map, params).unwrap();
                let gpu = GpuDensityMap::for_map(device, &gpu_map, params).unwrap();
                let mut encoder = device.create_command_encoder(&Default::default());
                pass.encode_full(device, queue, &mut encoder, &gpu_map, &gpu)
                    .unwrap();
                queue.submit([encoder.finish()]);
                pass.recall();
                let what = format!("{w}x{h} {wrap:?} {} exponent {exponent}", filter.name());
                let (max, differ) = compare(&ctx, &gpu, &cpu, &what);
                println!("{what}: max difference {max}, {differ} samples differ");
                assert!(max <= DENSITY_BOUND, "{what}: {max}");
                // The values are spread, not all 0 or 255 (the comparison means something).
                let l0 = cpu.level(0).unwrap().as_slice();
                assert!(
                    l0.iter().any(|&v| v > 20 && v < 235),
                    "{what}: level 0 from {:?} to {:?}, raw up to {}",
                    l0.iter().min(),
                    l0.iter().max(),
                    cpu.raw().as_slice().iter().fold(0.0f32, |m, &v| m.max(v))
                );
            }
        }
    }
}

#[test]
fn a_stamp_updates_the_same_samples_on_both_sides() {
    let Some(ctx) = context_or_skip("a_stamp_updates_the_same_samples_on_both_sides") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut map = bumpy(160, 128, WrapMode::Repeat);
    let params = DensityParams {
        tile_size: 8,
        full_density_bend: 0.3,
        ..Default::default()
    };
    let gpu_map = GpuHeightMap::from_map(device, queue, &map).unwrap();
    let gpu = GpuDensityMap::for_map(device, &gpu_map, params).unwrap();
    let mut cpu = DensityMap::from_map(&map, params).unwrap();
    let mut density = DensityPass::new(device).unwrap();
    let mut stamps = StampPass::new(device).unwrap();
    let mut encoder = device.create_command_encoder(&Default::default());
    density
        .encode_full(device, queue, &mut encoder, &gpu_map, &gpu)
        .unwrap();
    // A crater across the map's corner, so the update wraps on both axes.
    let gauss = GaussianStamp::default();
    let placement = StampPlacement::new(Vec2::new(1.0, 2.0), Vec2::splat(6.0), -3.0).unwrap();
    let op = StampOp {
        stamp: GpuStamp::Gaussian(&gauss),
        placement,
        blend: Blend::Add,
    };
    let gpu_rects = stamps
        .encode(device, queue, &mut encoder, &gpu_map, &op)
        .unwrap();
    for rect in &gpu_rects {
        density
            .encode(device, queue, &mut encoder, &gpu_map, &gpu, *rect)
            .unwrap();
    }
    queue.submit([encoder.finish()]);
    density.recall();
    stamps.recall();
    let mut g = gauss;
    let cpu_rects = apply_stamp(&mut map, &mut g, &placement, Blend::Add).unwrap();
    assert_eq!(cpu_rects, gpu_rects);
    for rect in cpu_rects {
        cpu.update_rect(&map, rect).unwrap();
    }
    // The stamped heights are equal (the stamp pass's own bound is 1 LSB; here they match),
    // so the densities compare as from the same map.
    assert_eq!(gpu_map.read(device, queue).unwrap(), map);
    let (max, _) = compare(&ctx, &gpu, &cpu, "after a stamp");
    assert!(max <= DENSITY_BOUND);
    // And the update is what a fresh computation gives.
    assert_eq!(cpu, DensityMap::from_map(&map, params).unwrap());
}

#[test]
fn bad_inputs_are_errors() {
    let Some(ctx) = context_or_skip("density bad_inputs_are_errors") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let map = bumpy(32, 32, WrapMode::Repeat);
    let gpu_map = GpuHeightMap::from_map(device, queue, &map).unwrap();
    let bad = DensityParams {
        gain: f32::NAN,
        ..Default::default()
    };
    assert!(matches!(
        GpuDensityMap::for_map(device, &gpu_map, bad),
        Err(GpuError::Lod(_))
    ));
    let other = GpuDensityMap::new(
        device,
        UVec2::new(40, 32),
        WrapMode::Repeat,
        DensityParams::default(),
    )
    .unwrap();
    let mut pass = DensityPass::new(device).unwrap();
    let mut encoder = device.create_command_encoder(&Default::default());
    assert!(matches!(
        pass.encode_full(device, queue, &mut encoder, &gpu_map, &other),
        Err(GpuError::SizeMismatch { .. })
    ));
    let clamped = GpuDensityMap::new(
        device,
        UVec2::new(32, 32),
        WrapMode::Clamp,
        DensityParams::default(),
    )
    .unwrap();
    assert!(
        pass.encode_full(device, queue, &mut encoder, &gpu_map, &clamped)
            .is_err()
    );
    // A rect far off the map wraps; nothing panics, nothing is out of range.
    let ok = GpuDensityMap::for_map(device, &gpu_map, DensityParams::default()).unwrap();
    pass.encode(
        device,
        queue,
        &mut encoder,
        &gpu_map,
        &ok,
        Rect::new(IVec2::splat(i32::MIN + 5), UVec2::splat(3)),
    )
    .unwrap();
    queue.submit([encoder.finish()]);
    ctx.check().expect("no GPU validation errors");
}
