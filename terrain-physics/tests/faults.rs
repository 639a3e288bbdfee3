//! The readback scheduler against a source that misbehaves at random: it drops requests,
//! delays them, delivers them twice, reorders them, fails requests and polls, and is made
//! anew mid-run (a device loss). A model test: the map is the reference. While faults go on,
//! bodies stay above every pending deformation and memory stays bounded; once they stop, the
//! mirror becomes the map exactly and the scheduler goes idle.

mod common;

use glam::{IVec2, UVec2, Vec2};
use std::collections::VecDeque;
use std::time::{Duration, Instant};
use terrain_core::{
    ArrivedRegion, Blend, CoarseMap, GaussianStamp, Rect, StampPlacement, apply_stamp,
};
use terrain_physics::{
    CollisionMirror, DeformationBound, GroundQuery, HeightfieldCollider, MAX_PENDING_DEFORMATIONS,
    PhysicsError, ReadbackScheduler, RegionSource, RequestId, SchedulerConfig, read_region,
};

/// splitmix64.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
    fn chance(&mut self, p: f32) -> bool {
        self.unit() < p
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

/// Fault rates of the source; all zero: a perfect source.
#[derive(Clone, Copy)]
struct Faults {
    fail_request: f32,
    fail_poll: f32,
    drop: f32,
    duplicate: f32,
    max_delay_polls: u64,
    reorder: bool,
}

const NONE: Faults = Faults {
    fail_request: 0.0,
    fail_poll: 0.0,
    drop: 0.0,
    duplicate: 0.0,
    max_delay_polls: 0,
    reorder: false,
};

/// A region source over a copy of the map that misbehaves at the given rates. Each request
/// copies the rect when it is made (as a recorded GPU copy does).
struct FaultySource {
    rng: Rng,
    faults: Faults,
    /// (polls left, region).
    queue: VecDeque<(u64, ArrivedRegion)>,
}

impl FaultySource {
    fn new(seed: u64, faults: Faults) -> Self {
        Self {
            rng: Rng(seed),
            faults,
            queue: VecDeque::new(),
        }
    }

    fn request_from(&mut self, map: &CoarseMap, rect: Rect) -> Result<RequestId, PhysicsError> {
        if self.rng.chance(self.faults.fail_request) {
            return Err(PhysicsError::OutOfRange {
                what: "injected request failure",
                value: 0.0,
                expected: "none",
            });
        }
        let id = RequestId::fresh();
        let region = ArrivedRegion {
            id,
            rect,
            heights: read_region(map, rect)?,
        };
        if self.rng.chance(self.faults.drop) {
            return Ok(id);
        }
        let delay = 1 + self.rng.below(self.faults.max_delay_polls + 1);
        if self.rng.chance(self.faults.duplicate) {
            let again = 1 + self.rng.below(self.faults.max_delay_polls + 3);
            self.queue.push_back((again, region.clone()));
        }
        self.queue.push_back((delay, region));
        Ok(id)
    }

    fn poll_now(&mut self) -> Result<Vec<ArrivedRegion>, PhysicsError> {
        if self.rng.chance(self.faults.fail_poll) {
            return Err(PhysicsError::OutOfRange {
                what: "injected poll failure",
                value: 0.0,
                expected: "none",
            });
        }
        let mut out = Vec::new();
        let mut keep = VecDeque::with_capacity(self.queue.len());
        for (left, region) in self.queue.drain(..) {
            if left <= 1 {
                out.push(region);
            } else {
                keep.push_back((left - 1, region));
            }
        }
        self.queue = keep;
        if self.faults.reorder {
            for i in (1..out.len()).rev() {
                let j = self.rng.below(i as u64 + 1) as usize;
                out.swap(i, j);
            }
        }
        Ok(out)
    }
}

/// The map and the faulty source read from it together.
struct World<'a> {
    map: &'a CoarseMap,
    source: &'a mut FaultySource,
}

impl RegionSource for World<'_> {
    type Error = PhysicsError;
    fn request(&mut self, rect: Rect) -> Result<RequestId, PhysicsError> {
        self.source.request_from(self.map, rect)
    }
    fn poll(&mut self) -> Result<Vec<ArrivedRegion>, PhysicsError> {
        self.source.poll_now()
    }
}

