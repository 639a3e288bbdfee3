//! The VRAM pool (Fikkan 2013, sec. 4.2, 5.3, 5.4.2, 5.6): which tiles of the RAM pool to hold in a
//! fixed number of GPU slots, and when to upload them. Policy only: the slots and the
//! indirection table live behind terrain-core's [`TileUploadTarget`] (terrain-gpu's
//! `GpuTileAtlas`, or terrain-core's CPU `TileAtlas`), which this crate never names.
//!
//! Per [`VramPool::update`]:
//! 1. **Stale copies.** Tiles the RAM pool reports as [`RamTiles::refreshed`] (coarser tiles
//!    rewritten on disk after a deformation was written back) or whose RAM copy was modified
//!    since the upload ([`RamTiles::version`]) are marked stale; they stay drawn until
//!    re-uploaded.
//! 2. **Selection.** Per level, tiles in the view frustum widened by a margin that grows with
//!    the camera's turn rate ([`FrustumSelection`], Fikkan 2013, sec. 5.4.2 and fig. 5.5) or the band
//!    regions of the camera's tile ([`BandSelection`], Flower 2010, fig. 2.4), each level out to the
//!    same number of its own tiles; plus the whole coarsest level when it fits, the fallback of
//!    every texel. Wanted tiles are ranked nearest first (3D distance to the tile's box), the
//!    coarsest level ahead of all, coarser ahead of finer at equal distance.
//! 3. **Uploads within the budget** (Fikkan 2013, sec. 5.3): in rank order, tiles that are loaded in
//!    RAM and not resident (or stale) are uploaded until the next would pass the frame's byte
//!    budget; the rest wait for the next frame. A slot comes from the free list, else from the
//!    resident tile wanted least recently (farthest first among equals): unwanted tiles stay
//!    resident, marked for deletion, until their slot is needed, so a tile wanted again soon is
//!    rescued without a transfer. Tiles ranked within the slot count are never evicted for
//!    others; tiles ranked beyond it only take free slots or unwanted ones.
//! 4. **Indirection.** An evicted tile is unmapped before its slot is reused; an uploaded tile
//!    is mapped after its upload. A renderer reading the table takes, per texel, the finest
//!    mapped level, so a missing tile is drawn from a coarser one.
//!
//! The same pool streams a world's paint or colour ([`VramPool::update_overlay`] into an
//! [`OverlayUploadTarget`]; [`crate::OverlayStream`] pairs it with a RAM pool of the layer).

use crate::CacheError;
use crate::manifest::Manifest;
use crate::policy::{
    BandSelection, CameraState, FrustumSelection, SelectionPolicy, TileGrid, Want,
};
use crate::pool::RamPool;
use crate::tile::{Layer, TileData, TileId};
use glam::{DVec2, DVec3, UVec2};
use std::collections::HashMap;
use terrain_core::{Grid, OverlayUploadTarget, TileLayout, TileUploadTarget, WrapMode};

/// Default per-frame upload budget: 2 MiB, sixteen 256^2 tiles of 16-bit heights. Fikkan 2013, sec. 5.3
/// limits transfers to a fixed share of the frame (2 ms of 16.7 ms); the bytes that take depend
/// on the hardware, so the budget is a plain number to tune (see the atlas upload bench).
pub const DEFAULT_UPLOAD_BUDGET_BYTES: u64 = 2 << 20;

/// How the VRAM pool selects tiles on each level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum VramSelection {
    /// Fikkan 2013, sec. 5.4.2: per level, tiles in the horizontal view cone widened by `fov_margin`
    /// plus `turn_gain` times the turn of the last frame, out to `far_tiles` tiles of that
    /// level, and every tile within `near_tiles` tiles of the camera (behind it too).
    Frustum {
        /// Reach, in tiles of each level.
        far_tiles: f64,
        /// Tiles this close (in tiles of each level, 3D) are wanted whatever the heading.
        near_tiles: f64,
        /// Extra half-angle in radians beyond the camera's horizontal half field of view.
        fov_margin: f64,
        /// Extra half-angle per radian turned in the last frame.
        turn_gain: f64,
    },
    /// Flower 2010, sec. 2.4.2, fig. 2.4: per level, the camera's tile and the neighbours its band
    /// region asks for (4, 6 or 9 tiles).
    Band {
        /// Band width as a fraction of the tile side (1/3: nine equal regions).
        band_width: f64,
    },
}

