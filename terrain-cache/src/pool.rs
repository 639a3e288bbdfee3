//! The RAM pool (seed 004 sec 4.2, 5.2-5.4.1): decoded tiles held within a memory budget, loaded
//! by worker threads and written back by a writer thread; the frame thread talks to them only
//! through lock-free queues (crossbeam channels and one atomic state per job) and never waits
//! on I/O.
//!
//! # States
//!
//! A tile is *queued* (a load job is in the queue), *loading* (a worker took the job), *loaded*,
//! *in use* (loaded and pinned by a consumer, e.g. the VRAM pool, so it is not evicted),
//! *marked for deletion* (loaded but no longer wanted: dropped when memory is needed, rescued
//! without I/O if wanted again first, seed 004 sec 5.3) or *failed* (its file is corrupt:
//! reported once, treated as missing). Orthogonally a loaded tile may be *dirty* (modified since
//! loaded); dirty tiles are written back atomically by the writer thread, and a dirty tile's
//! memory is freed only after its write-back succeeded. A queued job that is no longer wanted
//! is cancelled with one compare-and-swap; a worker that finds its job cancelled skips it, and a
//! tile wanted again before that is rescued by the reverse swap.
//!
//! # Memory
//!
//! `ram_bytes` counts every tile allocation the pool owns: loaded tiles, the reservations of
//! loads in flight (taken when the load is issued, so arrivals never overshoot), snapshots of
//! tiles being written back that were modified again meanwhile, and the shared zero tile once.
//! It never exceeds `budget_bytes`: a load is issued only after enough marked tiles were evicted
//! (farthest, finest first) to make room.

use crate::CacheError;
use crate::build::rebuild_ancestors;
use crate::policy::{CameraState, SelectionPolicy, SphericalSelection, TileGrid, Want};
use crate::tile::{Layer, TileData, TileId};
use crate::world::World;
use crossbeam_channel::{Receiver, Sender, TryRecvError, unbounded};
use glam::UVec2;
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use terrain_core::{CoreError, Grid, Rect};

/// Settings of a [`RamPool`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoolConfig {
    /// The layer the pool holds.
    pub layer: Layer,
    /// Memory budget in bytes (at least two tiles: the zero tile and one more).
    pub budget_bytes: u64,
    /// Loader threads (1..=64).
    pub workers: usize,
    /// Most loads in flight at once (1..=4096).
    pub max_in_flight: usize,
    /// Most loads issued by one [`RamPool::update`] (bounds its time).
    pub max_loads_per_frame: usize,
    /// Most write-backs issued by one update.
    pub max_writes_per_frame: usize,
    /// Most external requests drained by one update.
    pub max_requests_per_frame: usize,
    /// A dirty tile untouched for this many frames is written back (and stays loaded); `None`
    /// writes back only on eviction and [`RamPool::flush`].
    pub write_back_idle_frames: Option<u64>,
    /// After writing back height tiles, refresh their coarser ancestors on disk
    /// ([`rebuild_ancestors`]) on the writer thread.
    pub propagate_to_coarser: bool,
    /// A failed tile is retried after this many frames.
    pub retry_failed_frames: u64,
}

impl PoolConfig {
    /// Defaults for `layer` with `budget_bytes`: 2 workers, 16 loads in flight, 8 loads and 4
    /// writes per frame, idle write-back after 120 frames, ancestors refreshed.
    pub fn new(layer: Layer, budget_bytes: u64) -> Self {
        Self {
            layer,
            budget_bytes,
            workers: 2,
            max_in_flight: 16,
            max_loads_per_frame: 8,
            max_writes_per_frame: 4,
            max_requests_per_frame: 4096,
            write_back_idle_frames: Some(120),
            propagate_to_coarser: true,
            retry_failed_frames: 600,
        }
    }
}

/// What one [`RamPool::update`] did and where the pool stands.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FrameReport {
    /// The frame number (updates so far).
    pub frame: u64,
    /// Tiles the selection wanted this frame.
    pub wanted: usize,
    /// Wanted tiles loaded (or rescued) now.
    pub wanted_resident: usize,
    /// Load jobs issued.
    pub loads: usize,
    /// Loads that arrived.
    pub loaded: usize,
    /// Marked tiles rescued (wanted again before being dropped).
    pub rescued: usize,
    /// Queued loads cancelled.
    pub cancelled: usize,
    /// Tiles dropped to make room.
    pub evictions: usize,
    /// Write-backs issued.
    pub writes: usize,
    /// Write-backs finished.
    pub written: usize,
    /// Tiles that failed (corrupt, unreadable) this frame; see [`RamPool::errors`].
    pub failed: usize,
    /// Wanted tiles not issued for lack of memory (the budget is smaller than the selection).
    pub starved: usize,
    /// Tiles loaded (any state but queued / loading / failed).
    pub resident: usize,
    /// Loads queued or loading.
    pub in_flight: usize,
    /// Dirty tiles.
    pub dirty: usize,
    /// Bytes the pool owns now.
    pub ram_bytes: u64,
    /// The budget.
    pub budget_bytes: u64,
    /// Wall time of the update.
    pub update_time: Duration,
}

