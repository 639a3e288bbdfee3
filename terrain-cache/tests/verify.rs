//! `verify_world` and `repair_world`: each class of defect a world can have (a missing tile or
//! level, a damaged or stale `bounds.bin`, a tile swapped for another valid tile at level 0, at
//! the top and in a world of one level, a coarser tile that is not the reduction of its
//! children) is found, bounded work on a crafted manifest, the cancel flag, and a repair that
//! rebuilds what level 0 determines and leaves level-0 damage reported.

use glam::UVec2;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use terrain_cache::manifest::{MANIFEST_KEY, bounds_key};
use terrain_cache::{
    CacheError, DefectKind, Layer, LevelBounds, Manifest, MapSource, ObjectTileStore, TileData,
    TileId, TileRead, TileStore, VerifyError, VerifyOptions, VerifyReport, World, build_world,
    repair_world, verify_world,
};
use terrain_core::{CoarseMap, Grid, HeightEncoding, WrapMode};

const SIZE: UVec2 = UVec2::new(96, 80);
const TILE: u32 = 16;

fn encoding() -> HeightEncoding {
    HeightEncoding::spanning::<u16>(0.0, 200.0).unwrap()
}

/// Heights with a corner of fill (0): its level-0 tiles and the coarser tile above them are
/// the zero tile and have no file.
fn map(size: UVec2) -> CoarseMap {
    let grid = Grid::from_fn(size.x, size.y, |x, y| {
        if x < 32 && y < 32 {
            0
        } else {
            ((x.wrapping_mul(2654435761) ^ y.wrapping_mul(40503)) % 60000 + 1) as u16
        }
    })
    .unwrap();
    CoarseMap::coarse(grid, encoding(), 1.0).unwrap()
}

fn built(levels: Option<u32>) -> World {
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
    let mut m = Manifest::new(SIZE, TILE, 1.0, encoding(), WrapMode::Clamp).unwrap();
    if let Some(l) = levels {
        m.levels = l;
    }
    build_world(store, m, &MapSource::new(&map(SIZE)), &|_| true)
        .unwrap()
        .0
}

fn verify(world: &World) -> VerifyReport {
    verify_world(
        world,
        &VerifyOptions::default(),
        &AtomicBool::new(false),
        &mut |_| {},
    )
    .unwrap()
}

fn key(world: &World, id: TileId) -> String {
    world.manifest().tile_key(Layer::Height, id)
}

fn bytes(world: &World, key: &str) -> Vec<u8> {
    world.store().read(key, 1 << 20).unwrap().expect(key)
}

/// The defects of `report` as (key, kind, repairable).
fn defects(report: &VerifyReport) -> Vec<(String, DefectKind, bool)> {
    assert_eq!(report.listed.len() as u64, report.defects, "{report:#?}");
    let mut d: Vec<_> = report
        .listed
        .iter()
        .map(|d| (d.key.clone(), d.kind, d.repairable))
        .collect();
    d.sort();
    d
}

fn repair(world: &World) -> terrain_cache::RepairReport {
    repair_world(
        world,
        &VerifyOptions::default(),
        &AtomicBool::new(false),
        &mut |_| {},
    )
    .unwrap()
}

#[test]
fn a_built_world_is_valid_and_its_zero_tiles_are_known_empty() {
    let world = built(None);
    let m = *world.manifest();
    assert_eq!(m.levels, 4);
    // The corner's level-0 tiles and the level-1 tile above them have no file.
    for id in [
        TileId::new(0, 0, 0),
        TileId::new(0, 1, 1),
        TileId::new(1, 0, 0),
    ] {
        assert_eq!(world.read_tile(Layer::Height, id).unwrap(), TileRead::Zero);
    }
    let calls = std::cell::Cell::new(0u64);
    let report = verify_world(
        &world,
        &VerifyOptions::default(),
        &AtomicBool::new(false),
        &mut |p| {
            calls.set(calls.get() + 1);
            assert!(p.done <= p.total);
        },
    )
    .unwrap();
    assert!(report.is_valid(), "{report:#?}");
    // The height pyramid's tiles, the 30 hole tiles over level 0, and the material and colour
    // tiles over every level (their pyramids are the heights').
    assert_eq!(report.tiles, 3 * (30 + 9 + 4 + 1) + 30);
    assert_eq!(report.stored + report.zero, report.tiles);
    assert_eq!(
        report.zero,
        5 + 30 + 2 * 44,
        "4 level-0 tiles and 1 level-1 tile are the zero tile; no hole, paint or colour"
    );
    assert_eq!(calls.get(), report.tiles);
    // A repair of a valid world writes nothing.
    let r = repair(&world);
    assert_eq!((r.tiles_rewritten, r.bounds_rewritten), (0, 0));
}

