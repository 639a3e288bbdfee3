//! Must-show (a): crash safety of write-back. A child process (this test binary, re-run with
//! an environment variable) writes back tiles through a RAM pool in a loop and rewrites the
//! manifest; the parent kills it (SIGKILL) at random moments, many times. After each kill
//! every level-0 tile is one complete version, bit for bit (never a mix or a torn file),
//! versions never go back, every other file decodes, and the manifest is valid. The same for
//! the detail cache's write-back. Each kill also leaves the world's lock to the kernel: the
//! parent's next open takes it over.

mod common;

use common::{Rng, build, temp_dir};
use glam::UVec2;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};
use terrain_cache::detail::{DetailCache, detail_manifest_layout};
use terrain_cache::{
    BandSelection, CameraState, FsStore, Layer, Manifest, PoolConfig, RamPool, TileData, TileId,
    TileStore, VerifyOptions, World, manifest::parse_tile_key, verify_world,
};
use terrain_core::detail::DetailLayout;
use terrain_core::{Grid, WrapMode};

const ENV: &str = "TERRAIN_CACHE_CRASH_DIR";
const TILE: u32 = 32;

/// Version `v` of tile `id`: sample 0 holds `v`, the rest is a hash of `(id, v, i)`.
fn version(id: TileId, v: u16) -> TileData {
    let mut rng = Rng(u64::from(v) << 32 ^ u64::from(id.x) << 16 ^ u64::from(id.y));
    let mut data: Vec<u16> = (0..TILE * TILE)
        .map(|_| rng.next_u64() as u16 | 1)
        .collect();
    data[0] = v;
    TileData::U16(Grid::from_vec(TILE, TILE, data).unwrap())
}

/// The child: load every level-0 tile, then forever bump each tile's version and write it back
/// through the pool's writer thread, rewriting the manifest in between.
#[test]
fn crash_child() {
    let Ok(dir) = std::env::var(ENV) else { return };
    let store: Arc<dyn TileStore> = Arc::new(FsStore::open(&dir).unwrap());
    let mut world = World::open(store).unwrap();
    let mut cfg = PoolConfig::new(Layer::Height, 1 << 24);
    cfg.write_back_idle_frames = None;
    let mut pool = RamPool::new(world.clone(), cfg).unwrap();
    let ids: Vec<TileId> = world.manifest().tiles_of(Layer::Height, 0).collect();
    let h = pool.handle();
    for &id in &ids {
        h.request(id, 0.0);
    }
    let cam = CameraState::at(glam::Vec3::ZERO);
    while !ids.iter().all(|&id| pool.tile(id).is_some()) {
        pool.update(&cam).unwrap();
        std::thread::sleep(Duration::from_millis(1));
    }
    let mut v = ids
        .iter()
        .map(|&id| pool.tile(id).unwrap().as_u16().unwrap().as_slice()[0])
        .max()
        .unwrap();
    loop {
        v = v.wrapping_add(1).max(1);
        for &id in &ids {
            pool.write(id, version(id, v)).unwrap();
        }
        pool.flush();
        while pool.update(&cam).unwrap().dirty > 0 {
            std::thread::sleep(Duration::from_micros(200));
        }
        world.update_manifest(|m| m.height_fill = 0).unwrap();
    }
}

