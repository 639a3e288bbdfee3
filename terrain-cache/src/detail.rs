//! Detail tiles as cache tiles (Flower 2010, sec. 2.4.2 and 3.2.3, fig. 2.4): a
//! [`terrain_core::detail::DetailLayer`] whose tiles live in a [`World`]'s detail layer on disk,
//! a working set on the GPU chosen by the nine band regions of the camera's tile, and dirty
//! tiles written back atomically, all the store's I/O on worker threads.
//!
//! A tile is *loaded* when it holds a GPU slot and *active* when it is drawn. The camera's
//! tile is split into nine regions by a horizontal and a vertical band across its centre
//! ([`BandSelection::band_width`]): in a band both neighbours across it are loaded but not
//! active (they are about to be needed), outside it only the neighbour on the camera's side,
//! loaded and active; the centre region loads all nine tiles and activates one
//! ([`band_tiles`]). Entering and leaving a region never unloads a tile just loaded.
//!
//! [`DetailCache::update`] turns the camera's band into a plan: tiles to upload (active ones
//! first, within a per-frame upload budget; tiles a GPU stamp needs this frame whatever the
//! budget) and tiles to release. As the RAM pool of height tiles does (Fikkan 2013, sec.
//! 5.2-5.3), it only queues the store's work and takes in what finished: loader threads read
//! and decode the band's new tiles, a writer thread writes the deformed tiles that left it
//! (Flower 2010: "when a tile gets unloaded ... immediately written to the hard-disk") through
//! [`World::write_tile`]: a temporary file, fsync, rename; a tile back at zero loses its file and
//! reads as the shared zero tile again. A band tile whose read is in flight is not loaded yet
//! ([`DetailFrame::pending`]): a tile joins the band at least a band's width of camera travel
//! before it becomes active (a third of a tile by default, 11 m in the demo), so its read has
//! frames to land. A read leaving the band before a loader takes it is
//! cancelled, and rescued if the tile comes back first. Only the working set, deformed tiles
//! and tiles being written stay in RAM, so memory follows the working set, not the world.
//!
//! Nothing is lost: RAM is the truth. A read never replaces a tile in RAM; a deformed tile
//! stays in RAM, dirty, until the write-back of its latest texels is confirmed (a tile stamped
//! while its write is in flight stays dirty and is written again; a failed write is reported
//! and retried); a tile wanted again while it is written is loaded from RAM, without I/O. A
//! tile that must hold its texels now is read on the caller's thread, its read in flight
//! forgotten (its result dropped on arrival): the `needed` tiles of an update (a GPU stamp over
//! a tile without a slot is refused, and its footprint would be lost) and the tiles a stamp or
//! [`DetailCache::write_rect`] changes. Those are the tiles around the walker, which the band
//! holds already or the caller has the loaders read ahead ([`DetailCache::update_ahead`]):
//! [`DetailFrame::read_now`] counts the exceptions.
//! [`DetailCache::flush`] writes every dirty tile and waits for the writes (the end of a run).
//! In the demo (`--detail refine`, 60 frames at 640 x 360, llvmpipe on 2 cores) this took the
//! `detail` step's p95 from 6.3 to 5.8 ms and the update's own p95 from 2-2.5 to 0.3 ms.
//!
//! The detail's normals are the partial derivatives of eq. 3.3, which the shaders take from the
//! heights as they draw: a loaded tile needs no normal map rebuilt.
//!
//! ```
//! use std::sync::Arc;
//! use glam::{UVec2, Vec2};
//! use terrain_cache::detail::{DetailCache, detail_manifest_layout};
//! use terrain_cache::{BandSelection, Manifest, ObjectTileStore, TileStore, World};
//! use terrain_core::detail::DetailLayout;
//! use terrain_core::{Blend, GaussianStamp, HeightEncoding, StampPlacement, WrapMode};
//!
//! // A 256 x 256 coarse-map at 0.5 m, its detail refined x4 in 64-texel tiles (8 m a side).
//! let layout = DetailLayout::new(UVec2::splat(256), 0.5, 4, 64)?;
//! let mut manifest = Manifest::new(UVec2::splat(256), 64, 0.5,
//!     HeightEncoding::spanning::<u16>(0.0, 50.0)?, WrapMode::Repeat)?;
//! manifest.detail = Some(detail_manifest_layout(&layout)?);
//! let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory()?);
//! let world = World::create(store.clone(), manifest)?;
//!
//! let mut cache = DetailCache::open(world, layout, BandSelection::default(), 1 << 20)?;
//! let camera = Vec2::new(20.0, 20.0); // the middle of tile (2, 2): all nine tiles loaded
//! let frame = cache.update(camera, &[])?;
//! assert_eq!(frame.pending, 9); // read on the loaders; taken in by later updates
//! let mut loaded = frame.load.len();
//! for _ in 0..10_000 {
//!     if loaded == 9 { break; }
//!     std::thread::sleep(std::time::Duration::from_millis(1));
//!     loaded += cache.update(camera, &[])?.load.len();
//! }
//! assert_eq!((loaded, cache.active_tiles().len()), (9, 1));
//!
//! // A footprint: the tile becomes dirty, and is written back when it leaves the band.
//! let p = StampPlacement::new(Vec2::new(21.0, 19.0), Vec2::new(0.6, 0.9), -0.1)?;
//! cache.apply_stamp(&mut GaussianStamp::default(), &p, Blend::Add)?;
//! assert_eq!(cache.dirty_tiles().len(), 1);
//! let frame = cache.update(Vec2::new(100.0, 100.0), &[])?;
//! assert_eq!(frame.writes, 1); // queued; the flush at the end of a run waits for it
//! cache.flush()?;
//! assert!(cache.dirty_tiles().is_empty());
//! assert!(store.read("detail/00/0002/0002.tile", 1 << 20)?.is_some());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod stream;