#[test]
fn a_missing_level0_tile_is_lost_unless_its_bounds_say_it_is_the_zero_tile() {
    let world = built(None);
    let lost = TileId::new(0, 4, 3);
    world.store().remove(&key(&world, lost)).unwrap();
    let report = verify(&world);
    let found = defects(&report);
    assert!(
        found.contains(&(key(&world, lost), DefectKind::Missing, false)),
        "{report:#?}"
    );
    // Its parent no longer matches a zero child either.
    assert!(
        found
            .iter()
            .all(|(_, kind, _)| *kind == DefectKind::Missing),
        "{report:#?}"
    );
    assert_eq!(report.unrepairable, 1);
    // Repair cannot bring it back: it stays reported, and the ancestors keep their record.
    let parent = lost.parent().unwrap();
    let before = bytes(&world, &key(&world, parent));
    let r = repair(&world);
    assert_eq!(r.tiles_rewritten, 0);
    assert_eq!(bytes(&world, &key(&world, parent)), before);
    assert_eq!(defects(&verify(&world)), found);
}

#[test]
fn a_missing_level_is_found_and_rebuilt_from_level_0() {
    let world = built(None);
    let m = *world.manifest();
    for id in m.tiles_of(Layer::Height, 2) {
        world.store().remove(&key(&world, id)).unwrap();
    }
    world.store().remove(&bounds_key(Layer::Height, 2)).unwrap();
    let report = verify(&world);
    let found = defects(&report);
    // Every level-2 tile is stored (none is all fill), so all four are missing, and the bounds.
    let mut want: Vec<_> = m
        .tiles_of(Layer::Height, 2)
        .map(|id| (key(&world, id), DefectKind::Missing, true))
        .collect();
    want.push((
        bounds_key(Layer::Height, 2),
        DefectKind::BoundsMissing,
        true,
    ));
    want.sort();
    assert_eq!(found, want, "{report:#?}");
    assert_eq!(report.unrepairable, 0);
    let r = repair(&world);
    assert_eq!((r.tiles_rewritten, r.bounds_rewritten), (4, 1));
    assert!(verify(&world).is_valid());
    let fresh = built(None);
    for id in m.tiles_of(Layer::Height, 2) {
        assert_eq!(
            bytes(&world, &key(&world, id)),
            bytes(&fresh, &key(&fresh, id)),
            "{id}"
        );
    }
    assert_eq!(world.bounds(2).unwrap(), fresh.bounds(2).unwrap());
}

