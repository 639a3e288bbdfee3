//! Detail tiles as cache tiles: the band regions of Flower 2010, fig. 2.4 (loaded / active), the
//! working set within an upload budget, dirty-only atomic write-back and reading back what
//! was written, refusals; and the store's I/O off the caller's thread (Fikkan 2013, sec.
//! 5.2-5.3): a stalled store does not stall `update`, nothing deformed is lost while reads and
//! writes are in flight, failed writes are retried, and `flush` waits for the writes.

use glam::{UVec2, Vec2};
use std::collections::HashSet;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Condvar, Mutex};
use std::time::Duration;
use terrain_cache::detail::{
    BandTile, DetailCache, DetailFrame, band_tiles, detail_manifest_layout,
};
use terrain_cache::{BandSelection, CacheError, Manifest, ObjectTileStore, TileStore, World};
use terrain_core::detail::{DETAIL_ZERO_RAW, DetailLayout};
use terrain_core::{Blend, GaussianStamp, Grid, HeightEncoding, StampPlacement, WrapMode};

/// 256 x 256 coarse texels at 0.5 m refined x4: 1024 detail texels a side in 16 x 16 tiles of
/// 64 (8 m a side).
fn layout() -> DetailLayout {
    DetailLayout::new(UVec2::splat(256), 0.5, 4, 64).unwrap()
}

/// The world's manifest without a detail layer.
fn manifest() -> Manifest {
    let mut manifest = Manifest::new(
        UVec2::splat(256),
        64,
        0.5,
        HeightEncoding::spanning::<u16>(0.0, 50.0).unwrap(),
        WrapMode::Repeat,
    )
    .unwrap();
    manifest.detail = None;
    manifest
}

fn world(store: &Arc<dyn TileStore>) -> World {
    let mut manifest = manifest();
    manifest.detail = Some(detail_manifest_layout(&layout()).unwrap());
    World::create(store.clone(), manifest).unwrap()
}

fn store() -> Arc<dyn TileStore> {
    Arc::new(ObjectTileStore::in_memory().unwrap())
}

/// Most updates a test waits through for the loaders or the writer (a millisecond apart).
const TRIES: usize = 20_000;

fn pause() {
    std::thread::sleep(Duration::from_millis(1));
}

/// Updates at `camera` until the band has no read in flight (every tile read has landed),
/// at most [`TRIES`] times; returns the frames, the first included.
fn settle(cache: &mut DetailCache, camera: Vec2, needed: &[UVec2]) -> Vec<DetailFrame> {
    let mut frames = Vec::new();
    for _ in 0..TRIES {
        let f = cache.update(camera, needed).unwrap();
        let done = f.pending == 0 && f.deferred == 0;
        frames.push(f);
        if done {
            return frames;
        }
        pause();
    }
    panic!("the band at {camera} never finished loading");
}

/// Updates at `camera` until `done` holds, at most [`TRIES`] times; returns the frames.
fn update_until(
    cache: &mut DetailCache,
    camera: Vec2,
    mut done: impl FnMut(&DetailCache, &[DetailFrame]) -> bool,
) -> Vec<DetailFrame> {
    let mut frames = Vec::new();
    for _ in 0..TRIES {
        frames.push(cache.update(camera, &[]).unwrap());
        if done(cache, &frames) {
            return frames;
        }
        pause();
    }
    panic!("updates at {camera} never reached the state waited for");
}

fn counts(b: &[BandTile]) -> (usize, usize) {
    (b.len(), b.iter().filter(|t| t.active).count())
}