use crate::manifest;
use crate::policy::BandSelection;
use crate::{CacheError, Layer, TileId, World};
use glam::{DVec2, UVec2, Vec2};
use std::collections::{HashMap, HashSet};
use stream::{Streams, Texels, Written, read_now};
use terrain_core::detail::{
    DETAIL_ZERO_RAW, DetailChange, DetailLayer, DetailLayout, detail_encoding,
};
use terrain_core::{Blend, DirtyRect, Grid, HeightMap, HeightSample, Rect, Stamp, StampPlacement};

/// The manifest's detail section for a terrain-core detail layout: its tiles, texel spacing,
/// the detail encoding and the zero raw value. Fails for a tile side that is not a power of
/// two (the store's tiles are).
pub fn detail_manifest_layout(layout: &DetailLayout) -> Result<manifest::DetailLayout, CacheError> {
    let side = layout.tile_size();
    if !side.is_power_of_two() {
        return Err(CacheError::OutOfRange {
            what: "detail tile side",
            value: f64::from(side),
            expected: "a power of two",
        });
    }
    Ok(manifest::DetailLayout {
        tile_size: side,
        tiles: layout.tiles(),
        texel_size: layout.detail_texel_m(),
        encoding: detail_encoding(),
        fill: DETAIL_ZERO_RAW,
    })
}

/// Gives `world` the detail layer `layout` when it has none (its manifest rewritten
/// atomically): call it before anything else opens the world. `Ok` when the world already has
/// this layer; a world whose detail layer is another is refused, nothing changed.
pub fn ensure_detail_layer(world: &mut World, layout: &DetailLayout) -> Result<(), CacheError> {
    let wanted = detail_manifest_layout(layout)?;
    match world.manifest().detail {
        None => world.update_manifest(|m| m.detail = Some(wanted)),
        Some(d) if d == wanted => Ok(()),
        Some(d) => Err(CacheError::OutOfRange {
            what: "the world's detail layer (its tile side)",
            value: f64::from(d.tile_size),
            expected: "the layer asked for: another world, or the same tiles and spacing",
        }),
    }
}