#[test]
fn damaged_and_stale_bounds_are_found_and_rewritten() {
    let world = built(None);
    let fresh = built(None);
    // Level 1: one byte flipped (the checksum catches it).
    let k1 = bounds_key(Layer::Height, 1);
    let mut b = bytes(&world, &k1);
    b[18] ^= 0x10;
    world.store().write(&k1, &b).unwrap();
    // Level 0: a valid file with one entry off.
    let mut b0 = world.bounds(0).unwrap().unwrap();
    b0.min_max[8][1] -= 1;
    world.write_bounds(0, &b0).unwrap();
    // Level 3: a file of another layout (the top level has one tile, this says four).
    let other = LevelBounds::empty(UVec2::new(2, 2));
    world
        .store()
        .write(&bounds_key(Layer::Height, 3), &other.to_bytes())
        .unwrap();
    let report = verify(&world);
    assert_eq!(
        defects(&report),
        vec![
            (
                bounds_key(Layer::Height, 0),
                DefectKind::BoundsMismatch,
                true
            ),
            (k1.clone(), DefectKind::BoundsUnreadable, true),
            (
                bounds_key(Layer::Height, 3),
                DefectKind::BoundsUnreadable,
                true
            ),
        ],
        "{report:#?}"
    );
    let mismatch = report
        .listed
        .iter()
        .find(|d| d.kind == DefectKind::BoundsMismatch)
        .unwrap();
    assert!(
        mismatch.reason.contains("1 tile(s)") && mismatch.reason.contains("(2, 1)"),
        "{}",
        mismatch.reason
    );
    let r = repair(&world);
    assert_eq!((r.tiles_rewritten, r.bounds_rewritten), (0, 3));
    assert!(verify(&world).is_valid());
    for level in 0..4 {
        assert_eq!(world.bounds(level).unwrap(), fresh.bounds(level).unwrap());
    }
}

#[test]
fn a_level0_tile_swapped_for_another_valid_tile_is_found() {
    let world = built(None);
    let (a, b) = (TileId::new(0, 2, 0), TileId::new(0, 5, 4));
    let file_a = bytes(&world, &key(&world, a));
    world.store().write(&key(&world, b), &file_a).unwrap();
    let report = verify(&world);
    let found = defects(&report);
    assert!(
        found.contains(&(key(&world, b), DefectKind::Unreadable, false)),
        "{report:#?}"
    );
    let reason = &report.listed[0].reason;
    assert!(reason.contains("written for"), "{reason}");
    // Repair leaves it, and its ancestors, alone.
    let r = repair(&world);
    assert_eq!(r.tiles_rewritten, 0);
    assert_eq!(defects(&verify(&world)), found);
}

#[test]
fn tiles_without_an_identity_swapped_at_level_0_are_found_by_their_parent() {
    // Files as earlier builds wrote them (no identity): the parent check still sees the swap.
    let world = built(None);
    let m = *world.manifest();
    for id in m.tiles_of(Layer::Height, 0) {
        if let TileRead::Stored(d) = world.read_tile(Layer::Height, id).unwrap() {
            let old = world.encode_tile(Layer::Height, &d).unwrap();
            world.store().write(&key(&world, id), &old).unwrap();
        }
    }
    assert!(verify(&world).is_valid(), "identity-less files are valid");
    let (a, b) = (TileId::new(0, 2, 0), TileId::new(0, 5, 4));
    let file_a = bytes(&world, &key(&world, a));
    world.store().write(&key(&world, b), &file_a).unwrap();
    let report = verify(&world);
    let found = defects(&report);
    assert!(
        found.contains(&(key(&world, b.parent().unwrap()), DefectKind::Mismatch, true)),
        "{report:#?}"
    );
    assert!(
        found.contains(&(
            bounds_key(Layer::Height, 0),
            DefectKind::BoundsMismatch,
            true
        )),
        "{report:#?}"
    );
}

#[test]
fn a_swapped_tile_at_the_top_level_is_found() {
    // Multi-level: the top tile replaced by a (valid) level-0 tile's file.
    let world = built(None);
    let top = TileId::new(3, 0, 0);
    let file = bytes(&world, &key(&world, TileId::new(0, 3, 3)));
    world.store().write(&key(&world, top), &file).unwrap();
    let report = verify(&world);
    assert_eq!(
        defects(&report),
        vec![(key(&world, top), DefectKind::Unreadable, true)],
        "{report:#?}"
    );
    repair(&world);
    assert!(verify(&world).is_valid());

    // One level, so no parent: two of its tiles exchanged.
    let flat = built(Some(1));
    let (a, b) = (TileId::new(0, 3, 1), TileId::new(0, 4, 2));
    let (fa, fb) = (bytes(&flat, &key(&flat, a)), bytes(&flat, &key(&flat, b)));
    flat.store().write(&key(&flat, a), &fb).unwrap();
    flat.store().write(&key(&flat, b), &fa).unwrap();
    let report = verify(&flat);
    assert_eq!(
        defects(&report),
        vec![
            (key(&flat, a), DefectKind::Unreadable, false),
            (key(&flat, b), DefectKind::Unreadable, false),
        ],
        "{report:#?}"
    );
}