#[test]
fn band_regions_load_four_six_or_nine_tiles_and_activate_four_two_or_one() {
    let l = layout();
    let band = BandSelection::default();
    // Tile (5, 7) spans 40..48 m x 56..64 m; thirds at 2.67 m.
    let at = |fx: f32, fy: f32| band_tiles(&l, &band, Vec2::new(40.0 + 8.0 * fx, 56.0 + 8.0 * fy));
    let corner = at(0.1, 0.1).unwrap();
    assert_eq!(
        counts(&corner),
        (4, 4),
        "corner: the camera's side, all active"
    );
    let tiles: HashSet<UVec2> = corner.iter().map(|b| b.tile).collect();
    let expected: HashSet<UVec2> = [(5, 7), (4, 7), (5, 6), (4, 6)]
        .map(|(x, y)| UVec2::new(x, y))
        .into();
    assert_eq!(tiles, expected);
    let horizontal = at(0.9, 0.5).unwrap();
    assert_eq!(
        counts(&horizontal),
        (6, 2),
        "in a band: both neighbours across it, inactive"
    );
    for b in &horizontal {
        assert_eq!(b.active, b.tile.y == 7, "{b:?}");
    }
    let centre = at(0.5, 0.5).unwrap();
    assert_eq!(counts(&centre), (9, 1));
    assert_eq!(
        centre[0],
        BandTile {
            tile: UVec2::new(5, 7),
            active: true
        }
    );
    // Band width 0: always a corner; 1: always the centre.
    let none = BandSelection {
        band_width: 0.0,
        ..band
    };
    let all = BandSelection {
        band_width: 1.0,
        ..band
    };
    for f in [0.05f32, 0.3, 0.49, 0.51, 0.7, 0.95] {
        let p = Vec2::new(40.0 + 8.0 * f, 56.0 + 8.0 * (1.0 - f));
        assert_eq!(counts(&band_tiles(&l, &none, p).unwrap()), (4, 4));
        assert_eq!(counts(&band_tiles(&l, &all, p).unwrap()), (9, 1));
    }
    // Across the layer's wrap, and from far away (the layer repeats every 128 m).
    let wrap = band_tiles(&l, &band, Vec2::new(0.5, 127.8)).unwrap();
    let tiles: HashSet<UVec2> = wrap.iter().map(|b| b.tile).collect();
    let expected: HashSet<UVec2> = [(0, 15), (15, 15), (0, 0), (15, 0)]
        .map(|(x, y)| UVec2::new(x, y))
        .into();
    assert_eq!(tiles, expected);
    assert_eq!(
        band_tiles(&l, &band, Vec2::new(0.5 - 128.0 * 1e4, 127.8 + 128.0 * 3e3)).unwrap(),
        wrap
    );
    assert!(band_tiles(&l, &band, Vec2::new(f32::NAN, 0.0)).is_err());
    assert!(band_tiles(&l, &band, Vec2::new(0.0, f32::INFINITY)).is_err());
}

#[test]
fn crossing_one_region_edge_only_loads_or_only_unloads() {
    // Flower 2010: entering or leaving a region never unloads and reloads in one move, so a
    // tile is loaded well before it is needed.
    let l = layout();
    let band = BandSelection::default();
    let set = |p: Vec2| -> HashSet<UVec2> {
        band_tiles(&l, &band, p)
            .unwrap()
            .into_iter()
            .map(|b| b.tile)
            .collect()
    };
    for (start, step) in [
        (Vec2::new(3.0, 10.3), Vec2::new(0.05, 0.0)),
        (Vec2::new(21.7, 1.0), Vec2::new(0.0, 0.05)),
        (Vec2::new(5.1, 5.1), Vec2::new(-0.05, 0.0)),
    ] {
        let mut prev = set(start);
        for i in 1..2000 {
            let now = set(start + step * i as f32);
            let loaded = now.difference(&prev).count();
            let unloaded = prev.difference(&now).count();
            assert!(
                loaded == 0 || unloaded == 0,
                "step {i} from {start}: {loaded} loaded and {unloaded} unloaded at once"
            );
            prev = now;
        }
    }
}