/// One run: `steps` frames of 10 ms with faults, deformations at random (across the map's
/// edges too), bodies checked against the map; then a perfect source until idle.
fn run(seed: u64, faults: Faults, steps: u32) {
    let mut rng = Rng(seed ^ 0xABCD);
    let mut map = common::hills(48);
    let mirror = CollisionMirror::from_map(&map).expect("mirror");
    let config = SchedulerConfig {
        request_timeout: Duration::from_millis(200),
        ..SchedulerConfig::default()
    };
    let mut scheduler = ReadbackScheduler::for_mirror(&mirror, config).expect("scheduler");
    let mut source = FaultySource::new(seed, faults);
    let t0 = Instant::now();
    let mut crater = GaussianStamp::default();
    let extent = map.extent_m();
    let mut errors = 0u32;
    let mut abandoned = 0usize;
    for step in 0..steps {
        let now = t0 + Duration::from_millis(10 * u64::from(step));
        // A device loss: the source is made anew, with whatever it held lost.
        if rng.chance(0.01) {
            source = FaultySource::new(rng.next(), faults);
        }
        if rng.chance(0.3) {
            let centre = Vec2::new(rng.unit() * extent.x, rng.unit() * extent.y);
            let intensity = (rng.unit() - 0.4) * 3.0;
            let size = 2.0 + rng.unit() * 10.0;
            let placement =
                StampPlacement::new(centre, Vec2::splat(size), intensity).expect("placement");
            let dirty = apply_stamp(&mut map, &mut crater, &placement, Blend::Add).expect("stamp");
            let bound = DeformationBound::additive(intensity.abs(), map.encoding()).expect("bound");
            for r in dirty {
                scheduler.note_deformation(r, bound, now).expect("note");
            }
        }
        let mut world = World {
            map: &map,
            source: &mut source,
        };
        match scheduler.update(now, &mut world, &mirror) {
            Ok(report) => abandoned += report.abandoned.len(),
            Err(_) => errors += 1,
        }
        // Memory stays bounded whatever the source does.
        assert!(
            scheduler.in_flight() <= config.max_in_flight,
            "step {step}: {} in flight",
            scheduler.in_flight()
        );
        assert!(
            scheduler.pending_deformations().count() <= 2 * MAX_PENDING_DEFORMATIONS + 8,
            "step {step}"
        );
        // Bodies stay above the true surface: the mirror lifted by the pending bounds is never
        // below the map.
        let collider = HeightfieldCollider::new(mirror.snapshot());
        let ground = scheduler.ground(&collider);
        let truth = HeightfieldCollider::from_map(&map).expect("truth");
        for _ in 0..16 {
            let p = Vec2::new(rng.unit() * extent.x, rng.unit() * extent.y);
            let g = ground.ground_height(p).expect("ground");
            let t = truth.height(p).expect("truth");
            assert!(
                g >= t - 1e-3,
                "step {step}: ground {g} below the surface {t} at {p}"
            );
        }
    }
    // The faults stop (the source is made anew and is perfect): everything converges.
    let mut perfect = FaultySource::new(seed, NONE);
    let end = t0 + Duration::from_millis(10 * u64::from(steps));
    let mut converged = false;
    for k in 0..400u64 {
        let now = end + Duration::from_millis(10 * k);
        let mut world = World {
            map: &map,
            source: &mut perfect,
        };
        // Late or duplicated regions of the old sources cannot arrive any more; errors would
        // be a bug now.
        scheduler
            .update(now, &mut world, &mirror)
            .expect("perfect source");
        if scheduler.is_idle() {
            converged = true;
            break;
        }
    }
    assert!(converged, "seed {seed}: not idle after the faults stopped");
    assert_eq!(
        mirror.snapshot().heights(),
        map.grid(),
        "seed {seed}: the mirror equals the map"
    );
    assert_eq!(scheduler.pending_deformations().count(), 0);
    // The faults did happen (the test is not vacuous).
    if faults.drop > 0.0 {
        assert!(abandoned > 0, "seed {seed}: nothing was abandoned");
    }
    // Injected failures surface as errors, never as panics or a stuck scheduler.
    if faults.fail_request > 0.0 || faults.fail_poll > 0.0 {
        assert!(errors > 0, "seed {seed}: no injected failure was reported");
    }
}