impl Default for VramSelection {
    /// Frustum: 3 tiles of each level ahead, 1 around, a 15 degree margin, 8 radians of margin
    /// per radian turned per frame.
    fn default() -> Self {
        VramSelection::Frustum {
            far_tiles: 3.0,
            near_tiles: 1.0,
            fov_margin: 15f64.to_radians(),
            turn_gain: 8.0,
        }
    }
}

/// Settings of a [`VramPool`].
#[derive(Debug, Clone, PartialEq)]
pub struct VramConfig {
    /// The tile layout of the world's height layer.
    pub grid: TileGrid,
    /// Tile side in texels (the target must have the same).
    pub tile_size: u32,
    /// Tile slots the pool uses (the target must have at least this many).
    pub slots: u32,
    /// Bytes uploaded per frame at most (at least one tile's upload).
    pub upload_budget_bytes: u64,
    /// The selection on each level.
    pub selection: VramSelection,
}

impl VramConfig {
    /// `slots` tiles of the height layer of the world of `manifest`, with the default budget
    /// and frustum selection.
    pub fn new(manifest: &Manifest, slots: u32) -> Self {
        Self {
            grid: TileGrid::from_manifest(manifest, Layer::Height),
            tile_size: manifest.tile_size,
            slots,
            upload_budget_bytes: DEFAULT_UPLOAD_BUDGET_BYTES,
            selection: VramSelection::default(),
        }
    }
}

impl Manifest {
    /// The layout of the height pyramid as a tile upload target indexes it (the world's size,
    /// tile size, levels, texel size, encoding, wrap, and the zero tile's value as the fill).
    pub fn tile_layout(&self) -> TileLayout {
        TileLayout {
            world_size: self.world_size,
            tile_size: self.tile_size,
            levels: self.levels,
            texel_size: self.texel_size,
            encoding: self.encoding,
            wrap: self.wrap,
            fill: self.height_fill,
        }
    }
}

/// What the VRAM pool reads from the RAM pool: implemented by [`RamPool`]; tests and tools
/// can implement it over tiles in memory.
pub trait RamTiles {
    /// The samples of a loaded tile.
    fn tile(&self, id: TileId) -> Option<&TileData>;
    /// A number that changes whenever a loaded tile's samples change (`None` when not loaded).
    fn version(&self, id: TileId) -> Option<u64>;
    /// Tiles whose data on disk changed under any copy of them in the last update.
    fn refreshed(&self) -> &[TileId];
}

impl RamTiles for RamPool {
    fn tile(&self, id: TileId) -> Option<&TileData> {
        RamPool::tile(self, id)
    }
    fn version(&self, id: TileId) -> Option<u64> {
        RamPool::generation(self, id)
    }
    fn refreshed(&self) -> &[TileId] {
        RamPool::refreshed(self)
    }
}

/// What one [`VramPool::update`] did and where the pool stands.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct VramReport {
    /// The frame number (updates so far).
    pub frame: u64,
    /// Tiles the selection wanted.
    pub tiles_wanted: usize,
    /// Wanted tiles not resident after this update: drawn from a coarser level.
    pub tiles_missing: usize,
    /// Of the missing tiles, those not loaded in RAM (nothing to upload yet).
    pub waiting_for_ram: usize,
    /// Of the missing tiles, those loaded in RAM but left for a later frame by the budget or
    /// for lack of a slot.
    pub deferred: usize,
    /// Tiles resident (mapped in the target).
    pub resident: usize,
    /// Resident tiles whose data changed in RAM or on disk, not yet re-uploaded.
    pub stale: usize,
    /// Bytes of the resident tiles in the target.
    pub vram_bytes: u64,
    /// Bytes of all slots.
    pub capacity_bytes: u64,
    /// Bytes uploaded this frame (never more than `budget_bytes`).
    pub upload_bytes: u64,
    /// The per-frame budget.
    pub budget_bytes: u64,
    /// Tiles uploaded this frame (re-uploads of stale tiles included).
    pub uploads: usize,
    /// Of the uploads, re-uploads of stale tiles.
    pub refreshes: usize,
    /// Tiles evicted this frame to free a slot.
    pub evictions: usize,
}

