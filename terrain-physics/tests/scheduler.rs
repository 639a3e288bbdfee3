//! The readback scheduler with synthetic time: the quiet gap, merging a burst into one
//! request, applying on arrival (in request order), never blocking, wrap-edge rects, and the
//! pending-deformation bound that keeps bodies above ground before the readback arrives.

mod common;

use glam::{IVec2, UVec2, Vec2, Vec3};
use std::convert::Infallible;
use std::time::{Duration, Instant};
use terrain_core::{Blend, CoarseMap, GaussianStamp, Rect, StampPlacement, apply_stamp, bilinear};
use terrain_physics::{
    ArrivedRegion, CameraBody, CollisionMirror, CpuRegionSource, DeformationBound, GroundQuery,
    PhysicsError, ReadbackScheduler, RegionSource, RequestId, SchedulerConfig, SphereBody,
    UpdateError,
};

fn ms(t0: Instant, m: u64) -> Instant {
    t0 + Duration::from_millis(m)
}

struct Rig {
    source: CpuRegionSource,
    mirror: CollisionMirror,
    scheduler: ReadbackScheduler,
}

fn rig(map: CoarseMap, latency: u32) -> Rig {
    let mirror = CollisionMirror::from_map(&map).expect("mirror");
    let scheduler =
        ReadbackScheduler::for_mirror(&mirror, SchedulerConfig::default()).expect("scheduler");
    let source = CpuRegionSource::new(map)
        .with_latency(latency)
        .expect("latency");
    Rig {
        source,
        mirror,
        scheduler,
    }
}

impl Rig {
    /// Stamps a Gaussian of `intensity` metres at `centre` into the source map and notes it.
    fn stamp(&mut self, centre: Vec2, size_m: f32, intensity: f32, now: Instant) -> Vec<Rect> {
        let placement =
            StampPlacement::new(centre, Vec2::splat(size_m), intensity).expect("placement");
        let dirty = apply_stamp(
            self.source.map_mut(),
            &mut GaussianStamp::default(),
            &placement,
            Blend::Add,
        )
        .expect("stamp");
        let bound =
            DeformationBound::additive(intensity, self.source.map().encoding()).expect("bound");
        for r in &dirty {
            self.scheduler
                .note_deformation(*r, bound, now)
                .expect("note");
        }
        dirty
    }

    fn update(&mut self, now: Instant) -> terrain_physics::UpdateReport {
        self.scheduler
            .update(now, &mut self.source, &self.mirror)
            .expect("update")
    }

    fn mirror_equals_source(&self) -> bool {
        self.mirror.snapshot().heights() == self.source.map().grid()
    }
}

#[test]
fn nothing_is_requested_before_the_quiet_gap() {
    let mut r = rig(common::hills(64), 1);
    let t0 = Instant::now();
    r.stamp(Vec2::new(10.0, 10.0), 3.0, 1.0, t0);
    for m in [0, 5, 10, 19] {
        assert!(r.update(ms(t0, m)).requested.is_empty(), "at {m} ms");
    }
    assert!(r.source.requests().is_empty());
    let rep = r.update(ms(t0, 20));
    assert_eq!(rep.requested.len(), 1);
}

#[test]
fn a_burst_of_deformations_yields_one_merged_request_after_the_gap() {
    let mut r = rig(common::hills(64), 1);
    let t0 = Instant::now();
    let mut dirty = Vec::new();
    // Ten footprints 5 ms apart, walking across the map.
    for i in 0..10u64 {
        let now = ms(t0, 5 * i);
        dirty.extend(r.stamp(Vec2::new(5.0 + i as f32 * 0.8, 8.0), 2.0, -0.3, now));
        assert!(r.update(now).requested.is_empty());
    }
    assert!(r.update(ms(t0, 45 + 19)).requested.is_empty());
    let rep = r.update(ms(t0, 45 + 20));
    assert_eq!(rep.requested.len(), 1, "{rep:?}");
    let (_, merged) = rep.requested[0];
    for d in &dirty {
        assert!(merged.contains_rect(d), "{merged:?} misses {d:?}");
    }
    assert!(merged.size.cmple(UVec2::splat(64)).all());
    // It arrives on the next poll and the mirror then equals the source exactly.
    assert!(!r.mirror_equals_source());
    let rep = r.update(ms(t0, 70));
    assert_eq!(rep.applied.len(), 1);
    assert!(r.mirror_equals_source());
    assert!(r.scheduler.is_idle());
}

