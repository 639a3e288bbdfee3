//! Stamps on a streamed world: [`TileStamps`] applies each stamp (world metres) to every
//! level-0 tile it touches, once each, as the tiles become resident, and carries the protocol
//! that keeps a GPU deformation from being lost on its way back to RAM (Flower 2010, sec.
//! 3.2.3: the GPU's tiles are the truth, RAM receives them by readback):
//!
//! 1. **hold**: the tile's VRAM slot is held ([`VramPool::hold`]) before the stamp, so the slot
//!    is current and is neither re-uploaded nor evicted while its change is on the way;
//! 2. **pin**: the RAM tile is pinned ([`RamPool::pin`]) per rect in flight, so the readback
//!    has a tile to land in;
//! 3. **read back**: the caller's [`TileDeformer`] stamps the slot and requests the changed
//!    rects, returning a ticket per rect; [`TileStamps::receive`] writes an arrived rect into
//!    the RAM tile (which becomes dirty and is written back by the pool);
//! 4. **release**: the pin and the hold end with the RAM tile's new version, so the slot
//!    counts as current for it and is not uploaded again.
//!
//! A tile in RAM but not in a VRAM slot (or without a GPU) is stamped on the CPU in RAM
//! instead; stamps whose tiles never became resident go straight into the world's files at
//! the end ([`TileStamps::finish_into_world`]). Either way each tile receives each stamp
//! exactly once. terrain-cache names no GPU type: the deformer is the caller's.

use crate::error::CacheError;
use crate::manifest::Manifest;
use crate::pool::RamPool;
use crate::tile::{Layer, TileId};
use crate::vram::VramPool;
use crate::world::World;
use glam::{IVec2, UVec2};
use std::collections::HashMap;
use terrain_core::{CoarseMap, Grid, Rect, StampPlacement, WrapMode};

/// A stamp touches at most this many level-0 tiles (a footprint up to one tile wide touches
/// at most 4; the limit keeps a huge footprint's work bounded).
pub const MAX_TILES_PER_STAMP: usize = 64;

/// The deformer contract, in terrain-core (terrain-gpu implements it without naming this crate).
pub use terrain_core::TileDeformer;

/// Why a [`TileStamps`] call failed.
#[derive(Debug, thiserror::Error)]
pub enum TileStampError<E> {
    /// The RAM pool or the world refused (a write, a tile not resident).
    #[error(transparent)]
    Cache(#[from] CacheError),
    /// The caller's deformer failed.
    #[error("tile stamp failed: {0}")]
    Deformer(E),
    /// A readback arrived with a ticket nobody asked for (or twice).
    #[error("a tile readback with ticket {ticket} nobody asked for")]
    UnknownTicket {
        /// The ticket.
        ticket: u64,
    },
    /// A readback arrived for another rect than requested, or of another size.
    #[error("tile {id}: asked for {asked:?}, got {got:?}")]
    WrongRect {
        /// The tile.
        id: TileId,
        /// The rect requested.
        asked: Rect,
        /// The rect delivered.
        got: Rect,
    },
}

/// A stamp waiting for some of its tiles.
#[derive(Debug, Clone)]
struct Pending<K> {
    kind: K,
    placement: StampPlacement,
    /// The tiles it touches, and which are done.
    tiles: Vec<(TileId, bool)>,
}

/// What one [`TileStamps::apply`] did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TileStampReport {
    /// Rects changed on the CPU this call, in world texels (level 0), with their new heights:
    /// for collision and overviews (GPU rects come through [`TileStamps::receive`]).
    pub changed: Vec<(Rect, Grid<u16>)>,
    /// Tiles stamped on the GPU this call.
    pub gpu_tiles: u32,
    /// Tiles stamped on the CPU this call.
    pub cpu_tiles: u32,
}

