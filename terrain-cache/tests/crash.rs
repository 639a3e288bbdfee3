//! Must-show (a): crash safety of write-back. A child process (this test binary, re-run with
//! an environment variable) writes back tiles through a RAM pool in a loop and rewrites the
//! manifest; the parent kills it (SIGKILL) at random moments, many times. After each kill
//! every level-0 tile is one complete version, bit for bit (never a mix or a torn file),
//! versions never go back, every other file decodes, and the manifest is valid.

mod common;

use common::{Rng, build, temp_dir};
use glam::UVec2;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};
use terrain_cache::{
    CameraState, FsStore, Layer, PoolConfig, RamPool, TileData, TileId, TileStore, World,
    manifest::parse_tile_key,
};

const ENV: &str = "TERRAIN_CACHE_CRASH_DIR";
const TILE: u32 = 32;

/// Version `v` of tile `id`: sample 0 holds `v`, the rest is a hash of `(id, v, i)`.
fn version(id: TileId, v: u16) -> TileData {
    let mut rng = Rng(u64::from(v) << 32 ^ u64::from(id.x) << 16 ^ u64::from(id.y));
    let mut data: Vec<u16> = (0..TILE * TILE)
        .map(|_| rng.next_u64() as u16 | 1)
        .collect();
    data[0] = v;
    TileData::U16(terrain_core::Grid::from_vec(TILE, TILE, data).unwrap())
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
    let store: Arc<dyn TileStore> = Arc::new(FsStore::open(&dir).unwrap());
    let world = build(store, UVec2::splat(128), TILE);
    // Version 1 of every level-0 tile as the starting point.
    let ids: Vec<TileId> = world.manifest().tiles_of(Layer::Height, 0).collect();
    for &id in &ids {
        world
            .write_tile(Layer::Height, id, &version(id, 1))
            .unwrap();
    }
    let exe = std::env::current_exe().unwrap();
    let mut rng = Rng(2013);
    let mut last = vec![1u16; ids.len()];
    let mut temp_files = 0;
    let mut advanced = 0;
    let start = Instant::now();
    let kills = 24;
    for round in 0..kills {
        let mut child = Command::new(&exe)
            .args(["crash_child", "--exact", "--nocapture", "--test-threads=1"])
            .env(ENV, &dir)
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
        temp_files += count_temp(&dir);
        let fs = FsStore::open(&dir).unwrap();
        assert_eq!(count_temp(&dir), 0);
        let store: Arc<dyn TileStore> = Arc::new(fs);
        let world = World::open(store.clone()).expect("manifest valid after a kill");
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
        // Every other tile file (ancestors refreshed by the writer) decodes.
        for key in store.list("height").unwrap() {
            if let Some((layer, id)) = parse_tile_key(&key) {
                world.read_tile(layer, id).unwrap();
            } else if let Some(level) = key.strip_suffix("/bounds.bin") {
                let level = u32::from_str_radix(level.trim_start_matches("height/"), 16).unwrap();
                world.bounds(level).unwrap().unwrap();
            }
        }
    }
    eprintln!(
        "crash: {kills} kills in {:.1} s, tile versions advanced {advanced} times, {temp_files} temp files left by killed writers (removed on open)",
        start.elapsed().as_secs_f64()
    );
    assert!(advanced >= kills, "the child hardly wrote: {advanced}");
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
