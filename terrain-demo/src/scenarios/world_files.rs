//! The flyover's streamed world on disk: opened from `--world DIR`, or built there once (from
//! the procedural default or `--heightmap`) with a progress line; and `verify-world` (with
//! `--repair`), which checks everything the manifest promises and rebuilds what level 0
//! determines.

use crate::cli::Cli;
use crate::interrupt;
use crate::scenarios::heightmap::{HeightsInfo, PlannedMap};
use crate::usage_error::{UsageExt, usage};
use anyhow::{Context, Result};
use glam::UVec2;
use std::io::IsTerminal;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;
use terrain_cache::{
    FsStore, Manifest, MapSource, ProceduralSource, RepairReport, TileFormat, TileStore,
    VerifyError, VerifyOptions, VerifyProgress, VerifyReport, World, build_world, repair_world,
    verify_world,
};
use terrain_core::{HeightEncoding, TerrainParams, WrapMode};

/// Side of the procedural world in texels by default (8.2 km at 0.5 m per texel).
pub const DEFAULT_WORLD_SIZE: u32 = 16_384;
/// Metres per texel of the procedural world.
pub const WORLD_TEXEL: f32 = 0.5;
/// Height in metres of the largest stored value of the procedural world.
pub const WORLD_MAX_HEIGHT: f32 = 200.0;
/// Tile side in texels (Fikkan 2013's 256^2 blocks).
pub const TILE_SIZE: u32 = 256;

/// The largest manifest read: a real one is a few hundred bytes.
const MANIFEST_MAX_BYTES: u64 = 1 << 20;

/// The manifest of the world in `dir` if it has one (read alone, without opening the world:
/// to plan a run's memory), `None` when there is none yet (the world will be built).
pub fn existing_manifest(dir: &Path) -> Result<Option<Manifest>> {
    let path = dir.join(terrain_cache::manifest::MANIFEST_KEY);
    let cannot = || format!("the world in {} cannot be opened", dir.display());
    let meta = match std::fs::metadata(&path) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(usage(anyhow::Error::new(e).context(cannot()))),
    };
    // Anything but a regular file (a pipe would block the read) is not a manifest.
    if !meta.is_file() || meta.len() > MANIFEST_MAX_BYTES {
        return Err(usage(anyhow::anyhow!(
            "{}: {} is not a manifest file",
            cannot(),
            path.display()
        )));
    }
    let text = std::fs::read_to_string(&path)
        .with_context(cannot)
        .usage()?;
    let manifest = Manifest::from_json(&text).with_context(cannot).usage()?;
    Ok(Some(manifest))
}

/// The world in `cli.world`: opened if it has a manifest, else built there. Returns the world,
/// where its heights came from, and, when it was built from `--heightmap`, what the import
/// chose (for report.json).
pub fn open_or_build(
    cli: &Cli,
    heightmap: Option<super::heightmap::PlannedMap>,
) -> Result<(World, String, Option<HeightsInfo>)> {
    let (mut world, source, heights) = open_or_build_heights(cli, heightmap)?;
    // The world scenario's footprints need a detail layer: added once, before the world is
    // shared.
    if cli.scenario == crate::cli::ScenarioKind::World && cli.detail != crate::cli::DetailArg::None
    {
        super::world_detail::ensure_layer(&mut world)?;
    }
    // `--color`: the image becomes the world's colour tiles (replacing any), tile by tile.
    let size = world.manifest().world_size;
    if let Some(colors) = super::heightmap::color_layer(cli, size).usage()? {
        let all = terrain_core::Rect::from_size(size);
        let tiles = terrain_cache::write_color(&world, all, &colors)?.len();
        if !cli.quiet {
            crate::console::note!(
                "world {}: {tiles} colour tiles written (every level)",
                cli.world.display()
            );
        }
    }
    Ok((world, source, heights))
}

