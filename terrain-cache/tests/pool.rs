//! RAM pool behaviour: loading around a camera within the budget, write-back of dirty tiles
//! before eviction, rescue, zero-tile copy on write, and the concurrency stress test (many
//! threads requesting, cancelling and re-requesting at random for about two seconds).

mod common;

use common::{Rng, SlowStore, build};
use glam::{UVec2, Vec3};
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use terrain_cache::{
    CameraState, DetailLayout, Layer, ObjectTileStore, PoolConfig, RamPool, TileData, TileId,
    TileState, TileStore, World,
};

fn mem_world(size: u32, tile: u32) -> World {
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
    build(store, UVec2::splat(size), tile)
}

/// Runs updates until `done` says so or 5 s pass.
fn pump(
    pool: &mut RamPool,
    cam: &CameraState,
    mut done: impl FnMut(&RamPool, &terrain_cache::FrameReport) -> bool,
) {
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(5) {
        let r = pool.update(cam).unwrap();
        assert!(r.ram_bytes <= r.budget_bytes, "{r:?}");
        assert_eq!(pool.audit_ram_bytes(), pool.ram_bytes());
        if done(pool, &r) {
            return;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    panic!("pool did not settle in 5 s");
}

#[test]
fn loads_selection_within_budget_and_falls_back_to_coarser() {
    let world = mem_world(512, 32);
    let tb = 32 * 32 * 2;
    let mut pool = RamPool::new(world, PoolConfig::new(Layer::Height, 80 * tb)).unwrap();
    let cam = CameraState::at(Vec3::new(100.0, 50.0, 100.0));
    pump(&mut pool, &cam, |p, r| {
        r.wanted_resident == r.wanted
            && p.status(TileId::new(0, 3, 3))
                .is_some_and(|s| s.state == TileState::Loaded)
    });
    let (id, _) = pool.best_available(TileId::new(0, 3, 3)).unwrap();
    assert_eq!(id, TileId::new(0, 3, 3));
    // A far tile falls back to a loaded ancestor.
    let far = TileId::new(0, 15, 15);
    let (anc, _) = pool.best_available(far).unwrap();
    assert!(anc.level > 0, "{anc}");
    // Move far away: old tiles are marked, then evicted as new ones need room.
    let cam2 = CameraState::at(Vec3::new(400.0, 50.0, 400.0));
    pump(&mut pool, &cam2, |p, _| {
        p.status(TileId::new(0, 12, 12))
            .is_some_and(|s| s.state == TileState::Loaded)
    });
    let r = pool.update(&cam2).unwrap();
    assert!(r.ram_bytes <= r.budget_bytes);
    assert!(matches!(
        pool.update(&CameraState::at(Vec3::new(f32::NAN, 0.0, 0.0))),
        Err(terrain_cache::CacheError::OutOfRange { .. })
    ));
    // Far-off cameras are fine and bounded.
    for p in [
        Vec3::splat(f32::MAX),
        Vec3::splat(f32::MIN),
        Vec3::new(1e38, -1e38, 3.0),
    ] {
        let r = pool.update(&CameraState::at(p)).unwrap();
        assert!(r.wanted <= 256 + 64 + 16 + 4 + 1, "{r:?}");
    }
    pool.shutdown(Duration::from_secs(5)).unwrap();
}

#[test]
fn dirty_tiles_are_written_back_before_eviction_and_reload_new_data() {
    let world = mem_world(256, 32);
    let tb = 32 * 32 * 2;
    let mut cfg = PoolConfig::new(Layer::Height, 12 * tb);
    cfg.write_back_idle_frames = None;
    let mut pool = RamPool::new(world.clone(), cfg).unwrap();
    let near = CameraState::at(Vec3::new(16.0, 0.0, 16.0));
    let id = TileId::new(0, 0, 0);
    pump(&mut pool, &near, |p, _| p.tile(id).is_some());
    pool.modify(id, |d| d.as_u16_mut().unwrap().as_mut_slice()[0] = 12345)
        .unwrap();
    assert!(pool.status(id).unwrap().dirty);
    // Walk away: the tile is written back, then freed; nothing written while it stayed loaded.
    let far = CameraState::at(Vec3::new(144.0, 0.0, 144.0));
    pump(&mut pool, &far, |p, _| p.status(id).is_none());
    let on_disk = world.load_tile(Layer::Height, id).unwrap();
    assert_eq!(on_disk.as_u16().unwrap().as_slice()[0], 12345);
    // Coming back reloads the new version; the coarser ancestor was refreshed on disk.
    pump(&mut pool, &near, |p, _| p.tile(id).is_some());
    assert_eq!(
        pool.tile(id).unwrap().as_u16().unwrap().as_slice()[0],
        12345
    );
    pool.shutdown(Duration::from_secs(5)).unwrap();
}

#[test]
fn zero_tiles_are_shared_and_copied_on_write() {
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
    let mut world = build(store, UVec2::splat(128), 32);
    world
        .update_manifest(|m| {
            m.detail = Some(DetailLayout::covering(glam::Vec2::splat(128.0), 16, 1.0).unwrap());
        })
        .unwrap();
    let tb = 16 * 16;
    let mut cfg = PoolConfig::new(Layer::Detail, 8 * tb);
    cfg.write_back_idle_frames = Some(2);
    let mut pool = RamPool::with_policy(
        world.clone(),
        cfg,
        Box::new(terrain_cache::BandSelection::default()),
    )
    .unwrap();
    let cam = CameraState::at(Vec3::new(40.0, 0.0, 40.0));
    pump(&mut pool, &cam, |_, r| r.wanted_resident == 9);
    // Nine zero tiles cost nothing but the one shared zero tile.
    assert_eq!(pool.ram_bytes(), tb);
    let id = TileId::new(0, 2, 2);
    assert!(pool.status(id).unwrap().zero);
    pool.modify(id, |d| d.as_u8_mut().unwrap().as_mut_slice()[7] = 200)
        .unwrap();
    assert_eq!(pool.ram_bytes(), 2 * tb);
    assert!(!pool.status(id).unwrap().zero);
    // Idle write-back after 2 frames writes only that tile.
    pump(&mut pool, &cam, |p, _| !p.status(id).unwrap().dirty);
    let files = world.store().list("detail").unwrap();
    assert_eq!(files, vec!["detail/00/0002/0002.tile".to_string()]);
    pool.shutdown(Duration::from_secs(5)).unwrap();
}

#[test]
fn marked_tiles_are_rescued_without_io() {
    let inner: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
    build(inner.clone(), UVec2::splat(256), 32);
    let slow = Arc::new(SlowStore::new(inner, 0));
    let world = World::open(slow.clone()).unwrap();
    let tb = 32 * 32 * 2;
    let mut pool = RamPool::new(world, PoolConfig::new(Layer::Height, 200 * tb)).unwrap();
    let a = CameraState::at(Vec3::new(16.0, 0.0, 16.0));
    let b = CameraState::at(Vec3::new(144.0, 0.0, 144.0));
    pump(&mut pool, &a, |p, r| {
        r.in_flight == 0 && p.tile(TileId::new(0, 0, 0)).is_some()
    });
    pump(&mut pool, &b, |p, r| {
        r.in_flight == 0 && p.tile(TileId::new(0, 4, 4)).is_some()
    });
    assert_eq!(
        pool.status(TileId::new(0, 0, 0)).unwrap().state,
        TileState::MarkedForDeletion
    );
    let reads = slow.reads.load(Ordering::Relaxed);
    let r = pool.update(&a).unwrap();
    assert!(r.rescued > 0 && r.loads == 0, "{r:?}");
    assert_eq!(
        pool.status(TileId::new(0, 0, 0)).unwrap().state,
        TileState::Loaded
    );
    assert_eq!(slow.reads.load(Ordering::Relaxed), reads);
}

/// Must-show (c): many threads request, cancel and re-request tiles at random for ~2 s while
/// the frame thread updates, modifies and verifies; slow random-latency reads keep jobs queued
/// and loading. No tile is lost (everything still requested at the end arrives), duplicated
/// (never two reads of one tile at once) or stale (every loaded tile equals the last version
/// written), and memory stays within the budget (checked against the allocations themselves).
#[test]
fn stress_random_requests_cancels_and_rerequests() {
    let inner: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
    build(inner.clone(), UVec2::splat(512), 16);
    let slow = Arc::new(SlowStore::new(inner, 400));
    let world = World::open(slow.clone()).unwrap();
    let tb = 16 * 16 * 2;
    let mut cfg = PoolConfig::new(Layer::Height, 48 * tb);
    cfg.workers = 4;
    cfg.max_in_flight = 24;
    cfg.write_back_idle_frames = Some(5);
    cfg.propagate_to_coarser = false;
    // No camera selection: only the threads' requests drive the pool.
    #[derive(Debug)]
    struct Nothing;
    impl terrain_cache::SelectionPolicy for Nothing {
        fn select(
            &mut self,
            _: &CameraState,
            _: &terrain_cache::TileGrid,
            _: &mut Vec<terrain_cache::Want>,
        ) {
        }
    }
    let mut pool = RamPool::with_policy(world.clone(), cfg, Box::new(Nothing)).unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let tiles: Vec<TileId> = (0..32u32)
        .flat_map(|y| (0..32u32).map(move |x| TileId::new(0, x, y)))
        .collect();
    let tiles = Arc::new(tiles);
    let mut threads = Vec::new();
    for t in 0..6u64 {
        let h = pool.handle();
        let stop = stop.clone();
        let tiles = tiles.clone();
        threads.push(std::thread::spawn(move || {
            let mut rng = Rng(t * 7919 + 1);
            // Each thread works on its own slice so "still requested at the end" is known.
            let mine: Vec<TileId> = tiles.iter().copied().skip(t as usize).step_by(6).collect();
            let mut held = std::collections::HashSet::new();
            while !stop.load(Ordering::Relaxed) {
                let id = mine[rng.below(mine.len() as u64) as usize];
                if rng.below(3) == 0 {
                    h.cancel(id);
                    held.remove(&id);
                } else if held.len() < 6 || held.contains(&id) {
                    h.request(id, rng.below(100) as f32 / 100.0);
                    held.insert(id);
                }
                std::thread::sleep(Duration::from_micros(rng.below(300)));
            }
            held
        }));
    }
    // The frame thread: update, verify, modify some loaded tiles.
    let mut expected: HashMap<TileId, u16> = HashMap::new();
    let mut rng = Rng(99);
    let cam = CameraState::at(Vec3::ZERO);
    let start = Instant::now();
    let mut frames = 0u64;
    let mut loads = 0usize;
    let map = common::test_map(UVec2::splat(512));
    let originals: HashMap<TileId, u16> = tiles
        .iter()
        .map(|&id| (id, map.grid().get(id.x * 16, id.y * 16).unwrap()))
        .collect();
    let check = |pool: &RamPool, expected: &HashMap<TileId, u16>| {
        for &id in tiles.iter() {
            if let Some(d) = pool.tile(id) {
                let want = expected.get(&id).copied();
                let got = d.as_u16().unwrap().as_slice()[0];
                let original = originals[&id];
                assert_eq!(got, want.unwrap_or(original), "stale tile {id}");
            }
        }
    };
    while start.elapsed() < Duration::from_secs(2) {
        let r = pool.update(&cam).unwrap();
        frames += 1;
        loads += r.loads;
        assert!(r.ram_bytes <= r.budget_bytes, "{r:?}");
        assert_eq!(pool.audit_ram_bytes(), r.ram_bytes);
        assert!(pool.errors().is_empty(), "{:?}", pool.errors());
        if rng.below(4) == 0 {
            let resident = pool.resident_ids();
            if !resident.is_empty() {
                let id = resident[rng.below(resident.len() as u64) as usize];
                let v = rng.below(60000) as u16 + 1;
                match pool.modify(id, |d| d.as_u16_mut().unwrap().as_mut_slice()[0] = v) {
                    Ok(()) => {
                        expected.insert(id, v);
                    }
                    Err(terrain_cache::CacheError::OverBudget { .. }) => {}
                    Err(e) => panic!("{e}"),
                }
            }
        }
        check(&pool, &expected);
        std::thread::sleep(Duration::from_micros(500));
    }
    stop.store(true, Ordering::Relaxed);
    let mut still_wanted = Vec::new();
    for t in threads {
        still_wanted.extend(t.join().unwrap());
    }
    // Nothing lost: everything still requested arrives (the budget holds them all).
    assert!(still_wanted.len() <= 36);
    let settle = Instant::now();
    loop {
        let r = pool.update(&cam).unwrap();
        assert!(r.ram_bytes <= r.budget_bytes);
        check(&pool, &expected);
        if still_wanted.iter().all(|&id| pool.tile(id).is_some()) && r.in_flight == 0 {
            break;
        }
        assert!(
            settle.elapsed() < Duration::from_secs(5),
            "requested tiles never arrived: {r:?}"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
    assert_eq!(
        slow.max_overlap.load(Ordering::Relaxed),
        1,
        "a tile was loaded twice at once"
    );
    assert!(frames > 100 && loads > 50, "frames {frames}, loads {loads}");
    // Everything written back survives: the store holds the last versions.
    pool.shutdown(Duration::from_secs(10)).unwrap();
    for (id, v) in &expected {
        let d = world.load_tile(Layer::Height, *id).unwrap();
        assert_eq!(d.as_u16().unwrap().as_slice()[0], *v, "{id}");
    }
    eprintln!(
        "stress: {frames} frames, {loads} loads, {} reads, {} tiles modified",
        slow.reads.load(Ordering::Relaxed),
        expected.len()
    );
}

#[test]
fn write_replaces_and_rejects_wrong_shapes() {
    let world = mem_world(128, 32);
    let mut pool = RamPool::new(world, PoolConfig::new(Layer::Height, 64 * 2048)).unwrap();
    let cam = CameraState::at(Vec3::new(10.0, 0.0, 10.0));
    let id = TileId::new(0, 0, 0);
    pump(&mut pool, &cam, |p, _| p.tile(id).is_some());
    let bad = TileData::filled(Layer::Detail, 32, 1).unwrap();
    assert!(matches!(
        pool.write(id, bad),
        Err(terrain_cache::CacheError::TileDataMismatch { .. })
    ));
    let good = TileData::filled(Layer::Height, 32, 77).unwrap();
    pool.write(id, good.clone()).unwrap();
    assert_eq!(pool.tile(id), Some(&good));
    assert!(matches!(
        pool.modify(TileId::new(0, 99, 99), |_| ()),
        Err(terrain_cache::CacheError::NotResident { .. })
    ));
    pool.shutdown(Duration::from_secs(5)).unwrap();
}

#[test]
fn read_region_takes_level_0_where_loaded_and_the_nearest_coarser_sample_elsewhere() {
    use terrain_core::{Grid, Rect};
    let world = mem_world(512, 32);
    let truth0 = common::test_map(UVec2::splat(512));
    let tb = 32 * 32 * 2;
    let mut pool = RamPool::new(world, PoolConfig::new(Layer::Height, 80 * tb)).unwrap();
    let cam = CameraState::at(Vec3::new(100.0, 50.0, 100.0));
    pump(&mut pool, &cam, |_, r| r.wanted_resident == r.wanted);
    // A rect across several tiles, some loaded at level 0 and some not.
    let rect = Rect::new(glam::IVec2::new(70, 40), UVec2::new(300, 170));
    let mut out = Grid::new(300, 170, 0u16).unwrap();
    let coarse = pool.read_region(rect, &mut out).unwrap();
    let mut expect_coarse = 0u64;
    for y in 0..170u32 {
        for x in 0..300u32 {
            let (wx, wy) = (70 + x, 40 + y);
            let (found, data) = pool
                .best_available(TileId::new(0, wx / 32, wy / 32))
                .unwrap();
            let l = found.level;
            let want = if l == 0 {
                truth0.grid().get(wx, wy).unwrap()
            } else {
                expect_coarse += 1;
                let (cx, cy) = (wx >> l, wy >> l);
                data.as_u16()
                    .unwrap()
                    .get(cx - found.x * 32, cy - found.y * 32)
                    .unwrap()
            };
            assert_eq!(
                out.get(x, y).unwrap(),
                want,
                "texel ({wx}, {wy}) from {found}"
            );
        }
    }
    assert_eq!(coarse, expect_coarse);
    assert!(coarse > 0 && coarse < 300 * 170, "both kinds: {coarse}");
    // write_rect pastes into a loaded tile and marks it dirty; a read sees it.
    let id = TileId::new(0, 3, 3);
    let patch = Grid::from_fn(5, 4, |x, y| (1000 + x + 10 * y) as u16).unwrap();
    let local = Rect::new(glam::IVec2::new(27, 28), UVec2::new(5, 4));
    pool.write_rect(id, local, &patch).unwrap();
    assert!(pool.status(id).unwrap().dirty);
    let mut small = Grid::new(5, 4, 0u16).unwrap();
    let exact = pool
        .read_region(
            Rect::new(glam::IVec2::new(96 + 27, 96 + 28), UVec2::new(5, 4)),
            &mut small,
        )
        .unwrap();
    assert_eq!((exact, &small), (0, &patch));

    // Off the world, off the tile, wrong sizes, tiles not loaded: errors, nothing changed.
    let gen_before = pool.generation(id);
    for bad in [
        Rect::new(glam::IVec2::new(-1, 0), UVec2::new(5, 4)),
        Rect::new(glam::IVec2::new(510, 0), UVec2::new(5, 4)),
        Rect::new(glam::IVec2::new(i32::MAX, i32::MAX), UVec2::new(5, 4)),
    ] {
        assert!(pool.read_region(bad, &mut small).is_err(), "{bad:?}");
    }
    assert!(pool.read_region(rect, &mut small).is_err(), "size mismatch");
    assert!(
        pool.write_rect(
            id,
            Rect::new(glam::IVec2::new(28, 28), UVec2::new(5, 4)),
            &patch
        )
        .is_err()
    );
    assert!(
        pool.write_rect(
            id,
            Rect::new(glam::IVec2::new(-1, 0), UVec2::new(5, 4)),
            &patch
        )
        .is_err()
    );
    assert!(
        pool.write_rect(
            id,
            local,
            &small
                .map(|_| 0)
                .copy_rect(Rect::from_size(UVec2::new(2, 2)))
                .unwrap()
        )
        .is_err()
    );
    assert!(matches!(
        pool.write_rect(TileId::new(0, 15, 15), local, &patch),
        Err(terrain_cache::CacheError::NotResident { .. })
    ));
    assert_eq!(pool.generation(id), gen_before);
    pool.shutdown(Duration::from_secs(5)).unwrap();
}

#[test]
fn reloaded_tiles_come_back_from_their_rewritten_files() {
    // Paint written on the world under a material pool (as a writer of the world's paint
    // does): once named to `reload`, the pool reports the tiles refreshed and holds the new
    // texels, at level 0 and at the coarser levels the write rebuilt.
    let world = mem_world(256, 32);
    let tb = 32 * 32 * 4;
    let mut pool = RamPool::new(world.clone(), PoolConfig::new(Layer::Material, 200 * tb)).unwrap();
    let cam = CameraState::at(Vec3::new(20.0, 30.0, 20.0));
    let (fine, coarse) = (TileId::new(0, 0, 0), TileId::new(1, 0, 0));
    let loaded = |p: &RamPool, id| p.status(id).is_some_and(|s| s.state == TileState::Loaded);
    pump(&mut pool, &cam, |p, _| loaded(p, fine) && loaded(p, coarse));
    assert_eq!(
        pool.tile(fine)
            .and_then(|t| t.as_rgba8())
            .unwrap()
            .get(3, 3),
        Some([0; 4])
    );
    let rect = terrain_core::Rect::new(glam::IVec2::new(2, 2), UVec2::splat(4));
    let paint = terrain_core::Grid::new(4, 4, [0, 200, 0, 0]).unwrap();
    let written = terrain_cache::write_paint(&world, rect, &paint).unwrap();
    assert!(
        written.contains(&fine) && written.contains(&coarse),
        "{written:?}"
    );
    // Not named: the pool keeps its copies.
    pool.update(&cam).unwrap();
    assert_eq!(
        pool.tile(fine)
            .and_then(|t| t.as_rgba8())
            .unwrap()
            .get(3, 3),
        Some([0; 4])
    );
    pool.reload(&written);
    // Tiles of another layer or off the world are ignored.
    pool.reload(&[TileId::new(9, 0, 0), TileId::new(0, 99, 0)]);
    let r = pool.update(&cam).unwrap();
    assert_eq!(r.failed, 0);
    for id in &written {
        assert!(pool.refreshed().contains(id), "{id}");
    }
    pump(&mut pool, &cam, |p, _| loaded(p, fine) && loaded(p, coarse));
    let texel = |p: &RamPool, id, x, y| p.tile(id).and_then(|t| t.as_rgba8()).unwrap().get(x, y);
    assert_eq!(texel(&pool, fine, 3, 3), Some([0, 200, 0, 0]));
    // Level 1's texel (1, 1) is the mean of level-0 texels 2..4 x 2..4: all painted.
    assert_eq!(texel(&pool, coarse, 1, 1), Some([0, 200, 0, 0]));
    assert_eq!(texel(&pool, coarse, 0, 0), Some([0; 4]));
    pool.shutdown(Duration::from_secs(5)).unwrap();
}