/// The state of a tile in the pool (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TileState {
    /// A load job waits in the queue.
    Queued,
    /// A worker is loading it.
    Loading,
    /// A queued job was cancelled; it is rescued if wanted again before a worker skips it.
    Cancelled,
    /// Loaded and wanted.
    Loaded,
    /// Loaded and pinned by a consumer.
    InUse,
    /// Loaded, no longer wanted; dropped when memory is needed.
    MarkedForDeletion,
    /// Its file could not be read or decoded; treated as missing.
    Failed,
}

/// A tile's state and flags.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TileStatus {
    /// The state.
    pub state: TileState,
    /// Modified since loaded and not yet written back.
    pub dirty: bool,
    /// A write-back is in flight.
    pub writing: bool,
    /// Holds the shared zero tile (no file).
    pub zero: bool,
    /// Its coarser data on disk changed under it (an ancestor refreshed after a write-back
    /// while it was pinned or dirty).
    pub stale: bool,
}

const QUEUED: u8 = 0;
const LOADING: u8 = 1;
const CANCELLED: u8 = 2;
const SKIPPED: u8 = 3;

#[derive(Debug)]
struct JobCell {
    state: AtomicU8,
}

struct LoadJob {
    id: TileId,
    ticket: u64,
    cell: Arc<JobCell>,
}

enum LoadDone {
    Loaded {
        id: TileId,
        ticket: u64,
        result: Result<Arc<TileData>, CacheError>,
    },
    Skipped {
        id: TileId,
        ticket: u64,
    },
}

struct WriteJob {
    id: TileId,
    generation: u64,
    data: Arc<TileData>,
}

struct WriteDone {
    id: TileId,
    generation: u64,
    result: Result<Vec<TileId>, CacheError>,
}

/// A request from a [`RequestHandle`].
#[derive(Debug, Clone, Copy)]
enum Request {
    Want(TileId, f32),
    Cancel(TileId),
}

/// A cloneable, `Send` handle through which any thread asks the pool for tiles (physics wanting
/// a tile under a body, a scripted prefetch). Requests are queued lock-free and applied at the
/// next [`RamPool::update`]; a requested tile stays wanted until cancelled.
#[derive(Debug, Clone)]
pub struct RequestHandle {
    tx: Sender<Request>,
}

impl RequestHandle {
    /// Wants `id` with `priority` (lower loads first; the camera selection uses `[0, 1]`).
    pub fn request(&self, id: TileId, priority: f32) {
        // A closed channel means the pool is gone: nothing left to ask.
        let _ = self.tx.send(Request::Want(id, priority));
    }

    /// No longer wants `id` (it is marked for deletion, or its queued load cancelled).
    pub fn cancel(&self, id: TileId) {
        let _ = self.tx.send(Request::Cancel(id));
    }
}

#[derive(Debug, Clone)]
enum Slot {
    InFlight { ticket: u64, cell: Arc<JobCell> },
    Resident { data: Arc<TileData>, zero: bool },
    Failed { frame: u64 },
}

#[derive(Debug, Clone)]
struct Entry {
    slot: Slot,
    wanted_frame: u64,
    reserved: bool,
    dirty: bool,
    generation: u64,
    modified_frame: u64,
    writing: Option<u64>,
    snapshot_extra: bool,
    evict_after_write: bool,
    pins: u32,
    stale: bool,
}

impl Entry {
    fn new(slot: Slot) -> Self {
        Self {
            slot,
            wanted_frame: u64::MAX,
            reserved: false,
            dirty: false,
            generation: 0,
            modified_frame: 0,
            writing: None,
            snapshot_extra: false,
            evict_after_write: false,
            pins: 0,
            stale: false,
        }
    }
}

/// The RAM pool of one layer of a world. Owned by the frame thread; see the module docs.
pub struct RamPool {
    world: World,
    cfg: PoolConfig,
    grid: TileGrid,
    policy: Box<dyn SelectionPolicy>,
    tile_bytes: u64,
    zero: Arc<TileData>,
    entries: HashMap<TileId, Entry>,
    explicit: HashMap<TileId, f32>,
    load_tx: Option<Sender<LoadJob>>,
    done_rx: Receiver<LoadDone>,
    write_tx: Option<Sender<WriteJob>>,
    written_rx: Receiver<WriteDone>,
    req_tx: Sender<Request>,
    req_rx: Receiver<Request>,
    threads: Vec<JoinHandle<()>>,
    frame: u64,
    next_ticket: u64,
    in_flight: usize,
    writes_in_flight: usize,
    ram_bytes: u64,
    wants: Vec<Want>,
    newly_loaded: Vec<TileId>,
    evicted: Vec<TileId>,
    refreshed: Vec<TileId>,
    errors: Vec<(TileId, CacheError)>,
    last_camera: Option<CameraState>,
}

impl std::fmt::Debug for RamPool {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RamPool")
            .field("cfg", &self.cfg)
            .field("policy", &self.policy)
            .field("frame", &self.frame)
            .field("entries", &self.entries.len())
            .field("ram_bytes", &self.ram_bytes)
            .finish_non_exhaustive()
    }
}

impl RamPool {
    /// A pool over `world` with the default spherical selection scaled to its grid.
    pub fn new(world: World, cfg: PoolConfig) -> Result<Self, CacheError> {
        let grid = TileGrid::from_manifest(world.manifest(), cfg.layer);
        let policy = SphericalSelection::for_grid(&grid);
        Self::with_policy(world, cfg, Box::new(policy))
    }