/// Why an update failed.
#[derive(Debug, thiserror::Error)]
pub enum VramError<E> {
    /// A bad camera, a target that does not match the pool, or tile data of the wrong shape.
    #[error(transparent)]
    Cache(#[from] CacheError),
    /// The upload target refused an upload or a table write; its error, unchanged.
    #[error("the upload target failed on tile {id}")]
    Target {
        /// The tile being uploaded, mapped or unmapped.
        id: TileId,
        /// The target's error.
        #[source]
        source: E,
    },
}

#[derive(Debug, Clone, Copy)]
struct Resident {
    slot: u32,
    /// The last frame that wanted it.
    wanted_frame: u64,
    /// Its rank in the frame that last wanted it.
    rank: usize,
    /// The RAM version it was uploaded from.
    version: Option<u64>,
    stale: bool,
    /// Holds by [`VramPool::hold`]: while any, the slot is the tile's newest copy (changed on
    /// the GPU, not yet read back), so it is neither evicted nor overwritten from RAM.
    holds: u32,
}

#[derive(Debug, Clone, Copy)]
struct Ranked {
    id: TileId,
    root: bool,
    distance: f64,
}

/// The VRAM pool: a fixed number of slots of a [`TileUploadTarget`], filled from the RAM pool
/// around the camera within a per-frame byte budget (see the module docs).
#[derive(Debug)]
pub struct VramPool {
    cfg: VramConfig,
    policies: Vec<Box<dyn SelectionPolicy>>,
    resident: HashMap<TileId, Resident>,
    free: Vec<u32>,
    frame: u64,
    wants: Vec<Want>,
    ranked: Vec<Ranked>,
    victims: Vec<Victim>,
}

/// A resident tile that may give up its slot, ordered so that the first to go sorts last.
#[derive(Debug, Clone, Copy)]
struct Victim {
    id: TileId,
    /// Not wanted this frame (marked for deletion).
    unwanted: bool,
    /// Frames since last wanted (unwanted tiles).
    age: u64,
    /// Distance in metres (unwanted tiles) or rank (wanted tiles beyond the slot count).
    order: f64,
}

impl VramPool {
    /// A pool of `config.slots` slots, nothing resident. Fails on an empty grid, zero slots, a
    /// budget below one tile (even at 2 bytes per texel) or a bad selection parameter.
    pub fn new(config: VramConfig) -> Result<Self, CacheError> {
        let out = |what, value: f64, expected| CacheError::OutOfRange {
            what,
            value,
            expected,
        };
        if config.grid.levels.is_empty()
            || config
                .grid
                .levels
                .iter()
                .any(|l| l.tiles.min_element() == 0)
        {
            return Err(out(
                "VRAM pool levels",
                config.grid.levels.len() as f64,
                "at least one level, each with tiles",
            ));
        }
        if config.slots == 0 || config.slots == terrain_core::INVALID_SLOT {
            return Err(out("VRAM slots", f64::from(config.slots), "1 ..= 2^32 - 2"));
        }
        if config.tile_size == 0 {
            return Err(out("VRAM tile size", 0.0, "at least 1"));
        }
        let min_tile = u64::from(config.tile_size) * u64::from(config.tile_size) * 2;
        if config.upload_budget_bytes < min_tile {
            return Err(out(
                "upload_budget_bytes",
                config.upload_budget_bytes as f64,
                "at least one tile's upload",
            ));
        }
        let policies: Vec<Box<dyn SelectionPolicy>> = match config.selection {
            VramSelection::Frustum {
                far_tiles,
                near_tiles,
                fov_margin,
                turn_gain,
            } => {
                for (what, v) in [
                    ("far_tiles", far_tiles),
                    ("near_tiles", near_tiles),
                    ("fov_margin", fov_margin),
                    ("turn_gain", turn_gain),
                ] {
                    if !v.is_finite() || v < 0.0 {
                        return Err(out(what, v, "finite and not negative"));
                    }
                }
                config
                    .grid
                    .levels
                    .iter()
                    .enumerate()
                    .map(|(l, g)| {
                        Box::new(FrustumSelection {
                            level: l as u32,
                            far: far_tiles * g.tile_m,
                            near: near_tiles * g.tile_m,
                            fov_margin,
                            turn_gain,
                            last_forward: None,
                        }) as Box<dyn SelectionPolicy>
                    })
                    .collect()
            }
            VramSelection::Band { band_width } => {
                if !(0.0..=1.0).contains(&band_width) {
                    return Err(out("band_width", band_width, "0 ..= 1"));
                }
                (0..config.grid.levels.len() as u32)
                    .map(|level| {
                        Box::new(BandSelection { level, band_width }) as Box<dyn SelectionPolicy>
                    })
                    .collect()
            }
        };
        // Popped from the end: slot 0 first.
        let free = (0..config.slots).rev().collect();
        Ok(Self {
            cfg: config,
            policies,
            resident: HashMap::new(),
            free,
            frame: 0,
            wants: Vec::new(),
            ranked: Vec::new(),
            victims: Vec::new(),
        })
    }