#[test]
fn the_working_set_follows_the_band_within_the_upload_budget() {
    let s = store();
    let mut cache =
        DetailCache::open(world(&s), layout(), BandSelection::default(), 2 * 64 * 64).unwrap();
    let centre = Vec2::new(44.0, 60.0);
    let active = UVec2::new(5, 7);
    // The first update only asks the loaders: nothing is in RAM to upload yet.
    let f = cache.update(centre, &[]).unwrap();
    assert!(f.load.is_empty() && f.unload.is_empty());
    assert_eq!((f.pending, f.read_now), (9, 0));
    assert!(cache.reading(active));
    // The tiles come in two a frame (the budget), the active one before any inactive one.
    let mut loaded: Vec<UVec2> = Vec::new();
    let mut uploading = 0;
    let frames = update_until(&mut cache, centre, |c, _| c.loaded_tiles().len() == 9);
    for f in &frames {
        assert!(f.load.len() <= 2 && f.unload.is_empty(), "{f:?}");
        assert_eq!(f.upload_bytes, f.load.len() as u64 * 64 * 64);
        for &t in &f.load {
            assert!(
                t == active || loaded.contains(&active),
                "{t} before the active tile"
            );
            loaded.push(t);
        }
        uploading += usize::from(!f.load.is_empty());
    }
    assert!(uploading >= 5, "9 tiles at 2 a frame: {uploading} frames");
    assert_eq!(cache.active_tiles(), vec![active]);
    // Tiles a GPU stamp needs are read and loaded at once, whatever the budget, and are not
    // active.
    let far = [UVec2::new(12, 3), UVec2::new(13, 3), UVec2::new(12, 4)];
    let f = cache.update(centre, &far).unwrap();
    assert_eq!(f.load, far.to_vec());
    assert_eq!(f.read_now, 3);
    assert!(
        cache
            .loaded_tiles()
            .iter()
            .all(|&(t, a)| a == (t == active))
    );
    // Moving on releases what left the band; RAM holds only the working set.
    let f = cache.update(Vec2::new(100.0, 100.0), &[]).unwrap();
    assert_eq!(f.unload.len(), 12);
    assert!(cache.layer().resident_tiles() <= cache.loaded_tiles().len());
    assert!(
        cache.update(centre, &[UVec2::new(16, 0)]).is_err(),
        "off the grid"
    );
}

#[test]
fn tiles_read_ahead_are_in_ram_when_needed() {
    let s = store();
    // A stamped tile far from the band, stored.
    let far = UVec2::new(12, 2);
    let mut first =
        DetailCache::open(world(&s), layout(), BandSelection::default(), 1 << 20).unwrap();
    footprint(&mut first, Vec2::new(100.0, 20.0), -0.2);
    let stamped = first.tile(far).unwrap().clone();
    assert_eq!(first.flush().unwrap(), 1);
    drop(first);
    let mut cache = DetailCache::open(
        world_reopened(&s),
        layout(),
        BandSelection::default(),
        1 << 20,
    )
    .unwrap();
    let here = Vec2::new(44.0, 60.0);
    // Read ahead by the loaders: in RAM, not loaded (no GPU slot), not active.
    let f = cache.update_ahead(here, &[], &[far]).unwrap();
    assert!(cache.reading(far) && !f.load.contains(&far) && f.read_now == 0);
    for _ in 0..TRIES {
        if cache.tile(far).is_some() {
            break;
        }
        pause();
        let f = cache.update_ahead(here, &[], &[far]).unwrap();
        assert!(!f.load.contains(&far));
    }
    assert_eq!(cache.tile(far), Some(&stamped));
    assert!(cache.loaded_tiles().iter().all(|(t, _)| *t != far));
    // Needed now: loaded from RAM, nothing read on this thread.
    let f = cache.update(here, &[far]).unwrap();
    assert!(f.load.contains(&far));
    assert_eq!(f.read_now, 0);
    // Neither needed nor ahead: it leaves RAM.
    cache.update(here, &[]).unwrap();
    assert!(cache.tile(far).is_none());
    assert!(cache.update_ahead(here, &[], &[UVec2::new(0, 16)]).is_err());
}

fn footprint(cache: &mut DetailCache, at: Vec2, depth: f32) {
    let p = StampPlacement::new(at, Vec2::new(0.6, 0.9), depth).unwrap();
    cache
        .apply_stamp(&mut GaussianStamp::default(), &p, Blend::Add)
        .unwrap();
}

