//! Building a world: level-0 tiles from a [`TileSource`] (an in-memory coarse-map, a procedural
//! generator evaluated per region, a RAW16 DEM read row by row), coarser levels by 2x2 averaging,
//! per tile in parallel (rayon), written by I/O threads of their own, with a progress callback;
//! and [`rebuild_ancestors`] to refresh coarser levels after tiles were written back.
//!
//! The pyramid is built depth first: a tile of level `l + 1` is made from its four children
//! right after they are built, so a build holds at most (rayon threads) x (levels) x 4 tiles
//! plus the encoded tiles queued or being written (at most 64 MiB' worth, a few MiB with 256^2
//! tiles), never the whole map: a 16384^2 world builds in under 20 MiB.
//!
//! Reduction: level `l + 1` texel `(i, j)` is the mean of level-`l` texels `(2i..2i+2, 2j..2j+2)`
//! rounded to nearest (`(a + b + c + d + 2) / 4`), for rendering. The bounds side file of each
//! level keeps, per tile, the min and max of the level-0 samples under it (not of the
//! averages), for LOD bounds. Tiles equal to the zero tile are not stored.

use crate::CacheError;
use crate::manifest::Manifest;
use crate::store::TileStore;
use crate::tile::{Layer, TileData, TileId};
use crate::world::{LevelBounds, World};

mod procedural;
use glam::{IVec2, UVec2};
pub use procedural::ProceduralSource;
use rayon::prelude::*;
use std::fs::File;
use std::io::{ErrorKind, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use terrain_core::{CoarseMap, Grid, Rect};

/// Produces the level-0 samples of any rect of the world, so a world can be built without
/// holding the whole map.
pub trait TileSource: Sync {
    /// What a failed region reports.
    type Error: std::error::Error + Send + Sync + 'static;
    /// Level-0 size in texels.
    fn size(&self) -> UVec2;
    /// The samples of `rect` (inside `0..size`), row-major, `rect.size` in size.
    fn region(&self, rect: Rect) -> Result<Grid<u16>, Self::Error>;
    /// The hole mask (`terrain_core::holes`) of `rect`, or `None` where it has no hole (the
    /// default: a source without holes). The builder stores it in [`Layer::Hole`] tiles.
    fn holes(&self, rect: Rect) -> Result<Option<Grid<u8>>, Self::Error> {
        let _ = rect;
        Ok(None)
    }
}

/// A source over a coarse-map in memory (the demo's procedural default, or a DEM already read),
/// and its holes, if any (a DEM's nodata: `terrain_core::dem::Dem::holes`).
#[derive(Debug, Clone, Copy)]
pub struct MapSource<'a> {
    /// The map.
    pub map: &'a CoarseMap,
    /// Its hole mask, of the map's size.
    pub holes: Option<&'a Grid<u8>>,
}

impl<'a> MapSource<'a> {
    /// A source over `map`, without holes.
    pub fn new(map: &'a CoarseMap) -> Self {
        Self { map, holes: None }
    }
}

impl TileSource for MapSource<'_> {
    type Error = terrain_core::CoreError;
    fn size(&self) -> UVec2 {
        self.map.size()
    }
    fn region(&self, rect: Rect) -> Result<Grid<u16>, Self::Error> {
        self.map.grid().copy_rect(rect)
    }
    fn holes(&self, rect: Rect) -> Result<Option<Grid<u8>>, Self::Error> {
        let Some(mask) = self.holes else {
            return Ok(None);
        };
        if mask.size() != self.map.size() {
            return Err(terrain_core::CoreError::SizeMismatch {
                expected: self.map.size(),
                actual: mask.size(),
            });
        }
        let region = mask.copy_rect(rect)?;
        Ok(region
            .as_slice()
            .iter()
            .any(|&v| terrain_core::is_hole(v))
            .then_some(region))
    }
}

/// A RAW16 DEM (little-endian u16, row-major, no header) read row by row: worlds larger than RAM.
#[derive(Debug, Clone)]
pub struct Raw16Source {
    path: PathBuf,
    size: UVec2,
}

impl Raw16Source {
    /// A source over `path`, which must hold exactly `size.x * size.y` samples.
    pub fn open(path: impl AsRef<Path>, size: UVec2) -> Result<Self, CacheError> {
        let path = path.as_ref().to_path_buf();
        let len = std::fs::metadata(&path)
            .map_err(|source| CacheError::Io {
                path: path.clone(),
                source,
            })?
            .len();
        let expected = 2 * u64::from(size.x) * u64::from(size.y);
        if len != expected || size.min_element() == 0 {
            return Err(CacheError::OutOfRange {
                what: "RAW16 file length (bytes)",
                value: len as f64,
                expected: "2 * width * height of the given size",
            });
        }
        Ok(Self { path, size })
    }
}