    /// A pool over `world` selecting with `policy`.
    pub fn with_policy(
        world: World,
        cfg: PoolConfig,
        policy: Box<dyn SelectionPolicy>,
    ) -> Result<Self, CacheError> {
        let tile_size = world.manifest().layer_tile_size(cfg.layer)?;
        let tile_bytes = cfg.layer.tile_bytes(tile_size);
        if cfg.budget_bytes < 2 * tile_bytes {
            return Err(CacheError::OutOfRange {
                what: "budget_bytes",
                value: cfg.budget_bytes as f64,
                expected: "at least two tiles (the zero tile and one more)",
            });
        }
        let check = |what, v: usize, max: usize| {
            if (1..=max).contains(&v) {
                Ok(())
            } else {
                Err(CacheError::OutOfRange {
                    what,
                    value: v as f64,
                    expected: "within its documented range",
                })
            }
        };
        check("workers", cfg.workers, 64)?;
        check("max_in_flight", cfg.max_in_flight, 4096)?;
        check("max_loads_per_frame", cfg.max_loads_per_frame, 1 << 20)?;
        check("max_writes_per_frame", cfg.max_writes_per_frame, 1 << 20)?;
        check(
            "max_requests_per_frame",
            cfg.max_requests_per_frame,
            1 << 24,
        )?;
        let zero = world.zero_tile(cfg.layer)?;
        let grid = TileGrid::from_manifest(world.manifest(), cfg.layer);
        let (load_tx, load_rx) = unbounded::<LoadJob>();
        let (done_tx, done_rx) = unbounded::<LoadDone>();
        let (write_tx, write_rx) = unbounded::<WriteJob>();
        let (written_tx, written_rx) = unbounded::<WriteDone>();
        let (req_tx, req_rx) = unbounded();
        let mut threads = Vec::new();
        for i in 0..cfg.workers {
            let rx = load_rx.clone();
            let tx = done_tx.clone();
            let w = world.clone();
            let layer = cfg.layer;
            let t = std::thread::Builder::new()
                .name(format!("terrain-cache-load-{i}"))
                .spawn(move || loader(w, layer, rx, tx))
                .map_err(|e| CacheError::Worker {
                    what: "loader",
                    reason: e.to_string(),
                })?;
            threads.push(t);
        }
        {
            let w = world.clone();
            let layer = cfg.layer;
            let propagate = cfg.propagate_to_coarser && layer == Layer::Height;
            let t = std::thread::Builder::new()
                .name("terrain-cache-writer".into())
                .spawn(move || writer(w, layer, propagate, write_rx, written_tx))
                .map_err(|e| CacheError::Worker {
                    what: "writer",
                    reason: e.to_string(),
                })?;
            threads.push(t);
        }
        Ok(Self {
            world,
            cfg,
            grid,
            policy,
            tile_bytes,
            zero,
            entries: HashMap::new(),
            explicit: HashMap::new(),
            load_tx: Some(load_tx),
            done_rx,
            write_tx: Some(write_tx),
            written_rx,
            req_tx,
            req_rx,
            threads,
            frame: 0,
            next_ticket: 0,
            in_flight: 0,
            writes_in_flight: 0,
            ram_bytes: tile_bytes,
            wants: Vec::new(),
            newly_loaded: Vec::new(),
            evicted: Vec::new(),
            refreshed: Vec::new(),
            errors: Vec::new(),
            last_camera: None,
        })
    }

    /// The world.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The configuration.
    pub fn config(&self) -> &PoolConfig {
        &self.cfg
    }

    /// Bytes of one decoded tile.
    pub fn tile_bytes(&self) -> u64 {
        self.tile_bytes
    }

    /// Bytes the pool owns now (see the module docs).
    pub fn ram_bytes(&self) -> u64 {
        self.ram_bytes
    }

    /// A handle for requesting tiles from any thread.
    pub fn handle(&self) -> RequestHandle {
        RequestHandle {
            tx: self.req_tx.clone(),
        }
    }