#[test]
fn deformed_tiles_are_written_back_when_released_and_read_back_later() {
    let s = store();
    let mut cache =
        DetailCache::open(world(&s), layout(), BandSelection::default(), 1 << 20).unwrap();
    let here = Vec2::new(44.0, 60.0);
    settle(&mut cache, here, &[]);
    // Across the corner of four tiles (48 m, 64 m), and one far outside the working set.
    footprint(&mut cache, Vec2::new(48.0, 64.0), -0.2);
    footprint(&mut cache, Vec2::new(100.0, 20.0), -0.1);
    let dirty = cache.dirty_tiles();
    assert_eq!(dirty.len(), 5, "{dirty:?}");
    let before: Vec<(UVec2, Grid<u8>)> = dirty
        .iter()
        .map(|&t| (t, cache.tile(t).unwrap().clone()))
        .collect();
    // The far tile is queued at the next update and clean once its write lands; those in the
    // band stay in RAM, dirty.
    let f = cache.update(here, &[]).unwrap();
    assert_eq!(f.writes, 1);
    update_until(&mut cache, here, |c, _| c.dirty_tiles().len() == 4);
    assert!(
        s.read("detail/00/0002/000c.tile", 1 << 20)
            .unwrap()
            .is_some()
    );
    // Leaving queues the rest; the flush waits for them, and has nothing of its own to write
    // (dirty only).
    let f = cache.update(Vec2::new(100.0, 100.0), &[]).unwrap();
    assert_eq!(f.writes, 4);
    assert_eq!(cache.flush().unwrap(), 0);
    assert!(cache.dirty_tiles().is_empty());
    assert_eq!(cache.writes_in_flight(), 0);
    // Another cache over the same store reads them back, texel for texel; untouched tiles
    // have no file and read as the zero tile.
    let mut again = DetailCache::open(
        world_reopened(&s),
        layout(),
        BandSelection::default(),
        1 << 20,
    )
    .unwrap();
    for (t, texels) in &before {
        let centre = (t.as_vec2() + 0.5) * 8.0;
        settle(&mut again, centre, &[]);
        assert_eq!(again.tile(*t), Some(texels), "tile {t}");
    }
    assert!(
        s.read("detail/00/0000/0000.tile", 1 << 20)
            .unwrap()
            .is_none()
    );
    // A tile set back to zero loses its file.
    let t = before[0].0;
    let zero = Grid::new(64, 64, DETAIL_ZERO_RAW).unwrap();
    again.write_tile(t, zero).unwrap();
    assert_eq!(again.flush().unwrap(), 1);
    let key = format!("detail/00/{:04x}/{:04x}.tile", t.y, t.x);
    assert!(s.read(&key, 1 << 20).unwrap().is_none(), "{key}");
}

fn world_reopened(s: &Arc<dyn TileStore>) -> World {
    World::open(s.clone()).unwrap()
}

#[test]
fn a_corrupt_tile_file_is_an_error_and_the_rest_still_works() {
    let s = store();
    let w = world(&s);
    s.write("detail/00/0007/0005.tile", b"not a tile at all")
        .unwrap();
    let mut cache = DetailCache::open(w, layout(), BandSelection::default(), 1 << 20).unwrap();
    let bad = UVec2::new(5, 7);
    let here = Vec2::new(44.0, 60.0);
    // The loaders report it when its read lands; the other eight tiles load.
    let frames = update_until(&mut cache, here, |c, frames| {
        c.loaded_tiles().len() == 8 && frames.iter().any(|f| !f.failed.is_empty())
    });
    let failed: Vec<_> = frames.iter().flat_map(|f| &f.failed).collect();
    assert_eq!(failed[0].0, bad);
    assert!(
        failed
            .iter()
            .all(|(t, e)| *t == bad && matches!(e, CacheError::CorruptTile { .. })),
        "{failed:?}"
    );
    assert!(!cache.loaded_tiles().iter().any(|(t, _)| *t == bad));
    // A stamp over it is refused and changes nothing; it is tried again by later updates.
    let p = StampPlacement::new(here, Vec2::new(0.6, 0.9), -0.1).unwrap();
    assert!(
        cache
            .apply_stamp(&mut GaussianStamp::default(), &p, Blend::Add)
            .is_err()
    );
    assert!(cache.dirty_tiles().is_empty());
    update_until(&mut cache, here, |_, frames| {
        frames.last().is_some_and(|f| !f.failed.is_empty())
    });
    // Far from it, the cache works (a read of it still in flight may report once more).
    let frames = settle(&mut cache, Vec2::new(100.0, 20.0), &[]);
    assert!(
        frames
            .iter()
            .flat_map(|f| &f.failed)
            .all(|(t, _)| *t == bad),
        "{frames:?}"
    );
    assert_eq!(cache.loaded_tiles().len(), 9);
    assert!(cache.loaded_tiles().iter().all(|(t, _)| *t != bad));
}

