//! The collision mirror under concurrent use: a reader hammering snapshots and queries while a
//! writer applies region updates never sees a torn region or a snapshot inconsistent with its
//! version.

use glam::{IVec2, UVec2, Vec2};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use terrain_core::{CoarseMap, Grid, HeightEncoding, Rect};
use terrain_physics::{CollisionMirror, HeightField};

const UPDATES: u16 = 200;

/// Four regions, two of them across the wrap edges, disjoint on the 256 x 256 map.
fn regions() -> [Rect; 4] {
    [
        Rect::new(IVec2::new(0, 0), UVec2::new(100, 60)),
        Rect::new(IVec2::new(120, 10), UVec2::new(80, 100)),
        Rect::new(IVec2::new(220, 130), UVec2::new(70, 70)), // wraps in X
        Rect::new(IVec2::new(100, 230), UVec2::new(18, 46)), // wraps in Z
    ]
}

/// The value region `k` holds after `version` updates (update v writes v into region v % 4).
fn expected(k: usize, version: u64) -> u16 {
    (1..=version)
        .rev()
        .find(|v| (*v % 4) as usize == k)
        .map_or(0, |v| v as u16)
}

fn uniform(field: &HeightField, rect: Rect) -> Option<u16> {
    let g = field.heights();
    let first = g.get_wrapped(rect.min, terrain_core::WrapMode::Repeat);
    for y in 0..rect.size.y as i32 {
        for x in 0..rect.size.x as i32 {
            let p = rect.min + IVec2::new(x, y);
            if g.get_wrapped(p, terrain_core::WrapMode::Repeat) != first {
                return None;
            }
        }
    }
    Some(first)
}

#[test]
fn a_reader_never_sees_a_torn_region() {
    let enc = HeightEncoding::new(0.01, 0.0).expect("encoding");
    let map = CoarseMap::coarse(Grid::new(256, 256, 0u16).expect("grid"), enc, 0.25).expect("map");
    let mirror = Arc::new(CollisionMirror::from_map(&map).expect("mirror"));
    let done = Arc::new(AtomicBool::new(false));
    let snapshots_checked = Arc::new(AtomicU64::new(0));

    let reader = {
        let mirror = Arc::clone(&mirror);
        let done = Arc::clone(&done);
        let checked = Arc::clone(&snapshots_checked);
        std::thread::spawn(move || -> Result<usize, String> {
            let mut last_version = 0;
            let mut versions_seen = std::collections::BTreeSet::new();
            loop {
                let finished = done.load(Ordering::Acquire);
                let snap = mirror.snapshot();
                let v = snap.version();
                if v < last_version {
                    return Err(format!("version went back from {last_version} to {v}"));
                }
                last_version = v;
                versions_seen.insert(v);
                for (k, rect) in regions().into_iter().enumerate() {
                    let Some(value) = uniform(&snap, rect) else {
                        return Err(format!("region {k} torn in snapshot {v}"));
                    };
                    if value != expected(k, v) {
                        return Err(format!(
                            "region {k} holds {value} in snapshot {v}, expected {}",
                            expected(k, v)
                        ));
                    }
                    // A query through the collider sees the same snapshot's heights.
                    let centre = (rect.min.as_vec2() + rect.size.as_vec2() * 0.5) * 0.25;
                    let h = terrain_physics::HeightfieldCollider::new(snap.clone())
                        .height(Vec2::new(centre.x, centre.y))
                        .map_err(|e| e.to_string())?;
                    if (h - f32::from(value) * 0.01).abs() > 1e-4 {
                        return Err(format!("query saw {h} in region {k} of snapshot {v}"));
                    }
                }
                checked.fetch_add(1, Ordering::Relaxed);
                if finished {
                    return Ok(versions_seen.len());
                }
            }
        })
    };

    for v in 1..=UPDATES {
        let rect = regions()[usize::from(v % 4)];
        let data = Grid::new(rect.size.x, rect.size.y, v).expect("grid");
        let version = mirror.apply_next(rect, &data).expect("apply");
        assert_eq!(version, u64::from(v));
        // Let the reader get through a snapshot now and then so the two really interleave
        // (bounded: never more than 100 ms per update).
        let seen = snapshots_checked.load(Ordering::Relaxed);
        let start = std::time::Instant::now();
        while snapshots_checked.load(Ordering::Relaxed) == seen
            && start.elapsed() < std::time::Duration::from_millis(100)
        {
            std::thread::yield_now();
        }
    }
    done.store(true, Ordering::Release);
    let versions_seen = reader
        .join()
        .expect("reader thread")
        .expect("reader saw only whole updates");
    // The reader saw many different versions while the writer was working.
    assert!(
        versions_seen >= 20,
        "reader saw only {versions_seen} versions"
    );
    let last = mirror.snapshot();
    assert_eq!(last.version(), u64::from(UPDATES));
    for (k, rect) in regions().into_iter().enumerate() {
        assert_eq!(uniform(&last, rect), Some(expected(k, u64::from(UPDATES))));
    }
}

#[test]
fn a_long_lived_snapshot_is_unaffected_by_later_updates() {
    let enc = HeightEncoding::new(0.01, 0.0).expect("encoding");
    let map = CoarseMap::coarse(Grid::new(64, 64, 7u16).expect("grid"), enc, 1.0).expect("map");
    let mirror = CollisionMirror::from_map(&map).expect("mirror");
    let held = mirror.snapshot();
    for v in 1..=10u16 {
        let rect = Rect::new(IVec2::new(i32::from(v) * 3, 5), UVec2::new(30, 30));
        mirror
            .apply_next(rect, &Grid::new(30, 30, 100 + v).expect("grid"))
            .expect("apply");
    }
    assert_eq!(held.version(), 0);
    assert!(held.heights().as_slice().iter().all(|&h| h == 7));
    assert_eq!(mirror.version(), 10);
}