    /// One frame: applies queued requests, takes finished loads and write-backs, selects tiles
    /// for `camera`, cancels, rescues, evicts and issues loads and write-backs. Never blocks;
    /// its work is bounded by the selection's square, the budget and the per-frame limits.
    #[tracing::instrument(level = "debug", name = "ram_pool_update", skip_all)]
    pub fn update(&mut self, camera: &CameraState) -> Result<FrameReport, CacheError> {
        camera.validate()?;
        let start = Instant::now();
        self.frame += 1;
        let frame = self.frame;
        let mut r = FrameReport {
            frame,
            budget_bytes: self.cfg.budget_bytes,
            ..FrameReport::default()
        };
        self.newly_loaded.clear();
        self.evicted.clear();
        self.refreshed.clear();
        self.errors.clear();
        self.last_camera = Some(*camera);

        // 1. Requests from handles.
        for _ in 0..self.cfg.max_requests_per_frame {
            match self.req_rx.try_recv() {
                Ok(Request::Want(id, p)) => {
                    if let Err(e) = self.world.manifest().check_tile(self.cfg.layer, id) {
                        self.errors.push((id, e));
                        r.failed += 1;
                    } else {
                        self.explicit.insert(id, if p.is_nan() { 0.0 } else { p });
                    }
                }
                Ok(Request::Cancel(id)) => {
                    self.explicit.remove(&id);
                }
                Err(_) => break,
            }
        }

        // 2. Finished loads and write-backs.
        self.drain_loads(&mut r);
        self.drain_writes(&mut r);

        // 3. Selection.
        let mut wants = std::mem::take(&mut self.wants);
        wants.clear();
        self.policy.select(camera, &self.grid, &mut wants);
        for (&id, &p) in &self.explicit {
            wants.push(Want { id, priority: p });
        }
        wants.sort_by(|a, b| {
            a.priority
                .total_cmp(&b.priority)
                .then(b.id.level.cmp(&a.id.level))
                .then(a.id.cmp(&b.id))
        });
        wants.dedup_by_key(|w| w.id);
        r.wanted = wants.len();
        for w in &wants {
            if let Some(e) = self.entries.get_mut(&w.id) {
                let was_marked = matches!(e.slot, Slot::Resident { .. })
                    && (e.wanted_frame.saturating_add(1) < frame || e.evict_after_write);
                if was_marked {
                    r.rescued += 1;
                }
                e.evict_after_write = false;
                e.wanted_frame = frame;
            }
        }

        // 4. Unwanted: cancel queued jobs; resident ones become marked (nothing to do: marking
        //    is "not wanted this frame"). Wanted again: rescue cancelled jobs.
        for e in self.entries.values_mut() {
            if let Slot::InFlight { cell, .. } = &e.slot {
                if e.wanted_frame != frame {
                    if cell
                        .state
                        .compare_exchange(QUEUED, CANCELLED, Ordering::AcqRel, Ordering::Acquire)
                        .is_ok()
                    {
                        r.cancelled += 1;
                    }
                } else if cell
                    .state
                    .compare_exchange(CANCELLED, QUEUED, Ordering::AcqRel, Ordering::Acquire)
                    .is_ok()
                {
                    r.rescued += 1;
                }
            }
        }

        // 5. Issue loads in priority order, evicting marked tiles to make room.
        let mut issued = 0;
        for w in &wants {
            let retry = match self.entries.get(&w.id) {
                None => true,
                Some(Entry {
                    slot: Slot::Failed { frame: f },
                    ..
                }) => frame.saturating_sub(*f) >= self.cfg.retry_failed_frames,
                Some(_) => false,
            };
            if !retry {
                continue;
            }
            if issued >= self.cfg.max_loads_per_frame || self.in_flight >= self.cfg.max_in_flight {
                break;
            }
            if !self.make_room(self.tile_bytes, camera, &mut r) {
                r.starved += 1;
                continue;
            }
            self.issue_load(w.id);
            issued += 1;
        }
        r.loads = issued;
        self.wants = wants;

        // 6. Idle dirty tiles are written back.
        if let Some(idle) = self.cfg.write_back_idle_frames {
            let due: Vec<TileId> = self
                .entries
                .iter()
                .filter(|(_, e)| {
                    e.dirty && e.writing.is_none() && frame.saturating_sub(e.modified_frame) >= idle
                })
                .map(|(&id, _)| id)
                .take(self.cfg.max_writes_per_frame)
                .collect();
            for id in due {
                self.issue_write(id, false);
                r.writes += 1;
            }
        }

        // 7. Report.
        for e in self.entries.values() {
            match &e.slot {
                Slot::Resident { .. } => {
                    r.resident += 1;
                    if e.wanted_frame == frame {
                        r.wanted_resident += 1;
                    }
                }
                Slot::InFlight { .. } => r.in_flight += 1,
                Slot::Failed { .. } => {}
            }
            if e.dirty {
                r.dirty += 1;
            }
        }
        r.ram_bytes = self.ram_bytes;
        r.update_time = start.elapsed();
        if r.loaded + r.failed + r.evictions + r.writes + r.written > 0 {
            tracing::debug!(
                frame = r.frame,
                loaded = r.loaded,
                failed = r.failed,
                evicted = r.evictions,
                writes = r.writes,
                written = r.written,
                ram_bytes = self.ram_bytes,
                "RAM pool traffic"
            );
        }
        Ok(r)
    }

    fn drain_loads(&mut self, r: &mut FrameReport) {
        // At most the jobs in flight can have finished.
        for _ in 0..=self.in_flight {
            let msg = match self.done_rx.try_recv() {
                Ok(m) => m,
                Err(TryRecvError::Empty | TryRecvError::Disconnected) => break,
            };
            let (id, ticket) = match &msg {
                LoadDone::Loaded { id, ticket, .. } | LoadDone::Skipped { id, ticket } => {
                    (*id, *ticket)
                }
            };
            let Some(e) = self.entries.get_mut(&id) else {
                continue;
            };
            match &e.slot {
                Slot::InFlight { ticket: t, .. } if *t == ticket => {}
                _ => continue,
            }
            self.in_flight -= 1;
            if e.reserved {
                e.reserved = false;
                self.ram_bytes -= self.tile_bytes;
            }
            match msg {
                LoadDone::Skipped { .. } => {
                    self.entries.remove(&id);
                }
                LoadDone::Loaded {
                    result: Ok(data), ..
                } => {
                    let zero = Arc::ptr_eq(&data, &self.zero);
                    if !zero {
                        self.ram_bytes += self.tile_bytes;
                    }
                    e.slot = Slot::Resident { data, zero };
                    r.loaded += 1;
                    tracing::trace!(tile = ?id, zero, "tile loaded");
                    self.newly_loaded.push(id);
                }
                LoadDone::Loaded {
                    result: Err(err), ..
                } => {
                    e.slot = Slot::Failed { frame: self.frame };
                    r.failed += 1;
                    tracing::warn!(tile = ?id, error = %err, "tile failed to load; a coarser tile stands in");
                    self.errors.push((id, err));
                }
            }
        }
    }