#[test]
fn caches_that_do_not_fit_are_refused() {
    let s = store();
    let band = BandSelection::default();
    // No detail layer in the manifest.
    let plain = Manifest::new(
        UVec2::splat(256),
        64,
        0.5,
        HeightEncoding::spanning::<u16>(0.0, 50.0).unwrap(),
        WrapMode::Repeat,
    )
    .unwrap();
    let other = store();
    let w = World::create(other, plain).unwrap();
    assert!(matches!(
        DetailCache::open(w, layout(), band, 1 << 20),
        Err(CacheError::NoSuchLayer { .. })
    ));
    // Another layout than the manifest's, a budget below one tile, a band width out of range.
    let refine8 = DetailLayout::new(UVec2::splat(256), 0.5, 8, 64).unwrap();
    assert!(DetailCache::open(world(&s), refine8, band, 1 << 20).is_err());
    assert!(DetailCache::open(world_reopened(&s), layout(), band, 64 * 64 - 1).is_err());
    for w in [-0.1, 1.5, f64::NAN] {
        let b = BandSelection {
            band_width: w,
            ..band
        };
        assert!(DetailCache::open(world_reopened(&s), layout(), b, 1 << 20).is_err());
    }
    // Tile sides that are not powers of two cannot be stored.
    let odd = DetailLayout::new(UVec2::splat(256), 0.5, 3, 48).unwrap();
    assert!(detail_manifest_layout(&odd).is_err());
}

#[test]
fn rects_read_back_from_the_gpu_merge_into_the_stored_tile() {
    use terrain_core::Rect;
    let s = store();
    let mut cache =
        DetailCache::open(world(&s), layout(), BandSelection::default(), 1 << 20).unwrap();
    cache.update(Vec2::new(44.0, 60.0), &[]).unwrap();
    footprint(&mut cache, Vec2::new(44.0, 60.0), -0.2);
    assert_eq!(cache.flush().unwrap(), 1);
    let t = UVec2::new(5, 7);
    let stored = cache.tile(t).unwrap().clone();
    // Far away: the tile leaves RAM. A rect written now is merged into what the world holds.
    cache.update(Vec2::new(100.0, 20.0), &[]).unwrap();
    assert!(cache.tile(t).is_none());
    let rect = Rect::new(glam::IVec2::new(10, 20), UVec2::new(5, 3));
    let texels = Grid::from_fn(5, 3, |x, y| (x * 10 + y) as u8).unwrap();
    cache.write_rect(t, rect, &texels).unwrap();
    assert_eq!(cache.dirty_tiles(), vec![t]);
    let merged = cache.tile(t).unwrap().clone();
    for y in 0..64 {
        for x in 0..64 {
            let inside = (10..15).contains(&x) && (20..23).contains(&y);
            let expected = if inside {
                ((x - 10) * 10 + (y - 20)) as u8
            } else {
                stored.get(x, y).unwrap()
            };
            assert_eq!(merged.get(x, y).unwrap(), expected, "({x}, {y})");
        }
    }
    // Refused, changing nothing: wrong size, off the tile, off the grid.
    assert!(
        cache
            .write_rect(
                t,
                Rect::new(glam::IVec2::new(10, 20), UVec2::new(4, 3)),
                &texels
            )
            .is_err()
    );
    assert!(
        cache
            .write_rect(
                t,
                Rect::new(glam::IVec2::new(62, 20), UVec2::new(5, 3)),
                &texels
            )
            .is_err()
    );
    assert!(cache.write_rect(UVec2::new(16, 0), rect, &texels).is_err());
    assert_eq!(cache.tile(t).unwrap(), &merged);
}

/// A store in front of another whose detail reads on the cache's loader threads, and detail
/// writes, can be held at a gate until the test opens it, and whose detail writes can be made
/// to fail.
#[derive(Debug)]
struct GateStore {
    inner: Arc<dyn TileStore>,
    hold_reads: bool,
    hold_writes: bool,
    open: Mutex<bool>,
    opened: Condvar,
    /// Calls that reached the gate (held, or let through once open).
    arrived: AtomicUsize,
    /// Detail writes still to fail.
    failures: AtomicUsize,
}

