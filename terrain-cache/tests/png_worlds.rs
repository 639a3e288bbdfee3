//! Worlds of format version 1 (PNG tiles, as every build before the `.tile` files wrote them)
//! still open, stream and take writes as PNG; `convert_world` rewrites one as `.tile` files
//! with the same samples.

mod common;

use common::{encoding, temp_dir, test_map};
use glam::{UVec2, Vec3};
use std::sync::Arc;
use std::time::{Duration, Instant};
use terrain_cache::manifest::DetailLayout;
use terrain_cache::{
    CameraState, FsStore, Layer, Manifest, MapSource, PoolConfig, RamPool, TileData, TileFormat,
    TileId, TileStore, World, build_world, convert_world,
};
use terrain_core::WrapMode;
use terrain_core::io::{ReadLimits, decode_png16};

/// A world as the builds before format version 2 wrote it: a version-1 manifest (no
/// `tile_format` field) and PNG16 tiles named `.png`.
fn png_world(store: Arc<dyn TileStore>, size: UVec2, tile: u32) -> World {
    let mut m = Manifest::new(size, tile, 1.0, encoding(), WrapMode::Repeat).unwrap();
    m.format_version = 1;
    m.tile_format = TileFormat::Png;
    let map = test_map(size);
    build_world(store, m, &MapSource::new(&map), &|_| true)
        .unwrap()
        .0
}

fn every_tile(world: &World) -> Vec<(TileId, Arc<TileData>)> {
    let m = world.manifest();
    (0..m.levels)
        .flat_map(|l| m.tiles_of(Layer::Height, l))
        .map(|id| (id, world.load_tile(Layer::Height, id).unwrap()))
        .collect()
}

#[test]
fn a_png_world_opens_streams_and_is_written_as_png() {
    let dir = temp_dir("png-world");
    let store: Arc<dyn TileStore> = Arc::new(FsStore::open(&dir).unwrap());
    let size = UVec2::new(200, 130);
    png_world(store.clone(), size, 32);
    // The files are what the old builds wrote: no tile_format field, PNG16 tiles.
    let json = std::fs::read_to_string(dir.join("manifest.json")).unwrap();
    assert!(json.contains("\"format_version\": 1"), "{json}");
    assert!(!json.contains("tile_format"), "{json}");
    let keys = store.list("height").unwrap();
    let tiles: Vec<&String> = keys.iter().filter(|k| !k.ends_with("bounds.bin")).collect();
    assert!(tiles.iter().all(|k| k.ends_with(".png")), "{keys:?}");
    let png = std::fs::read(dir.join(tiles[0])).unwrap();
    let grid = decode_png16(
        &png,
        &ReadLimits {
            max_side: 32,
            ..ReadLimits::default()
        },
    )
    .unwrap();
    assert_eq!(grid.size(), UVec2::splat(32));

    let mut world = World::open(store.clone()).unwrap();
    assert_eq!(world.manifest().tile_format, TileFormat::Png);
    // The same samples as a world of `.tile` files built from the same map.
    let fresh = common::build(
        Arc::new(terrain_cache::ObjectTileStore::in_memory().unwrap()),
        size,
        32,
    );
    assert_eq!(fresh.manifest().tile_format, TileFormat::Tile);
    assert_eq!(every_tile(&world), every_tile(&fresh));

    // The RAM pool streams it.
    let mut pool = RamPool::new(world.clone(), PoolConfig::new(Layer::Height, 1 << 22)).unwrap();
    let cam = CameraState::at(Vec3::new(40.0, 0.0, 40.0));
    let here = TileId::new(0, 1, 1);
    let start = Instant::now();
    while pool.tile(here).is_none() {
        pool.update(&cam).unwrap();
        assert!(
            start.elapsed() < Duration::from_secs(5),
            "tile never loaded"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
    assert_eq!(
        pool.tile(here).unwrap(),
        world.load_tile(Layer::Height, here).unwrap().as_ref()
    );
    pool.shutdown(Duration::from_secs(5)).unwrap();

    // Writes stay PNG (an older build can still open the world), detail tiles too.
    let t = TileData::filled(Layer::Height, 32, 1234).unwrap();
    world.write_tile(Layer::Height, here, &t).unwrap();
    assert!(dir.join("height/00/0001/0001.png").is_file());
    assert!(!dir.join("height/00/0001/0001.tile").exists());
    assert_eq!(*world.load_tile(Layer::Height, here).unwrap(), t);
    world
        .update_manifest(|m| {
            m.detail = Some(DetailLayout::covering(m.extent_m().as_vec2(), 16, 0.5).unwrap());
        })
        .unwrap();
    let d = TileData::filled(Layer::Detail, 16, 3).unwrap();
    world
        .write_tile(Layer::Detail, TileId::new(0, 2, 1), &d)
        .unwrap();
    assert!(dir.join("detail/00/0001/0002.png").is_file());
    let reopened = World::open(store).unwrap();
    assert_eq!(reopened.manifest().format_version, 1);
    assert_eq!(
        *reopened
            .load_tile(Layer::Detail, TileId::new(0, 2, 1))
            .unwrap(),
        d
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn convert_world_rewrites_png_tiles_as_tile_files() {
    let dir = temp_dir("convert");
    let store: Arc<dyn TileStore> = Arc::new(FsStore::open(&dir).unwrap());
    let mut old = png_world(store.clone(), UVec2::new(150, 100), 32);
    old.update_manifest(|m| {
        m.detail = Some(DetailLayout::covering(m.extent_m().as_vec2(), 16, 0.5).unwrap());
    })
    .unwrap();
    let mut d = TileData::filled(Layer::Detail, 16, 100).unwrap();
    d.as_u8_mut().unwrap().as_mut_slice()[5] = 7;
    old.write_tile(Layer::Detail, TileId::new(0, 3, 2), &d)
        .unwrap();
    let before = every_tile(&old);
    let bounds: Vec<_> = (0..old.manifest().levels)
        .map(|l| old.bounds(l).unwrap())
        .collect();

    let (world, report) = convert_world(&old).unwrap();
    let stored = store.list("").unwrap();
    assert!(!stored.iter().any(|k| k.ends_with(".png")), "{stored:?}");
    assert_eq!(
        report.tiles,
        stored.iter().filter(|k| k.ends_with(".tile")).count() as u64
    );
    assert!(report.tile_bytes > 0 && report.png_bytes > 0, "{report:?}");
    for w in [&world, &World::open(store.clone()).unwrap()] {
        assert_eq!(w.manifest().tile_format, TileFormat::Tile);
        assert_eq!(w.manifest().format_version, 2);
        assert_eq!(every_tile(w), before);
        assert_eq!(
            *w.load_tile(Layer::Detail, TileId::new(0, 3, 2)).unwrap(),
            d
        );
        for (l, b) in bounds.iter().enumerate() {
            assert_eq!(&w.bounds(l as u32).unwrap(), b);
        }
    }
    // Converting a converted world changes nothing.
    let (again, report) = convert_world(&world).unwrap();
    assert_eq!(report.tiles, 0);
    assert_eq!(every_tile(&again), before);
    std::fs::remove_dir_all(&dir).unwrap();
}