#[test]
fn results_apply_on_arrival_and_the_caller_never_waits_for_them() {
    let mut r = rig(common::hills(64), 3);
    let t0 = Instant::now();
    r.stamp(Vec2::new(20.0, 12.0), 4.0, 1.5, t0);
    assert_eq!(r.update(ms(t0, 20)).requested.len(), 1);
    let before = r.mirror.version();
    // The readback is in flight for three polls: each update returns with nothing applied.
    for m in [21, 22] {
        let rep = r.update(ms(t0, m));
        assert!(rep.applied.is_empty());
        assert_eq!(r.mirror.version(), before);
        assert_eq!(r.scheduler.in_flight(), 1);
    }
    let rep = r.update(ms(t0, 23));
    assert_eq!(rep.applied.len(), 1);
    assert_eq!(r.mirror.version(), before + 1);
    assert!(r.mirror_equals_source());
}

/// A source whose data never arrives: update must still return at once, every time.
#[derive(Debug, Default)]
struct Never {
    next: u64,
}

impl RegionSource for Never {
    type Error = Infallible;

    fn request(&mut self, _rect: Rect) -> Result<RequestId, Infallible> {
        self.next += 1;
        Ok(RequestId(self.next))
    }
    fn poll(&mut self) -> Result<Vec<ArrivedRegion>, Infallible> {
        Ok(Vec::new())
    }
}

#[test]
fn update_returns_while_a_readback_never_arrives() {
    let r = rig(common::hills(32), 1);
    let (mirror, mut scheduler) = (r.mirror, r.scheduler);
    let mut never = Never::default();
    let t0 = Instant::now();
    let rect = Rect::new(IVec2::new(3, 3), UVec2::new(4, 4));
    let bound = DeformationBound::new(0.5, 0.0).expect("bound");
    scheduler.note_deformation(rect, bound, t0).expect("note");
    for m in 0..100 {
        scheduler
            .update(ms(t0, 20 + m), &mut never, &mirror)
            .expect("update");
    }
    assert_eq!(scheduler.in_flight(), 1);
    assert_eq!(mirror.version(), 0);
    // The bound stays in force while the readback is outstanding.
    assert_eq!(scheduler.pending_deformations().count(), 1);
}

/// A flush requests at once, quiet gap or not, waits for the arrivals (three polls late here)
/// and leaves the mirror equal to the source with nothing pending.
#[test]
fn a_flush_brings_the_mirror_level_with_the_source_before_the_quiet_gap() {
    let mut r = rig(common::hills(64), 3);
    let t0 = Instant::now();
    let dirty = r.stamp(Vec2::new(20.0, 12.0), 4.0, 1.5, t0);
    r.stamp(Vec2::new(1.0, 62.0), 3.0, -0.5, t0);
    assert!(r.update(t0).requested.is_empty(), "the gap has not passed");
    let rep = r
        .scheduler
        .flush(&mut r.source, &r.mirror, Duration::from_secs(5))
        .expect("flush");
    assert!(!rep.requested.is_empty());
    assert_eq!(rep.applied.len(), rep.requested.len());
    assert!(rep.applied_rects.iter().any(|a| a.contains_rect(&dirty[0])));
    assert!(r.mirror_equals_source());
    assert!(r.scheduler.is_idle());
    assert_eq!(r.scheduler.pending_deformations().count(), 0);
    // Nothing pending: a flush returns at once with nothing done.
    let rep = r
        .scheduler
        .flush(&mut r.source, &r.mirror, Duration::from_secs(5))
        .expect("flush");
    assert_eq!(rep, terrain_physics::UpdateReport::default());
}

