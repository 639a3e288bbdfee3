//! The flyover's streamed world on disk: opened from `--world DIR`, or built there once (from
//! the procedural default or `--heightmap`) with a progress line; and `--verify-world`, which
//! decodes every tile and checks the manifest.

use crate::cli::Cli;
use anyhow::{Context, Result, bail};
use glam::UVec2;
use std::io::Write;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;
use terrain_cache::{
    FsStore, Layer, Manifest, MapSource, ProceduralSource, TileRead, TileStore, World, build_world,
};
use terrain_core::{HeightEncoding, TerrainParams, WrapMode};

/// Side of the procedural world in texels by default (8.2 km at 0.5 m per texel).
pub const DEFAULT_WORLD_SIZE: u32 = 16_384;
/// Metres per texel of the procedural world.
pub const WORLD_TEXEL: f32 = 0.5;
/// Height in metres of the largest stored value of the procedural world.
pub const WORLD_MAX_HEIGHT: f32 = 200.0;
/// Tile side in texels (seed 004's 256^2 blocks).
pub const TILE_SIZE: u32 = 256;

/// The world in `cli.world`: opened if it has a manifest, else built there. Returns the world
/// and where its heights came from.
pub fn open_or_build(cli: &Cli) -> Result<(World, String)> {
    let store: Arc<dyn TileStore> = Arc::new(
        FsStore::open(&cli.world)
            .with_context(|| format!("cannot use world folder {}", cli.world.display()))?,
    );
    // A folder with a manifest is a world: opened, or its error reported; never rebuilt over
    // (it may hold deformations of earlier runs).
    if store.exists(terrain_cache::manifest::MANIFEST_KEY)? {
        let world = World::open(store.clone())
            .with_context(|| format!("the world in {} cannot be opened", cli.world.display()))?;
        eprintln!(
            "world {}: {} texels, {} levels (deformations of earlier runs included)",
            cli.world.display(),
            world.manifest().world_size,
            world.manifest().levels
        );
        return Ok((world, format!("world {}", cli.world.display())));
    }
    let started = Instant::now();
    let last = AtomicU64::new(0);
    let progress = |p: terrain_cache::BuildProgress| {
        // An update every 5 % (tiles finish on several threads; one of them prints).
        let step = (p.total / 20).max(1);
        let bucket = p.done / step;
        if last.fetch_max(bucket, Ordering::Relaxed) < bucket || p.done == p.total {
            eprint!(
                "\rbuilding world {}: {}/{} tiles ({:.0} %, {:.0} s)",
                cli.world.display(),
                p.done,
                p.total,
                100.0 * p.done as f64 / p.total.max(1) as f64,
                started.elapsed().as_secs_f64()
            );
            let _ = std::io::stderr().flush();
        }
        true
    };
    let (world, source) = match &cli.heightmap {
        Some(_) => {
            let (map, source) = super::heightmap::load(cli)?;
            let manifest = Manifest::new(
                map.size(),
                TILE_SIZE,
                map.texel_size(),
                map.encoding(),
                WrapMode::Clamp,
            )?;
            let (world, _) = build_world(store, manifest, &MapSource { map: &map }, &progress)?;
            (world, source)
        }
        None => {
            let size = cli.size.unwrap_or(DEFAULT_WORLD_SIZE);
            let base = TerrainParams {
                size: UVec2::splat(1024.min(size)),
                seed: cli.seed,
                persistence: 0.45,
                ..TerrainParams::default()
            };
            let source = ProceduralSource::new(UVec2::splat(size), &base, 3, 0.02)?;
            let encoding = HeightEncoding::spanning::<u16>(0.0, WORLD_MAX_HEIGHT)?;
            let manifest = Manifest::new(
                UVec2::splat(size),
                TILE_SIZE,
                WORLD_TEXEL,
                encoding,
                WrapMode::Clamp,
            )?;
            let (world, _) = build_world(store, manifest, &source, &progress)?;
            (world, "procedural world".to_string())
        }
    };
    eprintln!();
    Ok((world, source))
}

/// Decodes every tile file of the world in `dir` and checks its manifest. Returns the bad
/// tiles (key and why); an unreadable manifest is an error.
pub fn verify(dir: &Path) -> Result<Vec<String>> {
    if !dir.is_dir() {
        bail!("{} is not a world folder", dir.display());
    }
    let store: Arc<dyn TileStore> = Arc::new(FsStore::open(dir)?);
    let world =
        World::open(store).with_context(|| format!("no valid world in {}", dir.display()))?;
    let manifest = *world.manifest();
    let mut bad = Vec::new();
    for level in 0..manifest.levels {
        for id in manifest.tiles_of(Layer::Height, level) {
            match world.read_tile(Layer::Height, id) {
                Ok(TileRead::Stored(_) | TileRead::Zero) => {}
                Err(e) => bad.push(format!(
                    "{}: {e}",
                    terrain_cache::tile_key(Layer::Height, id)
                )),
            }
        }
    }
    Ok(bad)
}