/// [`open_or_build`]'s world, without `--color`.
fn open_or_build_heights(
    cli: &Cli,
    heightmap: Option<super::heightmap::PlannedMap>,
) -> Result<(World, String, Option<HeightsInfo>)> {
    // A folder that is no world and no build of ours is refused before anything (the lock
    // file included) is made in it; checked again under the lock.
    if !cli
        .world
        .join(terrain_cache::manifest::MANIFEST_KEY)
        .exists()
    {
        build_folder_state(&cli.world)?;
    }
    let store: Arc<dyn TileStore> = Arc::new(
        FsStore::open(&cli.world)
            .with_context(|| format!("cannot use world folder {}", cli.world.display()))
            .usage()?,
    );
    // A folder with a manifest is a world: opened, or its error reported; never rebuilt over
    // (it may hold deformations of earlier runs).
    if store.exists(terrain_cache::manifest::MANIFEST_KEY)? {
        // A build killed between its manifest and the marker's removal left the marker: the
        // world is whole, and the marker must not make a later loss of its manifest look like
        // a build of ours to clear.
        remove_marker(&cli.world)?;
        let world = World::open(store.clone())
            .with_context(|| format!("the world in {} cannot be opened", cli.world.display()))
            .usage()?;
        refuse_damaged(&world, &cli.world)?;
        if !cli.quiet {
            crate::console::note!(
                "world {}: {} texels, {} levels (deformations of earlier runs included)",
                cli.world.display(),
                world.manifest().world_size,
                world.manifest().levels
            );
            if world.manifest().tile_format == TileFormat::Png {
                crate::console::note!("{}", png_world_note(&cli.world));
            }
        }
        return Ok((world, format!("world {}", cli.world.display()), None));
    }
    // No manifest: built here, into an empty folder or over an unfinished build of this
    // program's (its marker is written first and removed after the manifest).
    let marker = cli.world.join(BUILD_MARKER);
    clear_for_build(&cli.world)?;
    terrain_core::io::write_atomic(&marker, b"a world is being built here\n")
        .with_context(|| format!("cannot write {}", marker.display()))?;
    let started = Instant::now();
    let last = AtomicU64::new(0);
    // On a terminal one line rewritten in place; in a log a line per 5 %; nothing with -q.
    let terminal = std::io::stderr().is_terminal();
    let progress = |p: terrain_cache::BuildProgress| {
        // An update every 5 % (tiles finish on several threads; one of them prints).
        let step = (p.total / 20).max(1);
        let bucket = p.done / step;
        if !cli.quiet && (last.fetch_max(bucket, Ordering::Relaxed) < bucket || p.done == p.total) {
            crate::console::stderr(format_args!(
                "{}building world {}: {}/{} tiles ({:.0} %, {:.0} s){}",
                if terminal { "\r" } else { "" },
                cli.world.display(),
                p.done,
                p.total,
                100.0 * p.done as f64 / p.total.max(1) as f64,
                started.elapsed().as_secs_f64(),
                if terminal { "" } else { "\n" },
            ));
        }
        // Ctrl-C cancels the build (the manifest is written last, so the next run builds the
        // world again instead of opening half of it).
        !interrupt::requested()
    };
    let (world, source, heights) = match &cli.heightmap {
        Some(_) => {
            // Read through the file the memory estimate measured (never opened again).
            let terrain = super::heightmap::load_planned(cli, heightmap)?;
            let map = terrain.map;
            let manifest = Manifest::new(
                map.size(),
                TILE_SIZE,
                map.texel_size(),
                map.encoding(),
                WrapMode::Clamp,
            )
            .usage()?;
            // A DEM's nodata goes into the world's hole tiles.
            let source = MapSource {
                map: &map,
                holes: terrain.holes.as_ref(),
            };
            let (world, _) = build_world(store, manifest, &source, &progress)?;
            (world, terrain.source, Some(terrain.heights))
        }
        None => {
            let size = cli.size.unwrap_or(DEFAULT_WORLD_SIZE);
            let base = TerrainParams {
                size: UVec2::splat(1024.min(size)),
                seed: cli.seed,
                persistence: 0.45,
                ..TerrainParams::default()
            };
            let source = ProceduralSource::new(UVec2::splat(size), &base, 3, 0.02).usage()?;
            let (world, _) = build_world(store, procedural_manifest(size)?, &source, &progress)?;
            (world, "procedural world".to_string(), None)
        }
    };
    if terminal && !cli.quiet {
        crate::console::note!();
    }
    remove_marker(&cli.world)?;
    Ok((world, source, heights))
}