/// A tile of the camera's band: loaded, and active or not.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BandTile {
    /// The tile.
    pub tile: UVec2,
    /// Drawn now (else loaded ahead of need).
    pub active: bool,
}

/// The tiles Flower 2010's fig. 2.4 loads for a camera at `camera_xz` (metres on the coarse-map's
/// plane, any finite value: the layer repeats), active ones first: per axis, the camera's tile
/// and, in the band, both neighbours (loaded, inactive), outside it the neighbour on the
/// camera's side (loaded, active). 4, 6 or 9 tiles; fewer on a layer of fewer tiles.
pub fn band_tiles(
    layout: &DetailLayout,
    band: &BandSelection,
    camera_xz: Vec2,
) -> Result<Vec<BandTile>, CacheError> {
    if !camera_xz.is_finite() {
        return Err(CacheError::OutOfRange {
            what: "detail camera position (m)",
            value: f64::from(if camera_xz.x.is_finite() {
                camera_xz.y
            } else {
                camera_xz.x
            }),
            expected: "finite",
        });
    }
    let tile_m = f64::from(layout.tile_size()) * f64::from(layout.detail_texel_m());
    let tiles = layout.tiles().as_dvec2();
    // The layer's period is the coarse-map's extent (its last tiles may reach past it).
    let period = layout.coarse_size().as_dvec2() * f64::from(layout.coarse_texel_m());
    let p = DVec2::new(
        f64::from(camera_xz.x).rem_euclid(period.x),
        f64::from(camera_xz.y).rem_euclid(period.y),
    ) / tile_m;
    let cell = p.floor().min(tiles - 1.0);
    let frac = p - cell;
    let axis = |f: f64| {
        let offsets = band.axis_offsets(f);
        // In a band (three offsets) only the camera's own tile is active on this axis.
        let active_all = offsets.len() < 3;
        offsets.iter().map(move |&o| (o, active_all || o == 0))
    };
    let mut out: Vec<BandTile> = Vec::with_capacity(9);
    for (dy, ay) in axis(frac.y) {
        for (dx, ax) in axis(frac.x) {
            let t = DVec2::new(
                (cell.x + f64::from(dx)).rem_euclid(tiles.x),
                (cell.y + f64::from(dy)).rem_euclid(tiles.y),
            )
            .as_uvec2();
            let active = ax && ay;
            match out.iter_mut().find(|b| b.tile == t) {
                // A layer of one or two tiles a side: the same tile through two offsets.
                Some(b) => b.active |= active,
                None => out.push(BandTile { tile: t, active }),
            }
        }
    }
    out.sort_by_key(|b| !b.active);
    Ok(out)
}

/// What one [`DetailCache::update`] decided.
#[derive(Debug, Default)]
pub struct DetailFrame {
    /// Tiles to upload to the GPU now (their texels: [`DetailCache::tile`]), active first.
    pub load: Vec<UVec2>,
    /// Tiles that left the working set: release their GPU slots.
    pub unload: Vec<UVec2>,
    /// Tiles of the band the upload budget left for a later frame.
    pub deferred: usize,
    /// Tiles of the band whose read is in flight: loaded by a later update.
    pub pending: usize,
    /// Needed tiles not in RAM, read on the caller's thread (see the [module docs](self)).
    pub read_now: usize,
    /// Write-backs of dirty tiles queued this frame.
    pub writes: usize,
    /// Write-backs confirmed this frame (the tile is clean, unless stamped since).
    pub written: usize,
    /// Bytes of u8 samples this frame uploads.
    pub upload_bytes: u64,
    /// Tiles that could not be read (a corrupt file: not loaded, tried again next update) or
    /// written back (kept dirty in RAM, tried again), with why.
    pub failed: Vec<(UVec2, CacheError)>,
}