#[test]
fn a_coarser_tile_that_is_not_the_reduction_of_its_children_is_found_and_repaired() {
    let world = built(None);
    let id = TileId::new(1, 1, 2);
    let good = bytes(&world, &key(&world, id));
    let mut t = world.load_tile(Layer::Height, id).unwrap().as_ref().clone();
    t.as_u16_mut().unwrap().as_mut_slice()[3] ^= 1;
    world.write_tile(Layer::Height, id, &t).unwrap();
    // And one that should be the zero tile but is not.
    let zero = TileId::new(1, 0, 0);
    let mut z = world
        .load_tile(Layer::Height, zero)
        .unwrap()
        .as_ref()
        .clone();
    z.as_u16_mut().unwrap().as_mut_slice()[0] = 5;
    world.write_tile(Layer::Height, zero, &z).unwrap();
    let report = verify(&world);
    assert_eq!(
        defects(&report),
        vec![
            (key(&world, zero), DefectKind::Mismatch, true),
            (key(&world, id), DefectKind::Mismatch, true),
        ],
        "{report:#?}"
    );
    assert!(
        report
            .listed
            .iter()
            .any(|d| d.reason.starts_with("1 of 256"))
    );
    let r = repair(&world);
    assert_eq!((r.tiles_rewritten, r.bounds_rewritten), (2, 0));
    assert!(verify(&world).is_valid());
    assert_eq!(bytes(&world, &key(&world, id)), good);
    assert_eq!(
        world.read_tile(Layer::Height, zero).unwrap(),
        TileRead::Zero,
        "the zero tile's file is removed again"
    );
}

#[test]
fn repair_rebuilds_around_level0_damage_and_leaves_it_reported() {
    let world = built(None);
    let bad = TileId::new(0, 5, 0);
    world
        .store()
        .write(&key(&world, bad), b"not a tile at all")
        .unwrap();
    // A stale tile elsewhere (its subtree is sound).
    let stale = TileId::new(1, 0, 2);
    let good = bytes(&world, &key(&world, stale));
    let mut t = world
        .load_tile(Layer::Height, stale)
        .unwrap()
        .as_ref()
        .clone();
    t.as_u16_mut().unwrap().as_mut_slice()[100] ^= 7;
    world.write_tile(Layer::Height, stale, &t).unwrap();
    let r = repair(&world);
    assert_eq!(r.found.defects, 2);
    assert_eq!(r.found.unrepairable, 1);
    assert_eq!(r.tiles_rewritten, 1);
    assert_eq!(bytes(&world, &key(&world, stale)), good);
    let after = verify(&world);
    assert_eq!(
        defects(&after),
        vec![(key(&world, bad), DefectKind::Unreadable, false)],
        "{after:#?}"
    );
}