impl TileSource for Raw16Source {
    type Error = std::io::Error;
    fn size(&self) -> UVec2 {
        self.size
    }
    fn region(&self, rect: Rect) -> Result<Grid<u16>, Self::Error> {
        check_region(rect, self.size)
            .map_err(|e| std::io::Error::new(ErrorKind::InvalidInput, e))?;
        let mut f = File::open(&self.path)?;
        let w = rect.size.x as usize;
        let mut row = vec![0u8; w * 2];
        let mut data = Vec::with_capacity(w * rect.size.y as usize);
        for y in rect.min.y..rect.max().y {
            let off =
                (u64::from(y as u32) * u64::from(self.size.x) + u64::from(rect.min.x as u32)) * 2;
            f.seek(SeekFrom::Start(off))?;
            f.read_exact(&mut row)?;
            data.extend(
                row.chunks_exact(2)
                    .map(|c| u16::from_le_bytes([c[0], c[1]])),
            );
        }
        Grid::from_vec(rect.size.x, rect.size.y, data).map_err(std::io::Error::other)
    }
}

/// Most texels one region of this crate's sources may have (512 MiB of u16): a builder asks
/// for a tile at a time.
pub const MAX_SOURCE_REGION_TEXELS: u64 = 1 << 28;

/// Refuses a rect that is empty, reaches outside `0..size` or has more than
/// [`MAX_SOURCE_REGION_TEXELS`] texels, before anything is read or allocated.
fn check_region(rect: Rect, size: UVec2) -> Result<(), CacheError> {
    if rect.is_empty() || !Rect::from_size(size).contains_rect(&rect) {
        return Err(CacheError::Core(
            terrain_core::CoreError::RegionOutOfBounds {
                rect,
                map_size: size,
            },
        ));
    }
    if rect.area() > MAX_SOURCE_REGION_TEXELS {
        return Err(CacheError::OutOfRange {
            what: "source region (texels)",
            value: rect.area() as f64,
            expected: "at most 2^28",
        });
    }
    Ok(())
}

#[cold]
fn unreachable_grid() -> Grid<u16> {
    // Only reached if a caller passes an empty rect; a 1x1 grid keeps the call panic-free.
    Grid::from_vec(1, 1, vec![0]).unwrap_or_else(|_| unreachable!("1x1 grid"))
}

/// Progress of a build, handed to the callback after each tile.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BuildProgress {
    /// Tiles finished (all levels).
    pub done: u64,
    /// Tiles in all.
    pub total: u64,
    /// Tiles that got a file.
    pub stored: u64,
    /// Tiles equal to the zero tile (no file).
    pub zero: u64,
}

/// What a build did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BuildReport {
    /// Tiles in the pyramid.
    pub tiles: u64,
    /// Tiles written as files.
    pub stored: u64,
    /// Tiles equal to the zero tile, not stored.
    pub zero: u64,
    /// Bytes of tile files written.
    pub bytes_written: u64,
    /// Wall time.
    pub elapsed: Duration,
}

/// A finished tile on its way to the store: its key and file bytes (`None`: the zero tile,
/// whose file is removed).
struct WriteJob {
    key: String,
    bytes: Option<Vec<u8>>,
}

/// What the compute threads and the I/O threads of a build share.
struct Tally<'a> {
    progress: &'a (dyn Fn(BuildProgress) -> bool + Sync),
    cancel: AtomicBool,
    done: AtomicU64,
    stored: AtomicU64,
    zero: AtomicU64,
    bytes: AtomicU64,
    total: u64,
    /// The first failed write; the build stops and returns it.
    failed: Mutex<Option<CacheError>>,
}

impl Tally<'_> {
    /// Counts a tile written (`bytes` 0: a zero tile) and reports progress.
    fn written(&self, bytes: u64) {
        if bytes > 0 {
            self.stored.fetch_add(1, Ordering::Relaxed);
            self.bytes.fetch_add(bytes, Ordering::Relaxed);
        } else {
            self.zero.fetch_add(1, Ordering::Relaxed);
        }
        let done = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        let p = BuildProgress {
            done,
            total: self.total,
            stored: self.stored.load(Ordering::Relaxed),
            zero: self.zero.load(Ordering::Relaxed),
        };
        if !(self.progress)(p) {
            self.cancel.store(true, Ordering::Relaxed);
        }
    }

    fn fail(&self, e: CacheError) {
        self.cancel.store(true, Ordering::Relaxed);
        if let Ok(mut slot) = self.failed.lock() {
            slot.get_or_insert(e);
        }
    }
}