/// Detail tiles over one coarse-map, stored in a [`World`]'s detail layer, with the working set
/// of the camera's band regions on the GPU (see the [module docs](self)). Owns two loader
/// threads and a writer thread; dropping it stops them once the write-backs queued are done
/// (call [`DetailCache::flush`] first to store every dirty tile).
#[derive(Debug)]
pub struct DetailCache {
    world: World,
    band: BandSelection,
    upload_budget_bytes: u64,
    /// The tiles in RAM: the loaded ones, and deformed ones not yet written back.
    layer: DetailLayer,
    /// Tiles whose stored texels are in `layer` (read from the world, or written since).
    read: HashSet<UVec2>,
    /// Tiles deformed since they were last written back, with their last change's generation.
    dirty: HashMap<UVec2, u64>,
    /// The last generation given to a change.
    changes: u64,
    /// The working set: loaded tiles and whether each is active.
    loaded: HashMap<UVec2, bool>,
    /// The loaders and the writer, and their jobs in flight.
    io: Streams,
}

impl DetailCache {
    /// A cache of `layout`'s tiles stored in `world` (whose manifest must describe the same
    /// detail layer: [`detail_manifest_layout`]), choosing its working set by `band` and
    /// uploading at most `upload_budget_bytes` of samples a frame (at least one tile's). Nothing
    /// is read until the first update. Fails on a mismatch, or when its threads cannot start.
    pub fn open(
        world: World,
        layout: DetailLayout,
        band: BandSelection,
        upload_budget_bytes: u64,
    ) -> Result<Self, CacheError> {
        let expected = detail_manifest_layout(&layout)?;
        match &world.manifest().detail {
            Some(d) if *d == expected => {}
            Some(_) => {
                return Err(CacheError::Manifest {
                    key: crate::manifest::MANIFEST_KEY.into(),
                    reason: "its detail layer differs from the layout given (tiles, tile side, \
                             texel size or encoding)"
                        .into(),
                });
            }
            None => {
                return Err(CacheError::NoSuchLayer {
                    layer: Layer::Detail,
                });
            }
        }
        if !(0.0..=1.0).contains(&band.band_width) || band.level != 0 {
            return Err(CacheError::OutOfRange {
                what: "detail band width (fraction of a tile)",
                value: band.band_width,
                expected: "0 to 1, on level 0",
            });
        }
        let tile_bytes = u64::from(layout.tile_size()).pow(2);
        if upload_budget_bytes < tile_bytes {
            return Err(CacheError::OutOfRange {
                what: "detail upload budget (bytes per frame)",
                value: upload_budget_bytes as f64,
                expected: "at least one tile's samples",
            });
        }
        let io = Streams::start(&world)?;
        Ok(Self {
            world,
            band,
            upload_budget_bytes,
            layer: DetailLayer::new(layout)?,
            read: HashSet::new(),
            dirty: HashMap::new(),
            changes: 0,
            loaded: HashMap::new(),
            io,
        })
    }

    /// The layout.
    pub fn layout(&self) -> &DetailLayout {
        self.layer.layout()
    }

    /// The tiles in RAM, as a layer (the shared zero tile elsewhere): what collision and the
    /// GPU read.
    pub fn layer(&self) -> &DetailLayer {
        &self.layer
    }

    /// A loaded tile's texels (`None`: the shared zero tile, or not in RAM).
    pub fn tile(&self, tile: UVec2) -> Option<&Grid<u8>> {
        self.layer.tile(tile)
    }

    /// The working set: loaded tiles, and whether each is active, in row-major order.
    pub fn loaded_tiles(&self) -> Vec<(UVec2, bool)> {
        row_major(self.loaded.keys().copied())
            .into_iter()
            .map(|t| (t, self.loaded[&t]))
            .collect()
    }

    /// The active tiles (drawn now), in row-major order.
    pub fn active_tiles(&self) -> Vec<UVec2> {
        row_major(self.loaded.iter().filter(|(_, a)| **a).map(|(&t, _)| t))
    }

    /// Tiles deformed since their last confirmed write-back, in row-major order.
    pub fn dirty_tiles(&self) -> Vec<UVec2> {
        row_major(self.dirty.keys().copied())
    }