impl GateStore {
    fn new(hold_reads: bool, hold_writes: bool) -> Arc<Self> {
        Arc::new(Self {
            inner: store(),
            hold_reads,
            hold_writes,
            open: Mutex::new(false),
            opened: Condvar::new(),
            arrived: AtomicUsize::new(0),
            failures: AtomicUsize::new(0),
        })
    }

    fn gate(&self) {
        self.arrived.fetch_add(1, Ordering::SeqCst);
        let mut open = self.open.lock().unwrap();
        while !*open {
            open = self.opened.wait(open).unwrap();
        }
    }

    fn open_gate(&self) {
        *self.open.lock().unwrap() = true;
        self.opened.notify_all();
    }

    /// Waits (a bounded number of tries) until `n` calls reached the gate.
    fn wait_arrived(&self, n: usize) {
        for _ in 0..TRIES {
            if self.arrived.load(Ordering::SeqCst) >= n {
                return;
            }
            pause();
        }
        panic!("{n} calls never reached the gate");
    }

    /// The next detail write fails while `failures` is above zero.
    fn written(&self, key: &str) -> Result<(), CacheError> {
        if !key.starts_with("detail/") {
            return Ok(());
        }
        let fail = self
            .failures
            .fetch_update(Ordering::SeqCst, Ordering::SeqCst, |n| n.checked_sub(1))
            .is_ok();
        if fail {
            return Err(CacheError::Io {
                path: key.into(),
                source: std::io::Error::other("the disk is full"),
            });
        }
        if self.hold_writes {
            self.gate();
        }
        Ok(())
    }
}

impl TileStore for GateStore {
    fn read(&self, key: &str, max_len: u64) -> Result<Option<Vec<u8>>, CacheError> {
        let loader = std::thread::current()
            .name()
            .is_some_and(|n| n.starts_with("terrain-detail-load"));
        if self.hold_reads && loader && key.starts_with("detail/") {
            self.gate();
        }
        self.inner.read(key, max_len)
    }
    fn write(&self, key: &str, bytes: &[u8]) -> Result<(), CacheError> {
        self.written(key)?;
        self.inner.write(key, bytes)
    }
    fn remove(&self, key: &str) -> Result<(), CacheError> {
        self.written(key)?;
        self.inner.remove(key)
    }
    fn exists(&self, key: &str) -> Result<bool, CacheError> {
        self.inner.exists(key)
    }
    fn list(&self, prefix: &str) -> Result<Vec<String>, CacheError> {
        self.inner.list(prefix)
    }
}

fn gated_cache(gate: &Arc<GateStore>) -> DetailCache {
    let s: Arc<dyn TileStore> = gate.clone();
    DetailCache::open(world(&s), layout(), BandSelection::default(), 1 << 20).unwrap()
}

#[test]
fn a_stalled_store_does_not_stall_update_and_a_stamp_outlives_the_read_in_flight() {
    let gate = GateStore::new(true, false);
    let mut cache = gated_cache(&gate);
    let here = Vec2::new(44.0, 60.0);
    // Every read on the loaders waits at the gate: the updates return all the same (were
    // they to read, they would wait there forever), with the band pending.
    let f = cache.update(here, &[]).unwrap();
    assert_eq!((f.pending, f.load.len()), (9, 0));
    gate.wait_arrived(2);
    for _ in 0..3 {
        let f = cache.update(here, &[]).unwrap();
        assert_eq!((f.pending, f.load.len()), (9, 0));
    }
    // A stamp on the camera's tile, whose read is in flight (perhaps held in a loader): the
    // stamp reads it on this thread, and the read that lands later is dropped.
    let t = UVec2::new(5, 7);
    assert!(cache.reading(t));
    footprint(&mut cache, Vec2::new(44.0, 60.0), -0.2);
    assert!(!cache.reading(t));
    let stamped = cache.tile(t).unwrap().clone();
    assert!(stamped.as_slice().iter().any(|&v| v != DETAIL_ZERO_RAW));
    // A needed tile is read now, on this thread, whatever the loaders are doing.
    let far = UVec2::new(12, 2);
    let f = cache.update(here, &[far]).unwrap();
    assert_eq!(f.read_now, 1);
    assert!(f.load.contains(&t) && f.load.contains(&far));
    gate.open_gate();
    settle(&mut cache, here, &[]);
    assert_eq!(cache.loaded_tiles().len(), 9);
    assert_eq!(
        cache.tile(t),
        Some(&stamped),
        "the late read overwrote the stamp"
    );
    assert_eq!(cache.dirty_tiles(), vec![t]);
}

