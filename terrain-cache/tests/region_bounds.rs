//! `RegionBounds`: the min / max under any rect of a streamed world, exact where the pool
//! holds the tiles, covering (from `bounds.bin`) where it does not, current after a change.

mod common;

use common::{build, test_map};
use glam::{IVec2, UVec2, Vec3};
use std::sync::Arc;
use std::time::{Duration, Instant};
use terrain_cache::{
    CameraState, Layer, ObjectTileStore, PoolConfig, RamPool, RegionBounds, TileId, TileStore,
};
use terrain_core::{Grid, Rect};

fn exact(rect: Rect) -> [u16; 2] {
    let map = test_map(UVec2::splat(96));
    let g = map.grid().copy_rect(rect).unwrap();
    [
        *g.as_slice().iter().min().unwrap(),
        *g.as_slice().iter().max().unwrap(),
    ]
}

#[test]
fn bounds_are_exact_in_ram_covering_elsewhere_and_follow_changes() {
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
    let world = build(store, UVec2::splat(96), 32);
    let mut bounds = RegionBounds::open(&world).unwrap();
    let empty = RamPool::new(world.clone(), PoolConfig::new(Layer::Height, 64 << 20)).unwrap();
    let rects = [
        Rect::new(IVec2::new(3, 5), UVec2::new(17, 9)),
        Rect::new(IVec2::new(30, 30), UVec2::new(5, 5)),
        Rect::new(IVec2::new(60, 0), UVec2::new(36, 96)),
    ];
    for r in rects {
        let [lo, hi] = bounds.of(&empty, r).unwrap();
        let [a, b] = exact(r);
        assert!(
            lo <= a && hi >= b,
            "{r:?}: [{lo}, {hi}] does not cover [{a}, {b}]"
        );
    }
    // Off the world: nothing; partly off: clipped.
    assert_eq!(
        bounds.of(&empty, Rect::new(IVec2::splat(-20), UVec2::splat(10))),
        None
    );
    assert_eq!(
        bounds.of(&empty, Rect::new(IVec2::splat(90), UVec2::splat(50))),
        bounds.of(&empty, Rect::new(IVec2::splat(90), UVec2::splat(6)))
    );

    let mut pool = RamPool::new(world.clone(), PoolConfig::new(Layer::Height, 64 << 20)).unwrap();
    let camera = CameraState::at(Vec3::new(48.0, 5.0, 48.0));
    let deadline = Instant::now() + Duration::from_secs(20);
    while (0..9).any(|i| pool.tile(TileId::new(0, i % 3, i / 3)).is_none()) {
        assert!(Instant::now() < deadline, "the pool never loaded level 0");
        pool.update(&camera).unwrap();
        std::thread::sleep(Duration::from_millis(5));
    }
    let enc = world.manifest().encoding;
    for r in rects {
        assert_eq!(bounds.of(&pool, r), Some(exact(r)), "{r:?}");
        let [lo, hi] = exact(r).map(|v| enc.to_metres(f64::from(v)));
        assert_eq!(bounds.metres(&pool, r), (lo, hi), "{r:?} in metres");
    }
    // Nothing inside: the whole stored range, in metres.
    let off = Rect::new(IVec2::splat(-20), UVec2::splat(10));
    let whole = (enc.to_metres(0.0), enc.to_metres(f64::from(u16::MAX)));
    assert_eq!(bounds.metres(&pool, off), whole);
    // A deep hole in tile (1, 1): exact at once from RAM, and in the tile's own bounds after
    // `update` (what stands in once the tile is evicted).
    pool.write_rect(
        TileId::new(0, 1, 1),
        Rect::new(IVec2::new(4, 4), UVec2::ONE),
        &Grid::new(1, 1, 0u16).unwrap(),
    )
    .unwrap();
    let hole = Rect::new(IVec2::new(36, 36), UVec2::ONE);
    assert_eq!(bounds.of(&pool, hole), Some([0, 0]));
    assert_ne!(
        bounds.of(&empty, hole).unwrap()[0],
        0,
        "bounds.bin knows no hole yet"
    );
    bounds.update(&pool, hole);
    assert_eq!(bounds.of(&empty, hole).unwrap()[0], 0);
}