/// Writes the jobs until the builder closes the queue; after a failure or a cancel it only
/// drains (so no compute thread waits on a full queue forever).
fn write_loop(
    store: &dyn TileStore,
    tally: &Tally<'_>,
    jobs: crossbeam_channel::Receiver<WriteJob>,
) {
    for job in jobs {
        if tally.cancel.load(Ordering::Relaxed) {
            continue;
        }
        let written = match &job.bytes {
            Some(b) => store.write(&job.key, b).map(|()| b.len() as u64),
            None => store.remove(&job.key).map(|()| 0),
        };
        match written {
            Ok(n) => tally.written(n),
            Err(e) => tally.fail(e),
        }
    }
}

/// I/O threads of a build. Each write is atomic and durable (fsync of the file and its folder
/// on a local store), which waits on the disk for milliseconds while using no CPU; concurrent
/// fsyncs share the file system's journal commits, so many writers in flight turn 5.5 ms per
/// tile into about 0.5 ms (ext4, this project's machine). Bounded by memory: each holds one
/// encoded tile, as does each queue slot.
fn writer_count(tile_bytes: u64) -> usize {
    ((64 << 20) / tile_bytes.max(1)).clamp(1, 16) as usize
}

struct BuildCtx<'a, S: TileSource> {
    world: &'a World,
    source: &'a S,
    tally: &'a Tally<'a>,
    bounds: Vec<Vec<AtomicU32>>,
    writes: crossbeam_channel::Sender<WriteJob>,
}

/// A built tile: its samples and the min / max of the level-0 samples under it.
pub(crate) struct Node {
    pub(crate) grid: Grid<u16>,
    pub(crate) min: u16,
    pub(crate) max: u16,
}

/// Builds the height pyramid of `manifest` from `source` into `store` and writes the manifest
/// last (a store without a manifest is not a world, so an interrupted build is never opened).
///
/// `progress` is called after every tile from the building threads; returning `false` cancels
/// the build ([`CacheError::Cancelled`]). `source.size()` must equal `manifest.world_size`.
#[tracing::instrument(level = "info", skip_all, fields(world_size = manifest.world_size.max_element(), levels = manifest.levels))]
pub fn build_world<S: TileSource>(
    store: Arc<dyn TileStore>,
    manifest: Manifest,
    source: &S,
    progress: &(dyn Fn(BuildProgress) -> bool + Sync),
) -> Result<(World, BuildReport), CacheError> {
    let start = Instant::now();
    manifest.validate()?;
    if source.size() != manifest.world_size {
        return Err(CacheError::OutOfRange {
            what: "source size (texels, larger side)",
            value: f64::from(source.size().max_element()),
            expected: "the manifest's world_size",
        });
    }
    let world = World::unwritten(store.clone(), manifest);
    let levels = manifest.levels;
    let total: u64 = (0..levels)
        .map(|l| {
            let t = manifest.tiles_at(l);
            u64::from(t.x) * u64::from(t.y)
        })
        .sum();
    let bounds = (0..levels)
        .map(|l| {
            let t = manifest.tiles_at(l);
            (0..t.x as usize * t.y as usize)
                .map(|_| AtomicU32::new(0xFFFF_0000))
                .collect()
        })
        .collect();
    let tally = Tally {
        progress,
        cancel: AtomicBool::new(false),
        done: AtomicU64::new(0),
        stored: AtomicU64::new(0),
        zero: AtomicU64::new(0),
        bytes: AtomicU64::new(0),
        total,
        failed: Mutex::new(None),
    };
    let writers = writer_count(Layer::Height.tile_bytes(manifest.tile_size));
    let top = levels - 1;
    let tops: Vec<TileId> = manifest.tiles_of(Layer::Height, top).collect();
    // Tiles are computed on rayon's threads (one per core) and written on I/O threads of
    // their own, so the disk's latency overlaps the computing.
    let (built, bounds) = std::thread::scope(|scope| {
        let (tx, rx) = crossbeam_channel::bounded(writers);
        for _ in 0..writers {
            let rx = rx.clone();
            let (store, tally) = (store.as_ref(), &tally);
            scope.spawn(move || write_loop(store, tally, rx));
        }
        drop(rx);
        let ctx = BuildCtx {
            world: &world,
            source,
            tally: &tally,
            bounds,
            writes: tx,
        };
        let built = tops
            .par_iter()
            .try_for_each(|&id| build_node(&ctx, id).map(|_| ()));
        // Dropping the context closes the queue: the writers finish what is queued and end.
        (built, ctx.bounds)
    });
    let failed = tally.failed.lock().ok().and_then(|mut f| f.take());
    if let Some(e) = failed {
        return Err(e);
    }
    built?;
    if tally.cancel.load(Ordering::Relaxed) {
        return Err(CacheError::Cancelled {
            done: tally.done.load(Ordering::Relaxed),
            total,
        });
    }
    for level in 0..levels {
        let t = manifest.tiles_at(level);
        let min_max = bounds[level as usize]
            .iter()
            .map(|a| {
                let v = a.load(Ordering::Relaxed);
                [(v >> 16) as u16, v as u16]
            })
            .collect();
        world.write_bounds(level, &LevelBounds { tiles: t, min_max })?;
    }
    write_source_holes(&world, source)?;
    let world = World::create(store, manifest)?;
    let report = BuildReport {
        tiles: total,
        stored: tally.stored.load(Ordering::Relaxed),
        zero: tally.zero.load(Ordering::Relaxed),
        bytes_written: tally.bytes.load(Ordering::Relaxed),
        elapsed: start.elapsed(),
    };
    tracing::info!(
        tiles = report.tiles,
        stored = report.stored,
        bytes = report.bytes_written,
        elapsed_ms = report.elapsed.as_secs_f64() * 1e3,
        "world built"
    );
    Ok((world, report))
}

