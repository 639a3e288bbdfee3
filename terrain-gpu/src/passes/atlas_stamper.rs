//! [`AtlasStamper`]: stamps on a streamed world's resident tiles, where they are drawn (the
//! tile atlas's slots), each changed rect requested back in the same submit (Flower 2010, sec.
//! 3.4: the CPU sees the heights only through readback). What the tiles' RAM copies and the
//! pools do with the rects (terrain-cache's `TileStamps`: hold, pin, receive, release) is the
//! caller's; this is the GPU half of that protocol.

use crate::{
    GpuError, GpuStamp, GpuTextureStamp, GpuTileAtlas, PlainSubmit, RegionReadback, StampOp,
    StampPass, Submit, TileSlot,
};
use terrain_core::{
    Blend, CoarseMap, GaussianStamp, Grid, Rect, StampPlacement, TextureStamp, TileDeformer,
    TileStamp,
};

/// What [`AtlasStamper`] adds to a tile.
#[derive(Debug, Clone, Copy)]
pub enum AtlasStamp<'a> {
    /// A Gaussian (a crater, with a negative intensity).
    Gaussian(&'a GaussianStamp),
    /// A texture stamp, uploaded into the stamper's own texture (rewritten in place: a
    /// shockwave's change, say).
    Texture(&'a TextureStamp),
    /// A texture stamp already on the GPU (a footprint uploaded once).
    Uploaded(&'a GpuTextureStamp),
}

/// One stamp on one atlas tile.
#[derive(Debug, Clone, Copy)]
pub struct AtlasStampOp<'a> {
    /// The tile's slot (and level) in the atlas.
    pub tile: TileSlot,
    /// Where, in the tile's frame: metres from its first texel at its level's texel size.
    pub placement: StampPlacement,
    /// What is added.
    pub stamp: AtlasStamp<'a>,
}

/// A rect of a stamped tile that came back: the ticket [`AtlasStamper::encode`] gave it, the
/// rect in the tile's texels, and its stored heights.
#[derive(Debug, Clone, PartialEq)]
pub struct ArrivedTileRect {
    /// The request's ticket.
    pub ticket: u64,
    /// The rect, tile texels.
    pub rect: Rect,
    /// Its heights, row-major.
    pub heights: Grid<u16>,
}

/// Stamps added to atlas tiles and the readback ring of their changed rects (module docs).
#[derive(Debug)]
pub struct AtlasStamper {
    stamps: StampPass,
    readback: RegionReadback,
    texture: Option<GpuTextureStamp>,
}

impl AtlasStamper {
    /// The name of a stamp's submit ([`Self::stamp_with`]).
    pub const STAMP: &'static str = "tile_stamp";

    /// The stamp pass and a ring of `ring` (1 to [`crate::MAX_READBACK_RING`]) readbacks: the
    /// stamps whose rects may be on their way at once.
    pub fn new(device: &wgpu::Device, ring: usize) -> Result<Self, GpuError> {
        Ok(Self {
            stamps: StampPass::new(device)?,
            readback: RegionReadback::new(device, ring)?,
            texture: None,
        })
    }

    /// Records `op`'s stamp added to its tile, and the copies of the rects it changed for
    /// readback. Returns a ticket and tile rect for each, or `None` with nothing recorded when
    /// the ring is full (stamp it in a later frame). Submit, then [`Self::recall`]. A texture
    /// is written through `queue`, ahead of the submit: one [`AtlasStamp::Texture`] per submit.
    pub fn encode(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        atlas: &GpuTileAtlas,
        op: AtlasStampOp<'_>,
    ) -> Result<Option<Vec<(u64, Rect)>>, GpuError> {
        // A tile is clamped: a stamp changes one rect of it, so one free slot is enough.
        if self.readback.in_flight() >= self.readback.ring() {
            return Ok(None);
        }
        let stamp = match op.stamp {
            AtlasStamp::Gaussian(g) => GpuStamp::Gaussian(g),
            AtlasStamp::Uploaded(t) => GpuStamp::Texture(t),
            AtlasStamp::Texture(texture) => GpuStamp::Texture(match &mut self.texture {
                Some(t) => {
                    t.update(device, queue, texture)?;
                    t
                }
                None => self.texture.insert(GpuTextureStamp::new(device, texture)?),
            }),
        };
        let stamp_op = StampOp {
            stamp,
            placement: op.placement,
            blend: Blend::Add,
        };
        let rects = (self.stamps).encode_tile(device, queue, encoder, atlas, op.tile, &stamp_op)?;
        let mut tickets = Vec::with_capacity(rects.len());
        for r in rects {
            let ticket = (self.readback).request_tile(device, encoder, atlas, op.tile, r)?;
            tickets.push((ticket.0, r));
        }
        Ok(Some(tickets))
    }

    /// Frees the stamp pass's uniform slots once the submit that carried the stamps is done.
    pub fn recall(&mut self) {
        self.stamps.recall();
    }

    /// [`Self::encode`] in a submit of its own.
    pub fn stamp(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        atlas: &GpuTileAtlas,
        op: AtlasStampOp<'_>,
    ) -> Result<Option<Vec<(u64, Rect)>>, GpuError> {
        self.stamp_with(device, queue, &mut PlainSubmit { device, queue }, atlas, op)
    }

    /// [`Self::stamp`] with its submit, named [`Self::STAMP`], made through `submit` (to time
    /// it, say).
    pub fn stamp_with(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        submit: &mut dyn Submit,
        atlas: &GpuTileAtlas,
        op: AtlasStampOp<'_>,
    ) -> Result<Option<Vec<(u64, Rect)>>, GpuError> {
        let mut tickets = None;
        let mut op = Some(op);
        submit.submit(Self::STAMP, &mut |encoder| {
            if let Some(op) = op.take() {
                tickets = self.encode(device, queue, encoder, atlas, op)?;
            }
            Ok(())
        })?;
        self.recall();
        Ok(tickets)
    }

    /// Stamps whose rects are on their way.
    pub fn in_flight(&self) -> usize {
        self.readback.in_flight()
    }

    /// The rects that have arrived, never waiting.
    pub fn poll(&mut self, device: &wgpu::Device) -> Result<Vec<ArrivedTileRect>, GpuError> {
        let arrived = self.readback.poll_with(device, to_arrived)?;
        arrived.into_iter().collect()
    }

    /// Waits (bounded) for the rects on their way: the end of a run.
    pub fn wait(&mut self, device: &wgpu::Device) -> Result<Vec<ArrivedTileRect>, GpuError> {
        let arrived = self.readback.wait_with(device, to_arrived)?;
        arrived.into_iter().collect()
    }
}

/// The [`TileDeformer`] of [`TileStamp`]s on a streamed world's atlas: each stamp in a submit
/// of its own through `stamper` on the GPU, or [`TileStamp::apply`] in RAM. An application
/// that times or batches its submits writes its own over [`AtlasStamper::encode`].
pub struct AtlasDeformer<'a> {
    /// The device the atlas lives on.
    pub device: &'a wgpu::Device,
    /// Its queue.
    pub queue: &'a wgpu::Queue,
    /// The tiles stamped.
    pub atlas: &'a GpuTileAtlas,
    /// The stamper whose ring brings the changed rects back ([`AtlasStamper::poll`]).
    pub stamper: &'a mut AtlasStamper,
    /// Where each stamp's submit goes (`None`: a plain submit; see [`AtlasStamper::stamp_with`]).
    pub submit: Option<&'a mut dyn Submit>,
}

