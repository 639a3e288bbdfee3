//! [`DetailReadback`]: the rects a detail stamp changed on the GPU
//! ([`crate::StampPass::encode_detail`], [`crate::SpillPass::encode`]) on their way back to the
//! CPU's copy of the tiles without a wait, in the order they were stamped (Flower 2010, sec.
//! 2.4.2: a deformed tile is written back from the CPU; with the GPU as the detail's truth,
//! the CPU learns its texels only through these rects).
//!
//! The protocol a caller follows, whatever holds the CPU's tiles (terrain-cache's
//! `DetailCache::write_rect` in the demo): record the stamps, then [`DetailReadback::request`]
//! their rects in the same encoder; each frame take what [`DetailReadback::poll`] hands over
//! and write it into the CPU's tiles; keep the tiles of [`DetailReadback::tiles_in_flight`] in
//! RAM (a tile unloaded before its rect arrives loses the footprint); at the end
//! [`DetailReadback::flush`]. Rects the ring has no room for wait in a queue and are requested
//! first by the next call, so the order of the texels' versions holds.

use crate::device::readback::{ReadbackTicket, RegionReadback};
use crate::error::GpuError;
use crate::resources::detail::GpuDetailTiles;
use glam::UVec2;
use std::collections::HashMap;
use std::time::{Duration, Instant};
use terrain_core::{Grid, Rect};

/// A detail rect that came back: the tile, the rect of its texels (tile coordinates) and the
/// texels.
pub type ArrivedDetail = (UVec2, Rect, Grid<u8>);

/// Stamped detail rects on their way back to the CPU (see the module docs).
#[derive(Debug)]
pub struct DetailReadback {
    ring: RegionReadback,
    /// Rects stamped and not yet requested (the ring was full), in stamp order.
    pending: Vec<(UVec2, Rect)>,
    /// What each ticket in flight is.
    in_flight: HashMap<u64, (UVec2, Rect)>,
}

impl DetailReadback {
    /// A readback of `ring` staging buffers (1 to [`crate::MAX_READBACK_RING`]).
    pub fn new(device: &wgpu::Device, ring: usize) -> Result<Self, GpuError> {
        Ok(Self {
            ring: RegionReadback::new(device, ring)?,
            pending: Vec::new(),
            in_flight: HashMap::new(),
        })
    }

    /// Records the copies of `rects` (tile, tile texels) of `tiles` into `encoder`, after what it
    /// stamped: first the rects an earlier call had no room for, then these, in order; those
    /// the ring has no room for wait for the next call. Fails, queueing none of `rects`, on a
    /// tile without a slot or a rect off its tile.
    pub fn request(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        tiles: &GpuDetailTiles,
        rects: impl IntoIterator<Item = (UVec2, Rect)>,
    ) -> Result<(), GpuError> {
        // Checked before anything is queued: a refused call adds nothing.
        let side = UVec2::splat(tiles.layout().tile_size());
        let rects: Vec<(UVec2, Rect)> = rects.into_iter().collect();
        for &(tile, rect) in &rects {
            if tiles.slot_of(tile).is_none() {
                return Err(GpuError::DetailTileNotLoaded { tile });
            }
            if rect.is_empty() || !Rect::from_size(side).contains_rect(&rect) {
                return Err(GpuError::BadRegion {
                    rect,
                    map_size: side,
                });
            }
        }
        let mut queue = std::mem::take(&mut self.pending);
        queue.extend(rects);
        let mut rest = queue.into_iter();
        while let Some((tile, rect)) = rest.next() {
            let asked = if self.ring.in_flight() >= self.ring.ring() {
                Err(GpuError::ReadbackBusy {
                    ring: self.ring.ring(),
                })
            } else {
                self.ring.request_detail(device, encoder, tiles, tile, rect)
            };
            match asked {
                Ok(ReadbackTicket(ticket)) => {
                    self.in_flight.insert(ticket, (tile, rect));
                }
                // No room: this rect and the rest wait, in order, for the next call.
                Err(GpuError::ReadbackBusy { .. }) => {
                    self.pending.push((tile, rect));
                    break;
                }
                // The rect is refused; the others still go back.
                Err(e) => {
                    self.pending.extend(rest);
                    return Err(e);
                }
            }
        }
        self.pending.extend(rest);
        Ok(())
    }

    /// The rects that have arrived, in the order they were requested; never waits.
    pub fn poll(&mut self, device: &wgpu::Device) -> Result<Vec<ArrivedDetail>, GpuError> {
        let arrived = self
            .ring
            .poll_with(device, |r| (r.ticket.0, r.rect, r.to_u8()))?;
        self.take(arrived)
    }

    /// Requests what is waiting for room (each round in its own submit) and waits until
    /// nothing is in flight: the end of a run. Returns every rect, in request order; fails
    /// when they have not all arrived within `timeout`.
    pub fn flush(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        tiles: &GpuDetailTiles,
        timeout: Duration,
    ) -> Result<Vec<ArrivedDetail>, GpuError> {
        let deadline = Instant::now() + timeout;
        let mut all = Vec::new();
        while !self.pending.is_empty() || !self.in_flight.is_empty() {
            if Instant::now() > deadline {
                let rects = self.in_flight.values().chain(&self.pending);
                return Err(GpuError::ReadbackFailed {
                    rects: rects.map(|(_, r)| *r).collect(),
                });
            }
            let mut encoder = device.create_command_encoder(&Default::default());
            self.request(device, &mut encoder, tiles, [])?;
            queue.submit([encoder.finish()]);
            let arrived = self
                .ring
                .wait_with(device, |r| (r.ticket.0, r.rect, r.to_u8()))?;
            all.extend(self.take(arrived)?);
        }
        Ok(all)
    }

    /// The tiles with stamped rects not yet handed over: the CPU must keep them until then.
    pub fn tiles_in_flight(&self) -> Vec<UVec2> {
        let mut tiles: Vec<UVec2> = self
            .in_flight
            .values()
            .chain(&self.pending)
            .map(|(t, _)| *t)
            .collect();
        tiles.sort_unstable_by_key(|t| (t.y, t.x));
        tiles.dedup();
        tiles
    }

    /// Rects requested or waiting for room.
    pub fn outstanding(&self) -> usize {
        self.in_flight.len() + self.pending.len()
    }

    /// The arrived regions matched to their tiles, in ticket (request) order: a later copy of
    /// the same texels is the newer one.
    fn take(
        &mut self,
        mut arrived: Vec<(u64, Rect, Result<Grid<u8>, GpuError>)>,
    ) -> Result<Vec<ArrivedDetail>, GpuError> {
        arrived.sort_by_key(|(ticket, _, _)| *ticket);
        let mut out = Vec::with_capacity(arrived.len());
        for (ticket, rect, texels) in arrived {
            match self.in_flight.remove(&ticket) {
                Some((tile, asked)) if asked == rect => out.push((tile, rect, texels?)),
                _ => {
                    return Err(GpuError::Unsupported {
                        what: "DetailReadback",
                        reason: "a region arrived that this readback did not ask for",
                    });
                }
            }
        }
        Ok(out)
    }
}