/// Refuses a world a run would make worse: a `bounds.bin` missing or damaged, or a level-0
/// tile lost (terrain-cache's `check_before_use`; milliseconds, no tile decoded).
fn refuse_damaged(world: &World, dir: &Path) -> Result<()> {
    let found = terrain_cache::check_before_use(world, 5)?;
    if found.is_empty() {
        return Ok(());
    }
    let listed: Vec<String> = found.iter().map(|d| format!("  {d}")).collect();
    let advice = if found.iter().all(|d| d.repairable) {
        format!(
            "`terrain-demo verify-world --repair {}` rebuilds them from level 0",
            dir.display()
        )
    } else {
        "level-0 tiles are the world's only record of its heights: restore them from a copy \
         of the world (`verify-world` lists every defect)"
            .to_string()
    };
    Err(usage(anyhow::anyhow!(
        "the world in {} is damaged; a run would write over what is left:\n{}\n{advice}",
        dir.display(),
        listed.join("\n")
    )))
}

/// The file that marks a folder as holding an unfinished build of this program's.
const BUILD_MARKER: &str = ".terrain-build";

/// The folders a build writes into (and a run adds to); an unfinished build's are removed
/// before it starts again, so no tile of it (a hole, a stroke of paint) outlives it.
const BUILD_FOLDERS: [&str; 6] = ["height", "hole", "material", "color", "detail", "journal"];

/// Whether the manifest-less folder `dir` may be built into, reading only: `Ok(false)` where
/// it is new or empty (the lock file apart), `Ok(true)` where it holds an unfinished build of
/// this program's (its marker, or the marker's temp file from a write cut short); any other
/// content is refused, since it is not a world (a world whose manifest was lost would be
/// rebuilt over its deformations, a user's folder filled with tiles).
fn build_folder_state(dir: &Path) -> Result<bool> {
    let entries = match std::fs::read_dir(dir) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(false),
        Err(e) => {
            return Err(usage(
                anyhow::Error::new(e)
                    .context(format!("cannot read world folder {}", dir.display())),
            ));
        }
    };
    let (mut others, mut ours) = (Vec::new(), false);
    for entry in entries {
        let name = entry?.file_name().to_string_lossy().into_owned();
        if name.starts_with(BUILD_MARKER) || name.starts_with(&format!(".{BUILD_MARKER}")) {
            ours = true;
        } else if name != terrain_cache::lock::LOCK_FILE {
            others.push(name);
        }
    }
    if others.is_empty() || ours {
        return Ok(ours);
    }
    others.sort();
    let shown = others
        .iter()
        .take(3)
        .cloned()
        .collect::<Vec<_>>()
        .join(", ");
    Err(usage(anyhow::anyhow!(
        "{} holds {} entries ({shown}{}) but no world (no manifest.json): a world is built only \
         into an empty or new folder. If it was a world whose manifest was lost, its tiles \
         cannot be trusted without it; choose another folder for a new one",
        dir.display(),
        others.len(),
        if others.len() > 3 { ", ..." } else { "" },
    )))
}

/// Makes `dir` (which has no manifest, and is locked) ready for a build: an unfinished build
/// of this program's has its folders removed, so no tile of it (a hole, a stroke of paint)
/// outlives it; see [`build_folder_state`] for what is refused.
fn clear_for_build(dir: &Path) -> Result<()> {
    if !build_folder_state(dir)? {
        return Ok(());
    }
    for name in BUILD_FOLDERS {
        let path = dir.join(name);
        if std::fs::symlink_metadata(&path).is_ok_and(|m| m.is_dir()) {
            std::fs::remove_dir_all(&path).with_context(|| {
                format!("cannot clear the unfinished build's {}", path.display())
            })?;
        }
    }
    Ok(())
}

/// Removes the build marker of `dir`, if any, durably (the folder synced after).
fn remove_marker(dir: &Path) -> Result<()> {
    let marker = dir.join(BUILD_MARKER);
    match std::fs::remove_file(&marker) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => {
            return Err(
                anyhow::Error::new(e).context(format!("cannot remove {}", marker.display()))
            );
        }
    }
    std::fs::File::open(dir)
        .and_then(|d| d.sync_all())
        .with_context(|| format!("cannot sync {}", dir.display()))
}

/// What a run says about a world of PNG tiles (format version 1): it works as it is, and how
/// to make it load faster.
pub fn png_world_note(dir: &Path) -> String {
    format!(
        "note: the world in {0} has PNG tiles (format version 1): it opens and is written back \
         as PNG, but its tiles load several times slower than .tile files. To convert it in \
         place: cargo run -p terrain-cache --release --example build_world -- --convert {0}",
        dir.display()
    )
}