    fn drain_writes(&mut self, r: &mut FrameReport) {
        for _ in 0..=self.writes_in_flight {
            let done = match self.written_rx.try_recv() {
                Ok(d) => d,
                Err(_) => break,
            };
            self.writes_in_flight -= 1;
            r.written += 1;
            let Some(e) = self.entries.get_mut(&done.id) else {
                continue;
            };
            e.writing = None;
            if e.snapshot_extra {
                e.snapshot_extra = false;
                self.ram_bytes -= self.tile_bytes;
            }
            match done.result {
                Ok(refreshed) => {
                    if e.generation == done.generation {
                        e.dirty = false;
                    }
                    for a in refreshed {
                        self.refreshed.push(a);
                    }
                }
                Err(err) => {
                    // Stays dirty; written again later (on eviction or when idle).
                    e.evict_after_write = false;
                    r.failed += 1;
                    self.errors.push((done.id, err));
                }
            }
            let id = done.id;
            if let Some(e) = self.entries.get(&id)
                && e.evict_after_write
                && !e.dirty
                && e.pins == 0
            {
                self.free(id);
                r.evictions += 1;
            }
        }
        // Ancestors rewritten on disk: clean, unpinned copies are dropped (reloaded when
        // wanted); others are flagged stale.
        for i in 0..self.refreshed.len() {
            let a = self.refreshed[i];
            let Some(e) = self.entries.get_mut(&a) else {
                continue;
            };
            match e.slot {
                Slot::Resident { .. } if !e.dirty && e.pins == 0 && e.writing.is_none() => {
                    self.free(a);
                }
                Slot::Resident { .. } => e.stale = true,
                _ => {}
            }
        }
    }

    /// Frees room for `bytes` by evicting marked tiles (farthest, finest first); dirty victims
    /// are written back first and freed when done. Returns whether the room is there now.
    fn make_room(&mut self, bytes: u64, camera: &CameraState, r: &mut FrameReport) -> bool {
        while self.ram_bytes + bytes > self.cfg.budget_bytes {
            let frame = self.frame;
            let victim = self
                .entries
                .iter()
                .filter(|(_, e)| {
                    matches!(
                        e.slot,
                        Slot::Resident { zero: false, .. } | Slot::Failed { .. }
                    ) && e.wanted_frame != frame
                        && e.pins == 0
                        && e.writing.is_none()
                        && !e.evict_after_write
                })
                .map(|(&id, e)| {
                    let free_now = matches!(e.slot, Slot::Failed { .. });
                    (id, free_now, self.grid.eviction_score(camera.position, id))
                })
                .max_by(|a, b| a.1.cmp(&b.1).then(a.2.total_cmp(&b.2)).then(b.0.cmp(&a.0)));
            let Some((id, _, _)) = victim else {
                return false;
            };
            let dirty = self.entries.get(&id).is_some_and(|e| e.dirty);
            if dirty {
                self.issue_write(id, true);
                r.writes += 1;
            } else {
                let had_bytes = self.free(id);
                r.evictions += 1;
                tracing::trace!(tile = ?id, "tile evicted");
                self.evicted.push(id);
                if !had_bytes {
                    continue;
                }
            }
        }
        true
    }

    /// Drops a tile; returns whether it freed tile bytes.
    fn free(&mut self, id: TileId) -> bool {
        let Some(e) = self.entries.remove(&id) else {
            return false;
        };
        let mut freed = false;
        if let Slot::Resident { zero: false, .. } = e.slot {
            self.ram_bytes -= self.tile_bytes;
            freed = true;
        }
        if e.snapshot_extra {
            self.ram_bytes -= self.tile_bytes;
        }
        freed
    }

    fn issue_load(&mut self, id: TileId) {
        let cell = Arc::new(JobCell {
            state: AtomicU8::new(QUEUED),
        });
        self.next_ticket += 1;
        let ticket = self.next_ticket;
        let mut e = Entry::new(Slot::InFlight {
            ticket,
            cell: cell.clone(),
        });
        e.wanted_frame = self.frame;
        e.reserved = true;
        self.ram_bytes += self.tile_bytes;
        self.entries.insert(id, e);
        self.in_flight += 1;
        if let Some(tx) = &self.load_tx
            && tx.send(LoadJob { id, ticket, cell }).is_err()
        {
            // Workers gone (a panic): report and leave the tile missing.
            self.errors.push((
                id,
                CacheError::Worker {
                    what: "loader",
                    reason: "the load queue is closed".into(),
                },
            ));
        }
    }

    fn issue_write(&mut self, id: TileId, evict_after: bool) {
        let Some(e) = self.entries.get_mut(&id) else {
            return;
        };
        let Slot::Resident { data, .. } = &e.slot else {
            return;
        };
        if e.writing.is_some() {
            e.evict_after_write |= evict_after;
            return;
        }
        e.writing = Some(e.generation);
        e.evict_after_write |= evict_after;
        let job = WriteJob {
            id,
            generation: e.generation,
            data: data.clone(),
        };
        self.writes_in_flight += 1;
        if let Some(tx) = &self.write_tx
            && tx.send(job).is_err()
        {
            self.writes_in_flight -= 1;
            e.writing = None;
        }
    }

