//! `OverlayWriter`: holes and paint written into a world's overlay tiles off the caller's
//! thread, in order (a job reads what the one before wrote), each change reported once (by
//! `poll` or `finish`), the world's files holding it afterwards; a stopped writer refuses jobs.

mod common;

use common::build;
use glam::{IVec2, UVec2, Vec2};
use std::sync::Arc;
use std::time::{Duration, Instant};
use terrain_cache::{
    ObjectTileStore, OverlayChange, OverlayJob, OverlayWriter, TileStore, read_holes, read_paint,
};
use terrain_core::{Grid, HOLE, MaterialEffect, Rect, StampPlacement, count_holes};

#[test]
fn cuts_and_paint_reach_the_world_in_order() {
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
    let world = build(store, UVec2::splat(128), 32);
    let mut writer = OverlayWriter::start(world.clone()).unwrap();
    let at = |x: f32, side: f32| StampPlacement::new(Vec2::new(x, 40.0), Vec2::splat(side), 1.0);
    // Two overlapping cuts: the second's cells hold the first's holes too.
    writer
        .send(OverlayJob::Cut(at(30.0, 8.0).unwrap()))
        .unwrap();
    writer
        .send(OverlayJob::Cut(at(36.0, 8.0).unwrap()))
        .unwrap();
    let dirt = MaterialEffect::new(1, 0.8).unwrap();
    writer
        .send(OverlayJob::Paint(at(80.0, 10.0).unwrap(), dirt))
        .unwrap();
    // Polled until the first change arrives, then the rest at the finish.
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut changes = Vec::new();
    while changes.is_empty() {
        assert!(Instant::now() < deadline, "the writer never answered");
        changes.extend(writer.poll().into_iter().map(|c| c.unwrap().unwrap()));
        std::thread::sleep(Duration::from_millis(1));
    }
    changes.extend(writer.finish().unwrap());
    assert_eq!(changes.len(), 3);
    let (OverlayChange::Holes(r1, m1), OverlayChange::Holes(r2, m2)) = (&changes[0], &changes[1])
    else {
        panic!("two cuts first: {changes:?}");
    };
    assert!(count_holes(m1) > 0);
    // Where the rects meet, the second cut's mask keeps every hole of the first.
    let overlap = r1.intersect(r2).expect("the cuts overlap");
    let mut kept = 0;
    for y in overlap.min.y..overlap.max().y {
        for x in overlap.min.x..overlap.max().x {
            let at = |r: &Rect, m: &Grid<u8>| m.get((x - r.min.x) as u32, (y - r.min.y) as u32);
            if at(r1, m1) == Some(HOLE) {
                assert_eq!(at(r2, m2), Some(HOLE), "({x}, {y}) was filled again");
                kept += 1;
            }
        }
    }
    assert!(kept > 0, "the cuts' holes do not overlap");
    assert_eq!(
        read_holes(&world, *r2).unwrap(),
        *m2,
        "the world holds the last mask"
    );
    let OverlayChange::Paint(tiles) = &changes[2] else {
        panic!("paint last: {changes:?}");
    };
    assert!(!tiles.is_empty());
    let painted = read_paint(&world, Rect::new(IVec2::new(76, 36), UVec2::splat(8))).unwrap();
    assert!(
        painted.as_slice().iter().any(|t| t[1] > 0),
        "no dirt in the files"
    );
    assert!(
        writer
            .send(OverlayJob::Cut(at(10.0, 4.0).unwrap()))
            .is_err()
    );
}
