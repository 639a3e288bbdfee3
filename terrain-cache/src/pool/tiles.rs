//! What consumers read and change of the loaded tiles: their samples (or the best coarser
//! ones), states, pins that keep a tile from eviction, modifications that make it dirty for
//! write-back, and a level-0 region copied out of whatever is loaded.

use super::workers::{LOADING, QUEUED};
use super::{Entry, FrameReport, RamPool, Slot, TileState, TileStatus};
use crate::CacheError;
use crate::policy::CameraState;
use crate::tile::{Layer, TileData, TileId};
use glam::UVec2;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use terrain_core::{CoreError, Grid, Rect};

impl RamPool {
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
            Some(TileData::U8(_) | TileData::Rgba8(_)) => {
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
}