    /// The configuration.
    pub fn config(&self) -> &VramConfig {
        &self.cfg
    }

    /// The slot holding `id`, if resident.
    pub fn slot_of(&self, id: TileId) -> Option<u32> {
        self.resident.get(&id).map(|r| r.slot)
    }

    /// Keeps `id` in its slot, unchanged from RAM, until [`release`](Self::release): for a tile
    /// deformed on the GPU in its slot whose change is on its way back to RAM by readback.
    /// Until then the slot is the newest copy, so re-uploading the RAM copy (or evicting the
    /// slot and uploading it again) would lose the change. Returns the slot, `None` (and
    /// holds nothing) when `id` is not resident or its slot is stale (older than RAM): change
    /// the RAM tile then. Holds nest.
    pub fn hold(&mut self, id: TileId) -> Option<u32> {
        let e = self.resident.get_mut(&id)?;
        // A stale slot is older than RAM (its re-upload waits for the budget): a change made
        // in it and read back would overwrite RAM's newer texels. Only a current slot is held
        // (nested holds keep the slot current: it is not refreshed while held).
        if e.stale && e.holds == 0 {
            return None;
        }
        e.holds = e.holds.saturating_add(1);
        Some(e.slot)
    }

    /// Ends one [`hold`](Self::hold) of `id`. `ram_version` is the RAM tile's version after
    /// the readback the hold waited for was written into it ([`RamTiles::version`]): the slot
    /// holds everything that version holds, so when the last hold ends the slot is current
    /// for it and is not uploaded again. Releasing a tile that is not held does nothing.
    pub fn release(&mut self, id: TileId, ram_version: Option<u64>) {
        let Some(e) = self.resident.get_mut(&id) else {
            return;
        };
        if e.holds == 0 {
            return;
        }
        e.holds -= 1;
        if e.holds == 0 {
            e.version = ram_version;
            e.stale = false;
        }
    }

    /// Ends one [`hold`](Self::hold) of `id` whose readback will never come: the slot may hold
    /// a change RAM does not, so it is marked out of date and uploaded again from RAM.
    pub fn abandon(&mut self, id: TileId) {
        self.release(id, None);
        if let Some(e) = self.resident.get_mut(&id) {
            e.stale = true;
        }
    }

    /// Tiles held by [`hold`](Self::hold) now.
    pub fn held(&self) -> usize {
        self.resident.values().filter(|e| e.holds > 0).count()
    }

    /// Ids of the resident tiles, unordered.
    pub fn resident_ids(&self) -> Vec<TileId> {
        self.resident.keys().copied().collect()
    }

    /// The tiles wanted by the last update, most urgent first.
    pub fn wanted(&self) -> impl Iterator<Item = TileId> + '_ {
        self.ranked.iter().map(|r| r.id)
    }

    /// Unmaps every resident tile (e.g. before switching worlds); the slots become free. Held
    /// tiles are unmapped too: read their changes back first.
    pub fn clear<T: TileUploadTarget>(
        &mut self,
        target: &mut T,
    ) -> Result<(), VramError<T::Error>> {
        self.clear_slots(&mut HeightSlots(target))
    }

