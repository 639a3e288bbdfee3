//! Loads COUNT random level-0 height tiles of a world from disk to RAM (store read, checks,
//! decode), twice, and reports the throughput and the time per block: Fikkan 2013, graph 6.1's
//! measure (1 000 random blocks; 279 MB/s from an SSD, 17 MB/s from a hard disk, 1.6 ms a
//! block from the SSD in graph 6.2, for the texture and heights of a 256^2 block).
//!
//! `cargo run -p terrain-cache --release --example random_blocks -- DIR [COUNT] [SEED]`
//! (DIR a world, as `build_world` writes). The first pass reads from the disk only if the page
//! cache does not hold the files: drop it first (`sync; echo 3 > /proc/sys/vm/drop_caches` as
//! root on Linux), or use a world larger than memory. The second pass reads the same blocks
//! again, from the page cache.

use std::sync::Arc;
use std::time::Instant;
use terrain_cache::{FsStore, Layer, TileId, TileRead, TileStore, World};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir = args
        .next()
        .ok_or("usage: random_blocks DIR [COUNT] [SEED]")?;
    let count: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(1000);
    let seed: u64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(1);
    if count == 0 || count > 1_000_000 {
        return Err("COUNT must be 1 to 1 000 000".into());
    }
    let store: Arc<dyn TileStore> = Arc::new(FsStore::open_read_only(&dir)?);
    let world = World::open(store)?;
    let tiles = world.manifest().tiles_at(0);
    let total = u64::from(tiles.x) * u64::from(tiles.y);
    // A splitmix64 sequence: the same blocks for the same seed, on every machine.
    let mut state = seed;
    let mut next = || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    };
    let ids: Vec<TileId> = (0..count)
        .map(|_| {
            let i = next() % total;
            TileId::new(
                0,
                (i % u64::from(tiles.x)) as u32,
                (i / u64::from(tiles.x)) as u32,
            )
        })
        .collect();
    println!(
        "{dir}: {} x {} level-0 tiles of {}^2; {count} random blocks (seed {seed})",
        tiles.x,
        tiles.y,
        world.manifest().tile_size
    );
    for pass in [
        "first pass (cold if the page cache was dropped)",
        "second pass (warm)",
    ] {
        let mut ms = Vec::with_capacity(count);
        let mut bytes = 0u64;
        let start = Instant::now();
        for &id in &ids {
            let t = Instant::now();
            if let TileRead::Stored(data) = world.read_tile(Layer::Height, id)? {
                bytes += data.byte_len();
            }
            ms.push(t.elapsed().as_secs_f64() * 1e3);
        }
        let secs = start.elapsed().as_secs_f64();
        ms.sort_by(f64::total_cmp);
        let p = |q: f64| ms[((ms.len() - 1) as f64 * q).round() as usize];
        println!(
            "{pass}: {:.1} MB/s of heights, {:.3} ms a block (p50 {:.3}, p95 {:.3}, max {:.3})",
            bytes as f64 / 1e6 / secs,
            secs * 1e3 / count as f64,
            p(0.5),
            p(0.95),
            p(1.0)
        );
    }
    Ok(())
}
