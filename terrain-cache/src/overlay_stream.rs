//! [`OverlayStream`]: a world's paint ([`Layer::Material`]) or colour ([`Layer::Color`])
//! streamed as its heights are (Fikkan 2013, ch. 5 streams colour textures beside the heights):
//! a [`RamPool`] of the layer's tiles and a [`VramPool`] that uploads them into an
//! [`OverlayUploadTarget`] (terrain-gpu's `GpuOverlayAtlas`), each frame.
//!
//! Give it the heights' selection policy and VRAM configuration and it holds the look of the
//! ground the heights' pools hold the shape of, level for level, within its own budgets. The
//! layer's files are written by someone else (`terrain_cache::overlays`, one writer at a time,
//! on any thread): name the tiles such a write returns to [`OverlayStream::reload`] and they
//! are read and uploaded again.

use crate::error::CacheError;
use crate::policy::{CameraState, SelectionPolicy};
use crate::pool::{FrameReport, PoolConfig, RamPool};
use crate::tile::{Layer, TileId};
use crate::vram::{VramConfig, VramError, VramPool, VramReport};
use crate::world::World;
use std::time::Duration;
use terrain_core::OverlayUploadTarget;

/// A layer's RAM and VRAM pools (see the module docs).
#[derive(Debug)]
pub struct OverlayStream {
    layer: Layer,
    ram: RamPool,
    vram: VramPool,
}

impl OverlayStream {
    /// Streams `layer` (paint or colour) of `world`: a RAM pool of `ram_budget_bytes` that
    /// selects with `policy`, and a VRAM pool configured by `vram` (the heights', for the same
    /// tiles; its per-frame upload budget raised to one RGBA tile if below). Its tiles never
    /// change in RAM, so nothing is written back. Fails on another
    /// layer, a world without it (a version-1 world), a budget below two tiles, or a bad VRAM
    /// configuration.
    pub fn new(
        world: World,
        layer: Layer,
        ram_budget_bytes: u64,
        policy: Box<dyn SelectionPolicy>,
        vram: VramConfig,
    ) -> Result<Self, CacheError> {
        if !matches!(layer, Layer::Material | Layer::Color) {
            return Err(CacheError::NoSuchLayer { layer });
        }
        if world.manifest().layer_levels(layer) == 0 {
            return Err(CacheError::NoSuchLayer { layer });
        }
        // An RGBA tile is twice a height tile's bytes: the per-frame budget takes at least one.
        let mut vram = vram;
        let tile = u64::from(world.manifest().tile_size).pow(2) * 4;
        vram.upload_budget_bytes = vram.upload_budget_bytes.max(tile);
        let cfg = PoolConfig {
            write_back_idle_frames: None,
            propagate_to_coarser: false,
            ..PoolConfig::new(layer, ram_budget_bytes)
        };
        Ok(Self {
            layer,
            ram: RamPool::with_policy(world, cfg, policy)?,
            vram: VramPool::new(vram)?,
        })
    }

    /// The layer streamed.
    pub fn layer(&self) -> Layer {
        self.layer
    }

    /// Tiles whose files were rewritten (what `write_paint` or `write_color` returned): read
    /// again and uploaded again from the next [`update`](Self::update).
    pub fn reload(&mut self, ids: &[TileId]) {
        self.ram.reload(ids);
    }

    /// One frame for `camera`: the RAM pool's loads, then the uploads into `target` within the
    /// VRAM budget. A tile that could not be read is listed by `ram().errors()` (as the
    /// heights' pool lists its own) and stands as its coarser tiles.
    pub fn update<T: OverlayUploadTarget>(
        &mut self,
        camera: &CameraState,
        target: &mut T,
    ) -> Result<(FrameReport, VramReport), VramError<T::Error>> {
        let ram = self.ram.update(camera)?;
        let vram = self
            .vram
            .update_overlay(camera, self.layer, &self.ram, target)?;
        Ok((ram, vram))
    }

    /// The RAM pool (its statuses, budget).
    pub fn ram(&self) -> &RamPool {
        &self.ram
    }

    /// The VRAM pool (its slots).
    pub fn vram(&self) -> &VramPool {
        &self.vram
    }

    /// Stops the RAM pool's threads (nothing to write back).
    pub fn shutdown(self, timeout: Duration) -> Result<(), CacheError> {
        self.ram.shutdown(timeout)
    }
}
