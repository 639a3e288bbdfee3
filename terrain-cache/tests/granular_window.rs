//! `GranularWindow` on a real RAM pool: columns taken from the resident tiles, stepped by
//! terrain-core's granular simulation, handed back area by area; the tiles hold exactly the
//! units taken after every step, a foreign write into the window is caught on release, and the
//! placement, take and hand-back refuse what they cannot do, as do a shift, its sum, the old
//! window's late areas and its retirement.

mod common;

use common::build;
use glam::{Affine3A, UVec2, Vec2, Vec3};
use std::sync::Arc;
use terrain_cache::{
    CacheError, GranularWindow, Layer, ObjectTileStore, PoolConfig, RamPool, TileId, TileStore,
    World,
};
use terrain_core::granular::{GranularObject, GranularParams, GranularSim, TriMesh};
use terrain_core::{Grid, Rect};

const WORLD: u32 = 128;
const TILE: u32 = 32;

fn world() -> World {
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
    build(store, UVec2::splat(WORLD), TILE)
}

/// A pool with every level-0 tile of the world loaded.
fn loaded_pool(world: &World) -> RamPool {
    let mut pool = RamPool::new(world.clone(), PoolConfig::new(Layer::Height, 64 << 20)).unwrap();
    common::load_level0(&mut pool);
    pool
}

fn units(pool: &RamPool, rect: Rect) -> u64 {
    let mut g = Grid::new(rect.size.x, rect.size.y, 0u16).unwrap();
    assert_eq!(pool.read_region(rect, &mut g).unwrap(), 0);
    g.as_slice().iter().map(|&h| u64::from(h)).sum()
}

#[test]
fn trails_reach_the_tiles_with_the_volume_exact_after_every_step() {
    let world = world();
    let mut pool = loaded_pool(&world);
    let mut window = GranularWindow::new(world.manifest(), 64).unwrap();
    // Across a tile corner (32, 32) and (64, 64): the window spans 3 x 3 tiles.
    let rect = window.placement(Vec2::new(50.0, 50.0));
    assert_eq!(rect, Rect::new(glam::IVec2::new(18, 18), UVec2::splat(64)));
    let map = window
        .take(&mut pool, rect)
        .unwrap()
        .expect("all tiles resident");
    let taken = units(&pool, rect);
    assert_eq!(window.volume_taken(), taken);
    assert_eq!(
        map.grid()
            .as_slice()
            .iter()
            .map(|&u| u64::from(u))
            .sum::<u64>(),
        taken
    );
    let mut sim = GranularSim::new(map, GranularParams::snow()).unwrap();
    let wheel = TriMesh::wheel(2.0, 1.0, 16).unwrap();
    let enc = world.manifest().encoding;
    let mut changed = 0u64;
    for step in 0..6 {
        // A wheel rolling across the window, its bottom 3 m under the local surface.
        let xz = Vec2::new(30.0 + 6.0 * step as f32, 50.0);
        let ground = enc.to_metres(60_000.0);
        let at = Affine3A::from_translation(Vec3::new(xz.x, ground - 3.0 + 2.0, xz.y));
        let report = sim
            .step(&[GranularObject::new(&wheel, window.to_local(at))])
            .unwrap();
        assert_eq!(report.removed, 0);
        for area in &report.active_areas {
            let heights = sim.map().grid().copy_rect(area.rect).unwrap();
            let (world_rect, stored) = window.hand_back(&mut pool, area.rect, &heights).unwrap();
            assert_eq!(world_rect.min, rect.min + area.rect.min);
            assert_eq!(stored.size(), area.rect.size);
            changed += area.rect.area();
        }
        assert_eq!(units(&pool, rect), taken, "step {step}");
    }
    assert!(changed > 0, "the wheel never touched the ground");
    // The tiles hold the simulation's heights, column for column.
    let mut now = Grid::new(64, 64, 0u16).unwrap();
    pool.read_region(rect, &mut now).unwrap();
    let sim_heights: Vec<u16> = sim
        .map()
        .grid()
        .as_slice()
        .iter()
        .map(|&u| u as u16)
        .collect();
    assert_eq!(now.as_slice(), sim_heights.as_slice());
    assert_ne!(
        now.as_slice(),
        world_heights(&world, rect).as_slice(),
        "nothing moved"
    );
    assert_eq!(window.release(&mut pool, 0).unwrap(), taken);
    assert_eq!(window.rect(), None);
}

/// `rect` of the world as built (its files).
fn world_heights(world: &World, rect: Rect) -> Grid<u16> {
    let fresh = loaded_pool(world);
    let mut g = Grid::new(rect.size.x, rect.size.y, 0u16).unwrap();
    fresh.read_region(rect, &mut g).unwrap();
    g
}

#[test]
fn a_foreign_write_into_the_window_is_caught_on_release() {
    let world = world();
    let mut pool = loaded_pool(&world);
    let mut window = GranularWindow::new(world.manifest(), 32).unwrap();
    let rect = window.placement(Vec2::new(16.0, 16.0));
    window.take(&mut pool, rect).unwrap().unwrap();
    pool.write_rect(
        TileId::new(0, 0, 0),
        Rect::new(glam::IVec2::new(3, 3), UVec2::ONE),
        &Grid::new(1, 1, 7u16).unwrap(),
    )
    .unwrap();
    assert!(matches!(
        window.release(&mut pool, 0),
        Err(CacheError::OutOfRange { .. })
    ));
    // Released anyway: a new window can be taken.
    assert!(window.take(&mut pool, rect).unwrap().is_some());
}