    /// The samples of a loaded tile (any loaded state), borrowed for this frame: upload it,
    /// copy it, sample it.
    pub fn tile(&self, id: TileId) -> Option<&TileData> {
        match &self.entries.get(&id)?.slot {
            Slot::Resident { data, .. } => Some(data),
            _ => None,
        }
    }

    /// The loaded tile nearest to `id` in the pyramid: `id` itself, else its closest loaded
    /// ancestor (what a renderer falls back to).
    pub fn best_available(&self, id: TileId) -> Option<(TileId, &TileData)> {
        let mut cur = Some(id);
        while let Some(c) = cur {
            if let Some(d) = self.tile(c) {
                return Some((c, d));
            }
            cur = c
                .parent()
                .filter(|p| p.level < self.grid.levels.len() as u32);
        }
        None
    }

    /// A counter bumped by every [`modify`](Self::modify) / [`write`](Self::write) of a loaded
    /// tile (restarting when the tile is loaded again), `None` when it is not loaded: a copy
    /// made at one generation (a VRAM upload) is stale once the generation differs.
    pub fn generation(&self, id: TileId) -> Option<u64> {
        let e = self.entries.get(&id)?;
        matches!(e.slot, Slot::Resident { .. }).then_some(e.generation)
    }

    /// The state of `id`, `None` if the pool has no record of it.
    pub fn status(&self, id: TileId) -> Option<TileStatus> {
        let e = self.entries.get(&id)?;
        let state = match &e.slot {
            Slot::InFlight { cell, .. } => match cell.state.load(Ordering::Acquire) {
                QUEUED => TileState::Queued,
                LOADING => TileState::Loading,
                _ => TileState::Cancelled,
            },
            Slot::Resident { .. } if e.pins > 0 => TileState::InUse,
            Slot::Resident { .. } if e.wanted_frame == self.frame => TileState::Loaded,
            Slot::Resident { .. } => TileState::MarkedForDeletion,
            Slot::Failed { .. } => TileState::Failed,
        };
        Some(TileStatus {
            state,
            dirty: e.dirty,
            writing: e.writing.is_some(),
            zero: matches!(e.slot, Slot::Resident { zero: true, .. }),
            stale: e.stale,
        })
    }

    /// Every tile the pool has a record of (queued, loading, loaded, failed), with its state:
    /// for tools and overlays that show the cache at work. Unordered.
    pub fn statuses(&self) -> Vec<(TileId, TileStatus)> {
        self.entries
            .keys()
            .filter_map(|&id| Some((id, self.status(id)?)))
            .collect()
    }

    /// Pins a loaded tile (in use: not evicted until unpinned). Returns false if not loaded.
    pub fn pin(&mut self, id: TileId) -> bool {
        match self.entries.get_mut(&id) {
            Some(e) if matches!(e.slot, Slot::Resident { .. }) => {
                e.pins = e.pins.saturating_add(1);
                true
            }
            _ => false,
        }
    }

    /// Releases one pin.
    pub fn unpin(&mut self, id: TileId) {
        if let Some(e) = self.entries.get_mut(&id) {
            e.pins = e.pins.saturating_sub(1);
            if e.pins == 0 {
                e.stale = false;
            }
        }
    }

    /// Modifies a loaded tile in place and marks it dirty. A tile sharing the zero tile, or
    /// whose previous version is still being written back, is copied first (copy on write);
    /// the copy must fit in the budget, evicting marked tiles if needed
    /// ([`CacheError::OverBudget`] otherwise).
    pub fn modify<R>(
        &mut self,
        id: TileId,
        f: impl FnOnce(&mut TileData) -> R,
    ) -> Result<R, CacheError> {
        let (needs_copy, zero) = match self.entries.get(&id) {
            Some(Entry {
                slot: Slot::Resident { data, zero },
                writing,
                ..
            }) => (
                *zero || (writing.is_some() && Arc::strong_count(data) > 1),
                *zero,
            ),
            _ => return Err(CacheError::NotResident { id }),
        };
        if needs_copy {
            // Pin while making room so the tile itself is never the victim.
            if let Some(e) = self.entries.get_mut(&id) {
                e.pins += 1;
            }
            let camera = self
                .last_camera
                .unwrap_or(CameraState::at(glam::Vec3::ZERO));
            let mut r = FrameReport::default();
            let ok = self.make_room(self.tile_bytes, &camera, &mut r);
            if let Some(e) = self.entries.get_mut(&id) {
                e.pins -= 1;
            }
            if !ok {
                return Err(CacheError::OverBudget {
                    budget: self.cfg.budget_bytes,
                    used: self.ram_bytes,
                    needed: self.tile_bytes,
                });
            }
            self.ram_bytes += self.tile_bytes;
        }
        let frame = self.frame;
        let e = self
            .entries
            .get_mut(&id)
            .ok_or(CacheError::NotResident { id })?;
        if needs_copy && !zero {
            // The writer keeps the old snapshot alive until it finishes.
            e.snapshot_extra = true;
        }
        let Slot::Resident { data, zero: z } = &mut e.slot else {
            return Err(CacheError::NotResident { id });
        };
        if *z {
            // Copy on write of the shared zero tile: the tile now owns its samples.
            *data = Arc::new((**data).clone());
            *z = false;
        }
        let out = f(Arc::make_mut(data));
        e.dirty = true;
        e.generation += 1;
        e.modified_frame = frame;
        Ok(out)
    }