#[test]
fn a_crafted_manifest_promising_billions_of_tiles_is_refused_at_once() {
    // 65536^2 level-0 tiles in a few hundred bytes: the world does not open (a level holds at
    // most 2^24 tiles), so nothing sized by its tiles is allocated.
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
    let m = Manifest::new(UVec2::splat(1 << 20), 256, 1.0, encoding(), WrapMode::Clamp).unwrap();
    let crafted = m.to_json().replace("1048576", "16777216");
    assert_ne!(crafted, m.to_json());
    store.write(MANIFEST_KEY, crafted.as_bytes()).unwrap();
    let start = Instant::now();
    let e = World::open(store).unwrap_err();
    assert!(
        matches!(
            e,
            CacheError::OutOfRange {
                what: "level-0 tiles",
                ..
            }
        ),
        "{e}"
    );
    // The largest world that opens (4096^2 level-0 tiles, 22 M in all) is over verification's
    // default limit, refused at once.
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
    store.write(MANIFEST_KEY, m.to_json().as_bytes()).unwrap();
    let world = World::open(store).unwrap();
    let cancel = AtomicBool::new(false);
    let e = verify_world(&world, &VerifyOptions::default(), &cancel, &mut |_| {}).unwrap_err();
    assert!(
        matches!(e, VerifyError::TooManyTiles { tiles, .. } if tiles > 1 << 24),
        "{e}"
    );
    let e = repair_world(&world, &VerifyOptions::default(), &cancel, &mut |_| {}).unwrap_err();
    assert!(matches!(e, VerifyError::TooManyTiles { .. }), "{e}");
    assert!(start.elapsed() < Duration::from_secs(1));
    // The limit is the caller's: a small world over a small limit is refused the same way.
    let small = built(None);
    let options = VerifyOptions {
        max_tiles: 161,
        ..VerifyOptions::default()
    };
    let e = verify_world(&small, &options, &cancel, &mut |_| {}).unwrap_err();
    assert!(
        matches!(
            e,
            VerifyError::TooManyTiles {
                tiles: 162,
                max: 161
            }
        ),
        "{e}"
    );
}

#[test]
fn the_cancel_flag_stops_the_walk() {
    let world = built(None);
    let cancel = AtomicBool::new(true);
    let e = verify_world(&world, &VerifyOptions::default(), &cancel, &mut |_| {}).unwrap_err();
    assert!(
        matches!(
            e,
            VerifyError::Cancelled {
                done: 0,
                total: 162
            }
        ),
        "{e}"
    );
    // Set from the progress callback (as a Ctrl-C handler would, from anywhere).
    let cancel = AtomicBool::new(false);
    let mut seen = 0;
    let e = verify_world(&world, &VerifyOptions::default(), &cancel, &mut |p| {
        seen = p.done;
        if p.done == 5 {
            cancel.store(true, Ordering::Relaxed);
        }
    })
    .unwrap_err();
    assert!(matches!(e, VerifyError::Cancelled { done: 5, .. }), "{e}");
    assert_eq!(seen, 5);
    // A cancelled repair writes no bounds.
    world.store().remove(&bounds_key(Layer::Height, 1)).unwrap();
    let cancel = AtomicBool::new(false);
    let e = repair_world(&world, &VerifyOptions::default(), &cancel, &mut |p| {
        if p.done == 40 {
            cancel.store(true, Ordering::Relaxed);
        }
    })
    .unwrap_err();
    assert!(matches!(e, VerifyError::Cancelled { .. }), "{e}");
    assert_eq!(world.bounds(1).unwrap(), None);
}

#[test]
fn the_report_lists_a_bounded_number_of_defects_and_counts_all() {
    let world = built(None);
    let m = *world.manifest();
    let mut broken = 0;
    for id in m.tiles_of(Layer::Height, 0) {
        if world.read_tile(Layer::Height, id).unwrap() != TileRead::Zero {
            world.store().write(&key(&world, id), b"junk").unwrap();
            broken += 1;
        }
    }
    let options = VerifyOptions {
        max_listed: 3,
        ..VerifyOptions::default()
    };
    let report = verify_world(&world, &options, &AtomicBool::new(false), &mut |_| {}).unwrap();
    assert_eq!(report.listed.len(), 3);
    assert_eq!(report.defects, broken);
    assert_eq!(report.unlisted(), broken - 3);
    assert!(!report.is_valid());
}

