//! The collision mirror follows the GPU map: deformations on the GPU, a quiet gap, a merged
//! readback through `GpuRegionSource`, and the mirror equals the GPU map exactly. The body
//! under a fresh deformation stays above ground before the readback lands.
//!
//! It joins terrain-gpu and terrain-physics, which do not name each other, so it lives here in
//! the crate that glues them.

use glam::{Vec2, Vec3};
use std::time::{Duration, Instant};
use terrain_core::{Blend, CoarseMap, GaussianStamp, Grid, HeightEncoding, StampPlacement};
use terrain_gpu::testing::context_or_skip;
use terrain_gpu::{GpuHeightMap, GpuRegionSource, GpuStamp, RegionReadback, StampOp, StampPass};
use terrain_physics::{
    CameraBody, CollisionMirror, DeformationBound, GroundQuery, ReadbackScheduler, SchedulerConfig,
};

#[test]
fn mirror_equals_the_gpu_map_after_the_quiet_gap_and_readback() {
    let Some(ctx) = context_or_skip("mirror_equals_the_gpu_map") else {
        return;
    };
    let (device, queue) = (&ctx.device, &ctx.queue);
    let enc = HeightEncoding::new(0.001, 0.0).unwrap();
    let map = CoarseMap::coarse(Grid::new(160, 120, 20_000u16).unwrap(), enc, 0.5).unwrap();
    let gpu = GpuHeightMap::from_map(device, queue, &map).unwrap();
    let mirror = CollisionMirror::from_map(&map).unwrap();
    let mut scheduler = ReadbackScheduler::for_mirror(&mirror, SchedulerConfig::default()).unwrap();
    let mut readback = RegionReadback::new(device, 4).unwrap();
    let mut pass = StampPass::new(device).unwrap();
    let gauss = GaussianStamp::default();

    // A body standing where a 3 m mound is about to rise.
    let mut body = CameraBody::new(Vec3::new(40.0, 25.0, 30.0));
    body.gravity_enabled = true;
    let t0 = Instant::now();
    for _ in 0..50 {
        let collider = mirror.collider();
        let ground = scheduler.ground(&collider);
        body.step(1.0 / 60.0, Vec3::ZERO, &ground).unwrap();
    }

    // A burst of deformations, one across the wrap corner, 5 ms apart.
    let stamps = [
        (Vec2::new(40.0, 30.0), 12.0, 3.0),
        (Vec2::new(1.0, 59.0), 8.0, -1.5),
        (Vec2::new(42.0, 33.0), 6.0, 1.0),
    ];
    let mut now = t0;
    for (center, size, intensity) in stamps {
        let p = StampPlacement::new(center, Vec2::splat(size), intensity).unwrap();
        let mut encoder = device.create_command_encoder(&Default::default());
        let rects = pass
            .encode(
                device,
                queue,
                &mut encoder,
                &gpu,
                &StampOp {
                    stamp: GpuStamp::Gaussian(&gauss),
                    placement: p,
                    blend: Blend::Add,
                },
            )
            .unwrap();
        queue.submit([encoder.finish()]);
        pass.recall();
        for r in rects {
            scheduler
                .note_deformation(r, DeformationBound::additive(intensity, enc).unwrap(), now)
                .unwrap();
        }
        now += Duration::from_millis(5);
        let mut source = GpuRegionSource::new(device, queue, &gpu, &mut readback);
        let report = scheduler.update(now, &mut source, &mirror).unwrap();
        assert!(
            report.requested.is_empty(),
            "no request before the quiet gap"
        );
    }

    // Before the readback the mirror is stale, but the bound keeps the body on the mound.
    let truth: CoarseMap = gpu.read(device, queue).unwrap();
    let true_ground = terrain_core::bilinear(&truth, Vec2::new(40.0, 30.0)).unwrap();
    for _ in 0..10 {
        let collider = mirror.collider();
        let ground = scheduler.ground(&collider);
        body.step(1.0 / 60.0, Vec3::ZERO, &ground).unwrap();
    }
    assert!(
        body.position.y - body.eye_height >= true_ground - 1e-3,
        "body at {} under the new ground {true_ground}",
        body.position.y - body.eye_height
    );

    // After the gap: requests go out; the caller never waits, arrivals apply on later updates.
    now += Duration::from_millis(30);
    let mut requested = 0;
    let mut applied = 0;
    for _ in 0..200 {
        let mut source = GpuRegionSource::new(device, queue, &gpu, &mut readback);
        let report = scheduler.update(now, &mut source, &mirror).unwrap();
        requested += report.requested.len();
        applied += report.applied.len();
        if scheduler.is_idle() {
            break;
        }
        device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
        now += Duration::from_millis(16);
    }
    assert!(
        (1..=2).contains(&requested),
        "merged into {requested} requests"
    );
    assert_eq!(applied, requested);
    assert!(scheduler.is_idle());
    let snapshot = mirror.snapshot();
    assert_eq!(
        snapshot.heights(),
        truth.grid(),
        "the mirror equals the GPU map exactly"
    );
    let mirror_ground = mirror
        .collider()
        .ground_height(Vec2::new(40.0, 30.0))
        .unwrap();
    assert!((mirror_ground - true_ground).abs() < 1e-4);
    ctx.check().expect("no GPU validation errors");
}