    /// Whether a read of `tile` is in flight on the loaders.
    pub fn reading(&self, tile: UVec2) -> bool {
        self.io.reading(tile)
    }

    /// Write-backs in flight on the writer.
    pub fn writes_in_flight(&self) -> usize {
        self.io.writes_in_flight()
    }

    /// Moves the working set to the band of a camera at `camera_xz` (metres), with `needed`
    /// tiles loaded too (those a GPU stamp writes this frame: loaded whatever the budget, and
    /// read now if not in RAM, as tiles a refused stamp would lose). Takes in the reads and
    /// write-backs that finished; tiles that leave the working set are queued for write-back
    /// if dirty and dropped from RAM once clean; the band's new tiles are queued for reading
    /// (a missing file is the zero tile) and loaded, nearest-need first within the upload
    /// budget, by the update after they arrive. Never waits on the store but for `needed`
    /// tiles not in RAM. A tile that cannot be read or written is reported in
    /// [`DetailFrame::failed`] and tried again at the next update (nothing is lost: an
    /// unwritten tile stays dirty in RAM). Fails only on a non-finite camera or a needed tile
    /// off the grid, before changing anything, or when the cache's threads are gone.
    pub fn update(&mut self, camera_xz: Vec2, needed: &[UVec2]) -> Result<DetailFrame, CacheError> {
        self.update_ahead(camera_xz, needed, &[])
    }

    /// [`DetailCache::update`], with `ahead` tiles read by the loaders and kept in RAM (not
    /// loaded) while they are listed: the tiles `needed` will soon hold beyond the band (the
    /// demo's walker runs ahead of its camera), so they are in RAM, not read on the caller's
    /// thread, when they are needed. Fails as `update` does, or on an `ahead` tile off the
    /// grid.
    pub fn update_ahead(
        &mut self,
        camera_xz: Vec2,
        needed: &[UVec2],
        ahead: &[UVec2],
    ) -> Result<DetailFrame, CacheError> {
        let tiles = self.layout().tiles();
        let off = |t: &&UVec2| t.x >= tiles.x || t.y >= tiles.y;
        if let Some(t) = needed.iter().find(off).or_else(|| ahead.iter().find(off)) {
            return Err(off_grid(*t, tiles));
        }
        let band = band_tiles(self.layout(), &self.band, camera_xz)?;
        let mut wanted: HashMap<UVec2, bool> = needed.iter().map(|&t| (t, false)).collect();
        for b in &band {
            let e = wanted.entry(b.tile).or_insert(false);
            *e |= b.active;
        }
        // The tiles kept in RAM: the working set and the tiles ahead.
        let keep: HashSet<UVec2> = wanted.keys().chain(ahead).copied().collect();
        let mut frame = DetailFrame::default();
        self.take_finished(&mut frame);
        let leaving = row_major(
            self.loaded
                .keys()
                .filter(|t| !wanted.contains_key(t))
                .copied(),
        );
        for t in leaving {
            self.loaded.remove(&t);
            frame.unload.push(t);
        }
        self.io.cancel_reads(|t| keep.contains(&t));
        // Deformed tiles outside the working set (released now, stamped while away, or whose
        // write failed or was overtaken by a stamp) are queued for write-back.
        let away = row_major(
            self.dirty
                .keys()
                .filter(|t| !keep.contains(t) && !self.io.writing(**t))
                .copied(),
        );
        for t in away {
            self.queue_write(t)?;
            frame.writes += 1;
        }
        // Clean tiles outside the working set leave RAM (a dirty one once its write lands).
        let drop: Vec<UVec2> = self
            .read
            .iter()
            .filter(|t| !keep.contains(t) && !self.dirty.contains_key(t))
            .copied()
            .collect();
        for t in drop {
            self.layer.clear_tile(t);
            self.read.remove(&t);
        }
        // Needed tiles are read now; the band's are asked of the loaders.
        for &t in needed {
            if self.read.contains(&t) {
                continue;
            }
            match self.read_into_ram(t) {
                Ok(()) => frame.read_now += 1,
                Err(e) => frame.failed.push((t, e)),
            }
        }
        for t in band.iter().map(|b| b.tile).chain(ahead.iter().copied()) {
            if !self.read.contains(&t) {
                self.io.request_read(t)?;
            }
        }
        // Needed tiles first, then the band's active tiles, then the rest of the band.
        let tile_bytes = u64::from(self.layout().tile_size()).pow(2);
        let order = needed
            .iter()
            .map(|&t| (t, true))
            .chain(band.iter().map(|b| (b.tile, false)));
        for (t, must) in order {
            if self.loaded.contains_key(&t) || !self.read.contains(&t) {
                // A band tile not in RAM is being read; a needed one failed (reported above).
                frame.pending += usize::from(!must && !self.read.contains(&t));
                continue;
            }
            if !must && frame.upload_bytes + tile_bytes > self.upload_budget_bytes {
                frame.deferred += 1;
                continue;
            }
            self.loaded.insert(t, false);
            frame.load.push(t);
            frame.upload_bytes += tile_bytes;
        }
        for (t, active) in self.loaded.iter_mut() {
            *active = wanted.get(t).copied().unwrap_or(false);
        }
        if frame.read_now + frame.writes + frame.written + frame.failed.len() > 0 {
            tracing::debug!(
                loaded = frame.load.len(),
                pending = frame.pending,
                read_now = frame.read_now,
                writes = frame.writes,
                written = frame.written,
                failed = frame.failed.len(),
                "detail cache traffic"
            );
        }
        Ok(frame)
    }