#[test]
fn detail_tiles_are_checked_and_missing_ones_are_the_zero_deformation() {
    let mut world = built(None);
    world
        .update_manifest(|m| {
            m.detail = Some(
                terrain_cache::DetailLayout::covering(glam::Vec2::new(96.0, 80.0), 32, 0.5)
                    .unwrap(),
            );
        })
        .unwrap();
    let mut d = world.zero_tile(Layer::Detail).unwrap().as_ref().clone();
    if let TileData::U8(g) = &mut d {
        g.as_mut_slice()[9] = 1;
    }
    let id = TileId::new(0, 1, 1);
    world.write_tile(Layer::Detail, id, &d).unwrap();
    let report = verify(&world);
    assert!(report.is_valid(), "{report:#?}");
    assert_eq!(report.tiles, 162 + 6 * 5);
    let other = world
        .manifest()
        .tile_key(Layer::Detail, TileId::new(0, 2, 2));
    let file = bytes(&world, &world.manifest().tile_key(Layer::Detail, id));
    world.store().write(&other, &file).unwrap();
    assert_eq!(
        defects(&verify(&world)),
        vec![(other.clone(), DefectKind::Unreadable, false)]
    );
    // Hole tiles the same way: a stored one is valid, one copied over another's path is not.
    world.store().remove(&other).unwrap();
    let mut h = world.zero_tile(Layer::Hole).unwrap().as_ref().clone();
    h.as_u8_mut().unwrap().as_mut_slice()[3] = 255;
    world.write_tile(Layer::Hole, id, &h).unwrap();
    let report = verify(&world);
    assert!(report.is_valid(), "{report:#?}");
    let copied = world.manifest().tile_key(Layer::Hole, TileId::new(0, 0, 1));
    let file = bytes(&world, &world.manifest().tile_key(Layer::Hole, id));
    world.store().write(&copied, &file).unwrap();
    assert_eq!(
        defects(&verify(&world)),
        vec![(copied, DefectKind::Unreadable, false)]
    );
}

/// The check a run makes before it uses a world finds, without decoding a tile, what a run
/// would make worse: a lost level-0 tile (its bounds say it held heights) and a missing or
/// damaged bounds.bin; a valid world, and a missing tile that is rightly the zero tile, pass.
#[test]
fn the_check_before_use_finds_lost_tiles_and_missing_bounds() {
    let world = built(None);
    assert_eq!(terrain_cache::check_before_use(&world, 10).unwrap(), vec![]);
    // (1, 0) is in the corner of fill, rightly not stored; (3, 0) holds heights.
    let empty = TileId::new(0, 1, 0);
    assert!(!world.store().exists(&key(&world, empty)).unwrap());
    let lost = TileId::new(0, 3, 0);
    world.store().remove(&key(&world, lost)).unwrap();
    let found = terrain_cache::check_before_use(&world, 10).unwrap();
    let kinds: Vec<_> = found
        .iter()
        .map(|d| (d.key.clone(), d.kind, d.repairable))
        .collect();
    assert_eq!(kinds, vec![(key(&world, lost), DefectKind::Missing, false)]);
    // A write-back in progress (a tile that became all fill is removed, its bounds rebuilt
    // after): the journal's recovery settles it, so the run is not refused.
    world
        .store()
        .write("journal/00-00000003-00000000", b"")
        .unwrap();
    assert_eq!(terrain_cache::check_before_use(&world, 10).unwrap(), vec![]);
    world
        .store()
        .remove("journal/00-00000003-00000000")
        .unwrap();
    // As verify_world says.
    assert!(defects(&verify(&world)).contains(&(key(&world, lost), DefectKind::Missing, false)));
    let bounds1 = bounds_key(Layer::Height, 1);
    world.store().remove(&bounds1).unwrap();
    world
        .store()
        .write(&bounds_key(Layer::Height, 0), b"TCBN garbage")
        .unwrap();
    let found = terrain_cache::check_before_use(&world, 10).unwrap();
    let kinds: Vec<_> = found.iter().map(|d| (d.key.clone(), d.kind)).collect();
    assert_eq!(
        kinds,
        vec![
            (bounds_key(Layer::Height, 0), DefectKind::BoundsUnreadable),
            (bounds1, DefectKind::BoundsMissing)
        ]
    );
    assert_eq!(
        terrain_cache::check_before_use(&world, 1).unwrap().len(),
        1,
        "at most listed"
    );
}