#[test]
fn collision_survives_dropped_delayed_duplicated_reordered_and_failed_readbacks() {
    let faults = Faults {
        fail_request: 0.05,
        fail_poll: 0.05,
        drop: 0.15,
        duplicate: 0.1,
        max_delay_polls: 12,
        reorder: true,
    };
    for seed in 1..=12 {
        run(seed, faults, 400);
    }
}

#[test]
fn a_source_that_never_delivers_does_not_freeze_or_grow_the_scheduler() {
    let faults = Faults { drop: 1.0, ..NONE };
    run(99, faults, 600);
}

#[test]
fn a_late_region_of_an_abandoned_request_is_ignored_and_never_overwrites_newer_heights() {
    let mut map = common::hills(32);
    let mirror = CollisionMirror::from_map(&map).expect("mirror");
    let config = SchedulerConfig {
        request_timeout: Duration::from_millis(100),
        ..SchedulerConfig::default()
    };
    let mut scheduler = ReadbackScheduler::for_mirror(&mirror, config).expect("scheduler");
    let t0 = Instant::now();
    let at = |m: u64| t0 + Duration::from_millis(m);
    let rect = Rect::new(IVec2::new(4, 4), UVec2::new(6, 6));
    let bound = DeformationBound::additive(1.0, map.encoding()).expect("bound");
    let stamp = |map: &mut CoarseMap, h: f32| {
        let p = StampPlacement::new(Vec2::splat(7.0), Vec2::splat(6.0), h).expect("p");
        apply_stamp(map, &mut GaussianStamp::default(), &p, Blend::Add).expect("stamp")
    };
    // Request A is made, then lost (held back by the test).
    for r in stamp(&mut map, 1.0) {
        scheduler.note_deformation(r, bound, at(0)).expect("note");
    }
    let mut held = FaultySource::new(1, NONE);
    let rep = scheduler
        .update(
            at(30),
            &mut World {
                map: &map,
                source: &mut held,
            },
            &mirror,
        )
        .expect("update");
    assert_eq!(rep.requested.len(), 1);
    let old = held.queue.pop_front().expect("A's region").1;
    // Before it times out, a newer request cannot overtake it: nothing is applied.
    let mut empty = FaultySource::new(2, NONE);
    let rep = scheduler
        .update(
            at(60),
            &mut World {
                map: &map,
                source: &mut empty,
            },
            &mirror,
        )
        .expect("update");
    assert!(rep.applied.is_empty());
    // After the timeout A is abandoned, its rect requested again, and applied.
    for r in stamp(&mut map, 0.5) {
        scheduler.note_deformation(r, bound, at(100)).expect("note");
    }
    let mut fresh = FaultySource::new(3, NONE);
    let rep = scheduler
        .update(
            at(140),
            &mut World {
                map: &map,
                source: &mut fresh,
            },
            &mirror,
        )
        .expect("update");
    assert_eq!(rep.abandoned, vec![old.id]);
    assert_eq!(rep.requested.len(), 1, "{rep:?}");
    scheduler
        .update(
            at(150),
            &mut World {
                map: &map,
                source: &mut fresh,
            },
            &mirror,
        )
        .expect("update");
    assert!(scheduler.is_idle());
    assert_eq!(mirror.snapshot().heights(), map.grid());
    // A's region arrives at last: ignored, counted, the mirror keeps the newer heights.
    let mut late = FaultySource::new(4, NONE);
    late.queue.push_back((1, old));
    let rep = scheduler
        .update(
            at(160),
            &mut World {
                map: &map,
                source: &mut late,
            },
            &mirror,
        )
        .expect("a late region is not an error");
    assert_eq!((rep.late, rep.applied.len()), (1, 0));
    assert_eq!(mirror.snapshot().heights(), map.grid());
    assert!(
        rep.requested.is_empty() && scheduler.is_idle(),
        "nothing re-requested for {rect:?}"
    );
}