/// A source that never delivers: the flush gives up after its timeout with an error that says
/// what is left, and the bound stays pending.
#[test]
fn a_flush_times_out_when_the_source_never_delivers() {
    let r = rig(common::hills(32), 1);
    let (mirror, mut scheduler) = (r.mirror, r.scheduler);
    let rect = Rect::new(IVec2::new(3, 3), UVec2::new(4, 4));
    let bound = DeformationBound::new(0.5, 0.0).expect("bound");
    scheduler
        .note_deformation(rect, bound, Instant::now())
        .expect("note");
    let t = Instant::now();
    let err = scheduler
        .flush(&mut Never::default(), &mirror, Duration::from_millis(30))
        .expect_err("never arrives");
    assert!(t.elapsed() < Duration::from_secs(5));
    assert!(
        matches!(
            err,
            UpdateError::Physics(PhysicsError::FlushTimedOut {
                in_flight: 1,
                dirty: 0,
                ..
            })
        ),
        "{err}"
    );
    assert_eq!(scheduler.pending_deformations().count(), 1);
    assert_eq!(mirror.version(), 0);
}

#[test]
fn a_deformation_across_the_corner_is_one_request_that_wraps() {
    let mut r = rig(common::hills(64), 1);
    let t0 = Instant::now();
    // 64 texels at 0.5 m: the map is 32 m; a stamp at the corner lands on all four corners.
    let dirty = r.stamp(Vec2::new(0.5, 31.8), 3.0, 1.0, t0);
    assert_eq!(dirty.len(), 4);
    let rep = r.update(ms(t0, 20));
    assert_eq!(rep.requested.len(), 1, "{rep:?}");
    let (_, rect) = rep.requested[0];
    assert!(
        rect.max().x > 64 && rect.max().y > 64,
        "{rect:?} should cross both edges"
    );
    assert!(
        rect.size.cmplt(UVec2::splat(20)).all(),
        "{rect:?} should stay small"
    );
    r.update(ms(t0, 21));
    assert!(r.mirror_equals_source());
}

/// A source that hands regions back in reverse order of request.
#[derive(Debug)]
struct Reversed {
    inner: CpuRegionSource,
    held: Vec<ArrivedRegion>,
}

impl RegionSource for Reversed {
    type Error = PhysicsError;

    fn request(&mut self, rect: Rect) -> Result<RequestId, PhysicsError> {
        self.inner.request(rect)
    }
    fn poll(&mut self) -> Result<Vec<ArrivedRegion>, PhysicsError> {
        self.held.extend(self.inner.poll()?);
        if self.held.len() < 2 {
            return Ok(Vec::new());
        }
        let mut out = std::mem::take(&mut self.held);
        out.reverse();
        Ok(out)
    }
}

#[test]
fn regions_arriving_out_of_order_apply_in_request_order() {
    let mut r = rig(common::hills(64), 1);
    let t0 = Instant::now();
    let centre = Vec2::new(12.0, 12.0);
    // Two batches over the same place: the second's data must win.
    r.stamp(centre, 4.0, 1.0, t0);
    let mut src = Reversed {
        inner: r.source.clone(),
        held: Vec::new(),
    };
    let first = r
        .scheduler
        .update(ms(t0, 20), &mut src, &r.mirror)
        .expect("update");
    let placement = StampPlacement::new(centre, Vec2::splat(4.0), 1.0).expect("placement");
    let dirty = apply_stamp(
        src.inner.map_mut(),
        &mut GaussianStamp::default(),
        &placement,
        Blend::Add,
    )
    .expect("stamp");
    let bound = DeformationBound::additive(1.0, src.inner.map().encoding()).expect("bound");
    for d in dirty {
        r.scheduler
            .note_deformation(d, bound, ms(t0, 30))
            .expect("note");
    }
    let rep = r
        .scheduler
        .update(ms(t0, 50), &mut src, &r.mirror)
        .expect("update");
    assert_eq!(rep.requested.len(), 1);
    let second = rep.requested[0].0;
    let rep = r
        .scheduler
        .update(ms(t0, 51), &mut src, &r.mirror)
        .expect("update");
    let ids: Vec<RequestId> = rep.applied.iter().map(|(id, _)| *id).collect();
    assert_eq!(ids, vec![first.requested[0].0, second]);
    assert_eq!(r.mirror.snapshot().heights(), src.inner.map().grid());
    assert!(r.scheduler.is_idle());
}

/// A source's own failure, in its own type (as terrain-gpu's source reports a `GpuError`).
#[derive(Debug, Clone, PartialEq, Eq)]
struct SourceFailed(&'static str);

impl std::fmt::Display for SourceFailed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.0)
    }
}