#[test]
fn a_tile_stamped_released_and_loaded_again_reads_back_its_texels() {
    let gate = GateStore::new(false, true);
    let mut cache = gated_cache(&gate);
    let (here, away) = (Vec2::new(44.0, 60.0), Vec2::new(100.0, 100.0));
    let t = UVec2::new(5, 7);
    settle(&mut cache, here, &[]);
    footprint(&mut cache, here, -0.2);
    let stamped = cache.tile(t).unwrap().clone();
    // Released: its write-back waits at the gate, so it stays in RAM, dirty.
    let f = cache.update(away, &[]).unwrap();
    assert!(f.unload.contains(&t) && f.writes == 1);
    gate.wait_arrived(1);
    assert_eq!(cache.tile(t), Some(&stamped));
    // Back before the write lands: loaded from RAM, no read.
    let f = cache.update(here, &[]).unwrap();
    assert!(f.load.contains(&t) && !cache.reading(t));
    assert_eq!(cache.tile(t), Some(&stamped));
    assert_eq!(cache.dirty_tiles(), vec![t]);
    // Stamped again while that write is in flight: the write of the older texels does not make
    // it clean.
    footprint(&mut cache, Vec2::new(46.0, 58.0), -0.1);
    let restamped = cache.tile(t).unwrap().clone();
    gate.open_gate();
    update_until(&mut cache, here, |c, _| c.writes_in_flight() == 0);
    assert_eq!(cache.dirty_tiles(), vec![t]);
    // Released once more: written, dropped from RAM, and read back from the store.
    update_until(&mut cache, away, |c, _| c.dirty_tiles().is_empty());
    update_until(&mut cache, away, |c, _| c.tile(t).is_none());
    settle(&mut cache, here, &[]);
    assert_eq!(cache.tile(t), Some(&restamped));
}

#[test]
fn a_failing_store_write_keeps_the_tile_dirty_and_is_retried() {
    let gate = GateStore::new(false, false);
    let mut cache = gated_cache(&gate);
    let (here, away) = (Vec2::new(44.0, 60.0), Vec2::new(100.0, 100.0));
    let t = UVec2::new(5, 7);
    settle(&mut cache, here, &[]);
    footprint(&mut cache, here, -0.2);
    let stamped = cache.tile(t).unwrap().clone();
    gate.failures.store(3, Ordering::SeqCst);
    // Three writes fail, each reported, the tile dirty and in RAM meanwhile; the fourth lands.
    let frames = update_until(&mut cache, away, |c, _| c.dirty_tiles().is_empty());
    let failed: Vec<_> = frames.iter().flat_map(|f| &f.failed).collect();
    assert_eq!(failed.len(), 3, "{failed:?}");
    assert!(failed.iter().all(|(f, _)| *f == t));
    assert_eq!(frames.iter().map(|f| f.writes).sum::<usize>(), 4);
    let key = "detail/00/0007/0005.tile";
    assert!(gate.inner.read(key, 1 << 20).unwrap().is_some());
    // A flush that fails keeps the tile dirty and says why; the next one stores it.
    footprint(&mut cache, here, -0.1);
    gate.failures.store(1, Ordering::SeqCst);
    assert!(matches!(cache.flush(), Err(CacheError::Io { .. })));
    assert_eq!(cache.dirty_tiles(), vec![t]);
    assert_eq!(cache.flush().unwrap(), 1);
    assert!(cache.dirty_tiles().is_empty());
    settle(&mut cache, here, &[]);
    assert_ne!(cache.tile(t), Some(&stamped), "the second stamp is kept");
}

