//! The RAM pool (Fikkan 2013, sec. 4.2, 5.2-5.4.1): decoded tiles held within a memory budget, loaded
//! by worker threads and written back by a writer thread; the frame thread talks to them only
//! through lock-free queues (crossbeam channels and one atomic state per job) and never waits
//! on I/O.
//!
//! # States
//!
//! A tile is *queued* (a load job is in the queue), *loading* (a worker took the job), *loaded*,
//! *in use* (loaded and pinned by a consumer, e.g. the VRAM pool, so it is not evicted),
//! *marked for deletion* (loaded but no longer wanted: dropped when memory is needed, rescued
//! without I/O if wanted again first, Fikkan 2013, sec. 5.3) or *failed* (its file is corrupt:
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
//!
//! # Layout
//!
//! This module holds the public types and the pool's state; `frame` is the frame thread's
//! per-frame step ([`RamPool::update`]) and write-back, `tiles` what consumers read and change
//! of the loaded tiles, `workers` the loader and writer threads with the jobs they exchange.

mod frame;
pub(crate) mod journal;
mod tiles;
mod window_fill;
pub(crate) mod workers;

pub use window_fill::{PoolWindowSource, WindowFill};

use crate::CacheError;
use crate::policy::{CameraState, SelectionPolicy, SphericalSelection, TileGrid, Want};
use crate::tile::{Layer, TileData, TileId};
use crate::world::World;
use crossbeam_channel::{Receiver, Sender, unbounded};
use std::collections::{HashMap, HashSet};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;
use workers::{JobCell, LoadDone, LoadJob, WriteDone, WriteJob, loader, writer};

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
    /// ([`rebuild_ancestors_shared`](crate::build::rebuild_ancestors_shared)) on the writer
    /// thread.
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
    /// Tiles [`RamPool::reload`] named, handled at the next update.
    to_reload: HashSet<TileId>,
    /// Tickets of loads in flight when their tile was named to reload: discarded on arrival.
    outdated: HashSet<u64>,
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

    /// A pool over `world` selecting with `policy`. A height pool that propagates to coarser
    /// levels first rebuilds the ancestors of write-backs a previous writer left unfinished
    /// (killed between a tile and its ancestors; see the write-back journal).
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
        if cfg.propagate_to_coarser && cfg.layer == Layer::Height {
            // A previous writer killed mid-write-back left stale ancestors: rebuilt before any
            // load can read them. A read-only store has nothing to fix with.
            match journal::recover(&world) {
                Ok(0) | Err(CacheError::ReadOnly { .. }) => {}
                Ok(n) => tracing::info!(tiles = n, "recovered interrupted write-backs"),
                Err(e) => return Err(e),
            }
        }
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
            to_reload: HashSet::new(),
            outdated: HashSet::new(),
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