impl std::error::Error for SourceFailed {}

/// A source that delivers a region nobody asked for.
#[derive(Debug)]
struct Rogue;

impl RegionSource for Rogue {
    type Error = SourceFailed;

    fn request(&mut self, _rect: Rect) -> Result<RequestId, SourceFailed> {
        Err(SourceFailed("staging ring full"))
    }
    fn poll(&mut self) -> Result<Vec<ArrivedRegion>, SourceFailed> {
        Ok(vec![ArrivedRegion {
            id: RequestId(99),
            rect: Rect::new(IVec2::ZERO, UVec2::ONE),
            heights: terrain_core::Grid::new(1, 1, 0).expect("grid"),
        }])
    }
}

#[test]
fn source_failures_are_errors_and_keep_the_rects_dirty() {
    let mut r = rig(common::hills(32), 1);
    let t0 = Instant::now();
    let e = r.scheduler.update(t0, &mut Rogue, &r.mirror);
    assert!(matches!(
        e,
        Err(UpdateError::Physics(PhysicsError::UnknownRequest {
            id: RequestId(99)
        }))
    ));
    r.stamp(Vec2::new(4.0, 4.0), 2.0, 1.0, t0);
    struct Failing;
    impl RegionSource for Failing {
        type Error = SourceFailed;

        fn request(&mut self, _rect: Rect) -> Result<RequestId, SourceFailed> {
            Err(SourceFailed("device lost"))
        }
        fn poll(&mut self) -> Result<Vec<ArrivedRegion>, SourceFailed> {
            Ok(Vec::new())
        }
    }
    let e = r.scheduler.update(ms(t0, 25), &mut Failing, &r.mirror);
    assert_eq!(e, Err(UpdateError::Source(SourceFailed("device lost"))));
    // The source's error is the update error's source, unchanged.
    let e = e.expect_err("failed");
    let cause = std::error::Error::source(&e).expect("a source");
    assert_eq!(cause.to_string(), "device lost");
    assert_eq!(r.scheduler.dirty_rects().len(), 1);
    // The next update with a working source requests it at once (the gap has passed).
    let rep = r.update(ms(t0, 26));
    assert_eq!(rep.requested.len(), 1);
    r.update(ms(t0, 27));
    assert!(r.mirror_equals_source());
}

#[test]
fn a_busy_source_is_back_pressure_not_a_failure() {
    // Every staging buffer on its way: the request is refused as busy. The update reports no
    // error (and what it did report is kept), the rect stays dirty and is asked for again.
    struct Busy;
    impl RegionSource for Busy {
        type Error = SourceFailed;

        fn request(&mut self, _rect: Rect) -> Result<RequestId, SourceFailed> {
            Err(SourceFailed("busy"))
        }
        fn poll(&mut self) -> Result<Vec<ArrivedRegion>, SourceFailed> {
            Ok(Vec::new())
        }
        fn is_busy(&self, error: &SourceFailed) -> bool {
            error.0 == "busy"
        }
    }
    let mut r = rig(common::hills(32), 1);
    let t0 = Instant::now();
    r.stamp(Vec2::new(4.0, 4.0), 2.0, 1.0, t0);
    let rep = r.scheduler.update(ms(t0, 25), &mut Busy, &r.mirror);
    let rep = rep.expect("busy is no error");
    assert!(rep.requested.is_empty());
    assert_eq!(r.scheduler.dirty_rects().len(), 1);
    let rep = r.update(ms(t0, 26));
    assert_eq!(rep.requested.len(), 1);
    r.update(ms(t0, 27));
    assert!(r.mirror_equals_source());
}

