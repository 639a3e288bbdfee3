//! The frame thread's step, [`RamPool::update`]: requests applied, finished loads and
//! write-backs taken in, the selection made, room made by evicting marked tiles, and loads and
//! write-backs issued within the per-frame limits; plus what the last step did, and flushing
//! and waiting for the threads (for shutdown and tools).

use super::workers::{CANCELLED, JobCell, LoadDone, LoadJob, QUEUED, WriteJob};
use super::{Entry, FrameReport, RamPool, Request, Slot};
use crate::CacheError;
use crate::policy::{CameraState, Want};
use crate::tile::TileId;
use crossbeam_channel::TryRecvError;
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};
use std::time::{Duration, Instant};

impl RamPool {
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
        self.take_reloads();

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
            // Read before its file was rewritten (reload): dropped, loaded again when wanted.
            let outdated = self.outdated.remove(&ticket);
            match msg {
                _ if outdated => {
                    self.entries.remove(&id);
                }
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
    pub(super) fn make_room(
        &mut self,
        bytes: u64,
        camera: &CameraState,
        r: &mut FrameReport,
    ) -> bool {
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

    /// Tiles rewritten on disk under the pool in the last update: coarser tiles after its
    /// write-backs, and those named by [`reload`](Self::reload) (a VRAM copy of them is stale).
    pub fn refreshed(&self) -> &[TileId] {
        &self.refreshed
    }

    /// Names tiles whose files were rewritten by someone else (a writer of the world's paint or
    /// colour, `terrain_cache::overlays`, or another process). At the next update a clean
    /// loaded copy is dropped and loaded again when wanted, a load in flight is discarded when
    /// it arrives, a failed tile is retried, and the tiles are listed in
    /// [`refreshed`](Self::refreshed), so the VRAM pool uploads them again. A copy changed in
    /// this pool and not yet written back is kept (flagged stale): its write-back would win.
    /// Ids outside the pool's layer's pyramid are ignored (an id names no layer: name only
    /// this layer's tiles).
    pub fn reload(&mut self, ids: &[TileId]) {
        let m = *self.world.manifest();
        let layer = self.cfg.layer;
        self.to_reload
            .extend(ids.iter().filter(|&&id| m.check_tile(layer, id).is_ok()));
    }

    /// Starts the update's handling of the tiles [`reload`](Self::reload) named: the loaded
    /// copies are dropped with the coarser tiles write-backs refresh (`drain_writes`).
    fn take_reloads(&mut self) {
        let ids: Vec<TileId> = self.to_reload.drain().collect();
        for id in ids {
            match self.entries.get(&id).map(|e| &e.slot) {
                Some(Slot::InFlight { ticket, .. }) => {
                    self.outdated.insert(*ticket);
                }
                Some(Slot::Failed { .. }) => {
                    self.entries.remove(&id);
                }
                _ => {}
            }
            self.refreshed.push(id);
        }
    }

    /// Errors of the last update, each naming its tile (corrupt files, failed writes,
    /// requests outside the world).
    pub fn errors(&self) -> &[(TileId, CacheError)] {
        &self.errors
    }
}
