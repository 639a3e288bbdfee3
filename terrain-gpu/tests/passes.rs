//! GPU passes against their terrain-core CPU references, on whatever adapter the machine has
//! (lavapipe in CI). Without an adapter they skip, or fail under `TERRAIN_REQUIRE_GPU=1`.

use glam::{IVec2, UVec2, Vec2};
use terrain_core::{
    Blend, DerivativeMap, GaussianStamp, Grid, HeightEncoding, HeightMap, HeightSample, Rect,
    Shockwave, ShockwaveParams, SlopeCodec, Stamp, StampPlacement, TextureStamp, WrapMode,
    apply_stamp,
};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{
    GpuContext, GpuDerivativeMap, GpuError, GpuHeightMap, GpuProceduralStamp, GpuStamp,
    GpuTextureStamp, NormalPass, RegionReadback, StampOp, StampPass,
};

/// Largest allowed difference between GPU and CPU stamps, in stored units (LSB): none. Both
/// run terrain-core's exact integer stamp program (`terrain_core::stamp::fixed`), so every
/// kind and blend is bit-identical on any conforming GPU.
const STAMP_BOUND_LSB: u32 = 0;

fn hashed<T: HeightSample>(w: u32, h: u32, lo: u32, span: u32) -> Grid<T> {
    Grid::from_fn(w, h, |x, y| {
        let mut z = u64::from(x).wrapping_mul(0x9E37_79B9) ^ u64::from(y).wrapping_mul(0x85EB_CA6B);
        z ^= z >> 15;
        T::from_raw_f64_clamped(f64::from(lo + (z % u64::from(span)) as u32))
    })
    .unwrap()
}

/// A diamond: `1 - (|x| + |y|)` inside `|x| + |y| < 0.5`, the user procedural stamp on both
/// sides. Written with exact f32 operations (a sum of two multiples of 2^-24 below 1, compared
/// with 0.5, and subtracted from 1), so the GPU's value equals the CPU's on any conforming GPU
/// (`length` would not: its last bits and any fused multiply-add are the GPU's choice).
struct Ring;
impl Stamp for Ring {
    fn value(&self, local: Vec2) -> f32 {
        let r = local.x.abs() + local.y.abs();
        if r < 0.5 { 1.0 - r } else { 0.0 }
    }
}
const RING_WGSL: &str = "fn user_stamp_value(local: vec2<f32>) -> f32 {
    let r = abs(local.x) + abs(local.y);
    return select(0.0, 1.0 - r, r < 0.5);
}";