impl std::fmt::Debug for AtlasDeformer<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AtlasDeformer")
            .field("stamper", &self.stamper)
            .field("plain_submit", &self.submit.is_none())
            .finish_non_exhaustive()
    }
}

impl TileDeformer<TileStamp> for AtlasDeformer<'_> {
    type Error = GpuError;

    fn stamp_slot(
        &mut self,
        slot: u32,
        kind: &TileStamp,
        placement: &StampPlacement,
    ) -> Result<Option<Vec<(u64, Rect)>>, GpuError> {
        let stamp = match kind {
            TileStamp::Gaussian(g) => AtlasStamp::Gaussian(g),
            TileStamp::Texture(t) => AtlasStamp::Texture(t),
        };
        let op = AtlasStampOp {
            tile: TileSlot { slot, level: 0 },
            placement: *placement,
            stamp,
        };
        let (device, queue) = (self.device, self.queue);
        let mut plain = PlainSubmit { device, queue };
        let submit: &mut dyn Submit = match self.submit.as_deref_mut() {
            Some(s) => s,
            None => &mut plain,
        };
        self.stamper
            .stamp_with(device, queue, submit, self.atlas, op)
    }

    fn stamp_ram(
        &mut self,
        kind: &TileStamp,
        tile: &mut CoarseMap,
        placement: &StampPlacement,
    ) -> Result<Vec<Rect>, GpuError> {
        Ok(kind.apply(tile, placement)?)
    }
}

/// u16 rows straight from the staging buffer (no u32 copy in between).
fn to_arrived(r: crate::RegionView<'_>) -> Result<ArrivedTileRect, GpuError> {
    Ok(ArrivedTileRect {
        ticket: r.ticket.0,
        rect: r.rect,
        heights: r.to_u16()?,
    })
}