    /// [`clear`](Self::clear) for a pool filled by [`update_overlay`](Self::update_overlay).
    pub fn clear_overlay<T: OverlayUploadTarget>(
        &mut self,
        target: &mut T,
    ) -> Result<(), VramError<T::Error>> {
        self.clear_slots(&mut OverlaySlots(target, Layer::Material))
    }

    fn clear_slots<S: Slots>(&mut self, target: &mut S) -> Result<(), VramError<S::Error>> {
        let ids: Vec<TileId> = self.resident.keys().copied().collect();
        for id in ids {
            target
                .map(id.level, UVec2::new(id.x, id.y), None)
                .map_err(|source| VramError::Target { id, source })?;
            if let Some(r) = self.resident.remove(&id) {
                self.free.push(r.slot);
            }
        }
        Ok(())
    }

    /// One frame: marks stale copies, selects tiles for `camera`, evicts and uploads from `ram`
    /// into `target` within the budget, and updates the indirection table (see the module
    /// docs). Its work is bounded by the selection (each level's square around the camera,
    /// clamped to the world), the slots and the budget, whatever the camera's coordinates; a
    /// non-finite camera is refused before anything changes.
    pub fn update<R, T>(
        &mut self,
        camera: &CameraState,
        ram: &R,
        target: &mut T,
    ) -> Result<VramReport, VramError<T::Error>>
    where
        R: RamTiles + ?Sized,
        T: TileUploadTarget,
    {
        self.update_slots(camera, ram, &mut HeightSlots(target))
    }

    /// [`update`](Self::update) for a world's paint or colour (`layer`, [`Layer::Material`] or
    /// [`Layer::Color`]): the same selection and budget, uploading the RAM pool's RGBA8 tiles
    /// of that layer into an [`OverlayUploadTarget`] (terrain-gpu's `GpuOverlayAtlas`). Give
    /// the pool the same slots and selection as the heights' and it holds the look of the
    /// ground the heights' pool holds the shape of. Tiles without a file arrive from the RAM
    /// pool as its zero tile and are uploaded like any other: a transparent tile must hide the
    /// coarser level's paint under it.
    pub fn update_overlay<R, T>(
        &mut self,
        camera: &CameraState,
        layer: Layer,
        ram: &R,
        target: &mut T,
    ) -> Result<VramReport, VramError<T::Error>>
    where
        R: RamTiles + ?Sized,
        T: OverlayUploadTarget,
    {
        if !matches!(layer, Layer::Material | Layer::Color) {
            return Err(CacheError::NoSuchLayer { layer }.into());
        }
        self.update_slots(camera, ram, &mut OverlaySlots(target, layer))
    }