/// Stores the source's holes in the hole tiles that have one (before the manifest: a build cut
/// short leaves no world that opens without them).
fn write_source_holes<S: TileSource>(world: &World, source: &S) -> Result<(), CacheError> {
    let m = world.manifest();
    let ts = m.tile_size;
    for id in m.tiles_of(Layer::Hole, 0) {
        let min = UVec2::new(id.x, id.y) * ts;
        let size = (m.world_size - min).min(UVec2::splat(ts));
        let rect = Rect::new(min.as_ivec2(), size);
        let holes = source.holes(rect).map_err(|e| CacheError::Source {
            id,
            source: Box::new(e),
        })?;
        let Some(holes) = holes else {
            continue;
        };
        if holes.size() != size {
            return Err(CacheError::Source {
                id,
                source: format!(
                    "the source's hole mask of a {}x{} region is {}x{}",
                    size.x,
                    size.y,
                    holes.size().x,
                    holes.size().y
                )
                .into(),
            });
        }
        // Cells beyond the world's edge are ground.
        let mut tile = Grid::new(ts, ts, terrain_core::GROUND)?;
        tile.paste(&holes, glam::IVec2::ZERO)?;
        world.write_tile(Layer::Hole, id, &TileData::U8(tile))?;
    }
    Ok(())
}

/// Builds, stores and returns tile `id` (`None` beyond the level's tiles).
fn build_node<S: TileSource>(
    ctx: &BuildCtx<'_, S>,
    id: TileId,
) -> Result<Option<Node>, CacheError> {
    let m = ctx.world.manifest();
    let tiles = m.tiles_at(id.level);
    if id.x >= tiles.x || id.y >= tiles.y {
        return Ok(None);
    }
    if ctx.tally.cancel.load(Ordering::Relaxed) {
        return Err(cancelled(ctx));
    }
    let node = if id.level == 0 {
        level0_tile(ctx, id)?
    } else {
        let kids = id.children().ok_or(CacheError::TileOutOfRange {
            id,
            levels: m.levels,
            tiles_x: tiles.x,
            tiles_y: tiles.y,
        })?;
        let ((a, b), (c, d)) = rayon::join(
            || rayon::join(|| build_node(ctx, kids[0]), || build_node(ctx, kids[1])),
            || rayon::join(|| build_node(ctx, kids[2]), || build_node(ctx, kids[3])),
        );
        let children = [a?, b?, c?, d?];
        reduce_children(m, id, &children)
    };
    store_node(ctx, id, &node)?;
    Ok(Some(node))
}

fn uniform_grid(size: u32, v: u16) -> Result<Grid<u16>, CacheError> {
    Ok(Grid::new(size, size, v)?)
}

fn level0_tile<S: TileSource>(ctx: &BuildCtx<'_, S>, id: TileId) -> Result<Node, CacheError> {
    let m = ctx.world.manifest();
    let ts = m.tile_size;
    let origin = UVec2::new(id.x, id.y) * ts;
    let valid = (m.world_size - origin).min(UVec2::splat(ts));
    let rect = Rect::new(origin.as_ivec2(), valid);
    let region = ctx.source.region(rect).map_err(|e| CacheError::Source {
        id,
        source: Box::new(e),
    })?;
    if region.size() != valid {
        return Err(CacheError::Source {
            id,
            source: format!(
                "the source returned {}x{} samples for a {}x{} rect",
                region.width(),
                region.height(),
                valid.x,
                valid.y
            )
            .into(),
        });
    }
    let (mut min, mut max) = (u16::MAX, 0);
    for &v in region.as_slice() {
        min = min.min(v);
        max = max.max(v);
    }
    let mut grid = Grid::new(ts, ts, 0u16)?;
    grid.paste(&region, IVec2::ZERO)?;
    pad_clamped(&mut grid, valid);
    Ok(Node { grid, min, max })
}