#[test]
fn the_deformation_bound_keeps_bodies_above_the_raised_ground_until_the_readback() {
    let mut r = rig(common::flat(64, 10.0), 4);
    let t0 = Instant::now();
    let spot = Vec2::new(16.0, 16.0);
    let mut camera = CameraBody::new(Vec3::new(spot.x, 10.0 + 1.7, spot.y));
    let mut ball = SphereBody::new(Vec3::new(spot.x + 1.0, 10.5, spot.y), 0.5).expect("ball");
    // Settle both on the flat ground.
    for _ in 0..5 {
        let c = r.mirror.collider();
        let g = r.scheduler.ground(&c);
        camera.step(1.0 / 60.0, Vec3::ZERO, &g).expect("step");
        ball.step(1.0 / 60.0, Vec3::ZERO, &g).expect("step");
    }
    // A 2 m mound rises under both.
    r.stamp(spot, 8.0, 2.0, t0);
    let true_height = |r: &Rig, p: Vec2| bilinear(r.source.map(), p).expect("finite");
    assert!(true_height(&r, spot) > 11.9);
    let mut frame = 0u64;
    let mut saw_gap = false;
    loop {
        let now = ms(t0, frame * 8);
        r.update(now);
        let c = r.mirror.collider();
        // Without the bound the mirror alone would put the camera 2 m underground.
        let mirror_only = c.height(spot).expect("h");
        let stale = mirror_only < true_height(&r, spot) - 1.0;
        saw_gap |= stale;
        let g = r.scheduler.ground(&c);
        camera.step(1.0 / 60.0, Vec3::ZERO, &g).expect("step");
        ball.step(1.0 / 60.0, Vec3::ZERO, &g).expect("step");
        let cam_ground = true_height(&r, Vec2::new(camera.position.x, camera.position.z));
        assert!(
            camera.position.y >= cam_ground + camera.eye_height - 1e-3,
            "frame {frame}: camera eye {} under ground {cam_ground} + eye",
            camera.position.y
        );
        let truth = r.source.map().clone();
        let truth = terrain_physics::HeightfieldCollider::from_map(&truth).expect("collider");
        let below = truth
            .height(Vec2::new(ball.center.x, ball.center.z))
            .expect("h");
        assert!(
            ball.center.y >= below,
            "frame {frame}: ball centre under ground"
        );
        let pen = truth
            .sphere_contact(ball.center, ball.radius)
            .expect("ok")
            .map_or(0.0, |k| k.depth);
        assert!(
            pen < 2e-3,
            "frame {frame}: ball sunk {pen} m into the true ground"
        );
        if r.scheduler.is_idle() && r.mirror_equals_source() {
            break;
        }
        frame += 1;
        assert!(frame < 100, "readback never completed");
    }
    assert!(
        saw_gap,
        "the test never exercised the gap before the readback"
    );
    // After the readback the bound is gone and the mirror is exact.
    let c = r.mirror.collider();
    let g = r.scheduler.ground(&c);
    assert_eq!(
        g.ground_height(spot).expect("h"),
        c.height(spot).expect("h")
    );
}

/// Idle only when nothing is waiting for the quiet gap, nothing is in flight and nothing is
/// dirty: checked at every stage of one deformation's life.
#[test]
fn idle_only_when_nothing_is_waiting_or_in_flight() {
    let mut r = rig(common::hills(64), 2);
    let t0 = Instant::now();
    assert!(r.scheduler.is_idle());
    r.stamp(Vec2::new(10.0, 10.0), 3.0, 1.0, t0);
    // Noted, waiting for the gap.
    assert!(!r.scheduler.is_idle());
    assert!(!r.scheduler.dirty_rects().is_empty());
    assert!(r.update(ms(t0, 5)).requested.is_empty());
    assert!(!r.scheduler.is_idle());
    // Requested: nothing dirty or waiting any more, one request in flight.
    assert_eq!(r.update(ms(t0, 20)).requested.len(), 1);
    assert!(r.scheduler.dirty_rects().is_empty());
    assert_eq!(r.scheduler.in_flight(), 1);
    assert!(!r.scheduler.is_idle());
    // Still in flight on the next poll (latency 2), applied on the one after.
    assert!(r.update(ms(t0, 21)).applied.is_empty());
    assert!(!r.scheduler.is_idle());
    assert_eq!(r.update(ms(t0, 22)).applied.len(), 1);
    assert_eq!(r.scheduler.in_flight(), 0);
    assert!(r.scheduler.is_idle());
    assert!(r.mirror_equals_source());
    // A new deformation while one is in flight: not idle until both are applied.
    r.stamp(Vec2::new(30.0, 10.0), 3.0, 1.0, ms(t0, 30));
    assert_eq!(r.update(ms(t0, 50)).requested.len(), 1);
    r.stamp(Vec2::new(20.0, 20.0), 3.0, -1.0, ms(t0, 51));
    assert!(!r.scheduler.is_idle());
    for m in 52..200 {
        r.update(ms(t0, m));
        if r.scheduler.is_idle() {
            break;
        }
        assert!(
            !r.mirror_equals_source() || r.scheduler.in_flight() > 0,
            "at {m} ms"
        );
    }
    assert!(r.scheduler.is_idle());
    assert!(r.mirror_equals_source());
}

