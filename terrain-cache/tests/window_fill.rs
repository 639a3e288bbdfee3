//! `WindowFill` and the pool's frame queries: a window filled before its tiles are in RAM
//! holds stand-ins, named tile by tile, which `ready` hands back once level 0 has loaded; the
//! refill is exact. `ground_m` is the tiles' bilinear height where they are loaded and `None`
//! where nothing is; `missing_near` counts the level-0 tiles around a point not in RAM, for
//! any finite or absurd input in bounded time.

mod common;

use common::build;
use glam::{IVec2, UVec2, Vec2};
use std::sync::Arc;
use terrain_cache::{Layer, ObjectTileStore, PoolConfig, RamPool, TileStore, WindowFill, World};
use terrain_core::{Grid, Rect};

const WORLD: u32 = 128;
const TILE: u32 = 32;

fn world() -> World {
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
    build(store, UVec2::splat(WORLD), TILE)
}

#[test]
fn stand_ins_are_refilled_once_level_0_loads() {
    let world = world();
    let mut pool = RamPool::new(world.clone(), PoolConfig::new(Layer::Height, 64 << 20)).unwrap();
    let mut fill = WindowFill::new(world.manifest());
    // Nothing loaded yet: a window across four tiles is all stand-ins.
    let window = Rect::new(IVec2::new(20, 20), UVec2::splat(40));
    let mut early = Grid::new(40, 40, 0u16).unwrap();
    fill.fill(&pool, window, &mut early).unwrap();
    assert_eq!(fill.stand_ins(), 4);
    assert!(fill.is_stand_in(UVec2::new(20, 20)) && fill.is_stand_in(UVec2::new(59, 59)));
    assert!(!fill.is_stand_in(UVec2::new(100, 100)));
    assert_eq!(pool.ground_m(Vec2::splat(30.0)), None);
    assert_eq!(pool.missing_near(Vec2::splat(40.0), 16.0), 4);
    assert!(
        fill.ready(&pool, Some(window)).is_empty(),
        "nothing loaded yet"
    );
    common::load_level0(&mut pool);
    // Loaded: every stand-in is handed back, whole tiles, once; the refill is exact.
    let ready = fill.ready(&pool, Some(window));
    assert_eq!(ready.len(), 4);
    assert!(fill.ready(&pool, Some(window)).is_empty());
    assert_eq!(fill.stand_ins(), 0);
    let mut exact = Grid::new(40, 40, 0u16).unwrap();
    fill.fill(&pool, window, &mut exact).unwrap();
    assert_eq!(fill.stand_ins(), 0);
    let mut truth = Grid::new(40, 40, 0u16).unwrap();
    assert_eq!(pool.read_region(window, &mut truth).unwrap(), 0);
    assert_eq!(exact, truth);
    assert_ne!(early, truth, "the stand-ins were level 0 already");
    // The ground: the stored heights, bilinear, in metres; at a texel, that texel.
    let enc = world.manifest().encoding;
    let at = truth.get(5, 7).unwrap();
    let g = pool.ground_m(Vec2::new(25.0, 27.0)).unwrap();
    assert!((g - enc.to_metres(f64::from(at))).abs() < 1e-3, "{g}");
    assert_eq!(pool.missing_near(Vec2::splat(40.0), 16.0), 0);
    // Absurd points answer at once.
    for p in [
        Vec2::splat(1e30),
        Vec2::splat(-1e30),
        Vec2::new(f32::NAN, 0.0),
    ] {
        assert_eq!(pool.missing_near(p, f32::MAX), 0);
        let _ = pool.ground_m(p);
    }
}

#[test]
fn stand_ins_outside_the_window_are_forgotten() {
    let world = world();
    let pool = RamPool::new(world.clone(), PoolConfig::new(Layer::Height, 64 << 20)).unwrap();
    let mut fill = WindowFill::new(world.manifest());
    let mut out = Grid::new(16, 16, 0u16).unwrap();
    fill.fill(&pool, Rect::new(IVec2::ZERO, UVec2::splat(16)), &mut out)
        .unwrap();
    fill.fill(
        &pool,
        Rect::new(IVec2::splat(100), UVec2::splat(16)),
        &mut out,
    )
    .unwrap();
    assert_eq!(fill.stand_ins(), 2);
    // The window moved to the far corner: the first tile's stand-in is dropped.
    let far = Rect::new(IVec2::splat(96), UVec2::splat(32));
    assert!(fill.ready(&pool, Some(far)).is_empty());
    assert_eq!(fill.stand_ins(), 1);
    fill.ready(&pool, None);
    assert_eq!(fill.stand_ins(), 0);
}

#[test]
fn a_changed_rect_reduces_to_whole_texels_of_a_coarser_level() {
    let world = world();
    let mut pool = RamPool::new(world.clone(), PoolConfig::new(Layer::Height, 64 << 20)).unwrap();
    common::load_level0(&mut pool);
    // (5, 6) 10 x 3 at level 2 grows to (4, 4)..(16, 12): 3 x 2 texels from (1, 1).
    let rect = Rect::new(IVec2::new(5, 6), UVec2::new(10, 3));
    let (at, reduced) = pool.read_reduced(rect, 2).unwrap().unwrap();
    assert_eq!(at, Rect::new(IVec2::new(1, 1), UVec2::new(3, 2)));
    let block = Rect::new(IVec2::new(4, 4), UVec2::new(12, 8));
    let mut level0 = Grid::new(12, 8, 0u16).unwrap();
    pool.read_region(block, &mut level0).unwrap();
    assert_eq!(reduced, terrain_cache::reduce_levels(&level0, 2).unwrap());
    // Off the world, or a level the world does not have.
    let off = Rect::new(IVec2::splat(-40), UVec2::splat(8));
    assert!(pool.read_reduced(off, 2).unwrap().is_none());
    let huge = Rect::new(IVec2::splat(i32::MAX - 4), UVec2::splat(u32::MAX));
    assert!(pool.read_reduced(huge, 1).unwrap().is_none());
    assert!(pool.read_reduced(rect, 40).is_err());
}

#[test]
fn the_pool_is_a_window_source() {
    use terrain_core::WindowSource;
    let world = world();
    let mut pool = RamPool::new(world.clone(), PoolConfig::new(Layer::Height, 64 << 20)).unwrap();
    let mut fill = WindowFill::new(world.manifest());
    let window = Rect::new(IVec2::new(20, 20), UVec2::splat(40));
    let mut out = Grid::new(40, 40, 0u16).unwrap();
    let mut source = fill.over(&pool);
    source.fill(window, &mut out).unwrap();
    assert!(source.is_stand_in(UVec2::new(20, 20)));
    assert!(source.improved(Some(window)).is_empty());
    common::load_level0(&mut pool);
    let mut source = fill.over(&pool);
    assert_eq!(source.improved(Some(window)).len(), 4);
    assert!(!source.is_stand_in(UVec2::new(20, 20)));
    // A rect off the world is the pool's error, not a panic.
    let off = Rect::new(IVec2::new(WORLD as i32, 0), UVec2::splat(40));
    assert!(source.fill(off, &mut out).is_err());
}
