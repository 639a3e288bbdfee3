//! GPU errors are errors: a device destroyed in the middle of a frame and of a readback gives
//! errors (and `GpuContext::check` says the device was lost), never a panic or a hang; and an
//! engine's device left with wgpu's default error handler (which panics on any error it is
//! told about) never panics because of a bad call of ours.

use glam::{IVec2, UVec2, Vec2};
use std::time::{Duration, Instant};
use terrain_core::{
    Blend, GaussianStamp, Grid, HeightEncoding, HeightMap, Rect, StampPlacement, TextureStamp,
    TileLayout, TileUploadTarget, WrapMode,
};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{
    AtlasConfig, GpuDerivativeMap, GpuError, GpuHeightMap, GpuStamp, GpuTextureStamp, GpuTileAtlas,
    NormalPass, OffscreenTarget, RegionReadback, SkyPass, StampOp, StampPass, TileSlot,
};

fn map() -> HeightMap<u16> {
    HeightMap::new(
        Grid::from_fn(32, 32, |x, y| (x * 100 + y) as u16).expect("grid"),
        HeightEncoding::new(0.01, 0.0).expect("encoding"),
        1.0,
        WrapMode::Repeat,
    )
    .expect("map")
}

fn layout() -> TileLayout {
    TileLayout {
        world_size: UVec2::splat(64),
        tile_size: 16,
        levels: 3,
        texel_size: 1.0,
        encoding: HeightEncoding::new(0.01, 0.0).expect("encoding"),
        wrap: WrapMode::Clamp,
        fill: 0,
    }
}

#[test]
fn a_device_destroyed_mid_frame_and_mid_readback_gives_errors_not_panics_or_hangs() {
    let Some(ctx) = context_or_skip("device_destroyed") else {
        return;
    };
    let start = Instant::now();
    let (device, queue) = (&ctx.device, &ctx.queue);
    let map = map();
    let gpu = GpuHeightMap::from_map(device, queue, &map).expect("map");
    let normals = GpuDerivativeMap::for_map(device, &gpu).expect("normals");
    let mut stamps = StampPass::new(device).expect("stamp pass");
    let mut normal_pass = NormalPass::new(device).expect("normal pass");
    let mut readback = RegionReadback::new(device, 2).expect("readback");
    let crater = GaussianStamp::default();
    let op = StampOp {
        stamp: GpuStamp::Gaussian(&crater),
        placement: StampPlacement::new(Vec2::splat(5.0), Vec2::splat(4.0), 1.0).expect("p"),
        blend: Blend::Add,
    };
    assert!(!ctx.is_lost());
    // A frame recorded, a readback requested, then the device is destroyed before the submit.
    let mut encoder = device.create_command_encoder(&Default::default());
    let rects = stamps
        .encode(device, queue, &mut encoder, &gpu, &op)
        .expect("encode");
    for r in &rects {
        normal_pass
            .encode(device, queue, &mut encoder, &gpu, &normals, *r)
            .expect("normals");
    }
    readback
        .request(
            device,
            &mut encoder,
            &gpu,
            Rect::new(IVec2::ZERO, UVec2::splat(4)),
        )
        .expect("request");
    device.destroy();
    queue.submit([encoder.finish()]);
    stamps.recall();
    normal_pass.recall();
    // The readback reports the failure; waiting ends; nothing arrives.
    let polled = readback.poll(device);
    let waited = readback.wait(device);
    assert!(
        polled.is_err() || waited.is_err() || polled.is_ok_and(|v| v.is_empty()),
        "a readback of a lost device delivered data"
    );
    assert_eq!(
        readback.in_flight(),
        0,
        "no slot is kept by the lost request"
    );
    // The context says so.
    assert!(ctx.is_lost());
    assert!(
        matches!(ctx.check(), Err(GpuError::DeviceLost { .. })),
        "{:?}",
        ctx.check()
    );
    // Every later call returns (an error or a dead object), none panics, none hangs.
    assert!(
        gpu.read(device, queue).is_err(),
        "a download from a lost device"
    );
    let _ = StampPass::new(device);
    let _ = NormalPass::new(device);
    let _ = GpuHeightMap::from_map(device, queue, &map);
    let _ = GpuTextureStamp::new(
        device,
        &TextureStamp::from_gray8(&Grid::new(4, 4, 9).expect("g")),
    );
    let _ = OffscreenTarget::new(device, UVec2::new(16, 16));
    let _ = GpuTileAtlas::new(
        device,
        queue,
        &AtlasConfig {
            slots: 2,
            world: layout(),
        },
    );
    let mut encoder = device.create_command_encoder(&Default::default());
    let _ = stamps.encode(device, queue, &mut encoder, &gpu, &op);
    let _ = readback.request(
        device,
        &mut encoder,
        &gpu,
        Rect::new(IVec2::ZERO, UVec2::ONE),
    );
    queue.submit([encoder.finish()]);
    let _ = readback.wait(device);
    assert!(
        start.elapsed() < Duration::from_secs(60),
        "took {:?}",
        start.elapsed()
    );
}