/// A scheduler over `map` with `config`, its source delivering after `latency` polls.
fn rig_with(map: CoarseMap, latency: u32, config: SchedulerConfig) -> Rig {
    let mirror = CollisionMirror::from_map(&map).expect("mirror");
    let scheduler = ReadbackScheduler::for_mirror(&mirror, config).expect("scheduler");
    let source = CpuRegionSource::new(map)
        .with_latency(latency)
        .expect("latency");
    Rig {
        source,
        mirror,
        scheduler,
    }
}

/// A 2 x 2 texel rect at `(x, y)`.
fn cell_rect(x: i32, y: i32) -> Rect {
    Rect::new(IVec2::new(x, y), UVec2::splat(2))
}

/// Beyond MAX_PENDING_DEFORMATIONS records, the merged ones still bound every deformation:
/// three that overlap a cell add up there.
#[test]
fn merged_pending_bounds_still_cover_every_deformation() {
    let map = common::hills(256);
    let collider = terrain_physics::HeightfieldCollider::from_map(&map).expect("collider");
    let mut s = ReadbackScheduler::new(UVec2::splat(256), SchedulerConfig::default()).expect("s");
    let t0 = Instant::now();
    let bound = DeformationBound::new(0.1, 0.05).expect("bound");
    for _ in 0..3 {
        s.note_deformation(cell_rect(100, 100), bound, t0)
            .expect("note");
    }
    for k in 0..terrain_physics::MAX_PENDING_DEFORMATIONS as i32 {
        let (x, y) = (2 * (k % 120), 2 * (k / 120) + 120);
        s.note_deformation(cell_rect(x, y), bound, t0)
            .expect("note");
    }
    assert!(s.pending_deformations().count() <= 8, "merged");
    let p = Vec2::new(100.5, 100.5) * 0.5; // texel (100, 100) at 0.5 m per texel
    let h = collider.height(p).expect("height");
    let (lo, hi) = s.ground(&collider).height_interval(p).expect("interval");
    assert!(hi >= h + 0.3 - 1e-5, "{hi} < {h} + 0.3");
    assert!(lo <= h - 0.15 + 1e-5, "{lo} > {h} - 0.15");
}

/// Requests that are abandoned give their deformation records back one by one (a few are no
/// reason to merge them into coarser ones).
#[test]
fn abandoned_requests_keep_their_records_exact() {
    let mut r = rig(common::hills(64), 1_000_000);
    let t0 = Instant::now();
    let bound = DeformationBound::new(0.2, 0.0).expect("bound");
    let rects: Vec<Rect> = (0..6).map(|k| cell_rect(10 * k, 5 * k)).collect();
    for &rect in &rects {
        r.scheduler.note_deformation(rect, bound, t0).expect("note");
    }
    assert!(!r.update(ms(t0, 30)).requested.is_empty());
    let report = r.update(ms(t0, 1100));
    assert!(!report.abandoned.is_empty());
    let mut kept: Vec<Rect> = r.scheduler.pending_deformations().map(|p| p.rect).collect();
    kept.sort_by_key(|q| (q.min.x, q.min.y));
    assert_eq!(kept, rects);
}

/// A batch that would take the requests in flight past `max_in_flight` waits.
#[test]
fn a_batch_waits_while_it_would_overfill_the_pipeline() {
    let config = SchedulerConfig {
        merge_distance: 0,
        max_requests: 2,
        max_in_flight: 2,
        request_timeout: Duration::from_secs(60),
        ..SchedulerConfig::default()
    };
    let mut r = rig_with(common::hills(64), 1_000_000, config);
    let t0 = Instant::now();
    let bound = DeformationBound::new(0.2, 0.0).expect("bound");
    // Two dirty and none in flight: exactly a full pipeline, which goes.
    for rect in [cell_rect(2, 2), cell_rect(40, 40)] {
        r.scheduler.note_deformation(rect, bound, t0).expect("note");
    }
    assert_eq!(r.update(ms(t0, 30)).requested.len(), 2);
    r.scheduler
        .note_deformation(cell_rect(20, 20), bound, ms(t0, 40))
        .expect("note");
    // Two in flight and one dirty: three would be in flight.
    assert!(r.update(ms(t0, 100)).requested.is_empty());
    assert_eq!(r.scheduler.in_flight(), 2);
    assert_eq!(r.scheduler.dirty_rects().len(), 1);
}