    fn update_slots<R, S>(
        &mut self,
        camera: &CameraState,
        ram: &R,
        target: &mut S,
    ) -> Result<VramReport, VramError<S::Error>>
    where
        R: RamTiles + ?Sized,
        S: Slots,
    {
        camera.validate()?;
        self.check_target(target)?;
        self.frame += 1;
        let frame = self.frame;
        let cost = target.upload_bytes();
        let slots = self.cfg.slots as usize;
        let mut r = VramReport {
            frame,
            budget_bytes: self.cfg.upload_budget_bytes,
            capacity_bytes: cost * u64::from(self.cfg.slots),
            ..VramReport::default()
        };

        // 1. Stale copies.
        for id in ram.refreshed() {
            if let Some(e) = self.resident.get_mut(id) {
                e.stale = true;
            }
        }
        for (id, e) in self.resident.iter_mut() {
            if let (Some(up), Some(now)) = (e.version, ram.version(*id))
                && up != now
            {
                e.stale = true;
            }
        }

        // 2. Selection, ranked.
        self.select(camera);
        for (rank, w) in self.ranked.iter().enumerate() {
            if let Some(e) = self.resident.get_mut(&w.id) {
                e.wanted_frame = frame;
                e.rank = rank;
            }
        }

        // 3. Uploads in rank order within the budget.
        let mut spent = 0u64;
        self.victims.clear();
        let mut victims_built = false;
        let mut budget_left = true;
        for rank in 0..self.ranked.len() {
            let id = self.ranked[rank].id;
            let (is_resident, stale) = match self.resident.get(&id) {
                // A held slot is newer than RAM: never overwritten from it.
                Some(e) => (true, e.stale && e.holds == 0),
                None => (false, false),
            };
            if is_resident && !stale {
                continue;
            }
            let Some(data) = ram.tile(id) else {
                if !is_resident {
                    r.waiting_for_ram += 1;
                }
                continue;
            };
            if !budget_left || spent + cost > self.cfg.upload_budget_bytes {
                budget_left = false;
                if !is_resident {
                    r.deferred += 1;
                }
                continue;
            }
            let texels = target.texels(data, self.cfg.tile_size)?;
            let slot = if let Some(e) = self.resident.get(&id) {
                e.slot
            } else if let Some(s) = self.free.pop() {
                s
            } else {
                if !victims_built {
                    self.build_victims(camera, frame);
                    victims_built = true;
                }
                match self.take_victim(rank < slots, frame) {
                    Some(victim) => {
                        let e = self.resident.remove(&victim).map(|e| e.slot);
                        let Some(s) = e else {
                            continue;
                        };
                        if let Err(source) =
                            target.map(victim.level, UVec2::new(victim.x, victim.y), None)
                        {
                            self.free.push(s);
                            return Err(VramError::Target { id: victim, source });
                        }
                        r.evictions += 1;
                        s
                    }
                    None => {
                        r.deferred += 1;
                        continue;
                    }
                }
            };
            let xy = UVec2::new(id.x, id.y);
            let bytes = match target.upload(slot, id.level, xy, texels) {
                Ok(b) => b,
                Err(source) => {
                    if !is_resident {
                        self.free.push(slot);
                    }
                    return Err(VramError::Target { id, source });
                }
            };
            spent += bytes;
            r.upload_bytes += bytes;
            r.uploads += 1;
            let version = ram.version(id);
            if is_resident {
                r.refreshes += 1;
                if let Some(e) = self.resident.get_mut(&id) {
                    e.stale = false;
                    e.version = version;
                }
            } else {
                if let Err(source) = target.map(id.level, xy, Some(slot)) {
                    self.free.push(slot);
                    return Err(VramError::Target { id, source });
                }
                self.resident.insert(
                    id,
                    Resident {
                        slot,
                        wanted_frame: frame,
                        rank,
                        version,
                        stale: false,
                        holds: 0,
                    },
                );
            }
        }

        // 4. Report.
        r.tiles_wanted = self.ranked.len();
        r.tiles_missing = self
            .ranked
            .iter()
            .filter(|w| !self.resident.contains_key(&w.id))
            .count();
        r.resident = self.resident.len();
        r.stale = self.resident.values().filter(|e| e.stale).count();
        r.vram_bytes = cost * r.resident as u64;
        Ok(r)
    }

    /// Checks that the target indexes this pool's world with enough slots.
    fn check_target<S: Slots>(&self, target: &S) -> Result<(), CacheError> {
        let mismatch =
            |what, pool: u64, target: u64| Err(CacheError::TargetMismatch { what, pool, target });
        let layout = target.layout();
        if layout.tile_size != self.cfg.tile_size {
            return mismatch(
                "tile size",
                u64::from(self.cfg.tile_size),
                u64::from(layout.tile_size),
            );
        }
        let levels = self.cfg.grid.levels.len() as u64;
        if u64::from(layout.levels) != levels {
            return mismatch("levels", levels, u64::from(layout.levels));
        }
        for (l, g) in self.cfg.grid.levels.iter().enumerate() {
            let t = layout.tiles_at(l as u32);
            if t != g.tiles {
                return mismatch(
                    "tiles of a level (x * 2^32 + y)",
                    (u64::from(g.tiles.x) << 32) | u64::from(g.tiles.y),
                    (u64::from(t.x) << 32) | u64::from(t.y),
                );
            }
        }
        if target.slot_count() < self.cfg.slots {
            return mismatch(
                "slot count",
                u64::from(self.cfg.slots),
                u64::from(target.slot_count()),
            );
        }
        let bytes = target.upload_bytes();
        if bytes == 0 || bytes > self.cfg.upload_budget_bytes {
            return mismatch(
                "upload size (bytes, at most the budget)",
                self.cfg.upload_budget_bytes,
                bytes,
            );
        }
        Ok(())
    }