/// Applies the same stamps on CPU and GPU and returns (max difference, texels that differ).
fn compare_stamps<T: terrain_gpu::ExactInF32>(
    ctx: &GpuContext,
    mut map: HeightMap<T>,
    stamps: &mut [(Box<dyn Stamp>, GpuStamp<'_>, StampPlacement, Blend)],
    pass: &mut StampPass,
) -> (u32, usize) {
    let (device, queue) = (&ctx.device, &ctx.queue);
    let gpu = GpuHeightMap::from_map(device, queue, &map).unwrap();
    let mut encoder = device.create_command_encoder(&Default::default());
    for (cpu_stamp, gpu_stamp, placement, blend) in stamps.iter_mut() {
        let cpu_dirty = apply_stamp(&mut map, cpu_stamp.as_mut(), placement, *blend).unwrap();
        let gpu_dirty = pass
            .encode(
                device,
                queue,
                &mut encoder,
                &gpu,
                &StampOp {
                    stamp: *gpu_stamp,
                    placement: *placement,
                    blend: *blend,
                },
            )
            .unwrap();
        assert_eq!(cpu_dirty, gpu_dirty, "dirty rects of {placement:?}");
    }
    queue.submit([encoder.finish()]);
    let back: HeightMap<T> = gpu.read(device, queue).unwrap();
    ctx.check().expect("no GPU validation errors");
    let mut max = 0;
    let mut differ = 0;
    for (a, b) in map.grid().as_slice().iter().zip(back.grid().as_slice()) {
        let d = (a.to_raw_f64() - b.to_raw_f64()).abs() as u32;
        max = max.max(d);
        differ += usize::from(d != 0);
    }
    (max, differ)
}

#[test]
fn stamps_match_the_cpu_reference_on_a_wrapping_coarse_map() {
    let Some(ctx) = context_or_skip("stamps_match_the_cpu_reference") else {
        return;
    };
    let device = &ctx.device;
    let mut pass = StampPass::new(device).unwrap();
    let map = HeightMap::new(
        hashed::<u16>(200, 150, 20_000, 20_000),
        HeightEncoding::new(0.001, -5.0).unwrap(),
        0.25,
        WrapMode::Repeat,
    )
    .unwrap();

    let gauss = GaussianStamp::default();
    let g2 = GaussianStamp::default();
    let image = Grid::from_fn(13, 7, |x, y| (x * 19 + y * 31) as u8).unwrap();
    let tex = TextureStamp::from_gray8(&image);
    let gpu_tex = GpuTextureStamp::new(device, &tex).unwrap();
    let mut wave = Shockwave::new(ShockwaveParams {
        resolution: 32,
        ..Default::default()
    })
    .unwrap();
    for _ in 0..6 {
        wave.step();
    }
    let wave_delta = wave.take_delta().unwrap();
    let gpu_wave = GpuTextureStamp::new(device, &wave_delta).unwrap();
    let ring = Ring;
    let gpu_ring = GpuProceduralStamp::new(device, &pass, RING_WGSL).unwrap();

    let p = |c: Vec2, s: Vec2, i: f32, r: f32| {
        StampPlacement::new(c, s, i)
            .unwrap()
            .with_rotation(r)
            .unwrap()
    };
    let extent = Vec2::new(50.0, 37.5);
    let mut stamps: Vec<(Box<dyn Stamp>, GpuStamp<'_>, StampPlacement, Blend)> = vec![
        (
            Box::new(gauss),
            GpuStamp::Gaussian(&g2),
            p(Vec2::new(20.0, 15.0), Vec2::splat(9.0), -3.0, 0.0),
            Blend::Add,
        ),
        // Across the wrap corner: 4 pieces on the CPU, one wrapped dispatch on the GPU.
        (
            Box::new(tex),
            GpuStamp::Texture(&gpu_tex),
            p(Vec2::new(0.3, 37.0), Vec2::new(6.0, 4.0), 2.5, 0.7),
            Blend::Add,
        ),
        (
            Box::new(wave_delta),
            GpuStamp::Texture(&gpu_wave),
            p(extent - 1.0, Vec2::splat(12.0), 4.0, 0.0),
            Blend::Add,
        ),
        (
            Box::new(ring),
            GpuStamp::Procedural(&gpu_ring),
            p(Vec2::new(49.0, 5.0), Vec2::splat(7.0), 1.5, -0.4),
            Blend::Add,
        ),
        (
            Box::new(Ring),
            GpuStamp::Procedural(&gpu_ring),
            p(Vec2::new(30.0, 30.0), Vec2::splat(8.0), -2.0, 0.0),
            Blend::Min { base_m: 20.0 },
        ),
        (
            Box::new(Ring),
            GpuStamp::Procedural(&gpu_ring),
            p(Vec2::new(10.0, 30.0), Vec2::splat(8.0), 2.0, 0.0),
            Blend::Max { base_m: 22.0 },
        ),
        // Saturates at the top of the encoding.
        (
            Box::new(GaussianStamp::default()),
            GpuStamp::Gaussian(&g2),
            p(Vec2::new(35.0, 10.0), Vec2::splat(5.0), 90.0, 0.0),
            Blend::Add,
        ),
    ];
    let (max, differ) = compare_stamps(&ctx, map, &mut stamps, &mut pass);
    eprintln!(
        "stamps on {}: max |GPU - CPU| = {max} LSB, {differ} texels differ",
        ctx.report().name
    );
    assert!(max == STAMP_BOUND_LSB, "max difference {max} LSB");
    assert_eq!(differ, 0, "{differ} texels differ");

    // Odd sizes: each row's last word holds one texel and a padding lane, and the wrap falls
    // inside a word's run of columns; u8 maps pack four texels a word. Both wrap modes.
    for (w, h) in [(201, 151), (199, 149)] {
        for wrap in [WrapMode::Repeat, WrapMode::Clamp] {
            let enc = HeightEncoding::new(0.001, -5.0).unwrap();
            let map = HeightMap::new(hashed::<u16>(w, h, 20_000, 20_000), enc, 0.25, wrap).unwrap();
            let (max, differ) = compare_stamps(&ctx, map, &mut stamps, &mut pass);
            assert_eq!((max, differ), (STAMP_BOUND_LSB, 0), "u16 {w}x{h} {wrap:?}");
            let enc8 = HeightEncoding::new(0.2, -5.0).unwrap();
            let map8 = HeightMap::new(hashed::<u8>(w, h, 60, 120), enc8, 0.25, wrap).unwrap();
            let (max, differ) = compare_stamps(&ctx, map8, &mut stamps, &mut pass);
            assert_eq!((max, differ), (STAMP_BOUND_LSB, 0), "u8 {w}x{h} {wrap:?}");
        }
    }
}

#[test]
fn stamps_on_a_clamped_detail_tile_match_and_off_map_is_a_no_op() {
    let Some(ctx) = context_or_skip("stamps_on_a_clamped_detail_tile") else {
        return;
    };
    let mut pass = StampPass::new(&ctx.device).unwrap();
    let tile = HeightMap::<u8>::detail(
        hashed::<u8>(64, 48, 60, 100),
        HeightEncoding::spanning::<u8>(-0.5, 0.5).unwrap(),
        0.03,
    )
    .unwrap();
    let g = GaussianStamp::default();
    let mut stamps: Vec<(Box<dyn Stamp>, GpuStamp<'_>, StampPlacement, Blend)> = vec![
        (
            Box::new(GaussianStamp::default()),
            GpuStamp::Gaussian(&g),
            StampPlacement::new(Vec2::new(0.1, 0.7), Vec2::splat(0.6), -0.3).unwrap(),
            Blend::Add,
        ),
        (
            Box::new(GaussianStamp::default()),
            GpuStamp::Gaussian(&g),
            StampPlacement::new(Vec2::new(-5.0, 0.7), Vec2::splat(0.6), -0.3).unwrap(),
            Blend::Add,
        ),
        (
            Box::new(GaussianStamp::default()),
            GpuStamp::Gaussian(&g),
            StampPlacement::new(Vec2::new(1.0, 0.8), Vec2::splat(0.5), 0.9).unwrap(),
            Blend::Add,
        ),
    ];
    let (max, differ) = compare_stamps(&ctx, tile, &mut stamps, &mut pass);
    assert!(
        max == STAMP_BOUND_LSB && differ == 0,
        "max {max}, {differ} differ"
    );
}

#[test]
fn u32_maps_and_oversized_stamps_are_errors() {
    let Some(ctx) = context_or_skip("u32_maps_and_oversized_stamps_are_errors") else {
        return;
    };
    // u32 maps cannot reach the stamp pass at all (`ExactInF32`, a compile_fail doctest).
    let map = HeightMap::new(
        hashed::<u16>(32, 32, 0, 100),
        HeightEncoding::new(0.01, 0.0).unwrap(),
        1.0,
        WrapMode::Repeat,
    )
    .unwrap();
    let gpu = GpuHeightMap::from_map(&ctx.device, &ctx.queue, &map).unwrap();
    let mut pass = StampPass::new(&ctx.device).unwrap();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    let huge = StampPlacement::new(Vec2::ZERO, Vec2::splat(100.0), 1.0).unwrap();
    let g = GaussianStamp::default();
    assert!(
        pass.encode(
            &ctx.device,
            &ctx.queue,
            &mut encoder,
            &gpu,
            &StampOp {
                stamp: GpuStamp::Gaussian(&g),
                placement: huge,
                blend: Blend::Add,
            },
        )
        .is_err()
    );
    assert!(matches!(
        GpuProceduralStamp::new(
            &ctx.device,
            &pass,
            "fn user_stamp_value(local: vec2<f32>) -> f32 { return nonsense; }"
        ),
        Err(GpuError::UserShader { .. })
    ));
}

/// The GPU's derivatives are 8-bit slope codes (terrain_core::slope_code): decoded, each
/// component's slope angle is within half a code step of the CPU's f32 derivative, or both are
/// at the steepest code.
fn assert_derivatives_close(cpu: &DerivativeMap, gpu: &DerivativeMap) {
    let half = 0.5 * terrain_core::slope_code::SLOPE_CODE_STEP + 1e-6;
    let top = f64::from(terrain_core::slope_code::SLOPE_CODE_MAX_DEGREES).to_radians() - half;
    for (a, b) in cpu.grid().as_slice().iter().zip(gpu.grid().as_slice()) {
        for (a, b) in [(a.x, b.x), (a.y, b.y)] {
            let (ta, tb) = (f64::from(a).atan(), f64::from(b).atan());
            let clamped = ta.abs() >= top && tb.abs() >= top && ta.signum() == tb.signum();
            assert!(clamped || (ta - tb).abs() <= half, "cpu {a} gpu {b}");
        }
    }
}

#[test]
fn normal_codes_equal_the_cpu_codes_bit_for_bit() {
    let Some(ctx) = context_or_skip("normal_codes_equal_the_cpu_codes") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    // Odd widths put a padding lane in each row's last word; the hashed heights give every
    // code from flat to the clamped ±127, the smooth ramp every code in between.
    for (w, h) in [(96, 80), (37, 21), (1, 5), (2, 3)] {
        for wrap in [WrapMode::Repeat, WrapMode::Clamp] {
            for smooth in [false, true] {
                let grid = if smooth {
                    Grid::from_fn(w, h, |x, y| (30_000 + x * x * 7 + y * 131) as u16).unwrap()
                } else {
                    hashed::<u16>(w, h, 1000, 60_000)
                };
                let enc = HeightEncoding::new(0.002, 0.0).unwrap();
                let map = HeightMap::new(grid, enc, 0.5, wrap).unwrap();
                let gpu_map = GpuHeightMap::from_map(device, queue, &map).unwrap();
                let gpu_normals = GpuDerivativeMap::for_map(device, &gpu_map).unwrap();
                let mut pass = NormalPass::new(device).unwrap();
                let mut encoder = device.create_command_encoder(&Default::default());
                pass.encode_full(device, queue, &mut encoder, &gpu_map, &gpu_normals)
                    .unwrap();
                queue.submit([encoder.finish()]);
                let want = SlopeCodec::for_map(&map).codes(&map);
                let got = gpu_normals.read_codes(device, queue).unwrap();
                assert_eq!(got, want, "{w}x{h} {wrap:?} smooth {smooth}");
                if w == 96 {
                    let codes: std::collections::HashSet<i8> =
                        want.as_slice().iter().flatten().copied().collect();
                    assert!(
                        codes.len() > if smooth { 20 } else { 100 },
                        "{}",
                        codes.len()
                    );
                }
            }
        }
    }
}

#[test]
fn normals_match_the_cpu_reference_full_and_in_dirty_rects() {
    let Some(ctx) = context_or_skip("normals_match_the_cpu_reference") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    for wrap in [WrapMode::Repeat, WrapMode::Clamp] {
        let mut map = HeightMap::new(
            hashed::<u16>(96, 80, 1000, 60_000),
            HeightEncoding::new(0.002, 0.0).unwrap(),
            0.5,
            wrap,
        )
        .unwrap();
        let gpu_map = GpuHeightMap::from_map(device, queue, &map).unwrap();
        let gpu_normals = GpuDerivativeMap::for_map(device, &gpu_map).unwrap();
        let mut pass = NormalPass::new(device).unwrap();
        let mut encoder = device.create_command_encoder(&Default::default());
        pass.encode_full(device, queue, &mut encoder, &gpu_map, &gpu_normals)
            .unwrap();
        queue.submit([encoder.finish()]);
        let mut cpu_normals = DerivativeMap::from_map(&map);
        assert_derivatives_close(&cpu_normals, &gpu_normals.read(device, queue).unwrap());
        let codec = SlopeCodec::for_map(&map);
        assert_eq!(
            gpu_normals.read_codes(device, queue).unwrap(),
            codec.codes(&map)
        );

        // Change heights in two rects (one across the corner on the repeating map), upload,
        // regenerate only those rects on both sides.
        let rects = [
            Rect::new(IVec2::new(10, 12), UVec2::new(9, 5)),
            match wrap {
                WrapMode::Repeat => Rect::new(IVec2::new(93, -2), UVec2::new(6, 6)),
                WrapMode::Clamp => Rect::new(IVec2::new(90, 0), UVec2::new(6, 6)),
            },
        ];
        for r in &rects {
            for p in r.split_toroidal(map.size()) {
                for y in p.map.min.y..p.map.max().y {
                    for x in p.map.min.x..p.map.max().x {
                        *map.grid_mut().get_mut(x as u32, y as u32).unwrap() =
                            64_000 - (x * y) as u16;
                    }
                }
            }
        }
        gpu_map.write(queue, &map).unwrap();
        let mut encoder = device.create_command_encoder(&Default::default());
        for r in rects {
            pass.encode(device, queue, &mut encoder, &gpu_map, &gpu_normals, r)
                .unwrap();
            cpu_normals.update_rect(&map, r).unwrap();
        }
        queue.submit([encoder.finish()]);
        assert_derivatives_close(&cpu_normals, &gpu_normals.read(device, queue).unwrap());
        // Only the dirty rects were regenerated, and every code is the new map's.
        assert_eq!(
            gpu_normals.read_codes(device, queue).unwrap(),
            codec.codes(&map)
        );
        assert_derivatives_close(&DerivativeMap::from_map(&map), &cpu_normals);
        ctx.check().expect("no GPU validation errors");
    }
}

/// The repeating 70 x 50 map the readback tests read from.
/// `rows`, read back for `rect` (unwrapped), are the map's texels there, wrapped.
fn assert_rows_are_the_map(rows: &Grid<u16>, rect: Rect, map: &HeightMap<u16>) {
    for y in 0..rect.size.y {
        for x in 0..rect.size.x {
            let p = rect.min + IVec2::new(x as i32, y as i32);
            let want = map.grid().get_wrapped(p, WrapMode::Repeat);
            assert_eq!(rows.get(x, y), Some(want), "texel {p} of {rect:?}");
        }
    }
}

fn readback_map() -> HeightMap<u16> {
    HeightMap::new(
        hashed::<u16>(70, 50, 0, 65_000),
        HeightEncoding::new(0.01, 1.0).unwrap(),
        1.0,
        WrapMode::Repeat,
    )
    .unwrap()
}

#[test]
fn readback_delivers_regions_without_waiting_and_equals_the_map() {
    let Some(ctx) = context_or_skip("readback_delivers_regions") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let map = readback_map();
    let gpu = GpuHeightMap::from_map(device, queue, &map).unwrap();
    let mut readback = RegionReadback::new(device, 2).unwrap();
    let rects = [
        Rect::new(IVec2::new(5, 7), UVec2::new(20, 11)),
        Rect::new(IVec2::new(-4, 45), UVec2::new(9, 10)), // across the corner
    ];
    let mut encoder = device.create_command_encoder(&Default::default());
    let tickets: Vec<_> = rects
        .iter()
        .map(|r| readback.request(device, &mut encoder, &gpu, *r).unwrap())
        .collect();
    // The ring is full until these arrive: back-pressure, as the region source says.
    let busy = readback.request(device, &mut encoder, &gpu, rects[0]);
    assert!(matches!(busy, Err(GpuError::ReadbackBusy { ring: 2 })));
    let busy = busy.expect_err("busy");
    let mut other = RegionReadback::new(device, 1).unwrap();
    let source = terrain_gpu::GpuRegionSource::new(device, queue, &gpu, &mut other);
    assert!(terrain_core::RegionSource::is_busy(&source, &busy));
    assert!(!terrain_core::RegionSource::is_busy(
        &source,
        &GpuError::MapDropped
    ));
    // Nothing can arrive before the copies are submitted, and poll does not wait.
    assert!(readback.poll(device).unwrap().is_empty());
    queue.submit([encoder.finish()]);
    let arrived = readback.wait(device).unwrap();
    assert_eq!(arrived.len(), 2);
    assert_eq!(readback.in_flight(), 0);
    for (data, (rect, ticket)) in arrived.iter().zip(rects.iter().zip(&tickets)) {
        assert_eq!(data.ticket, *ticket);
        assert_eq!(data.rect, *rect);
        let rows = data.to_u16();
        let metres = data.to_metres();
        for y in 0..rect.size.y {
            for x in 0..rect.size.x {
                let p = rect.min + IVec2::new(x as i32, y as i32);
                let want = map.grid().get_wrapped(p, WrapMode::Repeat);
                assert_eq!(rows.get(x, y), Some(want), "texel {p}");
                let m = metres.get(x, y).unwrap();
                assert!((m - map.encoding().to_metres(f64::from(want))).abs() < 1e-3);
            }
        }
    }
    // A clamped map refuses rects off the map; an empty rect is refused everywhere.
    let clamped = HeightMap::new(
        hashed::<u16>(16, 16, 0, 10),
        HeightEncoding::new(0.01, 0.0).unwrap(),
        1.0,
        WrapMode::Clamp,
    )
    .unwrap();
    let gpu_c = GpuHeightMap::from_map(device, queue, &clamped).unwrap();
    let mut encoder = device.create_command_encoder(&Default::default());
    assert!(matches!(
        readback.request(
            device,
            &mut encoder,
            &gpu_c,
            Rect::new(IVec2::new(10, 10), UVec2::new(8, 2))
        ),
        Err(GpuError::BadRegion { .. })
    ));
    assert!(
        readback
            .request(
                device,
                &mut encoder,
                &gpu,
                Rect::new(IVec2::ZERO, UVec2::ZERO)
            )
            .is_err()
    );
    // On the repeating map too, a rect past i32::MAX is refused: its last columns have no
    // place in the rows read back.
    assert!(matches!(
        readback.request(
            device,
            &mut encoder,
            &gpu,
            Rect::new(IVec2::new(i32::MAX - 2, 0), UVec2::new(8, 2))
        ),
        Err(GpuError::BadRegion { .. })
    ));
    assert!(RegionReadback::new(device, 0).is_err());
    ctx.check().expect("no GPU validation errors");
}

/// More rects than the ring holds: those without room wait in the queue and go with the next
/// request, every one arrives once and in request order, equal to the map, and the flush
/// leaves nothing on its way.
#[test]
fn queued_readback_keeps_order_and_drops_nothing() {
    let Some(ctx) = context_or_skip("queued_readback") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let map = readback_map();
    let gpu = GpuHeightMap::from_map(device, queue, &map).unwrap();
    let mut readback = terrain_gpu::QueuedReadback::new(device, 2).unwrap();
    let rects: Vec<Rect> = (0..7)
        .map(|i| Rect::new(IVec2::new(3 * i, 60 - 5 * i), UVec2::new(9 + i as u32, 4)))
        .collect();
    let mut arrived = Vec::new();
    for batch in rects.chunks(3) {
        let mut encoder = device.create_command_encoder(&Default::default());
        readback
            .request(device, &mut encoder, &gpu, batch.iter().copied())
            .unwrap();
        queue.submit([encoder.finish()]);
        assert!(readback.in_flight());
        // What the ring had room for arrives; the rest waits (the poll never blocks).
        device
            .poll(wgpu::PollType::Wait {
                submission_index: None,
                timeout: Some(std::time::Duration::from_secs(60)),
            })
            .unwrap();
        arrived.extend(readback.poll(device).unwrap());
    }
    arrived.extend(readback.flush(device, queue, &gpu).unwrap());
    assert!(!readback.in_flight());
    let got: Vec<Rect> = arrived.iter().map(|r| r.rect).collect();
    assert_eq!(got, rects);
    for data in &arrived {
        assert_rows_are_the_map(&data.to_u16(), data.rect, &map);
    }
    ctx.check().expect("no GPU validation errors");
}

/// Full-width rects (one copy for all their rows), a band across the map's wrap (two pieces
/// of whole rows) and the whole map, read with `wait_with` straight into u16 rows and
/// metres: equal to the map, and to what `wait` hands over.
#[test]
fn packed_rows_of_odd_maps_read_back_texel_for_texel() {
    let Some(ctx) = context_or_skip("packed_rows_of_odd_maps") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let mut readback = RegionReadback::new(device, 4).unwrap();
    // Odd widths and starts: rects begin and end mid-word, cross the wrap inside a word's
    // columns, and cover whole odd rows (the one-copy path with a padding lane per row).
    let map = HeightMap::new(
        hashed::<u16>(37, 23, 0, 65_000),
        HeightEncoding::new(0.01, 1.0).unwrap(),
        1.0,
        WrapMode::Repeat,
    )
    .unwrap();
    let gpu = GpuHeightMap::from_map(device, queue, &map).unwrap();
    assert_eq!(gpu.read_raw(device, queue).unwrap().len(), 37 * 23);
    let rects = [
        Rect::new(IVec2::new(3, 1), UVec2::new(1, 1)),
        Rect::new(IVec2::new(35, 20), UVec2::new(5, 6)),
        Rect::new(IVec2::new(-3, 2), UVec2::new(37, 4)),
        Rect::new(IVec2::new(0, 0), UVec2::new(37, 23)),
    ];
    let mut encoder = device.create_command_encoder(&Default::default());
    for r in rects {
        readback.request(device, &mut encoder, &gpu, r).unwrap();
    }
    queue.submit([encoder.finish()]);
    for (data, rect) in readback.wait(device).unwrap().iter().zip(rects) {
        assert_rows_are_the_map(&data.to_u16(), rect, &map);
    }
    // u8 maps pack four texels a word.
    let map8 = HeightMap::new(
        hashed::<u8>(13, 5, 0, 255),
        HeightEncoding::new(0.01, 0.0).unwrap(),
        1.0,
        WrapMode::Clamp,
    )
    .unwrap();
    let gpu8 = GpuHeightMap::from_map(device, queue, &map8).unwrap();
    assert_eq!(gpu8.read(device, queue).unwrap(), map8);
    let rect = Rect::new(IVec2::new(5, 1), UVec2::new(7, 3));
    let mut encoder = device.create_command_encoder(&Default::default());
    readback.request(device, &mut encoder, &gpu8, rect).unwrap();
    queue.submit([encoder.finish()]);
    let data = readback.wait(device).unwrap().remove(0);
    for y in 0..3 {
        for x in 0..7 {
            let want = map8.grid().get(5 + x, 1 + y).unwrap();
            assert_eq!(data.raw.get(x, y), Some(u32::from(want)));
        }
    }
}

#[test]
fn whole_rows_and_direct_conversion_equal_the_map() {
    let Some(ctx) = context_or_skip("whole_rows_and_direct_conversion") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let map = readback_map();
    let gpu = GpuHeightMap::from_map(device, queue, &map).unwrap();
    let mut readback = RegionReadback::new(device, 3).unwrap();
    let rects = [
        Rect::new(IVec2::new(0, 12), UVec2::new(70, 9)),
        Rect::new(IVec2::new(0, 44), UVec2::new(70, 13)), // rows 44..50 and 0..7
        Rect::from_size(UVec2::new(70, 50)),
    ];
    let request = |readback: &mut RegionReadback| {
        let mut encoder = device.create_command_encoder(&Default::default());
        for r in rects {
            readback.request(device, &mut encoder, &gpu, r).unwrap();
        }
        queue.submit([encoder.finish()]);
    };
    request(&mut readback);
    let direct = readback
        .wait_with(device, |r| {
            (r.rect, r.to_u16().unwrap(), r.to_metres().unwrap())
        })
        .unwrap();
    request(&mut readback);
    let owned = readback.wait(device).unwrap();
    assert_eq!(direct.len(), 3);
    for ((rect, rows, metres), (data, want_rect)) in direct.iter().zip(owned.iter().zip(rects)) {
        assert_eq!(*rect, want_rect);
        assert_eq!(*rows, data.to_u16());
        assert_eq!(*metres, data.to_metres());
        assert_rows_are_the_map(rows, *rect, &map);
    }
    ctx.check().expect("no GPU validation errors");
}

#[test]
fn errors_of_submitted_work_become_results_not_panics() {
    let Some(ctx) = context_or_skip("errors_of_submitted_work_become_results") else {
        return;
    };
    assert!(ctx.check().is_ok());
    // A copy past the end of a buffer is a validation error of recorded work.
    let small = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: 16,
        usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    encoder.copy_buffer_to_buffer(&small, 0, &small, 8, 64);
    ctx.queue.submit([encoder.finish()]);
    let _ = ctx.device.poll(wgpu::PollType::wait_indefinitely());
    assert!(matches!(ctx.check(), Err(GpuError::Submitted { .. })));
    assert!(ctx.check().is_ok(), "errors are handed over once");
}

#[test]
fn the_context_reports_its_adapter() {
    let Some(ctx) = context_or_skip("the_context_reports_its_adapter") else {
        return;
    };
    let r = ctx.report();
    eprintln!(
        "adapter: {} ({}, {}), timestamps {}",
        r.name, r.backend, r.device_type, r.timestamps
    );
    assert!(!r.name.is_empty() && !r.backend.is_empty());
}

#[test]
fn a_request_whose_encoder_is_dropped_frees_its_ring_slot() {
    let Some(ctx) = context_or_skip("readback_dropped_encoder") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let map = HeightMap::new(
        hashed::<u16>(32, 32, 0, 65_000),
        HeightEncoding::new(0.01, 0.0).unwrap(),
        1.0,
        WrapMode::Repeat,
    )
    .unwrap();
    let gpu = GpuHeightMap::from_map(device, queue, &map).unwrap();
    let mut readback = RegionReadback::new(device, 1).unwrap();
    let rect = Rect::new(IVec2::new(3, 4), UVec2::new(5, 6));
    // Many requests whose encoders are dropped before submit (an engine's frame abandoned on
    // an error): none of them may keep the only slot.
    for _ in 0..5 {
        let mut encoder = device.create_command_encoder(&Default::default());
        readback.request(device, &mut encoder, &gpu, rect).unwrap();
        drop(encoder);
        assert!(readback.poll(device).unwrap().is_empty());
        assert_eq!(
            readback.in_flight(),
            0,
            "the dropped request let its slot go"
        );
    }
    // The slot serves a real request afterwards, with the right data.
    let mut encoder = device.create_command_encoder(&Default::default());
    let ticket = readback.request(device, &mut encoder, &gpu, rect).unwrap();
    queue.submit([encoder.finish()]);
    let arrived = readback.wait(device).unwrap();
    assert_eq!(arrived.len(), 1);
    assert_eq!(arrived[0].ticket, ticket);
    assert_eq!(arrived[0].to_u16(), map.grid().copy_rect(rect).unwrap());
    // A finished but never submitted command buffer lets its slot go when it is dropped too.
    let mut encoder = device.create_command_encoder(&Default::default());
    readback.request(device, &mut encoder, &gpu, rect).unwrap();
    let commands = encoder.finish();
    assert_eq!(readback.in_flight(), 1);
    drop(commands);
    readback.poll(device).unwrap();
    assert_eq!(readback.in_flight(), 0);
    ctx.check().expect("no GPU validation errors");
}