/// Stamps on a streamed world, applied tile by tile as tiles become resident (see the
/// module docs for the protocol).
#[derive(Debug)]
pub struct TileStamps<K> {
    manifest: Manifest,
    pending: Vec<Pending<K>>,
    /// Rects stamped on the GPU on their way back: ticket -> (tile, rect in it).
    in_flight: HashMap<u64, (TileId, Rect)>,
    /// A tile-sized map the CPU stamps go through.
    scratch: CoarseMap,
}

impl<K> TileStamps<K> {
    /// Stamps on the world `manifest` describes (its level-0 tiles).
    pub fn new(manifest: &Manifest) -> Result<Self, CacheError> {
        let ts = manifest.tile_size;
        let scratch = CoarseMap::new(
            Grid::new(ts, ts, 0u16)?,
            manifest.encoding,
            manifest.texel_size,
            WrapMode::Clamp,
        )?;
        Ok(Self {
            manifest: *manifest,
            pending: Vec::new(),
            in_flight: HashMap::new(),
            scratch,
        })
    }

    /// Queues `kind` at `placement` (world metres). Returns the number of level-0 tiles it
    /// touches (0 for a footprint off the world: nothing is queued). Fails on a footprint that
    /// touches more than [`MAX_TILES_PER_STAMP`] tiles.
    pub fn push(&mut self, kind: K, placement: StampPlacement) -> Result<usize, CacheError> {
        let tiles = self.tiles_of(&placement)?;
        if tiles.len() > MAX_TILES_PER_STAMP {
            return Err(CacheError::Core(terrain_core::CoreError::OutOfRange {
                what: "level-0 tiles a tile stamp touches",
                value: tiles.len() as f64,
                expected: "at most 64 (MAX_TILES_PER_STAMP)",
            }));
        }
        let n = tiles.len();
        if n > 0 {
            self.pending.push(Pending {
                kind,
                placement,
                tiles: tiles.into_iter().map(|t| (t, false)).collect(),
            });
        }
        Ok(n)
    }

    /// Stamps not yet applied to every tile they touch.
    pub fn pending(&self) -> usize {
        self.pending.len()
    }

    /// The tiles queued stamps have not reached yet (sorted, each once): what
    /// [`TileStamps::finish_into_world`] would write.
    pub(crate) fn pending_tiles(&self) -> Vec<TileId> {
        let mut tiles: Vec<TileId> = (self.pending.iter())
            .flat_map(|p| p.tiles.iter().filter(|(_, done)| !done).map(|(id, _)| *id))
            .collect();
        tiles.sort_unstable_by_key(|id| (id.level, id.y, id.x));
        tiles.dedup();
        tiles
    }

    /// Rects stamped on the GPU whose readback has not arrived.
    pub fn in_flight(&self) -> usize {
        self.in_flight.len()
    }

    /// The level-0 tiles a footprint touches (world texels clipped to the world).
    fn tiles_of(&self, placement: &StampPlacement) -> Result<Vec<TileId>, CacheError> {
        let footprint = placement.footprint(self.manifest.texel_size)?;
        let Some(rect) = footprint.intersect(&Rect::from_size(self.manifest.world_size)) else {
            return Ok(Vec::new());
        };
        let ts = self.manifest.tile_size as i32;
        let (lo, hi) = (rect.min / ts, (rect.max() - IVec2::ONE) / ts);
        let count = (i64::from(hi.x - lo.x) + 1) * (i64::from(hi.y - lo.y) + 1);
        if count > MAX_TILES_PER_STAMP as i64 {
            return Err(CacheError::Core(terrain_core::CoreError::OutOfRange {
                what: "level-0 tiles a tile stamp touches",
                value: count as f64,
                expected: "at most 64 (MAX_TILES_PER_STAMP)",
            }));
        }
        let mut ids = Vec::new();
        for ty in lo.y..=hi.y {
            for tx in lo.x..=hi.x {
                ids.push(TileId::new(0, tx as u32, ty as u32));
            }
        }
        Ok(ids)
    }