/// Fills samples beyond `valid` with the last valid sample of their row, then column.
fn pad_clamped(grid: &mut Grid<u16>, valid: UVec2) {
    let (w, h) = (grid.width(), grid.height());
    if valid.x < w {
        for y in 0..valid.y.min(h) {
            let row = grid.row_mut(y);
            let edge = row[valid.x as usize - 1];
            row[valid.x as usize..].fill(edge);
        }
    }
    if valid.y < h {
        let last: Vec<u16> = grid.row(valid.y - 1).to_vec();
        for y in valid.y..h {
            grid.row_mut(y).copy_from_slice(&last);
        }
    }
}

/// The rounded mean of a 2x2 block: how each level's sample comes from the four below it.
fn mean4(a: u16, b: u16, c: u16, d: u16) -> u16 {
    let s = u32::from(a) + u32::from(b) + u32::from(c) + u32::from(d);
    ((s + 2) / 4) as u16
}

/// `grid` (level-0 heights of a block aligned to `2^levels` texels, sides multiples of it)
/// reduced `levels` times by the 2x2 rounded mean the pyramid is built with: the samples that
/// block has at level `levels` of the world, bit for bit. How an overview of a coarser level
/// follows a level-0 change without reloading tiles.
///
/// Fails on `levels` above 15 or sides that are not multiples of `2^levels`.
pub fn reduce_levels(grid: &Grid<u16>, levels: u32) -> Result<Grid<u16>, CacheError> {
    let fits = |s: u32| grid.width().is_multiple_of(s) && grid.height().is_multiple_of(s);
    if !(levels <= 15 && fits(1 << levels)) {
        return Err(CacheError::Core(terrain_core::CoreError::OutOfRange {
            what: "levels a block is reduced by",
            value: f64::from(levels),
            expected: "at most 15, with the block's sides multiples of 2^levels",
        }));
    }
    let mut cur = grid.clone();
    for _ in 0..levels {
        let (w, h) = (cur.width() / 2, cur.height() / 2);
        let next = Grid::from_fn(w, h, |x, y| {
            let (r0, r1) = (cur.row(2 * y), cur.row(2 * y + 1));
            let (i, j) = (2 * x as usize, 2 * x as usize + 1);
            mean4(r0[i], r0[j], r1[i], r1[j])
        })?;
        cur = next;
    }
    Ok(cur)
}

/// The parent tile from its (up to four) children: 2x2 mean into each quadrant, then clamped
/// padding beyond the parent level's size.
pub(crate) fn reduce_children(m: &Manifest, id: TileId, children: &[Option<Node>; 4]) -> Node {
    let ts = m.tile_size;
    let half = ts / 2;
    let mut out = vec![0u16; (ts * ts) as usize];
    let (mut min, mut max) = (u16::MAX, 0u16);
    for (q, c) in children.iter().enumerate() {
        let Some(c) = c else { continue };
        min = min.min(c.min);
        max = max.max(c.max);
        let (qx, qy) = ((q as u32 % 2) * half, (q as u32 / 2) * half);
        for j in 0..half {
            let r0 = c.grid.row(2 * j);
            let r1 = c.grid.row(2 * j + 1);
            let dst = &mut out[((qy + j) * ts + qx) as usize..][..half as usize];
            for (i, d) in dst.iter_mut().enumerate() {
                *d = mean4(r0[2 * i], r0[2 * i + 1], r1[2 * i], r1[2 * i + 1]);
            }
        }
    }
    // The grid has ts*ts samples by construction.
    let mut grid = Grid::from_vec(ts, ts, out).unwrap_or_else(|_| unreachable_grid());
    let origin = UVec2::new(id.x, id.y) * ts;
    let valid = (m.level_size(id.level) - origin).min(UVec2::splat(ts));
    pad_clamped(&mut grid, valid);
    Node { grid, min, max }
}

/// Records the tile's bounds and queues its file for the writers.
fn store_node<S: TileSource>(
    ctx: &BuildCtx<'_, S>,
    id: TileId,
    node: &Node,
) -> Result<(), CacheError> {
    let world = ctx.world;
    let t = world.manifest().tiles_at(id.level);
    if let Some(slot) = ctx.bounds[id.level as usize].get((id.y * t.x + id.x) as usize) {
        slot.store(
            (u32::from(node.min) << 16) | u32::from(node.max),
            Ordering::Relaxed,
        );
    }
    let (key, bytes) = world.encode_grid16(id, &node.grid)?;
    // A closed queue means every writer ended, which only a panic does; report it as a cancel.
    ctx.writes
        .send(WriteJob { key, bytes })
        .map_err(|_| cancelled(ctx))
}

fn cancelled<S: TileSource>(ctx: &BuildCtx<'_, S>) -> CacheError {
    CacheError::Cancelled {
        done: ctx.tally.done.load(Ordering::Relaxed),
        total: ctx.tally.total,
    }
}

