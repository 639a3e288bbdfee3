//! Helpers shared by the integration tests: temp folders, small worlds, a deterministic RNG and
//! a store wrapper that counts and delays reads.
#![allow(dead_code)]

use glam::UVec2;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use terrain_cache::{CacheError, Manifest, MapSource, TileStore, World, build_world};
use terrain_core::{CoarseMap, Grid, HeightEncoding, WrapMode};

/// A fresh temp folder unique to this process and call.
pub fn temp_dir(tag: &str) -> PathBuf {
    static N: AtomicU32 = AtomicU32::new(0);
    let dir = std::env::temp_dir().join(format!(
        "terrain-cache-it-{tag}-{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// splitmix64: a tiny deterministic RNG.
#[derive(Debug, Clone)]
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n.max(1)
    }
}

pub fn encoding() -> HeightEncoding {
    HeightEncoding::spanning::<u16>(0.0, 200.0).unwrap()
}

/// A map whose every texel differs from its neighbours (no zero tiles).
pub fn test_map(size: UVec2) -> CoarseMap {
    let grid = Grid::from_fn(size.x, size.y, |x, y| {
        ((x.wrapping_mul(2654435761) ^ y.wrapping_mul(40503)) % 60000 + 1) as u16
    })
    .unwrap();
    CoarseMap::coarse(grid, encoding(), 1.0).unwrap()
}

/// Builds a world of `size` texels with `tile` tiles into `store`.
pub fn build(store: Arc<dyn TileStore>, size: UVec2, tile: u32) -> World {
    let map = test_map(size);
    let m = Manifest::new(size, tile, 1.0, encoding(), WrapMode::Repeat).unwrap();
    build_world(store, m, &MapSource::new(&map), &|_| true)
        .unwrap()
        .0
}

/// Updates `pool` with a camera over the world's middle until every level-0 tile is in RAM
/// (at most 20 s): a pool tests can read and write anywhere.
pub fn load_level0(pool: &mut terrain_cache::RamPool) {
    use std::time::Instant;
    use terrain_cache::{CameraState, TileId};
    let m = *pool.world().manifest();
    let mid = m.world_size.as_vec2() * m.texel_size * 0.5;
    let camera = CameraState::at(glam::Vec3::new(mid.x, 5.0, mid.y));
    let tiles = (m.world_size + (m.tile_size - 1)) / m.tile_size;
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        pool.update(&camera).unwrap();
        let all = (0..tiles.x * tiles.y).all(|i| {
            pool.tile(TileId::new(0, i % tiles.x, i / tiles.x))
                .is_some()
        });
        if all {
            return;
        }
        assert!(Instant::now() < deadline, "the pool never loaded level 0");
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// A store wrapper that delays reads by a pseudo-random 0..max_delay and tracks reads in flight
/// per key (the largest overlap seen for any one key) and reads in all.
#[derive(Debug)]
pub struct SlowStore {
    pub inner: Arc<dyn TileStore>,
    pub max_delay_us: u64,
    pub reads: AtomicU64,
    pub max_overlap: AtomicU32,
    in_flight: Mutex<HashMap<String, u32>>,
    seq: AtomicU64,
}

impl SlowStore {
    pub fn new(inner: Arc<dyn TileStore>, max_delay_us: u64) -> Self {
        Self {
            inner,
            max_delay_us,
            reads: AtomicU64::new(0),
            max_overlap: AtomicU32::new(0),
            in_flight: Mutex::new(HashMap::new()),
            seq: AtomicU64::new(1),
        }
    }
}

impl TileStore for SlowStore {
    fn read(&self, key: &str, max_len: u64) -> Result<Option<Vec<u8>>, CacheError> {
        self.reads.fetch_add(1, Ordering::Relaxed);
        {
            let mut m = self.in_flight.lock().unwrap();
            let c = m.entry(key.to_owned()).or_insert(0);
            *c += 1;
            self.max_overlap.fetch_max(*c, Ordering::Relaxed);
        }
        let mut rng = Rng(self.seq.fetch_add(1, Ordering::Relaxed));
        if self.max_delay_us > 0 {
            std::thread::sleep(Duration::from_micros(rng.below(self.max_delay_us)));
        }
        let r = self.inner.read(key, max_len);
        *self.in_flight.lock().unwrap().get_mut(key).unwrap() -= 1;
        r
    }
    fn write(&self, key: &str, bytes: &[u8]) -> Result<(), CacheError> {
        self.inner.write(key, bytes)
    }
    fn remove(&self, key: &str) -> Result<(), CacheError> {
        self.inner.remove(key)
    }
    fn exists(&self, key: &str) -> Result<bool, CacheError> {
        self.inner.exists(key)
    }
    fn list(&self, prefix: &str) -> Result<Vec<String>, CacheError> {
        self.inner.list(prefix)
    }
}