    /// `placement` in the frame of level-0 tile `id`.
    fn local(&self, placement: &StampPlacement, id: TileId) -> StampPlacement {
        let origin = UVec2::new(id.x, id.y).as_vec2()
            * self.manifest.tile_size as f32
            * self.manifest.texel_size;
        StampPlacement {
            center: placement.center - origin,
            ..*placement
        }
    }

    /// `rect` of level-0 tile `id` in world texels.
    pub fn world_rect(&self, id: TileId, rect: Rect) -> Rect {
        let origin = UVec2::new(id.x, id.y) * self.manifest.tile_size;
        Rect::new(rect.min + origin.as_ivec2(), rect.size)
    }

    /// Applies the queued stamps to every level-0 tile they touch that is resident in `pool`
    /// and has not received them: on the GPU through `deformer` where `vram` holds the tile in
    /// a current slot (hold and pins taken until [`TileStamps::receive`]), else on the CPU in
    /// RAM. Call after the frame's uploads (`VramPool::update`), so a GPU stamp lands on what
    /// the slot holds this frame. A stamp leaves the queue once every tile has it.
    pub fn apply<D: TileDeformer<K>>(
        &mut self,
        pool: &mut RamPool,
        mut vram: Option<&mut VramPool>,
        deformer: &mut D,
    ) -> Result<TileStampReport, TileStampError<D::Error>> {
        let mut report = TileStampReport::default();
        let mut pending = std::mem::take(&mut self.pending);
        let mut result = Ok(());
        for stamp in &mut pending {
            if let Err(e) = self.apply_one(stamp, pool, vram.as_deref_mut(), deformer, &mut report)
            {
                result = Err(e);
                break;
            }
        }
        pending.retain(|p| p.tiles.iter().any(|(_, done)| !done));
        // Stamps queued meanwhile (none: `push` needs `&mut self`) and those kept.
        self.pending = pending;
        result.map(|()| report)
    }

    fn apply_one<D: TileDeformer<K>>(
        &mut self,
        stamp: &mut Pending<K>,
        pool: &mut RamPool,
        mut vram: Option<&mut VramPool>,
        deformer: &mut D,
        report: &mut TileStampReport,
    ) -> Result<(), TileStampError<D::Error>> {
        for (id, done) in stamp.tiles.iter_mut().filter(|(_, done)| !*done) {
            let id = *id;
            if pool.tile(id).is_none() {
                continue;
            }
            let local = self.local(&stamp.placement, id);
            // Held before the stamp: a held slot is current and stays in place until every
            // rect of the stamp is back in RAM.
            if let Some(v) = vram.as_deref_mut()
                && let Some(slot) = v.hold(id)
            {
                let version = pool.generation(id);
                let tickets = match deformer.stamp_slot(slot, &stamp.kind, &local) {
                    Ok(Some(t)) => t,
                    Ok(None) => {
                        // No readback to be had now: the slot was not changed; next frame.
                        v.release(id, version);
                        continue;
                    }
                    Err(e) => {
                        v.release(id, version);
                        return Err(TileStampError::Deformer(e));
                    }
                };
                // One hold and one pin per rect on its way back (the first hold is taken).
                if tickets.is_empty() {
                    v.release(id, version);
                }
                for _ in 1..tickets.len() {
                    v.hold(id);
                }
                for (ticket, rect) in tickets {
                    pool.pin(id);
                    self.in_flight.insert(ticket, (id, rect));
                }
                report.gpu_tiles += 1;
            } else {
                let scratch = &mut self.scratch;
                let stamped = pool.modify(id, |tile| -> Result<_, D::Error> {
                    let Some(grid) = tile.as_u16_mut() else {
                        return Ok(Vec::new());
                    };
                    if grid.size() != scratch.size() {
                        return Ok(Vec::new());
                    }
                    scratch
                        .grid_mut()
                        .as_mut_slice()
                        .copy_from_slice(grid.as_slice());
                    let rects = deformer.stamp_ram(&stamp.kind, scratch, &local)?;
                    grid.as_mut_slice()
                        .copy_from_slice(scratch.grid().as_slice());
                    Ok(rects)
                })?;
                for rect in stamped.map_err(TileStampError::Deformer)? {
                    let heights = self
                        .scratch
                        .grid()
                        .copy_rect(rect)
                        .map_err(CacheError::from)?;
                    report.changed.push((self.world_rect(id, rect), heights));
                }
                report.cpu_tiles += 1;
            }
            *done = true;
        }
        Ok(())
    }

