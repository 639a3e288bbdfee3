//! The collision mirror under shuttle's randomized scheduler (run with `cargo test -p
//! terrain-physics --features shuttle --test shuttle_mirror`; `cargo xtask ci` does): several
//! writers apply region updates while several readers take snapshots, over many random
//! interleavings. Every snapshot must be exactly the map after the updates up to its version,
//! applied in version order (never a torn or half-applied update), versions seen by a reader
//! never go back, and the final mirror is every update applied.
#![cfg(feature = "shuttle")]

use glam::{IVec2, UVec2};
use shuttle::sync::Mutex;
use std::sync::Arc;
use terrain_core::{Grid, HeightEncoding, Rect};
use terrain_physics::{CollisionMirror, HeightField};

const SIZE: u32 = 8;

/// (version, rect, value): what one update wrote.
type Log = Vec<(u64, Rect, u16)>;

fn replay(log: &Log, upto: u64) -> Grid<u16> {
    let mut g = Grid::new(SIZE, SIZE, 0u16).expect("grid");
    let mut entries: Vec<_> = log.iter().filter(|e| e.0 <= upto).collect();
    entries.sort_by_key(|e| e.0);
    for (_, rect, value) in entries {
        for piece in rect.split_toroidal(UVec2::splat(SIZE)) {
            for y in piece.map.min.y..piece.map.max().y {
                for x in piece.map.min.x..piece.map.max().x {
                    *g.get_mut(x as u32, y as u32).expect("inside") = *value;
                }
            }
        }
    }
    g
}

fn scenario() {
    let field = HeightField::new(
        Grid::new(SIZE, SIZE, 0u16).expect("grid"),
        HeightEncoding::new(0.01, 0.0).expect("encoding"),
        1.0,
    )
    .expect("field");
    let mirror = Arc::new(CollisionMirror::new(field));
    let log = Arc::new(Mutex::new(Log::new()));
    let seen = Arc::new(Mutex::new(Vec::<(u64, Grid<u16>)>::new()));
    let mut handles = Vec::new();
    for w in 0..2u16 {
        let (mirror, log) = (mirror.clone(), log.clone());
        handles.push(shuttle::thread::spawn(move || {
            // Overlapping rects, one across the wrap edge, one the whole map.
            let rects = [
                Rect::new(IVec2::new(1, 1), UVec2::new(4, 3)),
                Rect::new(IVec2::new(6, 5), UVec2::new(4, 4)),
                Rect::from_size(UVec2::splat(SIZE)),
            ];
            for (k, rect) in rects.iter().enumerate() {
                let value = 100 * (w + 1) + k as u16;
                let heights = Grid::new(rect.size.x, rect.size.y, value).expect("grid");
                // The version returned pairs the update with its place in the order; the log
                // is only read after every thread has finished.
                let version = mirror.apply_next(*rect, &heights).expect("apply");
                log.lock().expect("log").push((version, *rect, value));
            }
        }));
    }
    for _ in 0..2 {
        let (mirror, seen) = (mirror.clone(), seen.clone());
        handles.push(shuttle::thread::spawn(move || {
            let mut last = 0;
            for _ in 0..4 {
                let snap = mirror.snapshot();
                assert!(snap.version() >= last, "versions went back");
                last = snap.version();
                seen.lock()
                    .expect("seen")
                    .push((snap.version(), snap.heights().clone()));
                shuttle::thread::yield_now();
            }
        }));
    }
    for h in handles {
        h.join().expect("thread");
    }
    let log = log.lock().expect("log");
    assert_eq!(log.len(), 6);
    for (version, heights) in seen.lock().expect("seen").iter() {
        assert_eq!(
            heights,
            &replay(&log, *version),
            "snapshot at version {version}"
        );
    }
    assert_eq!(mirror.version(), 6);
    assert_eq!(mirror.snapshot().heights(), &replay(&log, 6));
}

#[test]
fn snapshots_are_whole_versions_under_random_interleavings() {
    shuttle::check_random(scenario, 2000);
}

#[test]
fn snapshots_are_whole_versions_under_pct_scheduling() {
    shuttle::check_pct(scenario, 1000, 3);
}