    /// Takes in the reads and write-backs that finished (never waits).
    fn take_finished(&mut self, frame: &mut DetailFrame) {
        for (t, result) in self.io.finished_reads() {
            // A tile in RAM is newer than any read (reads of it are superseded, but be sure).
            if self.read.contains(&t) {
                continue;
            }
            match result.and_then(|texels| self.keep(t, texels)) {
                Ok(()) => {}
                Err(e) => frame.failed.push((t, e)),
            }
        }
        for done in self.io.finished_writes() {
            match self.confirm(done) {
                Ok(true) => frame.written += 1,
                Ok(false) => {}
                Err((t, e)) => frame.failed.push((t, e)),
            }
        }
    }

    /// A write-back that finished: the tile is clean if nothing changed it since it was queued
    /// (returns whether it is); a failed one stays dirty, to be written again.
    fn confirm(&mut self, (t, generation, result): Written) -> Result<bool, (UVec2, CacheError)> {
        result.map_err(|e| (t, e))?;
        if self.dirty.get(&t) == Some(&generation) {
            self.dirty.remove(&t);
        }
        Ok(true)
    }

    /// Queues tile `t`'s texels (the zero tile: its file removed) for write-back.
    fn queue_write(&mut self, t: UVec2) -> Result<(), CacheError> {
        let side = self.layout().tile_size();
        let texels = match self.layer.tile(t) {
            Some(g) => g.clone(),
            None => Grid::new(side, side, DETAIL_ZERO_RAW)?,
        };
        let generation = self.dirty.get(&t).copied().unwrap_or(0);
        self.io.write(t, generation, texels)
    }

    /// [`DetailCache::update_ahead`] for a frame that stamps `stamps` on the GPU: the tiles
    /// their footprints cover and `keep` (the tiles whose stamped rects are still on their way
    /// back) are needed; the tiles within `read_ahead_m` of each stamp are read ahead. Fails as
    /// `update_ahead` does, or on a stamp whose footprint cannot be placed on the layer.
    pub fn update_for_stamps(
        &mut self,
        camera_xz: Vec2,
        stamps: &[StampPlacement],
        keep: &[UVec2],
        read_ahead_m: f32,
    ) -> Result<DetailFrame, CacheError> {
        let layout = *self.layout();
        let mut needed = keep.to_vec();
        let mut ahead = Vec::new();
        for p in stamps {
            needed.extend(layout.tiles_under(p)?);
            ahead.extend(layout.tiles_within(p.center, read_ahead_m)?);
        }
        for list in [&mut needed, &mut ahead] {
            list.sort_unstable_by_key(|t| (t.y, t.x));
            list.dedup();
        }
        self.update_ahead(camera_xz, &needed, &ahead)
    }