#[test]
fn take_waits_for_tiles_and_refuses_what_it_cannot_do() {
    let world = world();
    // An empty pool: nothing resident, nothing pinned, try again later.
    let mut empty = RamPool::new(world.clone(), PoolConfig::new(Layer::Height, 64 << 20)).unwrap();
    let mut window = GranularWindow::new(world.manifest(), 32).unwrap();
    let rect = window.placement(Vec2::new(64.0, 64.0));
    assert!(window.take(&mut empty, rect).unwrap().is_none());
    assert_eq!(window.rect(), None);

    let mut pool = loaded_pool(&world);
    // Off the map, or of another size.
    let off = Rect::new(glam::IVec2::new(100, 0), UVec2::splat(32));
    assert!(window.take(&mut pool, off).is_err());
    let small = Rect::new(glam::IVec2::ZERO, UVec2::splat(16));
    assert!(window.take(&mut pool, small).is_err());
    // Hand-back before a take, then outside the window.
    assert!(
        window
            .hand_back(&mut pool, small, &Grid::new(16, 16, 0u32).unwrap())
            .is_err()
    );
    window.take(&mut pool, rect).unwrap().unwrap();
    assert!(window.take(&mut pool, rect).is_err(), "two windows at once");
    let outside = Rect::new(glam::IVec2::new(20, 20), UVec2::splat(16));
    assert!(
        window
            .hand_back(&mut pool, outside, &Grid::new(16, 16, 0u32).unwrap())
            .is_err()
    );
    // A column above what a u16 holds is refused, and nothing is written.
    let before = units(&pool, rect);
    let tall = Grid::new(4, 4, 70_000u32).unwrap();
    assert!(
        window
            .hand_back(&mut pool, Rect::from_size(UVec2::splat(4)), &tall)
            .is_err()
    );
    assert_eq!(units(&pool, rect), before);
    assert_eq!(window.release(&mut pool, 0).unwrap(), before);

    // Sides out of range; placements for any centre stay inside the world.
    assert!(GranularWindow::new(world.manifest(), 8).is_err());
    assert!(GranularWindow::new(world.manifest(), WORLD + 1).is_err());
    let full = Rect::from_size(UVec2::splat(WORLD));
    for c in [
        Vec2::new(f32::NAN, 1.0),
        Vec2::splat(f32::INFINITY),
        Vec2::splat(-1e30),
        Vec2::new(1e9, -3.0),
    ] {
        assert!(full.contains_rect(&window.placement(c)), "{c}");
    }
    assert!(!window.covers(&[Vec2::ZERO], 0.0), "no window taken");
}

#[test]
fn a_shift_refuses_what_it_cannot_do_and_its_hand_over_is_checked() {
    let world = world();
    let mut pool = loaded_pool(&world);
    let mut window = GranularWindow::new(world.manifest(), 32).unwrap();
    let a = window.placement(Vec2::new(40.0, 40.0));
    let b = Rect::new(a.min + glam::IVec2::new(8, -4), a.size);
    // No window to move, a sum with no shift, nothing retiring.
    assert!(window.shift(&mut pool, b).is_err());
    assert!(window.shifted_sum(1).is_err());
    let empty = Grid::new(4, 4, 0u32).unwrap();
    let small = Rect::from_size(UVec2::splat(4));
    assert!(window.hand_back_retired(&mut pool, small, &empty).is_err());
    assert!(window.retire(&mut pool, 0).is_err());
    let held = units(&pool, a);
    window.take(&mut pool, a).unwrap().unwrap();
    // Off the world, or of another size: refused, nothing changed.
    let off = Rect::new(glam::IVec2::new(110, 0), UVec2::splat(32));
    assert!(window.shift(&mut pool, off).is_err());
    assert!(window.shift(&mut pool, small).is_err());
    assert_eq!(window.rect(), Some(a));
    let (map, offset) = window.shift(&mut pool, b).unwrap().unwrap();
    assert_eq!(offset, glam::IVec2::new(8, -4));
    assert_eq!((window.rect(), window.retiring_rect()), (Some(b), Some(a)));
    assert!(window.shift(&mut pool, a).is_err(), "two windows retiring");
    // The strips (the new window less the old) came from the tiles: a sum below them lost
    // units and is refused; the right one is the tiles' own here (nothing was stepped).
    let strips: u64 = b.minus(&a).iter().map(|r| units(&pool, *r)).sum();
    assert!(window.awaits_sum());
    assert!(window.shifted_sum(strips - 1).is_err());
    let sum: u64 = map.grid().as_slice().iter().map(|&u| u64::from(u)).sum();
    window.shifted_sum(sum).unwrap();
    // An area of the old window outside the new one lands; a wrong size is refused.
    assert!(
        window
            .hand_back_retired(&mut pool, small, &Grid::new(3, 3, 0u32).unwrap())
            .is_err()
    );
    // A retire that finds a unit missing is refused, and the old window is freed anyway.
    assert!(window.retire(&mut pool, 1).is_err());
    assert_eq!(window.retiring_rect(), None);
    assert_eq!(units(&pool, a), held);
    assert_eq!(window.release(&mut pool, 0).unwrap(), units(&pool, b));
    // A release while a window retires frees both, unchecked, and says so: no tile stays
    // pinned.
    window.take(&mut pool, a).unwrap().unwrap();
    window.shift(&mut pool, b).unwrap().unwrap();
    assert!(window.release(&mut pool, 0).is_err());
    assert_eq!((window.rect(), window.retiring_rect()), (None, None));
    for t in 0..(WORLD / TILE).pow(2) {
        let id = TileId::new(0, t % (WORLD / TILE), t / (WORLD / TILE));
        let state = pool.status(id).map(|s| s.state);
        assert_ne!(
            state,
            Some(terrain_cache::TileState::InUse),
            "{id:?} pinned"
        );
    }
}