    /// Fills `ranked` with this frame's wanted tiles, most urgent first.
    fn select(&mut self, camera: &CameraState) {
        let grid = &self.cfg.grid;
        self.wants.clear();
        for p in &mut self.policies {
            p.select(camera, grid, &mut self.wants);
        }
        let top = grid.levels.len() as u32 - 1;
        let root_tiles = grid.levels[top as usize].tiles;
        // The whole coarsest level is every texel's fallback, when it fits in half the slots.
        let root_whole =
            u64::from(root_tiles.x) * u64::from(root_tiles.y) <= u64::from(self.cfg.slots / 2);
        if root_whole {
            let xz = grid.camera_xz(camera.position);
            grid.square(top, xz, f64::MAX, |id, _| {
                self.wants.push(Want { id, priority: 0.0 });
            });
        }
        let xz = grid.camera_xz(camera.position);
        let eye = DVec3::new(xz.x, f64::from(camera.position.y), xz.y);
        self.ranked.clear();
        self.ranked.extend(self.wants.iter().map(|w| Ranked {
            id: w.id,
            root: root_whole && w.id.level == top,
            distance: tile_distance(grid, eye, w.id),
        }));
        self.ranked.sort_by(|a, b| {
            b.root
                .cmp(&a.root)
                .then(a.distance.total_cmp(&b.distance))
                .then(b.id.level.cmp(&a.id.level))
                .then(a.id.cmp(&b.id))
        });
        self.ranked.dedup_by_key(|w| w.id);
    }

    /// Resident tiles that may give up their slot this frame, the first to go last: unwanted
    /// ones (least recently wanted, then farthest, go first), then wanted ones ranked beyond the
    /// slot count (lowest rank last to go).
    fn build_victims(&mut self, camera: &CameraState, frame: u64) {
        let grid = &self.cfg.grid;
        let xz = grid.camera_xz(camera.position);
        let eye = DVec3::new(xz.x, f64::from(camera.position.y), xz.y);
        let slots = self.cfg.slots as usize;
        self.victims.clear();
        for (&id, e) in &self.resident {
            if e.holds > 0 {
                continue;
            }
            if e.wanted_frame != frame {
                self.victims.push(Victim {
                    id,
                    unwanted: true,
                    age: frame - e.wanted_frame,
                    order: tile_distance(grid, eye, id),
                });
            } else if e.rank >= slots {
                self.victims.push(Victim {
                    id,
                    unwanted: false,
                    age: 0,
                    order: e.rank as f64,
                });
            }
        }
        // Ascending: the first to go is popped from the end.
        self.victims.sort_by(|a, b| {
            a.unwanted
                .cmp(&b.unwanted)
                .then(a.age.cmp(&b.age))
                .then(a.order.total_cmp(&b.order))
                .then(b.id.cmp(&a.id))
        });
    }

    /// The next victim: an unwanted tile, or, if `may_take_wanted`, a tile ranked beyond the
    /// slot count.
    fn take_victim(&mut self, may_take_wanted: bool, frame: u64) -> Option<TileId> {
        let v = *self.victims.last()?;
        let unwanted = self
            .resident
            .get(&v.id)
            .is_some_and(|e| e.wanted_frame != frame);
        if unwanted || may_take_wanted {
            self.victims.pop();
            Some(v.id)
        } else {
            None
        }
    }
}

/// What the pool uploads into: a height target or an overlay target, behind one interface.
trait Slots {
    type Error;
    /// The samples a slot takes.
    type Texels: ?Sized;
    fn layout(&self) -> &TileLayout;
    fn slot_count(&self) -> u32;
    fn upload_bytes(&self) -> u64;
    /// `data`'s samples, or the mismatch with the target's kind and `tile_size` as an error.
    fn texels<'d>(
        &self,
        data: &'d TileData,
        tile_size: u32,
    ) -> Result<&'d Self::Texels, CacheError>;
    fn upload(
        &mut self,
        slot: u32,
        level: u32,
        tile: UVec2,
        texels: &Self::Texels,
    ) -> Result<u64, Self::Error>;
    fn map(&mut self, level: u32, tile: UVec2, slot: Option<u32>) -> Result<(), Self::Error>;
}