#[test]
fn killed_writers_leave_old_or_new_tiles_and_a_valid_manifest() {
    let dir = temp_dir("crash");
    let ids: Vec<TileId> = {
        let store: Arc<dyn TileStore> = Arc::new(FsStore::open(&dir).unwrap());
        let world = build(store, UVec2::splat(128), TILE);
        // Version 1 of every level-0 tile as the starting point.
        let ids: Vec<TileId> = world.manifest().tiles_of(Layer::Height, 0).collect();
        for &id in &ids {
            world
                .write_tile(Layer::Height, id, &version(id, 1))
                .unwrap();
        }
        // Coarser levels and bounds as a write-back leaves them: the world verifies whole.
        terrain_cache::build::rebuild_ancestors(&world, &ids).unwrap();
        ids
        // The store goes here, and with it this process's lock on the world: the child
        // writes to it, and after each kill -9 this process takes the lock over.
    };
    let mut last = vec![1u16; ids.len()];
    let mut advanced = 0;
    let (kills, temp_files, secs) = kill_rounds("crash_child", &dir, 2013, |round, world| {
        for (i, &id) in ids.iter().enumerate() {
            let tile = world.load_tile(Layer::Height, id).unwrap();
            let v = tile.as_u16().unwrap().as_slice()[0];
            assert_eq!(
                *tile,
                version(id, v),
                "round {round}: {id} is not a whole version"
            );
            assert!(
                v >= last[i],
                "round {round}: {id} went back from {} to {v}",
                last[i]
            );
            if v > last[i] {
                advanced += 1;
            }
            last[i] = v;
        }
        // The next writer recovers write-backs the kill interrupted (the journal): the world
        // then verifies whole, coarser levels and bounds included.
        drop(RamPool::new(world.clone(), PoolConfig::new(Layer::Height, 1 << 24)).unwrap());
        let verified = verify_world(
            world,
            &VerifyOptions::default(),
            &AtomicBool::new(false),
            &mut |_| {},
        )
        .unwrap();
        assert!(verified.is_valid(), "round {round}: {verified:?}");
        // Every other tile file (ancestors refreshed by the writer) decodes.
        for key in world.store().list("height").unwrap() {
            if let Some((layer, id)) = parse_tile_key(&key) {
                world.read_tile(layer, id).unwrap();
            } else if let Some(level) = key.strip_suffix("/bounds.bin") {
                let level = u32::from_str_radix(level.trim_start_matches("height/"), 16).unwrap();
                world.bounds(level).unwrap().unwrap();
            }
        }
    });
    eprintln!(
        "crash: {kills} kills in {secs:.1} s, tile versions advanced {advanced} times, {temp_files} temp files left by killed writers (removed on open)"
    );
    assert!(advanced >= kills, "the child hardly wrote: {advanced}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Runs the child test `child` on the world in `dir` and kills it (SIGKILL) at a random moment,
/// [`KILLS`] times. After each kill the world is opened again (which takes over the dead
/// child's lock and removes its temp files) and handed to `check`. Returns the kills, the temp
/// files the children left and the seconds taken.
fn kill_rounds(
    child: &str,
    dir: &std::path::Path,
    seed: u64,
    mut check: impl FnMut(u32, &World),
) -> (u32, usize, f64) {
    let exe = std::env::current_exe().unwrap();
    let mut rng = Rng(seed);
    let mut temp_files = 0;
    let start = Instant::now();
    for round in 0..KILLS {
        let mut child = Command::new(&exe)
            .args([child, "--exact", "--nocapture", "--test-threads=1"])
            .env(ENV, dir)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(Duration::from_millis(40 + rng.below(120)));
        if let Ok(Some(status)) = child.try_wait() {
            panic!("round {round}: the child exited on its own: {status}");
        }
        child.kill().unwrap();
        child.wait().unwrap();

        // Temp files of the killed writer are never listed; opening the store removes them.
        temp_files += count_temp(dir);
        let store: Arc<dyn TileStore> = Arc::new(FsStore::open(dir).unwrap());
        assert_eq!(count_temp(dir), 0);
        let world = World::open(store).expect("manifest valid after a kill");
        check(round, &world);
    }
    (KILLS, temp_files, start.elapsed().as_secs_f64())
}

/// Kills per test.
const KILLS: u32 = 24;

/// The detail world of the detail child: 64^2 coarse texels refined x2 in 4 x 4 tiles of 32.
fn detail_layout() -> DetailLayout {
    DetailLayout::new(UVec2::splat(64), 1.0, 2, 32).unwrap()
}

/// Version `v` of detail tile `t`: samples 0 and 1 hold `v` (little-endian), the rest a hash.
fn detail_version(t: UVec2, v: u16) -> Grid<u8> {
    let mut rng = Rng(u64::from(v) << 32 ^ u64::from(t.x) << 16 ^ u64::from(t.y));
    let mut data: Vec<u8> = (0..32 * 32).map(|_| rng.next_u64() as u8 | 1).collect();
    data[..2].copy_from_slice(&v.to_le_bytes());
    Grid::from_vec(32, 32, data).unwrap()
}

/// The detail child: forever writes the next version of every detail tile through a
/// [`DetailCache`] and flushes.
#[test]
fn detail_crash_child() {
    let Ok(dir) = std::env::var(ENV) else { return };
    let store: Arc<dyn TileStore> = Arc::new(FsStore::open(&dir).unwrap());
    let world = World::open(store).unwrap();
    let tiles = detail_layout().tiles();
    let first = world
        .load_tile(Layer::Detail, TileId::new(0, 0, 0))
        .unwrap();
    let mut v = u16::from_le_bytes([
        first.as_u8().unwrap().as_slice()[0],
        first.as_u8().unwrap().as_slice()[1],
    ]);
    let mut cache =
        DetailCache::open(world, detail_layout(), BandSelection::default(), 1 << 20).unwrap();
    loop {
        v += 1;
        for y in 0..tiles.y {
            for x in 0..tiles.x {
                let t = UVec2::new(x, y);
                cache.write_tile(t, detail_version(t, v)).unwrap();
            }
        }
        cache.flush().unwrap();
    }
}

#[test]
fn killed_detail_writers_leave_old_or_new_tiles() {
    let dir = temp_dir("detail-crash");
    let tiles = detail_layout().tiles();
    {
        let store: Arc<dyn TileStore> = Arc::new(FsStore::open(&dir).unwrap());
        let mut manifest = Manifest::new(
            UVec2::splat(64),
            32,
            1.0,
            common::encoding(),
            WrapMode::Repeat,
        )
        .unwrap();
        manifest.detail = Some(detail_manifest_layout(&detail_layout()).unwrap());
        let world = World::create(store, manifest).unwrap();
        for y in 0..tiles.y {
            for x in 0..tiles.x {
                let t = UVec2::new(x, y);
                let data = TileData::U8(detail_version(t, 1));
                world
                    .write_tile(Layer::Detail, TileId::new(0, x, y), &data)
                    .unwrap();
            }
        }
    }
    let mut last = vec![1u16; (tiles.x * tiles.y) as usize];
    let mut advanced = 0;
    let (kills, temp_files, secs) =
        kill_rounds("detail_crash_child", &dir, 2010, |round, world| {
            for (i, last) in last.iter_mut().enumerate() {
                let t = UVec2::new(i as u32 % tiles.x, i as u32 / tiles.x);
                let tile = world
                    .load_tile(Layer::Detail, TileId::new(0, t.x, t.y))
                    .unwrap();
                let grid = tile.as_u8().unwrap();
                let v = u16::from_le_bytes([grid.as_slice()[0], grid.as_slice()[1]]);
                assert_eq!(
                    *grid,
                    detail_version(t, v),
                    "round {round}: {t} is not a whole version"
                );
                assert!(
                    v >= *last,
                    "round {round}: {t} went back from {last} to {v}"
                );
                advanced += usize::from(v > *last);
                *last = v;
            }
        });
    eprintln!(
        "detail crash: {kills} kills in {secs:.1} s, tile versions advanced {advanced} times, {temp_files} temp files left"
    );
    assert!(
        advanced >= kills as usize,
        "the child hardly wrote: {advanced}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Temp files currently under `dir`.
fn count_temp(dir: &std::path::Path) -> usize {
    let mut n = 0;
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let e = e.unwrap();
            if e.file_type().unwrap().is_dir() {
                stack.push(e.path());
            } else if e.file_name().to_string_lossy().ends_with(".tmp") {
                n += 1;
            }
        }
    }
    n
}
