//! The VRAM pool fed by a real RAM pool (worker threads, an in-memory store) into terrain-core's
//! CPU `TileAtlas`: within the budget and the slots every frame while the camera flies, every
//! texel reads the true samples of the finest resident level, and a tile modified in RAM is
//! uploaded again.

mod common;

use common::build;
use glam::{IVec2, UVec2, Vec3};
use std::sync::Arc;
use std::time::{Duration, Instant};
use terrain_cache::{
    CameraState, Layer, ObjectTileStore, PoolConfig, RamPool, SphericalSelection, TileId,
    TileStore, VramConfig, VramPool, VramReport, VramSelection,
};
use terrain_core::{TileAtlas, TileUploadTarget};

/// Every texel of the world reads, through the atlas, the stored sample of the finest level
/// the VRAM pool holds, as the world's own tiles say.
fn assert_atlas_matches_world(pool: &VramPool, atlas: &TileAtlas, ram: &RamPool) {
    let m = *ram.world().manifest();
    let ts = m.tile_size;
    let mut tiles = std::collections::HashMap::new();
    for y in 0..m.world_size.y {
        for x in 0..m.world_size.x {
            let t = UVec2::new(x, y);
            let Some((level, _)) = atlas.resolve(t) else {
                panic!("texel {t} has no resident level");
            };
            let c = t >> level;
            let id = TileId::new(level, c.x / ts, c.y / ts);
            assert!(
                pool.slot_of(id).is_some(),
                "{id} mapped but not in the pool"
            );
            let data = tiles
                .entry(id)
                .or_insert_with(|| ram.world().load_tile(Layer::Height, id).unwrap());
            let want = data.as_u16().unwrap().get(c.x % ts, c.y % ts).unwrap();
            assert_eq!(
                atlas.stored_at(t.as_ivec2()),
                u32::from(want),
                "texel {t} ({id})"
            );
        }
    }
}