    /// Replaces a loaded tile's samples (a readback of a tile deformed on the GPU) and marks
    /// it dirty.
    pub fn write(&mut self, id: TileId, data: TileData) -> Result<(), CacheError> {
        self.world.check_data(self.cfg.layer, &data)?;
        self.modify(id, move |d| *d = data)
    }

    /// Pastes `heights` into the loaded tile `id` with its first sample at `rect.min` (tile
    /// texels; `rect` inside the tile, `heights` of its size) and marks the tile dirty: how the
    /// rect a GPU deformation changed, read back from its atlas slot, reaches RAM. Copy on
    /// write as [`modify`](Self::modify). A height-layer call only.
    pub fn write_rect(
        &mut self,
        id: TileId,
        rect: Rect,
        heights: &Grid<u16>,
    ) -> Result<(), CacheError> {
        let ts = self.world.manifest().tile_size;
        if heights.size() != rect.size || !Rect::from_size(UVec2::splat(ts)).contains_rect(&rect) {
            return Err(CoreError::RegionOutOfBounds {
                rect,
                map_size: UVec2::splat(ts),
            }
            .into());
        }
        match self.tile(id) {
            Some(TileData::U16(_)) => {}
            Some(TileData::U8(_)) => {
                return Err(CacheError::NoSuchLayer {
                    layer: Layer::Height,
                });
            }
            None => return Err(CacheError::NotResident { id }),
        }
        self.modify(id, |tile| match tile.as_u16_mut() {
            Some(grid) => grid.paste(heights, rect.min),
            None => Ok(()),
        })??;
        Ok(())
    }

    /// Fills `out` with the level-0 heights of `rect` (world texels, inside the world; `out` of
    /// its size) from the loaded tiles, never waiting: each texel from level 0 where its tile
    /// is loaded, else the nearest sample of the finest loaded coarser level, else the
    /// world's fill value. Returns how many texels did not come from level 0 (0: exact). What
    /// a collision window around the camera is filled from; the work is `rect`'s area plus one
    /// lookup per tile it touches.
    pub fn read_region(&self, rect: Rect, out: &mut Grid<u16>) -> Result<u64, CacheError> {
        let m = *self.world.manifest();
        if self.cfg.layer != Layer::Height {
            return Err(CacheError::NoSuchLayer {
                layer: Layer::Height,
            });
        }
        if out.size() != rect.size || !Rect::from_size(m.world_size).contains_rect(&rect) {
            return Err(CoreError::RegionOutOfBounds {
                rect,
                map_size: m.world_size,
            }
            .into());
        }
        if rect.is_empty() {
            return Ok(0);
        }
        let ts = m.tile_size;
        let lo = rect.min.as_uvec2();
        let hi = lo + rect.size; // exclusive
        let mut coarse = 0u64;
        for ty in lo.y / ts..=(hi.y - 1) / ts {
            for tx in lo.x / ts..=(hi.x - 1) / ts {
                let origin = UVec2::new(tx, ty) * ts;
                let a = lo.max(origin);
                let b = hi.min(origin + ts);
                let found = self.best_available(TileId::new(0, tx, ty));
                for y in a.y..b.y {
                    let dst =
                        &mut out.row_mut(y - lo.y)[(a.x - lo.x) as usize..(b.x - lo.x) as usize];
                    match found {
                        Some((t, TileData::U16(g))) if t.level == 0 => {
                            let row = g.row(y - origin.y);
                            dst.copy_from_slice(
                                &row[(a.x - origin.x) as usize..(b.x - origin.x) as usize],
                            );
                        }
                        Some((t, TileData::U16(g))) => {
                            // Nearest sample of the coarser tile `t` (level < 32: the pyramid's).
                            let l = t.level;
                            let base = UVec2::new(t.x, t.y) * ts;
                            let cy = ((y >> l) - base.y).min(ts - 1);
                            let row = g.row(cy);
                            for (i, d) in dst.iter_mut().enumerate() {
                                let cx = (((a.x + i as u32) >> l) - base.x).min(ts - 1);
                                *d = row[cx as usize];
                            }
                            coarse += u64::from(b.x - a.x);
                        }
                        _ => {
                            dst.fill(m.height_fill);
                            coarse += u64::from(b.x - a.x);
                        }
                    }
                }
            }
        }
        Ok(coarse)
    }

    /// Queues every dirty tile for write-back now (they stay loaded).
    pub fn flush(&mut self) -> usize {
        let dirty: Vec<TileId> = self
            .entries
            .iter()
            .filter(|(_, e)| e.dirty && e.writing.is_none())
            .map(|(&id, _)| id)
            .collect();
        let n = dirty.len();
        for id in dirty {
            self.issue_write(id, false);
        }
        n
    }