/// The manifest of the procedural world of `size` x `size` texels.
fn procedural_manifest(size: u32) -> Result<Manifest> {
    let encoding = HeightEncoding::spanning::<u16>(0.0, WORLD_MAX_HEIGHT)?;
    Manifest::new(
        UVec2::splat(size),
        TILE_SIZE,
        WORLD_TEXEL,
        encoding,
        WrapMode::Clamp,
    )
    .usage()
}

/// The world a flyover will stream, known before anything large is made or read: the manifest
/// in `--world`, else the one building it will write (from `--heightmap`'s size, or the
/// procedural world's). Says whether it must be built, and from a heightmap of which size.
pub fn planned_world(cli: &Cli) -> Result<PlannedWorld> {
    let planned = planned_layout(cli)?;
    // Checked before anything is built: the flyover streams tiles, so a world needs one.
    let size = planned.manifest.world_size;
    if size.max_element() < planned.manifest.tile_size {
        let from = match (&planned.build, &cli.heightmap) {
            (None, _) => format!("the world in {}", cli.world.display()),
            (Some(_), Some(path)) => format!("the heightmap {}", path.display()),
            (Some(_), None) => "--size".to_string(),
        };
        return Err(usage(anyhow::anyhow!(
            "{from} gives a world of {}x{} texels: a streamed world needs at least {} texels on \
             its longer side (one tile)",
            size.x,
            size.y,
            planned.manifest.tile_size
        )));
    }
    Ok(planned)
}

/// [`planned_world`]'s layout, unchecked.
fn planned_layout(cli: &Cli) -> Result<PlannedWorld> {
    if let Some(manifest) = existing_manifest(&cli.world)? {
        return Ok(PlannedWorld {
            manifest,
            build: None,
        });
    }
    match &cli.heightmap {
        Some(_) => {
            let planned = super::heightmap::planned(cli)?;
            // Only the layout matters here; the build validates spacing and encoding.
            let manifest = Manifest::new(
                planned.size,
                TILE_SIZE,
                WORLD_TEXEL,
                HeightEncoding::spanning::<u16>(0.0, WORLD_MAX_HEIGHT)?,
                WrapMode::Clamp,
            )
            .usage()?;
            Ok(PlannedWorld {
                manifest,
                build: Some(WorldBuild::Heightmap(planned)),
            })
        }
        None => Ok(PlannedWorld {
            manifest: procedural_manifest(cli.size.unwrap_or(DEFAULT_WORLD_SIZE))?,
            build: Some(WorldBuild::Procedural),
        }),
    }
}

/// The world a flyover will stream, and whether it is built first.
#[derive(Debug)]
pub struct PlannedWorld {
    /// Its layout.
    pub manifest: Manifest,
    /// `None` when it is on disk already.
    pub build: Option<WorldBuild>,
}

/// Where a world to build comes from.
#[derive(Debug, PartialEq, Eq)]
pub enum WorldBuild {
    /// The procedural terrain, generated tile by tile.
    Procedural,
    /// A heightmap of this size and format, read whole first.
    Heightmap(PlannedMap),
}

