//! Builds a procedural world tile by tile into a folder, printing a progress line, and reports
//! the time and the peak memory: a 16384^2 world builds without holding the map.
//!
//! `cargo run -p terrain-cache --release --example build_world -- [SIDE] [DIR]`
//! (default 4096 texels into the system temp folder).
//!
//! `cargo run -p terrain-cache --release --example build_world -- --convert DIR` rewrites the
//! world in DIR, of PNG tiles (format version 1), as `.tile` files in place.

use glam::UVec2;
use std::io::Write;
use std::sync::Arc;
use terrain_cache::{
    FsStore, Manifest, ProceduralSource, TileStore, World, build_world, convert_world,
};
use terrain_core::{HeightEncoding, TerrainParams, WrapMode};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1).peekable();
    if args.peek().map(String::as_str) == Some("--convert") {
        let dir = args.nth(1).ok_or("--convert needs the world's folder")?;
        let store: Arc<dyn TileStore> = Arc::new(FsStore::open(&dir)?);
        let world = World::open(store)?;
        let start = std::time::Instant::now();
        let (_, r) = convert_world(&world)?;
        println!(
            "{dir}: {} tile files converted ({:.1} MiB of PNG -> {:.1} MiB of .tile) in {:.1} s",
            r.tiles,
            r.png_bytes as f64 / 1048576.0,
            r.tile_bytes as f64 / 1048576.0,
            start.elapsed().as_secs_f64()
        );
        return Ok(());
    }
    let side: u32 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(4096);
    let dir = args
        .next()
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join(format!("terrain-cache-world-{side}")));
    let _ = std::fs::remove_dir_all(&dir);
    let store: Arc<dyn TileStore> = Arc::new(FsStore::open(&dir)?);
    let base = TerrainParams {
        size: UVec2::splat(1024),
        ..TerrainParams::default()
    };
    let source = ProceduralSource::new(UVec2::splat(side), &base, 4, 0.02)?;
    let manifest = Manifest::new(
        UVec2::splat(side),
        256,
        0.5,
        HeightEncoding::spanning::<u16>(0.0, 400.0)?,
        WrapMode::Repeat,
    )?;
    let (world, report) = build_world(store, manifest, &source, &|p| {
        if p.done % 64 == 0 || p.done == p.total {
            print!(
                "\rbuilding {side}^2: {}/{} tiles ({} stored, {} zero)",
                p.done, p.total, p.stored, p.zero
            );
            let _ = std::io::stdout().flush();
        }
        true
    })?;
    println!();
    let peak = std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM"))
                .map(str::to_owned)
        })
        .unwrap_or_else(|| "VmHWM: n/a".into());
    println!(
        "{} levels, {} tiles ({} stored, {} zero), {:.1} MiB of tile files in {:.1} s into {}; map would be {:.0} MiB; peak RSS {}",
        world.manifest().levels,
        report.tiles,
        report.stored,
        report.zero,
        report.bytes_written as f64 / 1048576.0,
        report.elapsed.as_secs_f64(),
        dir.display(),
        f64::from(side) * f64::from(side) * 2.0 / 1048576.0,
        peak.trim_start_matches("VmHWM:").trim()
    );
    Ok(())
}
