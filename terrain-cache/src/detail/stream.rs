//! The detail cache's threads (Fikkan 2013, sec. 5.2-5.3, as the RAM pool's): loaders read and
//! decode tiles, a writer stores dirty tiles atomically, and the frame thread queues jobs and
//! takes what finished without ever waiting on the store. Each read has one atomic state: it
//! is cancelled with one compare-and-swap when its tile leaves the band before a loader takes
//! it, and rescued by the reverse swap if the tile comes back first. A read superseded on the
//! frame thread (its tile was read there, or replaced whole) is forgotten: its result, told
//! apart by its ticket, is dropped when it arrives.

use crate::pool::workers::{
    CANCELLED, JobCell, LoadDone, LoadJob, QUEUED, SKIPPED, WriteDone, WriteJob, loader, writer,
};
use crate::{CacheError, Layer, TileData, TileId, TileRead, World};
use crossbeam_channel::{Receiver, Sender, TryRecvError, unbounded};
use glam::UVec2;
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};
use std::thread::JoinHandle;
use terrain_core::Grid;

/// Loader threads: a band crossing asks for three tiles at most, which two loaders read in
/// two rounds.
const LOADERS: usize = 2;

/// A tile's stored texels: `None` for the shared zero tile (no file).
pub(super) type Texels = Option<Grid<u8>>;

/// A finished write-back: the tile, the generation it wrote, and whether it is stored.
pub(super) type Written = (UVec2, u64, Result<(), CacheError>);

/// The channels to the loaders and the writer, and the jobs in flight.
#[derive(Debug)]
pub(super) struct Streams {
    load_tx: Option<Sender<LoadJob>>,
    done_rx: Receiver<LoadDone>,
    write_tx: Option<Sender<WriteJob>>,
    written_rx: Receiver<WriteDone>,
    threads: Vec<JoinHandle<()>>,
    /// The world's shared zero tile (what a loader returns for a tile without a file).
    zero: Arc<TileData>,
    tile_size: u32,
    next_ticket: u64,
    /// Reads in flight: the ticket of the one whose result is wanted, and its state.
    reads: HashMap<UVec2, (u64, Arc<JobCell>)>,
    /// Write-backs in flight: the generation each writes.
    writes: HashMap<UVec2, u64>,
}

impl Streams {
    /// Starts the loaders and the writer over `world`'s detail layer.
    pub(super) fn start(world: &World) -> Result<Self, CacheError> {
        let zero = world.zero_tile(Layer::Detail)?;
        let tile_size = world.manifest().layer_tile_size(Layer::Detail)?;
        let (load_tx, load_rx) = unbounded::<LoadJob>();
        let (done_tx, done_rx) = unbounded::<LoadDone>();
        let (write_tx, write_rx) = unbounded::<WriteJob>();
        let (written_tx, written_rx) = unbounded::<WriteDone>();
        let mut streams = Self {
            load_tx: Some(load_tx),
            done_rx,
            write_tx: Some(write_tx),
            written_rx,
            threads: Vec::with_capacity(LOADERS + 1),
            zero,
            tile_size,
            next_ticket: 0,
            reads: HashMap::new(),
            writes: HashMap::new(),
        };
        let spawn = |name: String, what, f: Box<dyn FnOnce() + Send>| {
            std::thread::Builder::new()
                .name(name)
                .spawn(f)
                .map_err(|e| CacheError::Worker {
                    what,
                    reason: e.to_string(),
                })
        };
        for i in 0..LOADERS {
            let (w, rx, tx) = (world.clone(), load_rx.clone(), done_tx.clone());
            let f = Box::new(move || loader(w, Layer::Detail, rx, tx));
            // On an error `streams` drops here, closing the queues: the threads started exit.
            streams.threads.push(spawn(
                format!("terrain-detail-load-{i}"),
                "detail loader",
                f,
            )?);
        }
        let w = world.clone();
        let f = Box::new(move || writer(w, Layer::Detail, false, write_rx, written_tx));
        streams
            .threads
            .push(spawn("terrain-detail-writer".into(), "detail writer", f)?);
        Ok(streams)
    }

    /// Whether a read of `t` is in flight.
    pub(super) fn reading(&self, t: UVec2) -> bool {
        self.reads.contains_key(&t)
    }

    /// Whether a write-back of `t` is in flight.
    pub(super) fn writing(&self, t: UVec2) -> bool {
        self.writes.contains_key(&t)
    }

    /// Write-backs in flight.
    pub(super) fn writes_in_flight(&self) -> usize {
        self.writes.len()
    }

    /// Reads of tiles the caller no longer wants are cancelled (if no loader took them yet).
    pub(super) fn cancel_reads(&mut self, wanted: impl Fn(UVec2) -> bool) {
        for (t, (_, cell)) in &self.reads {
            if !wanted(*t) {
                swap(cell, QUEUED, CANCELLED);
            }
        }
    }

    /// Asks for `t`'s stored texels: a read already in flight is kept (rescued if cancelled
    /// and not skipped yet), else a new one is queued. Fails only when the loaders are gone.
    pub(super) fn request_read(&mut self, t: UVec2) -> Result<(), CacheError> {
        if let Some((_, cell)) = self.reads.get(&t) {
            swap(cell, CANCELLED, QUEUED);
            if cell.state.load(Ordering::Acquire) != SKIPPED {
                return Ok(());
            }
        }
        let cell = Arc::new(JobCell {
            state: AtomicU8::new(QUEUED),
        });
        self.next_ticket += 1;
        let job = LoadJob {
            id: TileId::new(0, t.x, t.y),
            ticket: self.next_ticket,
            cell: cell.clone(),
        };
        let sent = self.load_tx.as_ref().is_some_and(|tx| tx.send(job).is_ok());
        if !sent {
            self.reads.remove(&t);
            return Err(gone("detail loader"));
        }
        self.reads.insert(t, (self.next_ticket, cell));
        Ok(())
    }