/// Records are merged only beyond MAX_PENDING_DEFORMATIONS: exactly that many, waiting and in
/// flight together, or given back by abandoned requests, stay one by one.
#[test]
fn exactly_the_record_limit_is_not_merged() {
    let config = SchedulerConfig {
        request_timeout: Duration::from_secs(1),
        max_in_flight: 64,
        ..SchedulerConfig::default()
    };
    let max = terrain_physics::MAX_PENDING_DEFORMATIONS;
    let bound = DeformationBound::new(0.1, 0.0).expect("bound");
    let rect = |k: usize| cell_rect(2 * (k % 30) as i32, 2 * (k / 30 % 30) as i32);
    // Waiting and in flight: `max - 24` requested, then 24 more.
    let mut r = rig_with(common::hills(64), 1_000_000, config);
    let t0 = Instant::now();
    for k in 0..max - 24 {
        r.scheduler
            .note_deformation(rect(k), bound, t0)
            .expect("note");
    }
    assert!(!r.update(ms(t0, 30)).requested.is_empty());
    for k in 0..24 {
        r.scheduler
            .note_deformation(rect(k), bound, ms(t0, 40))
            .expect("note");
    }
    assert!(!r.update(ms(t0, 100)).requested.is_empty());
    assert_eq!(r.scheduler.pending_deformations().count(), max);
    // Abandoned: the requests of `max` records time out and give them back.
    let mut r = rig_with(common::hills(64), 1_000_000, config);
    for k in 0..max {
        r.scheduler
            .note_deformation(rect(k), bound, t0)
            .expect("note");
    }
    assert!(!r.update(ms(t0, 30)).requested.is_empty());
    assert!(!r.update(ms(t0, 1100)).abandoned.is_empty());
    assert_eq!(r.scheduler.pending_deformations().count(), max);
}

/// Batch after batch whose requests never arrive: the records in flight stay within the
/// documented bound (twice MAX_PENDING_DEFORMATIONS and a few), merged as they go.
#[test]
fn records_in_flight_stay_bounded_when_nothing_arrives() {
    let config = SchedulerConfig {
        max_in_flight: 64,
        request_timeout: Duration::from_secs(600),
        ..SchedulerConfig::default()
    };
    let mut r = rig_with(common::hills(64), 1_000_000, config);
    let t0 = Instant::now();
    let bound = DeformationBound::new(0.1, 0.0).expect("bound");
    let limit = 2 * terrain_physics::MAX_PENDING_DEFORMATIONS + 16;
    for b in 0..5u64 {
        let t = ms(t0, 100 * b);
        for k in 0..1000 {
            let rect = cell_rect(2 * (k % 30), 2 * (k / 30 % 30));
            r.scheduler.note_deformation(rect, bound, t).expect("note");
        }
        assert!(
            !r.update(t + Duration::from_millis(30)).requested.is_empty(),
            "batch {b}"
        );
        let n = r.scheduler.pending_deformations().count();
        assert!(n <= limit, "batch {b}: {n} records pending");
    }
}

/// Deformations close in one axis only are separate requests (merging needs both axes).
#[test]
fn rects_far_apart_along_one_axis_are_requested_apart() {
    let mut r = rig(common::hills(128), 1_000_000);
    let t0 = Instant::now();
    let bound = DeformationBound::new(0.2, 0.0).expect("bound");
    for rect in [cell_rect(5, 5), cell_rect(60, 5), cell_rect(5, 60)] {
        r.scheduler.note_deformation(rect, bound, t0).expect("note");
    }
    let mut got: Vec<Rect> = r.update(ms(t0, 30)).requested.iter().map(|q| q.1).collect();
    got.sort_by_key(|q| (q.min.x, q.min.y));
    assert_eq!(
        got,
        vec![cell_rect(5, 5), cell_rect(5, 60), cell_rect(60, 5)]
    );
}

