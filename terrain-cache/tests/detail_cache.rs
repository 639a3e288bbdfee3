//! Detail tiles as cache tiles: the band regions of Flower 2010, fig. 2.4 (loaded / active), the
//! working set within an upload budget, dirty-only atomic write-back and reading back what
//! was written, refusals.

use glam::{UVec2, Vec2};
use std::collections::HashSet;
use std::sync::Arc;
use terrain_cache::detail::{BandTile, DetailCache, band_tiles, detail_manifest_layout};
use terrain_cache::{BandSelection, CacheError, Manifest, ObjectTileStore, TileStore, World};
use terrain_core::detail::{DETAIL_ZERO_RAW, DetailLayout};
use terrain_core::{Blend, GaussianStamp, Grid, HeightEncoding, StampPlacement, WrapMode};

/// 256 x 256 coarse texels at 0.5 m refined x4: 1024 detail texels a side in 16 x 16 tiles of
/// 64 (8 m a side).
fn layout() -> DetailLayout {
    DetailLayout::new(UVec2::splat(256), 0.5, 4, 64).unwrap()
}

fn world(store: &Arc<dyn TileStore>) -> World {
    let mut manifest = Manifest::new(
        UVec2::splat(256),
        64,
        0.5,
        HeightEncoding::spanning::<u16>(0.0, 50.0).unwrap(),
        WrapMode::Repeat,
    )
    .unwrap();
    manifest.detail = Some(detail_manifest_layout(&layout()).unwrap());
    World::create(store.clone(), manifest).unwrap()
}

fn store() -> Arc<dyn TileStore> {
    Arc::new(ObjectTileStore::in_memory().unwrap())
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
    let f = cache.update(centre, &[]).unwrap();
    assert_eq!(f.load.len(), 2, "two tiles' worth of budget");
    assert_eq!(f.load[0], UVec2::new(5, 7), "the active tile first");
    assert_eq!((f.deferred, f.upload_bytes), (7, 2 * 64 * 64));
    let mut frames = 1;
    while cache.loaded_tiles().len() < 9 {
        let f = cache.update(centre, &[]).unwrap();
        assert!(f.load.len() <= 2 && f.unload.is_empty());
        frames += 1;
        assert!(frames < 10);
    }
    assert_eq!(frames, 5);
    assert_eq!(cache.active_tiles(), vec![UVec2::new(5, 7)]);
    // Tiles a GPU stamp needs are loaded at once, whatever the budget, and are not active.
    let far = [UVec2::new(12, 3), UVec2::new(13, 3), UVec2::new(12, 4)];
    let f = cache.update(centre, &far).unwrap();
    assert_eq!(f.load, far.to_vec());
    assert!(
        cache
            .loaded_tiles()
            .iter()
            .all(|&(t, a)| a == (t == UVec2::new(5, 7)))
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
    cache.update(here, &[]).unwrap();
    // Across the corner of four tiles (48 m, 64 m), and one far outside the working set.
    footprint(&mut cache, Vec2::new(48.0, 64.0), -0.2);
    footprint(&mut cache, Vec2::new(100.0, 20.0), -0.1);
    let dirty = cache.dirty_tiles();
    assert_eq!(dirty.len(), 5, "{dirty:?}");
    let before: Vec<(UVec2, Grid<u8>)> = dirty
        .iter()
        .map(|&t| (t, cache.tile(t).unwrap().clone()))
        .collect();
    // The far tile is written at the next update; those in the band stay in RAM, dirty.
    let f = cache.update(here, &[]).unwrap();
    assert_eq!(f.written, 1);
    assert_eq!(cache.dirty_tiles().len(), 4);
    assert!(
        s.read("detail/00/0002/000c.png", 1 << 20)
            .unwrap()
            .is_some()
    );
    // Leaving writes the rest back; a second flush has nothing to write (dirty only).
    let f = cache.update(Vec2::new(100.0, 100.0), &[]).unwrap();
    assert_eq!(f.written, 4);
    assert_eq!(cache.flush().unwrap(), 0);
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
        again.update(centre, &[]).unwrap();
        assert_eq!(again.tile(*t), Some(texels), "tile {t}");
    }
    assert!(
        s.read("detail/00/0000/0000.png", 1 << 20)
            .unwrap()
            .is_none()
    );
    // A tile set back to zero loses its file.
    let t = before[0].0;
    let zero = Grid::new(64, 64, DETAIL_ZERO_RAW).unwrap();
    again.write_tile(t, zero).unwrap();
    assert_eq!(again.flush().unwrap(), 1);
    let key = format!("detail/00/{:04x}/{:04x}.png", t.y, t.x);
    assert!(s.read(&key, 1 << 20).unwrap().is_none(), "{key}");
}

fn world_reopened(s: &Arc<dyn TileStore>) -> World {
    World::open(s.clone()).unwrap()
}

#[test]
fn a_corrupt_tile_file_is_an_error_and_the_rest_still_works() {
    let s = store();
    let w = world(&s);
    s.write("detail/00/0007/0005.png", b"not a png at all")
        .unwrap();
    let mut cache = DetailCache::open(w, layout(), BandSelection::default(), 1 << 20).unwrap();
    let f = cache.update(Vec2::new(44.0, 60.0), &[]).unwrap();
    assert_eq!(f.failed.len(), 1);
    assert_eq!(f.failed[0].0, UVec2::new(5, 7));
    assert!(
        matches!(f.failed[0].1, CacheError::CorruptTile { .. }),
        "{}",
        f.failed[0].1
    );
    assert_eq!(f.load.len(), 8, "the other tiles load");
    assert!(
        !cache
            .loaded_tiles()
            .iter()
            .any(|(t, _)| *t == UVec2::new(5, 7))
    );
    // A stamp over it is refused and changes nothing; it is tried again next update.
    let p = StampPlacement::new(Vec2::new(44.0, 60.0), Vec2::new(0.6, 0.9), -0.1).unwrap();
    assert!(
        cache
            .apply_stamp(&mut GaussianStamp::default(), &p, Blend::Add)
            .is_err()
    );
    assert!(cache.dirty_tiles().is_empty());
    let f = cache.update(Vec2::new(44.0, 60.0), &[]).unwrap();
    assert_eq!(f.failed.len(), 1);
    // Far from it, the cache works.
    let f = cache.update(Vec2::new(100.0, 20.0), &[]).unwrap();
    assert!(f.failed.is_empty());
    assert_eq!(f.load.len(), 9 - f.deferred);
    assert!(
        cache
            .loaded_tiles()
            .iter()
            .all(|(t, _)| *t != UVec2::new(5, 7))
    );
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