    /// Applies a stamp to the detail layer (as [`DetailLayer::apply_stamp`]), reading the tiles
    /// it covers from the world first if they are not in RAM (on the caller's thread); they
    /// become dirty. Tiles outside the working set are written back from the next update.
    /// Fails as the layer's stamp does, or on a corrupt tile file; nothing is written then.
    pub fn apply_stamp<S: Stamp + ?Sized>(
        &mut self,
        stamp: &mut S,
        placement: &StampPlacement,
        blend: Blend,
    ) -> Result<DetailChange, CacheError> {
        self.read_footprint(placement)?;
        let change = self.layer.apply_stamp(stamp, placement, blend)?;
        self.mark_dirty(&change);
        Ok(change)
    }

    /// Applies a stamp as [`DetailCache::apply_stamp`] does, spilling what leaves the tiles'
    /// range into `coarse` (as [`DetailLayer::apply_stamp_spilling`]); returns the detail change
    /// and the coarse rects the spill changed. Fails as the layer's spilling stamp does, or on
    /// a corrupt tile file; nothing is written then.
    pub fn apply_stamp_spilling<T: HeightSample, S: Stamp + ?Sized>(
        &mut self,
        coarse: &mut HeightMap<T>,
        stamp: &mut S,
        placement: &StampPlacement,
        blend: Blend,
    ) -> Result<(DetailChange, Vec<DirtyRect>), CacheError> {
        self.read_footprint(placement)?;
        let (change, rects) = self
            .layer
            .apply_stamp_spilling(coarse, stamp, placement, blend)?;
        self.mark_dirty(&change);
        Ok((change, rects))
    }

    /// Reads every tile a stamp at `placement` covers from the world, if not in RAM yet.
    fn read_footprint(&mut self, placement: &StampPlacement) -> Result<(), CacheError> {
        for t in self.layout().tiles_under(placement)? {
            if !self.read.contains(&t) {
                self.read_into_ram(t)?;
            }
        }
        Ok(())
    }

    /// The tiles a stamp wrote become dirty (a shared zero tile it left unchanged does not).
    fn mark_dirty(&mut self, change: &DetailChange) {
        for (t, _) in &change.tiles {
            if self.layer.tile(*t).is_some() {
                self.touch(*t);
            }
        }
    }

    /// Tile `t` changed: dirty, with a new generation (a write-back in flight of older texels
    /// no longer makes it clean).
    fn touch(&mut self, t: UVec2) {
        self.changes += 1;
        self.dirty.insert(t, self.changes);
    }

    /// Replaces a tile's texels (one read back from the GPU after a stamp there): it becomes
    /// dirty, and a read of it in flight is forgotten. Fails on a tile off the grid or texels
    /// of the wrong size.
    pub fn write_tile(&mut self, tile: UVec2, texels: Grid<u8>) -> Result<(), CacheError> {
        self.layer.set_tile(tile, texels)?;
        self.io.supersede(tile);
        self.read.insert(tile);
        self.touch(tile);
        Ok(())
    }