#[test]
fn streams_from_the_ram_pool_within_budget_and_slots_and_stays_exact() {
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
    let world = build(store, UVec2::splat(512), 32);
    let manifest = *world.manifest();
    let tile_ram = 32 * 32 * 2;
    // Fikkan 2013, sec. 4.3: the RAM selection is coarser and wider than the GPU's, so what the GPU
    // wants is in RAM: spherical, 4 tiles of each level against the frustum's 3.
    let spherical = SphericalSelection {
        view_distance: 1e4,
        lod0_range: 4.0 * 32.0,
        lod_ratio: 2.0,
    };
    let mut ram = RamPool::with_policy(
        world,
        PoolConfig::new(Layer::Height, 400 * tile_ram),
        Box::new(spherical),
    )
    .unwrap();
    let slots = 96;
    let mut cfg = VramConfig::new(&manifest, slots);
    cfg.upload_budget_bytes = 4 * 32 * 32 * 4;
    let mut vram = VramPool::new(cfg).unwrap();
    let mut atlas = TileAtlas::new(manifest.tile_layout(), slots).unwrap();

    // Fly across the world, turning; every frame within the budget and the slots.
    let start = Instant::now();
    let mut last = VramReport::default();
    for frame in 0..400 {
        let s = frame as f32 / 400.0;
        let camera = CameraState {
            forward: Vec3::new((s * 9.0).cos(), -0.3, (s * 9.0).sin()),
            ..CameraState::at(Vec3::new(40.0 + 420.0 * s, 60.0, 60.0 + 380.0 * s))
        };
        ram.update(&camera).unwrap();
        let before = atlas.uploaded_bytes();
        last = vram.update(&camera, &ram, &mut atlas).unwrap();
        assert!(last.upload_bytes <= last.budget_bytes, "{last:?}");
        assert_eq!(atlas.uploaded_bytes() - before, last.upload_bytes);
        assert!(last.resident <= slots as usize);
        assert_eq!(atlas.mapped(), last.resident);
        if frame % 100 == 99 {
            assert_atlas_matches_world(&vram, &atlas, &ram);
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    assert!(
        atlas.uploads() > slots as u64,
        "the flight must reuse slots: {last:?}"
    );

    // Hover until everything wanted that RAM holds is resident.
    let camera = CameraState::at(Vec3::new(300.0, 40.0, 280.0));
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        ram.update(&camera).unwrap();
        last = vram.update(&camera, &ram, &mut atlas).unwrap();
        if last.deferred == 0 && last.uploads == 0 && last.waiting_for_ram == 0 {
            break;
        }
        assert!(Instant::now() < deadline, "did not settle: {last:?}");
        std::thread::sleep(Duration::from_millis(2));
    }
    assert_eq!(last.tiles_missing, 0, "{last:?}");
    assert_atlas_matches_world(&vram, &atlas, &ram);

    // A deformation in RAM reaches the atlas on the next update.
    let here = TileId::new(0, 9, 8);
    assert!(vram.slot_of(here).is_some());
    ram.modify(here, |t| {
        *t.as_u16_mut().unwrap().get_mut(3, 4).unwrap() = 4242
    })
    .unwrap();
    ram.update(&camera).unwrap();
    let r = vram.update(&camera, &ram, &mut atlas).unwrap();
    assert_eq!(r.refreshes, 1, "{r:?}");
    assert_eq!(atlas.stored_at(IVec2::new(9 * 32 + 3, 8 * 32 + 4)), 4242);
    eprintln!("{:?} for {} uploads", start.elapsed(), atlas.uploads());
    ram.shutdown(Duration::from_secs(10)).unwrap();
}

#[test]
fn band_selection_holds_the_band_tiles_of_every_level() {
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
    let world = build(store, UVec2::splat(256), 32);
    let manifest = *world.manifest();
    let mut ram = RamPool::new(world, PoolConfig::new(Layer::Height, 100 * 32 * 32 * 2)).unwrap();
    let mut cfg = VramConfig::new(&manifest, 40);
    cfg.selection = VramSelection::Band {
        band_width: 1.0 / 3.0,
    };
    let mut vram = VramPool::new(cfg).unwrap();
    let mut atlas = TileAtlas::new(manifest.tile_layout(), 40).unwrap();
    // The centre region of tile (3, 3): all nine neighbours on level 0.
    let camera = CameraState::at(Vec3::new(112.0, 30.0, 112.0));
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        ram.update(&camera).unwrap();
        let r = vram.update(&camera, &ram, &mut atlas).unwrap();
        if r.tiles_missing == 0 {
            break;
        }
        assert!(Instant::now() < deadline, "did not settle: {r:?}");
        std::thread::sleep(Duration::from_millis(2));
    }
    for y in 2..5 {
        for x in 2..5 {
            assert!(vram.slot_of(TileId::new(0, x, y)).is_some(), "({x}, {y})");
        }
    }
    let level0 = vram.wanted().filter(|w| w.level == 0).count();
    assert_eq!(level0, 9);
    assert!(atlas.slot_count() >= vram.resident_ids().len() as u32);
    assert_atlas_matches_world(&vram, &atlas, &ram);
    ram.shutdown(Duration::from_secs(10)).unwrap();
}