/// Recomputes, in the store, every coarser-level ancestor of `changed` (tiles of any level)
/// from its four children, and updates the bounds side files; returns the ancestors rewritten,
/// finest first. Run it on a worker after write-back (the pool's writer does), never on the
/// frame thread.
pub fn rebuild_ancestors(world: &World, changed: &[TileId]) -> Result<Vec<TileId>, CacheError> {
    let m = *world.manifest();
    let mut rewritten = Vec::new();
    let mut level_set: Vec<TileId> = changed.to_vec();
    let mut bounds_cache: Vec<Option<LevelBounds>> = vec![None; m.levels as usize];
    // Level of the changed tiles themselves: refresh their own bounds from their data.
    for &id in changed {
        m.check_tile(Layer::Height, id)?;
        let data = world.load_tile(Layer::Height, id)?;
        let (lo, hi) = data.min_max();
        if id.level == 0 {
            set_bounds(world, &mut bounds_cache, id, [lo, hi])?;
        }
    }
    while !level_set.is_empty() {
        let mut parents: Vec<TileId> = level_set
            .iter()
            .filter_map(|id| id.parent())
            .filter(|p| p.level < m.levels)
            .collect();
        parents.sort();
        parents.dedup();
        for &p in &parents {
            let kids = p.children().ok_or(CacheError::TileOutOfRange {
                id: p,
                levels: m.levels,
                tiles_x: 0,
                tiles_y: 0,
            })?;
            let mut nodes: [Option<Node>; 4] = [None, None, None, None];
            let t = m.tiles_at(p.level - 1);
            let child_bounds = level_bounds(world, &mut bounds_cache, p.level - 1)?;
            for (slot, k) in nodes.iter_mut().zip(kids) {
                if k.x >= t.x || k.y >= t.y {
                    continue;
                }
                let grid = match world.load_tile(Layer::Height, k)?.as_ref() {
                    TileData::U16(g) => g.clone(),
                    TileData::U8(_) | TileData::Rgba8(_) => {
                        uniform_grid(m.tile_size, m.height_fill)?
                    }
                };
                let [min, max] = child_bounds.get(k.x, k.y).unwrap_or([u16::MAX, 0]);
                *slot = Some(Node { grid, min, max });
            }
            let node = reduce_children(&m, p, &nodes);
            let (min, max) = (node.min, node.max);
            world.write_tile(Layer::Height, p, &TileData::U16(node.grid))?;
            set_bounds(world, &mut bounds_cache, p, [min, max])?;
            rewritten.push(p);
        }
        level_set = parents;
    }
    for (level, b) in bounds_cache.iter().enumerate() {
        if let Some(b) = b {
            world.write_bounds(level as u32, b)?;
        }
    }
    Ok(rewritten)
}

/// How many times [`rebuild_ancestors`] is run again after a [`CacheError::Conflict`].
const CONFLICT_RETRIES: u32 = 8;

/// [`rebuild_ancestors`] for a store shared with other writers (a bucket with conflict
/// detection): a coarser tile or `bounds.bin` that another writer changed since this store
/// last saw it is refused with [`CacheError::Conflict`]; the key is then read again (the
/// store learns its new version) and the ancestors are recomputed from the children as they
/// are now, which include the other writer's, up to 8 times. Derived data
/// is never a conflict to report: it only has to be recomputed.
pub fn rebuild_ancestors_shared(
    world: &World,
    changed: &[TileId],
) -> Result<Vec<TileId>, CacheError> {
    let mut retries = 0;
    loop {
        match rebuild_ancestors(world, changed) {
            Err(CacheError::Conflict { key }) if retries < CONFLICT_RETRIES => {
                retries += 1;
                tracing::debug!(%key, retries, "derived tile changed by another writer");
                world.store().read(&key, u64::MAX)?;
            }
            done => return done,
        }
    }
}

fn level_bounds<'a>(
    world: &World,
    cache: &'a mut [Option<LevelBounds>],
    level: u32,
) -> Result<&'a LevelBounds, CacheError> {
    let slot = &mut cache[level as usize];
    if slot.is_none() {
        let b = match world.bounds(level) {
            Ok(Some(b)) => b,
            // Missing or unreadable: start from empty bounds, rebuilt as tiles are refreshed.
            _ => LevelBounds::empty(world.manifest().tiles_at(level)),
        };
        *slot = Some(b);
    }
    slot.as_ref().ok_or(CacheError::Manifest {
        key: String::new(),
        reason: "bounds".into(),
    })
}

