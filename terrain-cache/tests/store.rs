//! Must-show (b): corrupt, truncated and foreign tile files are reported with typed errors and
//! treated as missing; (d): the object_store backends (`LocalFileSystem`, `InMemory`) and the
//! local file store give bit-identical tiles for the same world.

mod common;

use common::{build, temp_dir};
use glam::{UVec2, Vec3};
use std::sync::Arc;
use std::time::{Duration, Instant};
use terrain_cache::tile_file::{self, TileCodec};
use terrain_cache::{
    CacheError, CameraState, FsStore, Layer, ObjectTileStore, PoolConfig, RamPool, TileFileError,
    TileId, TileState, TileStore, World,
};
use terrain_core::Grid;
use terrain_core::io::encode_png16;

#[test]
fn corrupt_truncated_and_foreign_tiles_are_reported_and_missing() {
    let dir = temp_dir("corrupt");
    let store: Arc<dyn TileStore> = Arc::new(FsStore::open(&dir).unwrap());
    let world = build(store.clone(), UVec2::splat(128), 32);
    let key = |id| world.manifest().tile_key(Layer::Height, id);
    let good = store
        .read(&key(TileId::new(0, 0, 0)), 1 << 20)
        .unwrap()
        .unwrap();
    let cases: Vec<(TileId, Vec<u8>, &str)> = vec![
        (
            TileId::new(0, 0, 0),
            b"definitely not a tile".to_vec(),
            "garbage",
        ),
        (
            TileId::new(0, 1, 0),
            good[..good.len() / 2].to_vec(),
            "truncated",
        ),
        (TileId::new(0, 2, 0), Vec::new(), "empty"),
        (
            TileId::new(0, 3, 0),
            tile_file::encode_u8(&Grid::new(32, 32, 5u8).unwrap(), TileCodec::Raw),
            "8-bit",
        ),
        (
            TileId::new(0, 0, 1),
            tile_file::encode_u16(&Grid::new(16, 32, 5u16).unwrap(), TileCodec::Lz4),
            "wrong size",
        ),
        (
            TileId::new(0, 1, 1),
            // Constant, so LZ4 makes it shorter than the largest valid file: the header's
            // size is what is refused.
            tile_file::encode_u16(&Grid::new(64, 64, 5u16).unwrap(), TileCodec::Lz4),
            "too wide",
        ),
        (
            TileId::new(0, 2, 1),
            vec![7u8; world.max_tile_file_bytes(Layer::Height) as usize + 1],
            "huge",
        ),
        (
            TileId::new(0, 3, 1),
            {
                let mut b = good.clone();
                let n = b.len();
                b[n / 2] ^= 0x55;
                b[n / 2 + 1] ^= 0xAA;
                b
            },
            "bit flips",
        ),
        (
            TileId::new(0, 0, 2),
            encode_png16(&Grid::new(32, 32, 5u16).unwrap()).unwrap(),
            "a PNG",
        ),
    ];
    for (id, bytes, what) in &cases {
        store.write(&key(*id), bytes).unwrap();
        let err = world.read_tile(Layer::Height, *id).expect_err(what);
        match (&err, *what) {
            (CacheError::WrongTileShape { .. }, "wrong size" | "too wide") => {}
            (CacheError::TileTooLarge { .. }, "huge") => {}
            (
                CacheError::CorruptTile {
                    source: TileFileError::Checksum { .. },
                    ..
                },
                "bit flips",
            ) => {}
            (
                CacheError::CorruptTile {
                    source: TileFileError::Bits { .. },
                    ..
                },
                "8-bit",
            ) => {}
            (
                CacheError::CorruptTile {
                    source: TileFileError::Length { .. },
                    ..
                },
                "truncated",
            ) => {}
            (
                CacheError::CorruptTile {
                    id: e,
                    source: TileFileError::Magic { .. } | TileFileError::Truncated { .. },
                    ..
                },
                "garbage" | "empty" | "a PNG",
            ) => assert_eq!(e, id, "{what}"),
            (other, _) => panic!("{what}: unexpected {other:?}"),
        }
        assert!(err.to_string().contains(&id.to_string()), "{what}: {err}");
    }
    // The pool reports each once, marks it failed (missing) and falls back to the parent.
    let mut pool = RamPool::new(world.clone(), PoolConfig::new(Layer::Height, 1 << 20)).unwrap();
    let cam = CameraState::at(Vec3::new(64.0, 0.0, 32.0));
    let mut failed = std::collections::BTreeSet::new();
    let start = Instant::now();
    loop {
        let r = pool.update(&cam).unwrap();
        for (id, e) in pool.errors() {
            assert!(matches!(
                e,
                CacheError::CorruptTile { .. }
                    | CacheError::WrongTileShape { .. }
                    | CacheError::TileTooLarge { .. }
            ));
            assert!(
                failed.insert(*id),
                "{id} reported twice: {e} (frame {})",
                r.frame
            );
        }
        if r.in_flight == 0 && failed.len() == cases.len() {
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(5),
            "reported {failed:?}"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
    assert_eq!(failed.len(), cases.len(), "{failed:?}");
    for (id, _, _) in &cases {
        assert_eq!(pool.status(*id).unwrap().state, TileState::Failed);
        assert!(pool.tile(*id).is_none());
        let (fallback, _) = pool.best_available(*id).unwrap();
        assert_eq!(Some(fallback), id.parent());
    }
    // A later write makes a failed tile whole again (write-back over the bad file).
    world
        .write_tile(
            Layer::Height,
            TileId::new(0, 0, 0),
            &terrain_cache::TileData::filled(Layer::Height, 32, 9).unwrap(),
        )
        .unwrap();
    assert!(world.read_tile(Layer::Height, TileId::new(0, 0, 0)).is_ok());
    // A corrupt manifest and a corrupt bounds file are reported too.
    store.write("height/01/bounds.bin", b"junk").unwrap();
    assert!(matches!(world.bounds(1), Err(CacheError::Manifest { .. })));
    store
        .write("manifest.json", b"{\"format_version\": 1}")
        .unwrap();
    assert!(matches!(
        World::open(store.clone()),
        Err(CacheError::Manifest { .. })
    ));
    store.write("manifest.json", &vec![b' '; 1 << 20]).unwrap();
    assert!(matches!(
        World::open(store),
        Err(CacheError::TooLarge { .. })
    ));
    drop(pool);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn object_store_backends_and_files_are_bit_identical() {
    let d1 = temp_dir("fs");
    let d2 = temp_dir("os");
    let stores: Vec<(&str, Arc<dyn TileStore>)> = vec![
        ("FsStore", Arc::new(FsStore::open(&d1).unwrap())),
        (
            "object_store LocalFileSystem",
            Arc::new(ObjectTileStore::local(&d2).unwrap()),
        ),
        (
            "object_store InMemory",
            Arc::new(ObjectTileStore::in_memory().unwrap()),
        ),
    ];
    let worlds: Vec<World> = stores
        .iter()
        .map(|(_, s)| build(s.clone(), UVec2::new(200, 150), 32))
        .collect();
    let keys = stores[0].1.list("").unwrap();
    assert!(keys.len() > 10, "{keys:?}");
    for (name, s) in &stores[1..] {
        assert_eq!(s.list("").unwrap(), keys, "{name}");
    }
    for k in &keys {
        let a = stores[0].1.read(k, 1 << 24).unwrap().unwrap();
        for (name, s) in &stores[1..] {
            assert_eq!(s.read(k, 1 << 24).unwrap().unwrap(), a, "{name}: {k}");
        }
    }
    let m = *worlds[0].manifest();
    for l in 0..m.levels {
        for id in m.tiles_of(Layer::Height, l) {
            let a = worlds[0].load_tile(Layer::Height, id).unwrap();
            for w in &worlds[1..] {
                assert_eq!(w.load_tile(Layer::Height, id).unwrap(), a);
            }
        }
    }
    // The object_store local backend's files are plain files the file store reads too.
    let cross = World::open(Arc::new(FsStore::open(&d2).unwrap())).unwrap();
    assert_eq!(cross.manifest(), &m);
    std::fs::remove_dir_all(&d1).unwrap();
    std::fs::remove_dir_all(&d2).unwrap();
}

/// A tile path that is a named pipe or a directory is an error at once (opening the pipe used
/// to block the loader thread until something wrote to it), and the pool treats it as missing.
#[test]
fn special_files_in_place_of_tiles_are_errors_not_hangs() {
    let dir = temp_dir("special");
    let store: Arc<dyn TileStore> = Arc::new(FsStore::open(&dir).unwrap());
    let world = build(store.clone(), UVec2::splat(64), 32);
    let pipe_key = world
        .manifest()
        .tile_key(Layer::Height, TileId::new(0, 1, 0));
    let dir_key = world
        .manifest()
        .tile_key(Layer::Height, TileId::new(0, 0, 1));
    let pipe = dir.join(&pipe_key);
    std::fs::remove_file(&pipe).unwrap();
    let made = std::process::Command::new("mkfifo").arg(&pipe).status();
    assert!(made.is_ok_and(|s| s.success()), "mkfifo");
    let as_dir = dir.join(&dir_key);
    std::fs::remove_file(&as_dir).unwrap();
    std::fs::create_dir(&as_dir).unwrap();
    // On another thread with a deadline: the old code blocked forever on the pipe.
    let (tx, rx) = std::sync::mpsc::channel();
    let s = store.clone();
    std::thread::spawn(move || {
        let _ = tx.send((
            s.read(&pipe_key, 1 << 20).is_err(),
            s.read(&dir_key, 1 << 20).is_err(),
        ));
    });
    let (pipe_err, dir_err) = rx
        .recv_timeout(Duration::from_secs(10))
        .expect("reading a named pipe as a tile must not block");
    assert!(pipe_err && dir_err);
}