/// `verify-world DIR` (with `--repair`): checks everything the world's manifest promises
/// (terrain-cache's `verify_world`: every tile present or rightly the zero tile and decoding as
/// itself, coarser levels equal to the reduction of their children, each level's `bounds.bin`
/// equal to what the tiles give), lists each defect on stdout (key, what, whether repairable),
/// and with `repair` rebuilds what level 0 determines, then checks again. Returns whether the
/// world is valid (after the repair). Ctrl-C ends it with an error (`interrupt::requested`);
/// a folder without a world, and a manifest promising more tiles than a verification walks,
/// are usage errors.
pub fn verify_command(dir: &Path, repair: bool, quiet: bool) -> Result<bool> {
    if !dir.is_dir() {
        return Err(usage(anyhow::anyhow!(
            "{} is not a world folder",
            dir.display()
        )));
    }
    // The manifest alone first: anything but a regular file (a pipe would block) is refused.
    existing_manifest(dir)?;
    // Checking only reads: no lock, so a world in use by a run can be verified meanwhile (its
    // owner is named with any defect found: a write-back in progress may show as one). A
    // repair writes, so it takes the world's lock (exit 2 naming the owner while a run has it).
    let in_use = terrain_cache::lock::lock_holder(dir).filter(|_| !repair);
    let store = if repair {
        FsStore::open(dir)
    } else {
        FsStore::open_read_only(dir)
    };
    let store: Arc<dyn TileStore> = Arc::new(
        store
            .with_context(|| format!("cannot use world folder {}", dir.display()))
            .usage()?,
    );
    let world = World::open(store)
        .with_context(|| format!("no valid world in {}", dir.display()))
        .usage()?;
    let options = VerifyOptions::default();
    let walk = |repairing: bool| -> Result<Walked> {
        let what = if repairing { "repairing" } else { "verifying" };
        let cancel = AtomicBool::new(false);
        let started = Instant::now();
        let last = AtomicU64::new(0);
        let terminal = std::io::stderr().is_terminal();
        let mut progress = |p: VerifyProgress| {
            // Ctrl-C stops the walk before its next tile.
            if interrupt::requested() {
                cancel.store(true, Ordering::Relaxed);
            }
            let bucket = p.done / (p.total / 20).max(1);
            if terminal && !quiet && last.fetch_max(bucket, Ordering::Relaxed) < bucket {
                crate::console::stderr(format_args!(
                    "\r{what} {}: {}/{} tiles ({:.0} %, {:.0} s)",
                    dir.display(),
                    p.done,
                    p.total,
                    100.0 * p.done as f64 / p.total.max(1) as f64,
                    started.elapsed().as_secs_f64(),
                ));
            }
        };
        let done = if repairing {
            repair_world(&world, &options, &cancel, &mut progress).map(Walked::Repaired)
        } else {
            verify_world(&world, &options, &cancel, &mut progress).map(Walked::Verified)
        };
        if terminal && !quiet && last.load(Ordering::Relaxed) > 0 {
            crate::console::note!();
        }
        done.map_err(|e| match e {
            VerifyError::TooManyTiles { .. } => usage(
                anyhow::Error::new(e).context(format!("{} cannot be verified", dir.display())),
            ),
            e => anyhow::Error::new(e).context(format!("{what} {}", dir.display())),
        })
    };
    let report = match walk(repair)? {
        Walked::Verified(report) => report,
        Walked::Repaired(r) => {
            if r.found.is_valid() {
                return valid(dir, &r.found);
            }
            print_defects(&r.found)?;
            crate::console::note!(
                "world {}: {} defect(s), {} repairable: rewrote {} tile(s) and {} bounds.bin \
                 file(s); checking again",
                dir.display(),
                r.found.defects,
                r.found.defects - r.found.unrepairable,
                r.tiles_rewritten,
                r.bounds_rewritten
            );
            let after = match walk(false)? {
                Walked::Verified(after) => after,
                Walked::Repaired(again) => again.found,
            };
            if after.is_valid() {
                return valid(dir, &after);
            }
            crate::console::stdout("left after the repair:\n")?;
            after
        }
    };
    if report.is_valid() {
        return valid(dir, &report);
    }
    print_defects(&report)?;
    if let Some(owner) =
        in_use.or_else(|| terrain_cache::lock::lock_holder(dir).filter(|_| !repair))
    {
        crate::console::note!(
            "note: a run was writing this world meanwhile ({owner}): a tile or bounds.bin it \
             was writing back may show as a defect; verify again once it has ended"
        );
    }
    crate::console::note!(
        "world {}: {} defect(s), {} of them not repairable from level 0{}",
        dir.display(),
        report.defects,
        report.unrepairable,
        if repair || report.defects == report.unrepairable {
            ""
        } else {
            " (--repair rebuilds the others)"
        }
    );
    Ok(false)
}

/// What one walk over a world gave.
enum Walked {
    Verified(VerifyReport),
    Repaired(RepairReport),
}

/// Prints the listed defects on stdout, one a line, and how many more were counted.
fn print_defects(report: &VerifyReport) -> Result<()> {
    for d in &report.listed {
        crate::console::stdout(&format!("{d}\n"))?;
    }
    if report.unlisted() > 0 {
        crate::console::stdout(&format!("... and {} more defect(s)\n", report.unlisted()))?;
    }
    Ok(())
}

/// Says on stdout that the world in `dir` is valid.
fn valid(dir: &Path, report: &VerifyReport) -> Result<bool> {
    crate::console::stdout(&format!(
        "world {}: every tile, level and bounds.bin is valid ({} tiles: {} stored, {} empty)\n",
        dir.display(),
        report.tiles,
        report.stored,
        report.zero
    ))?;
    Ok(true)
}