    /// Blocks until no load or write-back is in flight, or `timeout` passes. For shutdown,
    /// tests and tools: never call it on the frame thread.
    pub fn wait_idle(&mut self, timeout: Duration) -> Result<(), CacheError> {
        let deadline = Instant::now() + timeout;
        let mut r = FrameReport::default();
        loop {
            self.drain_loads(&mut r);
            self.drain_writes(&mut r);
            if self.in_flight == 0 && self.writes_in_flight == 0 {
                return Ok(());
            }
            if Instant::now() >= deadline {
                return Err(CacheError::Timeout {
                    what: "RAM pool loads and write-backs",
                    timeout_ms: timeout.as_millis() as u64,
                });
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// Writes back every dirty tile and waits for it (and for loads in flight) up to `timeout`.
    pub fn flush_and_wait(&mut self, timeout: Duration) -> Result<(), CacheError> {
        self.flush();
        self.wait_idle(timeout)?;
        if self.errors.is_empty() {
            Ok(())
        } else {
            Err(self.errors.remove(0).1)
        }
    }

    /// Tiles that arrived in the last update (for the VRAM pool's uploads).
    pub fn newly_loaded(&self) -> &[TileId] {
        &self.newly_loaded
    }

    /// Tiles evicted in the last update.
    pub fn evicted(&self) -> &[TileId] {
        &self.evicted
    }

    /// Coarser tiles rewritten on disk after write-backs in the last update (a VRAM copy of
    /// them is stale).
    pub fn refreshed(&self) -> &[TileId] {
        &self.refreshed
    }

    /// Errors of the last update, each naming its tile (corrupt files, failed writes,
    /// requests outside the world).
    pub fn errors(&self) -> &[(TileId, CacheError)] {
        &self.errors
    }

    /// Bytes recomputed from the allocations themselves (distinct tile buffers held, plus
    /// reservations and the zero tile): equals [`ram_bytes`](Self::ram_bytes) unless the
    /// accounting is wrong. For tests and debugging; O(tiles held).
    pub fn audit_ram_bytes(&self) -> u64 {
        let mut total = self.tile_bytes; // the zero tile
        for e in self.entries.values() {
            match &e.slot {
                Slot::Resident { data, zero: false } => {
                    total += data.byte_len();
                }
                Slot::InFlight { .. } if e.reserved => total += self.tile_bytes,
                _ => {}
            }
            if e.snapshot_extra {
                total += self.tile_bytes;
            }
        }
        total
    }

    /// Ids of every loaded tile (any loaded state), unordered.
    pub fn resident_ids(&self) -> Vec<TileId> {
        self.entries
            .iter()
            .filter(|(_, e)| matches!(e.slot, Slot::Resident { .. }))
            .map(|(&id, _)| id)
            .collect()
    }

    /// Writes back dirty tiles, waits up to `timeout`, and stops the threads.
    pub fn shutdown(mut self, timeout: Duration) -> Result<(), CacheError> {
        let res = self.flush_and_wait(timeout);
        self.stop_threads();
        res
    }

    fn stop_threads(&mut self) {
        self.load_tx = None;
        self.write_tx = None;
        for t in self.threads.drain(..) {
            // Threads exit once their queue is closed and drained; a panicked one is reported
            // by its join result, which has nothing left to tell the caller here.
            let _ = t.join();
        }
    }
}

impl Drop for RamPool {
    /// Best effort: writes back dirty tiles (waiting at most 10 s), then stops the threads.
    /// Call [`RamPool::shutdown`] to see errors.
    fn drop(&mut self) {
        if self.load_tx.is_some() {
            let _ = self.flush_and_wait(Duration::from_secs(10));
            self.stop_threads();
        }
    }
}

fn loader(world: World, layer: Layer, rx: Receiver<LoadJob>, tx: Sender<LoadDone>) {
    while let Ok(job) = rx.recv() {
        // Take the job (QUEUED -> LOADING) or make its cancellation final (CANCELLED ->
        // SKIPPED); retry if the frame thread swapped the state in between.
        let take = loop {
            match job.cell.state.load(Ordering::Acquire) {
                QUEUED => {
                    if job
                        .cell
                        .state
                        .compare_exchange(QUEUED, LOADING, Ordering::AcqRel, Ordering::Acquire)
                        .is_ok()
                    {
                        break true;
                    }
                }
                CANCELLED => {
                    if job
                        .cell
                        .state
                        .compare_exchange(CANCELLED, SKIPPED, Ordering::AcqRel, Ordering::Acquire)
                        .is_ok()
                    {
                        break false;
                    }
                }
                _ => break false,
            }
        };
        let msg = if take {
            LoadDone::Loaded {
                id: job.id,
                ticket: job.ticket,
                result: world.load_tile(layer, job.id),
            }
        } else {
            LoadDone::Skipped {
                id: job.id,
                ticket: job.ticket,
            }
        };
        if tx.send(msg).is_err() {
            return;
        }
    }
}

fn writer(
    world: World,
    layer: Layer,
    propagate: bool,
    rx: Receiver<WriteJob>,
    tx: Sender<WriteDone>,
) {
    while let Ok(job) = rx.recv() {
        let result = world.write_tile(layer, job.id, &job.data).and_then(|_| {
            if propagate {
                rebuild_ancestors(&world, &[job.id])
            } else {
                Ok(Vec::new())
            }
        });
        drop(job.data);
        if tx
            .send(WriteDone {
                id: job.id,
                generation: job.generation,
                result,
            })
            .is_err()
        {
            return;
        }
    }
}