    /// Replaces the texels of `rect` (tile coordinates) of `tile` with `texels`: the dirty rect
    /// of a stamp on the GPU, read back so the cache (collision, write-back) holds the GPU's
    /// result. The tile is read from the world first (on the caller's thread) if it is not in
    /// RAM; it becomes dirty. Fails, changing nothing, on a tile off the grid, a rect off the
    /// tile, texels of another size than the rect, or a corrupt tile file.
    pub fn write_rect(
        &mut self,
        tile: UVec2,
        rect: Rect,
        texels: &Grid<u8>,
    ) -> Result<(), CacheError> {
        let tiles = self.layout().tiles();
        if tile.x >= tiles.x || tile.y >= tiles.y {
            return Err(off_grid(tile, tiles));
        }
        let side = self.layout().tile_size();
        if !Rect::from_size(UVec2::splat(side)).contains_rect(&rect) {
            return Err(terrain_core::CoreError::RegionOutOfBounds {
                rect,
                map_size: UVec2::splat(side),
            }
            .into());
        }
        if texels.size() != rect.size {
            return Err(terrain_core::CoreError::SizeMismatch {
                expected: rect.size,
                actual: texels.size(),
            }
            .into());
        }
        if !self.read.contains(&tile) {
            self.read_into_ram(tile)?;
        }
        let mut grid = match self.layer.tile(tile) {
            Some(g) => g.clone(),
            None => Grid::new(side, side, DETAIL_ZERO_RAW)?,
        };
        let (x0, w) = (rect.min.x as usize, rect.size.x as usize);
        for (y, row) in texels.as_slice().chunks_exact(w.max(1)).enumerate() {
            let start = (rect.min.y as usize + y) * side as usize + x0;
            grid.as_mut_slice()[start..start + w].copy_from_slice(row);
        }
        self.layer.set_tile(tile, grid)?;
        self.touch(tile);
        Ok(())
    }

    /// Writes every dirty tile back and waits until each write is confirmed (the end of a
    /// session; write-backs already in flight are waited for too). Returns how many tiles this
    /// call queued and stored. A write that fails is not retried here: the tile stays dirty
    /// and the first error is returned once the other writes have landed.
    pub fn flush(&mut self) -> Result<usize, CacheError> {
        let mut stored = 0;
        let mut queued: HashSet<UVec2> = HashSet::new();
        let mut failed: Option<CacheError> = None;
        let mut refused: HashSet<UVec2> = HashSet::new();
        loop {
            // Dirty tiles not being written (a tile stamped while its write was in flight is
            // queued again once that write lands).
            for t in self.dirty_tiles() {
                if !self.io.writing(t) && !refused.contains(&t) {
                    self.queue_write(t)?;
                    queued.insert(t);
                }
            }
            let Some(done) = self.io.wait_write()? else {
                break;
            };
            let t = done.0;
            match self.confirm(done) {
                Ok(_) => stored += usize::from(queued.remove(&t) && !self.dirty.contains_key(&t)),
                Err((t, e)) => {
                    refused.insert(t);
                    failed.get_or_insert(e);
                }
            }
        }
        match failed {
            Some(e) => Err(e),
            None => Ok(stored),
        }
    }

    /// Reads tile `t`'s stored texels into the layer on the caller's thread, forgetting a read
    /// of it in flight.
    fn read_into_ram(&mut self, t: UVec2) -> Result<(), CacheError> {
        let texels = read_now(&self.world, t)?;
        self.io.supersede(t);
        self.keep(t, texels)
    }

    /// Puts tile `t`'s stored texels (`None`: the zero tile) in the layer.
    fn keep(&mut self, t: UVec2, texels: Texels) -> Result<(), CacheError> {
        match texels {
            Some(grid) => self.layer.set_tile(t, grid)?,
            None => self.layer.clear_tile(t),
        }
        self.read.insert(t);
        Ok(())
    }
}

/// Tiles sorted row by row.
fn row_major(tiles: impl Iterator<Item = UVec2>) -> Vec<UVec2> {
    let mut v: Vec<UVec2> = tiles.collect();
    v.sort_unstable_by_key(|t| (t.y, t.x));
    v
}

fn off_grid(t: UVec2, tiles: UVec2) -> CacheError {
    CacheError::TileOutOfRange {
        id: TileId::new(0, t.x, t.y),
        levels: 1,
        tiles_x: tiles.x,
        tiles_y: tiles.y,
    }
}
