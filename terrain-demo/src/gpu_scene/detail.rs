//! The detail layer on the GPU scene (Flower 2010 sec. 2.3): the tile slots following the
//! scenario's detail cache, the spill pass footprints go through, the refined geometry of
//! `--detail refine`, and the readback that brings stamped detail rects to the cache without
//! a wait.

use super::*;
use terrain_gpu::GpuDetailStream;

/// Detail tile slots on the GPU (1 MiB each at 1024^2 texels, packed four to a word): the nine
/// of a band and the tiles beyond it under the walker and this frame's footprints (within 2 m
/// of the walker: at most four). Only tiles with detail take a slot; the zero tile is shared.
pub const DETAIL_SLOTS: u32 = 13;

/// The detail layer on the GPU: terrain-gpu's stream (tile slots following the scenario's
/// detail cache, footprints stamped there and their rects read back into the cache, whose copy
/// is the one written back), the spill pass and how the renderer shades the tiles.
pub(super) struct DetailScene {
    pub(super) stream: GpuDetailStream,
    /// The coarse-map's footprints are stamped through it: what leaves the tiles' range
    /// spills into the coarse-map.
    pub(super) spill: SpillPass,
    pub(super) shading: DetailShading,
    /// Detail texels inside the rects the last deformation stamped.
    pub(super) dirty_texels: u64,
}

/// Detail rects in flight at most (the ring's limit; a frame's footprints stamp about four).
const DETAIL_READBACK_RING: usize = 16;

/// The refinement pass and its renderer, with the radius they refine.
pub(super) struct RefinedGeometry {
    pub(super) pass: RefinePass,
    pub(super) renderer: RefineRenderer,
    pub(super) radius_m: f32,
    /// The newest refined triangle count that came back (the report's).
    pub(super) last_count: u32,
}

/// The refined radius of `--detail refine`: 9 m, at most 90 texels (the region must stay where
/// the finest clipmap level, N = 255, does not morph: about 100 texels from the camera).
pub(super) fn refine_radius(texel_size: f32) -> f32 {
    (REFINE_TEXELS * texel_size).min(9.0)
}

/// The most texels the refined radius spans (see [`refine_radius`]).
pub(super) const REFINE_TEXELS: f32 = 90.0;

/// The largest footprint a spilling detail stamp covers (256 KiB of excess window): the
/// default footprints cover about 10 x 20 detail texels.
pub const SPILL_WINDOW_TEXELS: u32 = 256 * 256;

/// The demo's detail shading: footprints drawn fully to 12 m and faded out by 22 m, within the
/// two thirds of a tile the band regions hold around the camera in every direction (so no
/// tile ever appears or leaves where the detail shows).
pub(super) fn detail_shading() -> DetailShading {
    DetailShading {
        fade_start_m: 12.0,
        fade_end_m: 22.0,
        ..DetailShading::default()
    }
}

impl GpuScene {
    /// Draws the coarse-map (or the world's atlas, once enabled) through a detail layer of
    /// `layout` from now on, and stamps the footprints into its tiles
    /// ([`GpuScene::stream_detail`] keeps them resident). With `refine`, the cells near the
    /// camera are refined geometry (Flower 2010, sec. 2.4.3) and the clipmap shades the rest
    /// with the detail normals; else the clipmap draws the detail by parallax occlusion
    /// mapping.
    pub fn enable_detail(&mut self, layout: DetailLayout, refine: bool) -> Result<()> {
        let device = &self.ctx.device;
        let stream = GpuDetailStream::new(device, layout, DETAIL_SLOTS, DETAIL_READBACK_RING)?;
        let mut shading = detail_shading();
        let refine = if refine {
            // The texels refined are the drawn surface's: a streamed world's level 0.
            let texel = match &self.atlas {
                Some(atlas) => atlas.config().world.texel_size,
                None => self.ground.heights().texel_size(),
            };
            let radius_m = refine_radius(texel);
            let view = terrain_lod::RefineView::new(Vec2::ZERO, texel, radius_m)?;
            shading.parallax_steps = 0;
            // The layers bound so far (a streamed world's paint and colour) draw on it too.
            let mut renderer = RefineRenderer::new(device, &self.target.format())?;
            renderer.adopt_layers(&self.terrain);
            Some(RefinedGeometry {
                pass: RefinePass::new(device, view.half_cells())?,
                renderer,
                radius_m,
                last_count: 0,
            })
        } else {
            None
        };
        self.detail = Some(DetailScene {
            stream,
            spill: SpillPass::new(device, SPILL_WINDOW_TEXELS)?,
            shading,
            dirty_texels: 0,
        });
        self.refined = refine;
        Ok(())
    }

