//! Two writers of one bucket world editing different children of the same parent: the parent
//! and `bounds.bin` are derived data, so a conflict on them is recomputed from the children as
//! they are now, never reported; the result is the reduction of both writers' children.

#![cfg(feature = "object-store")]

mod common;

use common::build;
use glam::UVec2;
use std::sync::Arc;
use terrain_cache::{
    Layer, ObjectStoreConfig, ObjectTileStore, TileData, TileId, TileStore, World,
    rebuild_ancestors, rebuild_ancestors_shared, reduce_levels,
};
use terrain_core::Grid;

/// A store over `mem` with conflict detection (as bucket stores have it).
fn writer(mem: &Arc<object_store::memory::InMemory>) -> Arc<dyn TileStore> {
    Arc::new(ObjectTileStore::with_config(mem.clone(), "w", ObjectStoreConfig::default()).unwrap())
}

fn flat(world: &World, v: u16) -> TileData {
    let t = world.manifest().tile_size;
    TileData::U16(Grid::new(t, t, v).unwrap())
}

#[test]
fn derived_tiles_are_recomputed_on_conflict_and_hold_both_writers_children() {
    let mem = Arc::new(object_store::memory::InMemory::new());
    let a = build(writer(&mem), UVec2::splat(64), 32);
    let b = World::open(writer(&mem)).unwrap();
    let parent = TileId::new(1, 0, 0);
    // B has seen the parent and the bounds (its pool loaded them for display).
    b.load_tile(Layer::Height, parent).unwrap();
    b.bounds(0).unwrap();
    b.bounds(1).unwrap();
    // A changes one child and rebuilds the parent; B then changes another.
    let (ka, kb) = (TileId::new(0, 0, 0), TileId::new(0, 1, 1));
    a.write_tile(Layer::Height, ka, &flat(&a, 1000)).unwrap();
    rebuild_ancestors_shared(&a, &[ka]).unwrap();
    b.write_tile(Layer::Height, kb, &flat(&b, 50_000)).unwrap();
    // Without the retry, B's stale view of the parent is refused...
    assert!(matches!(
        rebuild_ancestors(&b, &[kb]),
        Err(terrain_cache::CacheError::Conflict { .. })
    ));
    // ...with it, the parent is recomputed from both writers' children.
    rebuild_ancestors_shared(&b, &[kb]).unwrap();
    let fresh = World::open(writer(&mem)).unwrap();
    let stored = fresh.load_tile(Layer::Height, parent).unwrap();
    // The reference: level 0 as it now is, whole, reduced once.
    let level0 = Grid::from_fn(64, 64, |x, y| {
        let tile = fresh
            .load_tile(Layer::Height, TileId::new(0, x / 32, y / 32))
            .unwrap();
        tile.as_u16().unwrap().get(x % 32, y % 32).unwrap()
    })
    .unwrap();
    let expected = TileData::U16(reduce_levels(&level0, 1).unwrap());
    assert_eq!(*stored, expected, "the parent holds both children");
    let b0 = fresh.bounds(0).unwrap().unwrap();
    assert_eq!(b0.get(0, 0), Some([1000, 1000]));
    assert_eq!(b0.get(1, 1), Some([50_000, 50_000]));
}
