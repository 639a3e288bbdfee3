//! The GPU scene's LOD mode (Cervin 2012): terrain-gpu's `TerrainRenderer` in CDLOD or
//! adaptive tessellation instead of the clipmap, kept current from the regions read back.

use super::*;

impl GpuScene {
    /// Draws with `terrain` from now on, every layer the one it replaces had (holes, paint,
    /// colour, materials) bound to it too.
    pub(super) fn set_terrain(&mut self, mut terrain: TerrainRenderer) {
        terrain.adopt_layers(&self.terrain);
        self.terrain = terrain;
    }

    /// Draws the coarse-map with CDLOD instead of the clipmap: the quadtree of `map` with
    /// `config`, kept current by [`GpuScene::update_lod`].
    pub fn enable_cdlod(&mut self, map: &CoarseMap, config: CdlodConfig) -> Result<()> {
        let format = self.target.format();
        let terrain = TerrainRenderer::cdlod(&self.ctx.device, &format, map, config)?;
        self.set_terrain(terrain);
        Ok(())
    }

    /// Draws a streamed world's atlas with CDLOD instead of the clipmap: `tree` is the world's
    /// quadtree (terrain-lod's `CdlodTree::from_leaf_bounds`), kept current by the caller
    /// through [`GpuScene::update_streamed_bounds`].
    pub fn enable_cdlod_tree(&mut self, tree: CdlodTree) -> Result<()> {
        let format = self.target.format();
        let terrain = TerrainRenderer::cdlod_streamed(&self.ctx.device, &format, tree)?;
        self.set_terrain(terrain);
        Ok(())
    }

    /// Draws a streamed world's atlas with adaptive tessellation instead of the clipmap: its
    /// splits decided from `tree`, the world's quadtree (kept current by the caller through
    /// [`GpuScene::update_streamed_bounds`]), its heights from the atlas, stored as
    /// `encoding` says.
    pub fn enable_tessellation_tree(
        &mut self,
        tree: CdlodTree,
        config: TessConfig,
        encoding: terrain_core::HeightEncoding,
    ) -> Result<()> {
        let (device, queue, format) = (&self.ctx.device, &self.ctx.queue, self.target.format());
        let terrain =
            TerrainRenderer::tessellated_streamed(device, queue, &format, tree, config, encoding)?;
        self.set_terrain(terrain);
        Ok(())
    }

    /// Updates the streamed world's quadtree (CDLOD's or the tessellation's) over `dirty` from
    /// `leaf_bounds`; nothing when the terrain draws no streamed world.
    pub fn update_streamed_bounds(
        &mut self,
        dirty: Rect,
        leaf_bounds: impl FnMut(Rect) -> (f32, f32),
    ) -> Result<()> {
        self.terrain.update_streamed_bounds(dirty, leaf_bounds)?;
        Ok(())
    }

    /// Draws the coarse-map with adaptive tessellation instead of the clipmap: the hierarchy of
    /// `map` with `config` (and its density map when `density`), kept current by
    /// [`GpuScene::update_lod`].
    pub fn enable_tessellation(
        &mut self,
        map: &CoarseMap,
        config: TessConfig,
        density: bool,
    ) -> Result<()> {
        let (device, queue, format) = (&self.ctx.device, &self.ctx.queue, self.target.format());
        let terrain = TerrainRenderer::tessellated(device, queue, &format, map, config, density)?;
        self.set_terrain(terrain);
        Ok(())
    }

    /// Hands the deformations in `dirty` (already in `map`, from the readback) to the LOD
    /// data's worker thread and takes in what it finished (timed as `lod`: the frame pays for
    /// copying the rects' rows, not for the update). Nothing under the clipmap; a streamed
    /// world's quadtree is kept current by its scenario.
    pub fn update_lod(
        &mut self,
        map: &CoarseMap,
        dirty: &[Rect],
        timings: &mut Timings,
    ) -> Result<()> {
        if self.terrain.mode() == "clipmap" {
            return Ok(());
        }
        let t = std::time::Instant::now();
        self.terrain.heights_changed(&self.ctx.queue, map, dirty)?;
        timings.add(Step::Lod, crate::timings::ms_since(t));
        Ok(())
    }

    /// The popping metric of the last frame against the one before (`None` on the first
    /// frame, under the clipmap or on a streamed world): the largest screen-space jump of the
    /// drawn surface, in pixels, both frames evaluated on `map` and projected with `camera`,
    /// so only a change of the mesh counts.
    pub fn lod_jump_px(&self, map: &CoarseMap, camera: &Camera) -> Option<f32> {
        self.terrain.popping_px(map, camera, self.target.size())
    }
}