#[test]
fn an_engine_device_with_the_default_error_handler_never_panics_on_bad_calls() {
    let Some(ctx) = context_or_skip("default_error_handler") else {
        return;
    };
    // An engine's device: its own, with wgpu's default (panicking) error handler untouched.
    let (device, queue) = pollster::block_on(ctx.adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("engine device"),
        required_limits: ctx.adapter.limits(),
        ..Default::default()
    }))
    .expect("device");
    let map = map();
    let gpu = GpuHeightMap::from_map(&device, &queue, &map).expect("map");
    let normals = GpuDerivativeMap::for_map(&device, &gpu).expect("normals");
    let mut stamps = StampPass::new(&device).expect("stamp pass");
    let mut normal_pass = NormalPass::new(&device).expect("normal pass");
    let mut readback = RegionReadback::new(&device, 1).expect("readback");
    let crater = GaussianStamp::default();
    let mut encoder = device.create_command_encoder(&Default::default());
    // Bad inputs: every one refused before wgpu sees it.
    let off_map = Rect::new(IVec2::new(30, 30), UVec2::new(8, 8));
    let clamped = HeightMap::new(
        Grid::new(16, 16, 1u16).expect("grid"),
        HeightEncoding::new(0.01, 0.0).expect("encoding"),
        1.0,
        WrapMode::Clamp,
    )
    .expect("map");
    let gpu_clamped = GpuHeightMap::from_map(&device, &queue, &clamped).expect("map");
    assert!(
        readback
            .request(&device, &mut encoder, &gpu_clamped, off_map)
            .is_err()
    );
    assert!(
        readback
            .request(
                &device,
                &mut encoder,
                &gpu,
                Rect::new(IVec2::ZERO, UVec2::new(64, 1))
            )
            .is_err()
    );
    // An empty rect: nothing to do or an error, never a panic of the default handler.
    let _ = normal_pass.encode(
        &device,
        &queue,
        &mut encoder,
        &gpu,
        &normals,
        Rect::new(IVec2::ZERO, UVec2::ZERO),
    );
    let bad_base = StampOp {
        stamp: GpuStamp::Gaussian(&crater),
        placement: StampPlacement::new(Vec2::splat(5.0), Vec2::splat(4.0), 1.0).expect("p"),
        blend: Blend::Min { base_m: f32::NAN },
    };
    assert!(
        stamps
            .encode(&device, &queue, &mut encoder, &gpu, &bad_base)
            .is_err()
    );
    assert!(
        gpu.write(&queue, &clamped).is_err(),
        "a map of another size"
    );
    assert!(OffscreenTarget::new(&device, UVec2::new(0, 16)).is_err());
    assert!(OffscreenTarget::new(&device, UVec2::new(1 << 20, 16)).is_err());
    let mut atlas = GpuTileAtlas::new(
        &device,
        &queue,
        &AtlasConfig {
            slots: 2,
            world: layout(),
        },
    )
    .expect("atlas");
    assert!(
        atlas
            .upload(5, 0, UVec2::ZERO, &Grid::new(16, 16, 0).expect("g"))
            .is_err()
    );
    assert!(atlas.map(9, UVec2::ZERO, Some(0)).is_err());
    assert!(
        stamps
            .encode_tile(
                &device,
                &queue,
                &mut encoder,
                &atlas,
                TileSlot { slot: 7, level: 0 },
                &bad_base
            )
            .is_err()
    );
    assert!(
        SkyPass::new(
            &device,
            &OffscreenTarget::new(&device, UVec2::splat(8))
                .expect("t")
                .format()
        )
        .is_ok()
    );
    // And good work after all that still runs and arrives.
    let op = StampOp {
        blend: Blend::Add,
        ..bad_base
    };
    stamps
        .encode(&device, &queue, &mut encoder, &gpu, &op)
        .expect("encode");
    readback
        .request(
            &device,
            &mut encoder,
            &gpu,
            Rect::new(IVec2::ZERO, UVec2::splat(8)),
        )
        .expect("request");
    queue.submit([encoder.finish()]);
    stamps.recall();
    let arrived = readback.wait(&device).expect("arrived");
    assert_eq!(arrived.len(), 1);
}
