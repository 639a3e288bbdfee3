//! [`GpuDetailStream`]: a streamed detail layer on the GPU, whole (Flower 2010, sec. 2.3-2.4):
//! the tile slots that follow the CPU's working set (terrain-cache's `DetailCache`), the
//! stamps pressed into them, and the stamped rects on their way back to the CPU's tiles
//! without a wait ([`crate::DetailReadback`]'s protocol). Drawing reads [`Self::tiles`].
//!
//! Per frame: [`GpuDetailStream::follow`] the working set (keeping
//! [`GpuDetailStream::tiles_in_flight`] in it), [`GpuDetailStream::encode_stamps`], submit,
//! [`GpuDetailStream::recall`], and write what [`GpuDetailStream::poll`] hands over into the
//! CPU's tiles; at the end [`GpuDetailStream::flush`].

use crate::device::detail_readback::{ArrivedDetail, DetailReadback};
use crate::error::GpuError;
use crate::resources::detail::GpuDetailTiles;
use crate::{GpuStamp, StampOp, StampPass};
use glam::UVec2;
use std::time::Duration;
use terrain_core::detail::DetailLayout;
use terrain_core::{Blend, Grid, Rect, StampPlacement};

/// A detail layer's tiles on the GPU, their stamps and readback (module docs).
#[derive(Debug)]
pub struct GpuDetailStream {
    tiles: GpuDetailTiles,
    stamps: StampPass,
    readback: DetailReadback,
}

impl GpuDetailStream {
    /// `slots` tile slots of `layout` and a readback ring of `ring` (1 to
    /// [`crate::MAX_READBACK_RING`]) rects.
    pub fn new(
        device: &wgpu::Device,
        layout: DetailLayout,
        slots: u32,
        ring: usize,
    ) -> Result<Self, GpuError> {
        Ok(Self {
            tiles: GpuDetailTiles::new(device, layout, slots)?,
            stamps: StampPass::new(device)?,
            readback: DetailReadback::new(device, ring)?,
        })
    }

    /// The tiles, for the renderer.
    pub fn tiles(&self) -> &GpuDetailTiles {
        &self.tiles
    }

    /// The tiles, for passes that stamp them themselves (the spill pass): request their rects
    /// back with [`Self::request`].
    pub fn tiles_mut(&mut self) -> &mut GpuDetailTiles {
        &mut self.tiles
    }

    /// Releases the slots of `unload` and uploads `load` (a tile's texels, `None` for the
    /// shared zero tile): the CPU working set's change this frame. Keep the tiles of
    /// [`Self::tiles_in_flight`] loaded: a tile unloaded before its rects arrive loses them.
    pub fn follow<'a>(
        &mut self,
        queue: &wgpu::Queue,
        unload: &[UVec2],
        load: impl IntoIterator<Item = (UVec2, Option<&'a Grid<u8>>)>,
    ) -> Result<(), GpuError> {
        for &tile in unload {
            self.tiles.unload(queue, tile);
        }
        for (tile, texels) in load {
            self.tiles.load(queue, tile, texels)?;
        }
        Ok(())
    }

    /// Records `stamp` added at each of `placements` (metres on the coarse-map's plane) into
    /// the tiles, each one's rects requested back after it. Every tile a footprint covers must
    /// be loaded. Returns the detail texels covered. Submit, then [`Self::recall`].
    pub fn encode_stamps(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        stamp: GpuStamp<'_>,
        placements: &[StampPlacement],
    ) -> Result<u64, GpuError> {
        let mut texels = 0;
        for placement in placements {
            let op = StampOp {
                stamp,
                placement: *placement,
                blend: Blend::Add,
            };
            let rects =
                (self.stamps).encode_detail(device, queue, encoder, &mut self.tiles, &op)?;
            texels += rects.iter().map(|(_, r)| r.area()).sum::<u64>();
            self.readback.request(device, encoder, &self.tiles, rects)?;
        }
        Ok(texels)
    }

    /// Frees the stamp pass's uniform slots once the submit that carried the stamps is done.
    pub fn recall(&mut self) {
        self.stamps.recall();
    }

    /// Records the copies of `rects` (tile, tile texels) stamped by another pass, after it.
    pub fn request(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        rects: impl IntoIterator<Item = (UVec2, Rect)>,
    ) -> Result<(), GpuError> {
        self.readback.request(device, encoder, &self.tiles, rects)
    }

    /// The tiles with rects on their way back: the working set must keep them.
    pub fn tiles_in_flight(&self) -> Vec<UVec2> {
        self.readback.tiles_in_flight()
    }

    /// The rects that have arrived, in stamp order (a later copy of the same texels is the
    /// newer one); never waits.
    pub fn poll(&mut self, device: &wgpu::Device) -> Result<Vec<ArrivedDetail>, GpuError> {
        self.readback.poll(device)
    }

    /// Requests what waits for room and waits until every rect has arrived, within `timeout`:
    /// the end of a run.
    pub fn flush(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        timeout: Duration,
    ) -> Result<Vec<ArrivedDetail>, GpuError> {
        self.readback.flush(device, queue, &self.tiles, timeout)
    }
}