    /// Forgets the read of `t` in flight, if any: its result is dropped when it arrives.
    pub(super) fn supersede(&mut self, t: UVec2) {
        if let Some((_, cell)) = self.reads.remove(&t) {
            swap(&cell, QUEUED, CANCELLED);
        }
    }

    /// The reads that finished since the last call, each wanted result once (never waits).
    pub(super) fn finished_reads(&mut self) -> Vec<(UVec2, Result<Texels, CacheError>)> {
        let mut out = Vec::new();
        loop {
            let msg = match self.done_rx.try_recv() {
                Ok(m) => m,
                Err(TryRecvError::Empty | TryRecvError::Disconnected) => break,
            };
            let (id, ticket, result) = match msg {
                LoadDone::Loaded { id, ticket, result } => (id, ticket, Some(result)),
                LoadDone::Skipped { id, ticket } => (id, ticket, None),
            };
            let t = UVec2::new(id.x, id.y);
            if self.reads.get(&t).is_none_or(|(want, _)| *want != ticket) {
                continue;
            }
            self.reads.remove(&t);
            if let Some(result) = result {
                out.push((t, result.and_then(|data| self.texels(data))));
            }
        }
        out
    }

    /// A loaded tile's texels, taken out of the loader's `Arc` (its only owner by now).
    fn texels(&self, data: Arc<TileData>) -> Result<Texels, CacheError> {
        if Arc::ptr_eq(&data, &self.zero) {
            return Ok(None);
        }
        match Arc::try_unwrap(data).unwrap_or_else(|shared| (*shared).clone()) {
            TileData::U8(grid) => Ok(Some(grid)),
            other => Err(mismatch(self.tile_size, &other)),
        }
    }

    /// Queues the write-back of `texels` (the zero tile: its file removed) as `generation`.
    /// Fails only when the writer is gone.
    pub(super) fn write(
        &mut self,
        t: UVec2,
        generation: u64,
        texels: Grid<u8>,
    ) -> Result<(), CacheError> {
        let job = WriteJob {
            id: TileId::new(0, t.x, t.y),
            generation,
            data: Arc::new(TileData::U8(texels)),
        };
        let sent = self
            .write_tx
            .as_ref()
            .is_some_and(|tx| tx.send(job).is_ok());
        if !sent {
            return Err(gone("detail writer"));
        }
        self.writes.insert(t, generation);
        Ok(())
    }

    /// The write-backs that finished since the last call (never waits).
    pub(super) fn finished_writes(&mut self) -> Vec<Written> {
        let mut out = Vec::new();
        while let Ok(done) = self.written_rx.try_recv() {
            out.extend(self.written(done));
        }
        out
    }

    /// Waits for the next write-back in flight to finish (the end of a run); `None` when none
    /// is in flight. Fails when the writer is gone with writes unfinished.
    pub(super) fn wait_write(&mut self) -> Result<Option<Written>, CacheError> {
        while !self.writes.is_empty() {
            let done = self.written_rx.recv().map_err(|_| gone("detail writer"))?;
            if let Some(w) = self.written(done) {
                return Ok(Some(w));
            }
        }
        Ok(None)
    }

    fn written(&mut self, done: WriteDone) -> Option<Written> {
        let t = UVec2::new(done.id.x, done.id.y);
        self.writes.remove(&t)?;
        Some((t, done.generation, done.result.map(|_| ())))
    }
}

impl Drop for Streams {
    /// Cancels the queued reads and stops the threads; the writer finishes the write-backs
    /// queued before it exits (a tile queued for write-back is stored).
    fn drop(&mut self) {
        for (_, cell) in self.reads.values() {
            swap(cell, QUEUED, CANCELLED);
        }
        self.load_tx = None;
        self.write_tx = None;
        for t in self.threads.drain(..) {
            // A panicked thread has nothing left to tell here.
            let _ = t.join();
        }
    }
}

/// Reads `t`'s stored texels on the caller's thread.
pub(super) fn read_now(world: &World, t: UVec2) -> Result<Texels, CacheError> {
    let id = TileId::new(0, t.x, t.y);
    match world.read_tile(Layer::Detail, id)? {
        TileRead::Stored(TileData::U8(grid)) => Ok(Some(grid)),
        TileRead::Stored(other) => {
            let size = world.manifest().layer_tile_size(Layer::Detail)?;
            Err(mismatch(size, &other))
        }
        TileRead::Zero => Ok(None),
    }
}

/// A detail tile file that decoded to other samples than u8.
fn mismatch(size: u32, found: &TileData) -> CacheError {
    CacheError::TileDataMismatch {
        layer: Layer::Detail,
        expected_bits: 8,
        size,
        found_bits: found.bits(),
        found_w: found.size().x,
        found_h: found.size().y,
    }
}

/// One compare-and-swap of a read's state (a no-op when it is in another state).
fn swap(cell: &JobCell, from: u8, to: u8) {
    let _ = cell
        .state
        .compare_exchange(from, to, Ordering::AcqRel, Ordering::Acquire);
}

fn gone(what: &'static str) -> CacheError {
    CacheError::Worker {
        what,
        reason: "its queue is closed (the thread stopped)".into(),
    }
}