/// Several abandoned requests whose regions arrive late all count as late, none as unknown
/// (their ids are remembered, not only the last one's).
#[test]
fn late_regions_of_several_abandoned_requests_are_all_recognised() {
    let config = SchedulerConfig {
        merge_distance: 0,
        request_timeout: Duration::from_millis(500),
        ..SchedulerConfig::default()
    };
    let mut r = rig_with(common::hills(64), 3, config);
    let t0 = Instant::now();
    let bound = DeformationBound::new(0.2, 0.0).expect("bound");
    for rect in [cell_rect(2, 2), cell_rect(30, 30)] {
        r.scheduler.note_deformation(rect, bound, t0).expect("note");
    }
    assert_eq!(r.update(ms(t0, 30)).requested.len(), 2);
    assert_eq!(r.update(ms(t0, 600)).abandoned.len(), 2);
    let late: usize = (1..=3).map(|k| r.update(ms(t0, 600 + 10 * k)).late).sum();
    assert_eq!(late, 2);
}

/// A source that delivers every region it was asked for, but moved by `shift` and
/// `narrower` texels too narrow.
#[derive(Debug)]
struct Misdelivering {
    shift: IVec2,
    narrower: u32,
    next: u64,
    asked: Vec<(RequestId, Rect)>,
}

impl Misdelivering {
    fn new(shift: IVec2, narrower: u32) -> Self {
        Self {
            shift,
            narrower,
            next: 0,
            asked: Vec::new(),
        }
    }
}

impl RegionSource for Misdelivering {
    type Error = Infallible;

    fn request(&mut self, rect: Rect) -> Result<RequestId, Infallible> {
        self.next += 1;
        self.asked.push((RequestId(self.next), rect));
        Ok(RequestId(self.next))
    }
    fn poll(&mut self) -> Result<Vec<ArrivedRegion>, Infallible> {
        let (shift, narrower) = (self.shift, self.narrower);
        Ok(self
            .asked
            .drain(..)
            .map(|(id, rect)| ArrivedRegion {
                id,
                rect: Rect::new(rect.min + shift, rect.size),
                heights: terrain_core::Grid::new(rect.size.x - narrower, rect.size.y, 0)
                    .expect("grid"),
            })
            .collect())
    }
}

/// One 2 x 2 deformation requested from `source` and its region delivered: the error of the
/// update it arrives in. Nothing of it may reach the mirror, and its bound stays pending.
fn deliver_one(source: &mut Misdelivering) -> UpdateError<Infallible> {
    let map = common::hills(64);
    let mirror = CollisionMirror::from_map(&map).expect("mirror");
    let mut s = ReadbackScheduler::for_mirror(&mirror, SchedulerConfig::default()).expect("s");
    let t0 = Instant::now();
    let bound = DeformationBound::new(0.2, 0.0).expect("bound");
    s.note_deformation(cell_rect(10, 10), bound, t0)
        .expect("note");
    let before = mirror.version();
    assert!(s.update(ms(t0, 30), source, &mirror).is_ok());
    let err = s
        .update(ms(t0, 40), source, &mirror)
        .expect_err("a misdelivered region");
    assert_eq!(mirror.version(), before);
    assert!(s.pending_deformations().count() > 0);
    err
}

/// A region of the right size at the wrong place is refused.
#[test]
fn a_region_delivered_at_the_wrong_place_is_refused() {
    let err = deliver_one(&mut Misdelivering::new(IVec2::X, 0));
    assert!(
        matches!(err, UpdateError::Physics(PhysicsError::WrongRegion { .. })),
        "{err:?}"
    );
}

/// A region of the wrong size is refused when it arrives, with the sizes named.
#[test]
fn a_region_of_the_wrong_size_is_refused_on_arrival() {
    let err = deliver_one(&mut Misdelivering::new(IVec2::ZERO, 1));
    assert_eq!(
        err,
        UpdateError::Physics(PhysicsError::SizeMismatch {
            expected: UVec2::splat(2),
            actual: UVec2::new(1, 2),
        })
    );
}
