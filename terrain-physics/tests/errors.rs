//! Bad input to the mirror, the source, the scheduler and the shapes returns its error (the
//! query and body errors are checked in collider.rs and bodies.rs).

mod common;

use glam::{IVec2, UVec2};
use std::time::Instant;
use terrain_core::{Grid, HeightEncoding, HeightMap, Rect, WrapMode};
use terrain_physics::{
    CollisionMirror, CpuRegionSource, DeformationBound, HeightField, PhysicsError,
    ReadbackScheduler, RegionSource, RegionUpdate, SchedulerConfig,
};

#[test]
fn rects_off_the_map_are_errors_everywhere() {
    let map = common::hills(32);
    let size = map.size();
    let mirror = CollisionMirror::from_map(&map).expect("mirror");
    let mut source = CpuRegionSource::new(map);
    let mut scheduler =
        ReadbackScheduler::for_mirror(&mirror, SchedulerConfig::default()).expect("scheduler");
    let bound = DeformationBound::default();
    let off = [
        Rect::new(IVec2::new(64, 0), UVec2::new(4, 4)), // two periods to the right
        Rect::new(IVec2::new(0, -33), UVec2::new(4, 4)), // more than a period above
        Rect::new(IVec2::new(0, 0), UVec2::new(33, 4)), // wider than the map
        Rect::new(IVec2::new(3, 3), UVec2::new(0, 4)),  // empty
        Rect::new(IVec2::new(i32::MAX - 1, 0), UVec2::new(4, 4)),
    ];
    for rect in off {
        let grid = Grid::new(rect.size.x.max(1), rect.size.y.max(1), 0u16).expect("grid");
        let want = |e: Result<_, PhysicsError>| matches!(e, Err(PhysicsError::RegionOffMap { rect: r, map_size }) if r == rect && map_size == size);
        assert!(want(mirror.apply_next(rect, &grid).map(|_| ())), "{rect:?}");
        assert!(want(source.request(rect).map(|_| ())), "{rect:?}");
        assert!(
            want(scheduler.note_deformation(rect, bound, Instant::now())),
            "{rect:?}"
        );
    }
    // Within one period on either side is on the map (it wraps).
    let wrapped = Rect::new(IVec2::new(-32, 40), UVec2::new(4, 4));
    assert!(source.request(wrapped).is_ok());
    assert!(
        scheduler
            .note_deformation(wrapped, bound, Instant::now())
            .is_ok()
    );
    assert_eq!(mirror.version(), 0);
}

#[test]
fn mismatched_sizes_and_stale_versions_are_errors() {
    let mirror = CollisionMirror::from_map(&common::hills(32)).expect("mirror");
    let rect = Rect::new(IVec2::new(2, 2), UVec2::new(4, 4));
    let wrong = Grid::new(4, 5, 0u16).expect("grid");
    assert!(matches!(
        mirror.apply_next(rect, &wrong),
        Err(PhysicsError::SizeMismatch { expected, actual })
            if expected == UVec2::new(4, 4) && actual == UVec2::new(4, 5)
    ));
    let ok = Grid::new(4, 4, 0u16).expect("grid");
    let update = RegionUpdate {
        rect,
        heights: ok,
        version: 0,
    };
    assert!(matches!(
        mirror.apply(&update),
        Err(PhysicsError::StaleVersion {
            version: 0,
            current: 0
        })
    ));
}

#[test]
fn clamped_maps_and_bad_parameters_are_errors() {
    let enc = HeightEncoding::new(0.01, 0.0).expect("encoding");
    let clamped = HeightMap::new(
        Grid::new(8, 8, 0u16).expect("grid"),
        enc,
        1.0,
        WrapMode::Clamp,
    )
    .expect("map");
    assert!(matches!(
        CollisionMirror::from_map(&clamped),
        Err(PhysicsError::NotToroidal {
            wrap: WrapMode::Clamp
        })
    ));
    assert!(matches!(
        HeightField::new(Grid::new(8, 8, 0).expect("grid"), enc, -1.0),
        Err(PhysicsError::Core(_))
    ));
    assert!(matches!(
        DeformationBound::new(f32::NAN, 0.0),
        Err(PhysicsError::NonFinite { .. })
    ));
    assert!(matches!(
        DeformationBound::new(0.0, -0.5),
        Err(PhysicsError::OutOfRange { .. })
    ));
    assert!(matches!(
        CpuRegionSource::new(common::hills(8)).with_latency(0),
        Err(PhysicsError::OutOfRange { .. })
    ));
}