    /// With a detail layer: tiles in a GPU slot, and the detail texels the last deformation
    /// stamped.
    pub fn detail_stats(&self) -> Option<(u32, u64)> {
        self.detail
            .as_ref()
            .map(|d| (d.stream.tiles().resident(), d.dirty_texels))
    }

    /// Makes the GPU's detail slots follow `frame` of `cache` (the detail cache the footprints
    /// are also stamped on, on the CPU): releases the tiles that left its working set and
    /// uploads those that joined it (a tile joins once the cache's loaders have read it, never
    /// before its texels are in RAM). Timed as [`Step::Detail`]. Nothing without a detail
    /// layer.
    pub fn stream_detail(
        &mut self,
        cache: &DetailCache,
        frame: &DetailFrame,
        timings: &mut Timings,
    ) -> Result<()> {
        let Some(detail) = self.detail.as_mut() else {
            return Ok(());
        };
        let t = std::time::Instant::now();
        let load = frame.load.iter().map(|&tile| (tile, cache.tile(tile)));
        detail.stream.follow(&self.ctx.queue, &frame.unload, load)?;
        timings.add(Step::Detail, crate::timings::ms_since(t));
        Ok(())
    }

    /// The detail rects stamped on the GPU that have arrived go into `cache` (collision walks
    /// on it, and it writes the tiles back): the GPU's stamps are the detail's truth. Never
    /// waits; with `wait`, requests what is pending and waits until nothing is in flight (the
    /// end of a run). Timed as [`Step::Detail`]. Nothing without a detail layer.
    pub fn take_detail_readbacks(
        &mut self,
        cache: &mut DetailCache,
        wait: bool,
        timings: &mut Timings,
    ) -> Result<()> {
        let Some(detail) = self.detail.as_mut() else {
            return Ok(());
        };
        let t = std::time::Instant::now();
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        // In request order: a later copy of the same texels is the newer one.
        let arrived = if wait {
            let timeout = std::time::Duration::from_secs(60);
            detail.stream.flush(device, queue, timeout)?
        } else {
            detail.stream.poll(device)?
        };
        for (tile, rect, texels) in arrived {
            cache.write_rect(tile, rect, &texels)?;
        }
        timings.add(Step::Detail, crate::timings::ms_since(t));
        Ok(())
    }

    /// Stamps `placements` (footprints of `stamp`, added) into the detail tiles only, as one
    /// submit timed as [`Step::StampGpu`] (GPU work, as the other stamps), and requests the
    /// stamped rects back: a streamed world's footprints, whose excess beyond the tiles' range
    /// is not spilled (the world's coarse tiles are not a map the spill pass can write). Every tile a footprint covers must
    /// hold a slot (the cache's `needed` tiles). Returns the detail texels covered.
    pub fn stamp_detail(
        &mut self,
        stamp: &mut terrain_core::GaussianStamp,
        placements: &[terrain_core::StampPlacement],
        timings: &mut Timings,
    ) -> Result<u64> {
        let Some(detail) = self.detail.as_mut() else {
            anyhow::bail!("no detail layer to stamp footprints into");
        };
        if placements.is_empty() {
            return Ok(0);
        }
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let mut texels = 0;
        let time = self.timer.time(device, queue, Step::StampGpu, |encoder| {
            let foot = GpuStamp::Gaussian(stamp);
            texels = (detail.stream).encode_stamps(device, queue, encoder, foot, placements)?;
            Ok(())
        });
        detail.dirty_texels = texels;
        detail.stream.recall();
        time.map_err(|e| self.lost_or(e.into()))?.record(timings);
        Ok(texels)
    }

    /// The detail tiles with stamped rects not yet back on the CPU: the detail cache must keep
    /// them until they arrive.
    pub fn detail_tiles_in_flight(&self) -> Vec<glam::UVec2> {
        self.detail
            .as_ref()
            .map_or_else(Vec::new, |d| d.stream.tiles_in_flight())
    }

    /// A resident detail tile's texels on the GPU (waits for the GPU), `None` for a tile
    /// without a slot: for tests that compare the detail cache with the truth.
    #[cfg(test)]
    pub fn read_detail(&self, tile: glam::UVec2) -> Result<Option<Grid<u8>>> {
        let Some(detail) = self.detail.as_ref() else {
            return Ok(None);
        };
        let tiles = detail.stream.tiles();
        if tiles.slot_of(tile).is_none() {
            return Ok(None);
        }
        let side = tiles.layout().tile_size();
        let all = Rect::from_size(UVec2::splat(side));
        Ok(Some(tiles.read(
            &self.ctx.device,
            &self.ctx.queue,
            tile,
            all,
        )?))
    }
}