/// A height target.
struct HeightSlots<'a, T>(&'a mut T);

/// An overlay target of a layer.
struct OverlaySlots<'a, T>(&'a mut T, Layer);

impl<T: TileUploadTarget> Slots for HeightSlots<'_, T> {
    type Error = T::Error;
    type Texels = Grid<u16>;
    fn layout(&self) -> &TileLayout {
        self.0.layout()
    }
    fn slot_count(&self) -> u32 {
        self.0.slot_count()
    }
    fn upload_bytes(&self) -> u64 {
        self.0.upload_bytes()
    }
    fn texels<'d>(&self, data: &'d TileData, tile_size: u32) -> Result<&'d Grid<u16>, CacheError> {
        match data.as_u16() {
            Some(g) if g.size() == UVec2::splat(tile_size) => Ok(g),
            _ => Err(mismatch(Layer::Height, data, tile_size)),
        }
    }
    fn upload(
        &mut self,
        slot: u32,
        level: u32,
        tile: UVec2,
        texels: &Grid<u16>,
    ) -> Result<u64, T::Error> {
        self.0.upload(slot, level, tile, texels)
    }
    fn map(&mut self, level: u32, tile: UVec2, slot: Option<u32>) -> Result<(), T::Error> {
        self.0.map(level, tile, slot)
    }
}

impl<T: OverlayUploadTarget> Slots for OverlaySlots<'_, T> {
    type Error = T::Error;
    type Texels = Grid<[u8; 4]>;
    fn layout(&self) -> &TileLayout {
        self.0.layout()
    }
    fn slot_count(&self) -> u32 {
        self.0.slot_count()
    }
    fn upload_bytes(&self) -> u64 {
        self.0.upload_bytes()
    }
    fn texels<'d>(
        &self,
        data: &'d TileData,
        tile_size: u32,
    ) -> Result<&'d Grid<[u8; 4]>, CacheError> {
        match data.as_rgba8() {
            Some(g) if g.size() == UVec2::splat(tile_size) => Ok(g),
            _ => Err(mismatch(self.1, data, tile_size)),
        }
    }
    fn upload(
        &mut self,
        slot: u32,
        level: u32,
        tile: UVec2,
        texels: &Grid<[u8; 4]>,
    ) -> Result<u64, T::Error> {
        self.0.upload(slot, level, tile, texels)
    }
    fn map(&mut self, level: u32, tile: UVec2, slot: Option<u32>) -> Result<(), T::Error> {
        self.0.map(level, tile, slot)
    }
}

/// Tile data of another kind or size than `layer`'s tiles of side `tile_size`.
fn mismatch(layer: Layer, data: &TileData, tile_size: u32) -> CacheError {
    let s = data.size();
    CacheError::TileDataMismatch {
        layer,
        expected_bits: layer.bits(),
        size: tile_size,
        found_bits: data.bits(),
        found_w: s.x,
        found_h: s.y,
    }
}

/// 3D distance in metres from `eye` (x and z wrapped into the world) to tile `id`'s box, at its
/// nearest periodic image on a repeating world.
fn tile_distance(grid: &TileGrid, eye: DVec3, id: TileId) -> f64 {
    let Some(g) = grid.levels.get(id.level as usize) else {
        return f64::INFINITY;
    };
    let shifts: &[f64] = if grid.wrap == WrapMode::Repeat {
        &[-1.0, 0.0, 1.0]
    } else {
        &[0.0]
    };
    let extent = g.tiles.as_dvec2() * g.tile_m;
    let mut best = f64::INFINITY;
    for &sy in shifts {
        for &sx in shifts {
            best = best.min(grid.distance(eye, id, DVec2::new(sx, sy) * extent));
        }
    }
    best
}

#[cfg(test)]
mod tests;