#[test]
fn flush_waits_for_the_writes() {
    let gate = GateStore::new(false, true);
    let mut cache = gated_cache(&gate);
    let here = Vec2::new(44.0, 60.0);
    settle(&mut cache, here, &[]);
    // Across four tiles, and one far away (queued for write-back by the next update).
    footprint(&mut cache, Vec2::new(48.0, 64.0), -0.2);
    footprint(&mut cache, Vec2::new(100.0, 20.0), -0.1);
    let dirty = cache.dirty_tiles();
    assert_eq!(cache.update(here, &[]).unwrap().writes, 1);
    // The writer waits at the gate until a helper opens it; the flush waits for the writer.
    let helper = {
        let gate = gate.clone();
        std::thread::spawn(move || {
            gate.wait_arrived(1);
            gate.open_gate();
        })
    };
    assert_eq!(cache.flush().unwrap(), 4);
    helper.join().unwrap();
    assert!(cache.dirty_tiles().is_empty());
    assert_eq!(cache.writes_in_flight(), 0);
    for t in dirty {
        let key = format!("detail/00/{:04x}/{:04x}.tile", t.y, t.x);
        assert!(gate.inner.read(&key, 1 << 20).unwrap().is_some(), "{key}");
    }
}

/// `update_for_stamps`: the tiles a frame's stamps cover are loaded (across a tile corner,
/// four), those it is told to keep stay and leave once not asked for; a read-ahead reach of
/// any size is bounded by the grid, and a tile to keep off the grid is refused.
#[test]
fn a_frame_of_stamps_loads_the_tiles_they_cover_and_keeps_those_asked() {
    let s = store();
    let mut cache =
        DetailCache::open(world(&s), layout(), BandSelection::default(), 1 << 20).unwrap();
    let here = Vec2::new(44.0, 60.0);
    // Far from the band, on the corner of tiles (12, 2), (13, 2), (12, 3), (13, 3).
    let corner = StampPlacement::new(Vec2::new(104.0, 24.0), Vec2::splat(1.0), -0.1).unwrap();
    let kept = UVec2::new(0, 15);
    let f = cache
        .update_for_stamps(here, &[corner], &[kept], 4.0)
        .unwrap();
    for t in [(12, 2), (13, 2), (12, 3), (13, 3)] {
        assert!(f.load.contains(&UVec2::new(t.0, t.1)), "{t:?} not loaded");
    }
    assert!(f.load.contains(&kept));
    // Released once neither stamped nor kept.
    let f = cache.update_for_stamps(here, &[], &[], 4.0).unwrap();
    assert!(f.unload.contains(&kept) && f.unload.contains(&UVec2::new(12, 2)));
    // Any reach reads at most the grid.
    let f = cache.update_for_stamps(here, &[corner], &[], 1e30).unwrap();
    assert!(f.failed.is_empty());
    assert!(
        cache
            .update_for_stamps(here, &[], &[UVec2::new(99, 0)], 1.0)
            .is_err()
    );
}

#[test]
fn a_world_gets_a_detail_layer_once_and_another_is_refused() {
    let store = store();
    let mut w = World::create(store.clone(), manifest()).unwrap();
    terrain_cache::detail::ensure_detail_layer(&mut w, &layout()).unwrap();
    let wanted = detail_manifest_layout(&layout()).unwrap();
    assert_eq!(w.manifest().detail, Some(wanted));
    // Written: a world opened again has it; asking again changes nothing.
    let mut again = World::open(store.clone()).unwrap();
    assert_eq!(again.manifest().detail, Some(wanted));
    let generation = again.manifest().generation;
    terrain_cache::detail::ensure_detail_layer(&mut again, &layout()).unwrap();
    assert_eq!(again.manifest().generation, generation);
    // Another layer (tiles of 128) is refused, the manifest as it was.
    let other = DetailLayout::new(UVec2::splat(256), 0.5, 4, 128).unwrap();
    let refused = terrain_cache::detail::ensure_detail_layer(&mut again, &other);
    assert!(matches!(refused, Err(CacheError::OutOfRange { .. })));
    assert_eq!(World::open(store).unwrap().manifest().detail, Some(wanted));
}