fn set_bounds(
    world: &World,
    cache: &mut [Option<LevelBounds>],
    id: TileId,
    v: [u16; 2],
) -> Result<(), CacheError> {
    level_bounds(world, cache, id.level)?;
    if let Some(b) = cache[id.level as usize].as_mut() {
        let i = id.y as usize * b.tiles.x as usize + id.x as usize;
        if let Some(s) = b.min_max.get_mut(i) {
            *s = v;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::object::ObjectTileStore;
    use terrain_core::{HeightEncoding, TerrainParams, WrapMode};

    fn enc() -> HeightEncoding {
        HeightEncoding::spanning::<u16>(0.0, 100.0).unwrap()
    }

    /// Reference pyramid computed whole, in memory.
    fn reference_level(prev: &Grid<u16>, size: UVec2) -> Grid<u16> {
        Grid::from_fn(size.x, size.y, |i, j| {
            let at = |x: u32, y: u32| {
                u32::from(
                    prev.get(x.min(prev.width() - 1), y.min(prev.height() - 1))
                        .unwrap(),
                )
            };
            ((at(2 * i, 2 * j)
                + at(2 * i + 1, 2 * j)
                + at(2 * i, 2 * j + 1)
                + at(2 * i + 1, 2 * j + 1)
                + 2)
                / 4) as u16
        })
        .unwrap()
    }

    #[test]
    fn pyramid_matches_whole_map_reduction_and_bounds() {
        let size = UVec2::new(150, 90);
        let grid = Grid::from_fn(size.x, size.y, |x, y| {
            ((x * 37 + y * 101) % 5000 + 1) as u16
        })
        .unwrap();
        let map = CoarseMap::coarse(grid.clone(), enc(), 1.0).unwrap();
        let m = Manifest::new(size, 32, 1.0, enc(), WrapMode::Repeat).unwrap();
        let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
        let calls = AtomicU64::new(0);
        let (world, report) = build_world(store, m, &MapSource::new(&map), &|p| {
            calls.fetch_add(1, Ordering::Relaxed);
            assert!(p.done <= p.total);
            true
        })
        .unwrap();
        assert_eq!(report.tiles, calls.load(Ordering::Relaxed));
        assert_eq!(m.levels, 4);
        let mut level = grid;
        for l in 0..m.levels {
            if l > 0 {
                level = reference_level(&level, m.level_size(l));
            }
            for id in m.tiles_of(Layer::Height, l) {
                let tile = world.load_tile(Layer::Height, id).unwrap();
                let t = tile.as_u16().unwrap();
                for y in 0..32 {
                    for x in 0..32 {
                        let gx = (id.x * 32 + x).min(level.width() - 1);
                        let gy = (id.y * 32 + y).min(level.height() - 1);
                        assert_eq!(t.get(x, y), level.get(gx, gy), "{id} ({x},{y})");
                    }
                }
            }
            let b = world.bounds(l).unwrap().unwrap();
            assert!(
                b.min_max
                    .iter()
                    .all(|&[lo, hi]| lo >= 1 && hi <= 5000 && lo <= hi)
            );
        }
        let top = world.bounds(m.levels - 1).unwrap().unwrap();
        assert_eq!(top.min_max, vec![[1, 5000]]);
    }

    /// A RAW16 file is read where asked, and rects off it, empty or too large are refused
    /// before a row is allocated.
    #[test]
    fn raw16_regions_are_read_inside_the_file_only() {
        let dir = std::env::temp_dir().join(format!("raw16-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("dem.raw");
        let samples: Vec<u8> = (0u16..6 * 4)
            .flat_map(|v| (v * 300).to_le_bytes())
            .collect();
        std::fs::write(&path, samples).unwrap();
        let src = Raw16Source::open(&path, UVec2::new(6, 4)).unwrap();
        let got = src
            .region(Rect::new(IVec2::new(4, 2), UVec2::new(2, 2)))
            .unwrap();
        assert_eq!(got.as_slice(), &[16 * 300, 17 * 300, 22 * 300, 23 * 300]);
        for rect in [
            Rect::new(IVec2::new(5, 0), UVec2::new(2, 1)),
            Rect::new(IVec2::new(0, -1), UVec2::new(1, 1)),
            Rect::new(IVec2::ZERO, UVec2::ZERO),
            Rect::new(IVec2::ZERO, UVec2::splat(u32::MAX)),
        ] {
            let e = src.region(rect).unwrap_err();
            assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput, "{rect:?}: {e}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_sources_holes_go_into_the_hole_tiles_that_have_one() {
        // 100 x 70 texels in 32-texel tiles (4 x 3, the last ones partial), holes in two tiles.
        let size = UVec2::new(100, 70);
        let map = CoarseMap::coarse(Grid::new(size.x, size.y, 7u16).unwrap(), enc(), 1.0).unwrap();
        let mask = Grid::from_fn(size.x, size.y, |x, y| {
            u8::from((x, y) == (3, 4) || (x == 99 && y >= 64)) * 255
        })
        .unwrap();
        let m = Manifest::new(size, 32, 1.0, enc(), WrapMode::Clamp).unwrap();
        let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
        let source = MapSource {
            map: &map,
            holes: Some(&mask),
        };
        let (world, _) = build_world(store.clone(), m, &source, &|_| true).unwrap();
        assert_eq!(store.list("hole").unwrap().len(), 2);
        let all = crate::read_holes(&world, Rect::from_size(size)).unwrap();
        assert_eq!(all, mask);
        // A mask of another size is the source's error, and no world is made.
        let small = Grid::new(10, 10, 0u8).unwrap();
        let bad = MapSource {
            map: &map,
            holes: Some(&small),
        };
        let store2: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
        let e = build_world(store2.clone(), m, &bad, &|_| true).unwrap_err();
        assert!(matches!(e, CacheError::Source { .. }), "{e}");
        assert!(crate::world::read_manifest(store2.as_ref()).is_err());
    }

    #[test]
    fn zero_tiles_are_not_stored_and_cancel_works() {
        let size = UVec2::new(128, 128);
        let grid =
            Grid::from_fn(size.x, size.y, |x, y| if x < 32 && y < 32 { 9 } else { 0 }).unwrap();
        let map = CoarseMap::coarse(grid, enc(), 1.0).unwrap();
        let m = Manifest::new(size, 32, 1.0, enc(), WrapMode::Clamp).unwrap();
        let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
        let (_, r) = build_world(store.clone(), m, &MapSource::new(&map), &|_| true).unwrap();
        // Level 0: 1 of 16 stored; level 1: 1 of 4; level 2: 1 of 1.
        assert_eq!((r.tiles, r.stored, r.zero), (21, 3, 18));
        let keys = store.list("height").unwrap();
        assert_eq!(keys.iter().filter(|k| k.ends_with(".tile")).count(), 3);
        let store2: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
        let e = build_world(store2.clone(), m, &MapSource::new(&map), &|p| p.done < 5).unwrap_err();
        assert!(matches!(e, CacheError::Cancelled { .. }), "{e}");
        assert!(
            World::open(store2).is_err(),
            "no manifest after a cancelled build"
        );
    }

    #[test]
    fn procedural_source_is_region_consistent_and_rebuild_ancestors_refreshes() {
        let base = TerrainParams {
            size: UVec2::splat(32),
            ..TerrainParams::default()
        };
        let src = ProceduralSource::new(UVec2::splat(256), &base, 3, 0.05).unwrap();
        let a = src
            .region(Rect::new(IVec2::new(10, 20), UVec2::new(40, 30)))
            .unwrap();
        let b = src
            .region(Rect::new(IVec2::new(0, 0), UVec2::new(64, 64)))
            .unwrap();
        assert_eq!(a.get(0, 0), b.get(10, 20));
        assert_eq!(a.get(39, 29), b.get(49, 49));
        let m = Manifest::new(UVec2::splat(256), 64, 1.0, enc(), WrapMode::Repeat).unwrap();
        let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
        let (world, _) = build_world(store, m, &src, &|_| true).unwrap();
        // Raise one level-0 tile, refresh its ancestors, compare with a full rebuild.
        let id = TileId::new(0, 1, 2);
        let mut t = (*world.load_tile(Layer::Height, id).unwrap()).clone();
        t.as_u16_mut()
            .unwrap()
            .as_mut_slice()
            .iter_mut()
            .for_each(|v| *v = v.saturating_add(1000));
        world.write_tile(Layer::Height, id, &t).unwrap();
        let up = rebuild_ancestors(&world, &[id]).unwrap();
        assert_eq!(up, vec![TileId::new(1, 0, 1), TileId::new(2, 0, 0)]);
        // Full rebuild from the modified level 0 as a map.
        let mut full = Grid::new(256, 256, 0u16).unwrap();
        for tid in m.tiles_of(Layer::Height, 0) {
            let tile = world.load_tile(Layer::Height, tid).unwrap();
            full.paste(
                tile.as_u16().unwrap(),
                IVec2::new(tid.x as i32 * 64, tid.y as i32 * 64),
            )
            .unwrap();
        }
        let map = CoarseMap::coarse(full, enc(), 1.0).unwrap();
        let store2: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
        let (w2, _) = build_world(store2, m, &MapSource::new(&map), &|_| true).unwrap();
        for l in 0..m.levels {
            for tid in m.tiles_of(Layer::Height, l) {
                assert_eq!(
                    world.load_tile(Layer::Height, tid).unwrap(),
                    w2.load_tile(Layer::Height, tid).unwrap(),
                    "{tid}"
                );
            }
            assert_eq!(world.bounds(l).unwrap(), w2.bounds(l).unwrap(), "level {l}");
        }
    }
}