    /// A rect of a GPU-stamped tile arrived (`ticket` as [`TileDeformer::stamp_slot`] gave it,
    /// `rect` in tile texels): its heights go into the RAM tile (dirty: written back by the
    /// pool), the tile's pin and the slot's hold end. Returns the tile and the rect in world
    /// texels (for collision and overviews).
    pub fn receive<E>(
        &mut self,
        pool: &mut RamPool,
        vram: Option<&mut VramPool>,
        ticket: u64,
        rect: Rect,
        heights: &Grid<u16>,
    ) -> Result<(TileId, Rect), TileStampError<E>> {
        let Some(&(id, asked)) = self.in_flight.get(&ticket) else {
            return Err(TileStampError::UnknownTicket { ticket });
        };
        if asked != rect || heights.size() != rect.size {
            return Err(TileStampError::WrongRect {
                id,
                asked,
                got: if asked == rect {
                    Rect::new(rect.min, heights.size())
                } else {
                    rect
                },
            });
        }
        self.in_flight.remove(&ticket);
        // Pinned since the stamp, so still loaded.
        let written = pool.write_rect(id, rect, heights);
        let version = pool.generation(id);
        pool.unpin(id);
        if let Some(v) = vram {
            v.release(id, version);
        }
        written?;
        Ok((id, self.world_rect(id, rect)))
    }

    /// Gives up on every rect still on its way back (the device was lost, or a readback will
    /// never come): each tile's pin and slot hold end, the slot marked out of date so that the
    /// RAM tile is uploaded again. Those rects' stamps stay out of the RAM tiles (and so out of
    /// the world). Returns how many rects were given up.
    pub fn abandon(&mut self, pool: &mut RamPool, mut vram: Option<&mut VramPool>) -> usize {
        let n = self.in_flight.len();
        for (_, (id, _)) in self.in_flight.drain() {
            pool.unpin(id);
            if let Some(v) = vram.as_deref_mut() {
                v.abandon(id);
            }
        }
        n
    }

    /// Applies the stamps still queued to the tiles they have not reached, straight in the
    /// world's files (the end of a run: the tiles never became resident), and returns the
    /// tiles written. The caller rebuilds their coarser levels (`rebuild_ancestors`). Call
    /// after the pool is flushed and shut down, so no write-back races these writes.
    pub fn finish_into_world<D: TileDeformer<K>>(
        &mut self,
        world: &World,
        deformer: &mut D,
    ) -> Result<Vec<TileId>, TileStampError<D::Error>> {
        let mut written = Vec::new();
        for stamp in std::mem::take(&mut self.pending) {
            for (id, _) in stamp.tiles.iter().filter(|(_, done)| !done) {
                let mut data = (*world.load_tile(Layer::Height, *id)?).clone();
                let Some(grid) = data.as_u16_mut() else {
                    continue;
                };
                if grid.size() != self.scratch.size() {
                    continue;
                }
                let local = self.local(&stamp.placement, *id);
                self.scratch
                    .grid_mut()
                    .as_mut_slice()
                    .copy_from_slice(grid.as_slice());
                deformer
                    .stamp_ram(&stamp.kind, &mut self.scratch, &local)
                    .map_err(TileStampError::Deformer)?;
                grid.as_mut_slice()
                    .copy_from_slice(self.scratch.grid().as_slice());
                world.write_tile(Layer::Height, *id, &data)?;
                written.push(*id);
            }
        }
        Ok(written)
    }
}