#[test]
fn an_overlay_stream_holds_the_paint_of_the_tiles_the_heights_hold_and_follows_its_writes() {
    use glam::DVec2;
    use terrain_cache::{OverlayStream, write_paint};
    use terrain_core::{Grid, OverlayAtlas, Rect};
    let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
    let world = build(store, UVec2::splat(256), 32);
    let manifest = *world.manifest();
    // Paint over the whole world: green where x < 128, else red.
    let paint = Grid::from_fn(256, 256, |x, _| {
        if x < 128 {
            [0, 255, 0, 0]
        } else {
            [255, 0, 0, 0]
        }
    })
    .unwrap();
    write_paint(&world, Rect::from_size(UVec2::splat(256)), &paint).unwrap();
    // The RAM selection reaches beyond the VRAM pool's (as a streaming app sets it up).
    let policy = || {
        let grid = terrain_cache::TileGrid::from_manifest(&manifest, Layer::Height);
        let mut spherical = SphericalSelection::for_grid(&grid);
        spherical.lod0_range *= 3.0;
        spherical.view_distance *= 3.0;
        Box::new(spherical)
    };
    let mut heights = RamPool::with_policy(
        world.clone(),
        PoolConfig::new(Layer::Height, 200 * 32 * 32 * 2),
        policy(),
    )
    .unwrap();
    let cfg = VramConfig::new(&manifest, 60);
    let mut height_vram = VramPool::new(cfg.clone()).unwrap();
    let mut height_atlas = TileAtlas::new(manifest.tile_layout(), 60).unwrap();
    let mut stream = OverlayStream::new(
        world.clone(),
        Layer::Material,
        200 * 32 * 32 * 4,
        policy(),
        cfg,
    )
    .unwrap();
    let mut atlas = OverlayAtlas::new(manifest.tile_layout(), 60).unwrap();
    let camera = CameraState::at(Vec3::new(100.0, 30.0, 100.0));
    let settle = |heights: &mut RamPool,
                  height_vram: &mut VramPool,
                  height_atlas: &mut TileAtlas,
                  stream: &mut OverlayStream,
                  atlas: &mut OverlayAtlas| {
        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            heights.update(&camera).unwrap();
            let h = height_vram.update(&camera, heights, height_atlas).unwrap();
            let (_, p) = stream.update(&camera, atlas).unwrap();
            assert!(p.upload_bytes <= p.budget_bytes);
            if h.tiles_missing == 0 && p.tiles_missing == 0 && p.uploads == 0 && p.stale == 0 {
                return;
            }
            assert!(Instant::now() < deadline, "did not settle: {p:?}");
            std::thread::sleep(Duration::from_millis(2));
        }
    };
    settle(
        &mut heights,
        &mut height_vram,
        &mut height_atlas,
        &mut stream,
        &mut atlas,
    );
    // Every texel's paint comes from the level its height does, and is the world's.
    for y in (0..256).step_by(7) {
        for x in (0..256).step_by(5) {
            let t = UVec2::new(x, y);
            let level = height_atlas.resolve(t).map(|r| r.0);
            assert_eq!(atlas.resolve(t).map(|r| r.0), level, "{t}");
            if level == Some(0) && !(124..=132).contains(&x) {
                let v = atlas.sample(DVec2::new(f64::from(x), f64::from(y)), false);
                let want = if x < 128 {
                    glam::Vec4::Y
                } else {
                    glam::Vec4::X
                };
                assert_eq!(v, want, "{t}");
            }
        }
    }
    // Paint written under the stream: blue over a 16 x 16 square under the camera; once the
    // tiles are named, the atlas shows it.
    let square = Rect::new(IVec2::new(96, 96), UVec2::splat(16));
    let blue = Grid::new(16, 16, [0, 0, 255, 0]).unwrap();
    let written = write_paint(&world, square, &blue).unwrap();
    stream.reload(&written);
    settle(
        &mut heights,
        &mut height_vram,
        &mut height_atlas,
        &mut stream,
        &mut atlas,
    );
    assert_eq!(atlas.resolve(UVec2::new(104, 104)).map(|r| r.0), Some(0));
    assert_eq!(atlas.sample(DVec2::new(104.0, 104.0), false), glam::Vec4::Z);
    // Heights are no overlay; a version-1 (PNG) world has no paint.
    let none = OverlayStream::new(
        world,
        Layer::Height,
        1 << 20,
        policy(),
        VramConfig::new(&manifest, 4),
    );
    assert!(none.is_err());
    stream.shutdown(Duration::from_secs(10)).unwrap();
    heights.shutdown(Duration::from_secs(10)).unwrap();
}