#[test]
fn pending_deformations_noted_without_updates_stay_bounded_and_conservative() {
    let map = common::hills(64);
    let mirror = CollisionMirror::from_map(&map).expect("mirror");
    let mut scheduler =
        ReadbackScheduler::for_mirror(&mirror, SchedulerConfig::default()).expect("scheduler");
    let t0 = Instant::now();
    let mut rng = Rng(5);
    let bound = DeformationBound::new(0.01, 0.02).expect("bound");
    for i in 0..20_000u32 {
        let r = Rect::new(
            IVec2::new(rng.below(64) as i32, rng.below(64) as i32),
            UVec2::new(1 + rng.below(5) as u32, 1 + rng.below(5) as u32),
        );
        scheduler
            .note_deformation(r, bound, t0 + Duration::from_micros(u64::from(i)))
            .expect("note");
    }
    let pending: Vec<_> = scheduler.pending_deformations().copied().collect();
    assert!(
        pending.len() <= MAX_PENDING_DEFORMATIONS,
        "{}",
        pending.len()
    );
    // Conservative: every texel some deformation touched is covered by a pending bound at
    // least as large as one deformation's.
    let collider = HeightfieldCollider::from_map(&map).expect("collider");
    let ground = scheduler.ground(&collider);
    let p = Vec2::new(30.5, 30.5);
    assert!(ground.ground_height(p).expect("g") >= collider.height(p).expect("h") + 0.01 - 1e-4);
}

#[test]
fn a_lost_request_keeps_its_batch_bounds_pending_when_the_rest_of_the_batch_applies() {
    let mut map = common::hills(64);
    let mirror = CollisionMirror::from_map(&map).expect("mirror");
    let config = SchedulerConfig {
        request_timeout: Duration::from_millis(100),
        ..SchedulerConfig::default()
    };
    let mut scheduler = ReadbackScheduler::for_mirror(&mirror, config).expect("scheduler");
    let t0 = Instant::now();
    let at = |m: u64| t0 + Duration::from_millis(m);
    // Two raises far apart: one batch of two requests.
    let e = map.extent_m();
    let places = [e * 0.2, e * 0.7];
    for c in places {
        let p = StampPlacement::new(c, Vec2::splat(6.0), 2.0).expect("placement");
        let dirty =
            apply_stamp(&mut map, &mut GaussianStamp::default(), &p, Blend::Add).expect("stamp");
        let bound = DeformationBound::additive(2.0, map.encoding()).expect("bound");
        for r in dirty {
            scheduler.note_deformation(r, bound, at(0)).expect("note");
        }
    }
    let mut source = FaultySource::new(7, NONE);
    let rep = scheduler
        .update(
            at(30),
            &mut World {
                map: &map,
                source: &mut source,
            },
            &mirror,
        )
        .expect("update");
    assert_eq!(rep.requested.len(), 2);
    // The first request is lost; the second arrives and waits behind it, then applies once
    // the first is abandoned.
    let lost = rep.requested[0];
    source.queue.retain(|(_, r)| r.id != lost.0);
    scheduler
        .update(
            at(40),
            &mut World {
                map: &map,
                source: &mut source,
            },
            &mirror,
        )
        .expect("update");
    let rep = scheduler
        .update(
            at(140),
            &mut World {
                map: &map,
                source: &mut source,
            },
            &mirror,
        )
        .expect("update");
    assert_eq!(rep.abandoned, vec![lost.0]);
    assert_eq!(rep.applied.len(), 1, "{rep:?}");
    // The lost rect's raise is still pending: bodies there stay above the raised surface.
    let truth = HeightfieldCollider::from_map(&map).expect("truth");
    let collider = HeightfieldCollider::new(mirror.snapshot());
    let ground = scheduler.ground(&collider);
    let texel = (places[0] / map.texel_size()).as_ivec2();
    let c = if lost.1.contains(texel) {
        places[0]
    } else {
        places[1]
    };
    let g = ground.ground_height(c).expect("ground");
    let t = truth.height(c).expect("truth");
    assert!(
        g >= t - 1e-3,
        "ground {g} below the raised surface {t} at {c}"
    );
}
