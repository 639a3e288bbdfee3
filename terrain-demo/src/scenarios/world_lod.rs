//! The streamed world's LOD data under `--lod cdlod` and `--lod tessellated`: the world's
//! quadtree, built from its level-0 bounds (exact where tiles are in RAM, the pyramid's
//! `bounds.bin` elsewhere) and kept current after every change. terrain-gpu's
//! `TerrainRenderer` draws CDLOD from it, and decides the tessellation's splits from it
//! (terrain-lod's `StreamedTessellation`).

use super::*;

impl FlyoverScenario {
    /// The world's quadtree of `config`; keeps the bounds it was built from for
    /// [`FlyoverScenario::follow_bounds`]. `flag` names the option in errors.
    pub(super) fn world_tree(
        &mut self,
        config: CdlodConfig,
        flag: &str,
    ) -> Result<terrain_lod::CdlodTree> {
        if self.manifest.wrap != WrapMode::Clamp {
            return Err(usage(anyhow::anyhow!(
                "{flag} draws a streamed world clamped at its edges; this one repeats"
            )));
        }
        let Some(pool) = self.pool() else {
            bail!("the world's pool was shut down");
        };
        let bounds = RegionBounds::open(pool.world())?;
        let tree = terrain_lod::CdlodTree::from_leaf_bounds(
            config,
            self.manifest.world_size,
            self.manifest.texel_size,
            |r| bounds.metres(pool, r),
        )?;
        self.bounds = Some(bounds);
        Ok(tree)
    }

    /// Updates the bounds of the rects that `changed` in RAM and the GPU scene's quadtree
    /// over them; returns the time it took (ms), added to the frame's `lod` step.
    pub(super) fn follow_bounds(
        &mut self,
        changed: &[Rect],
        ctx: &mut FrameContext<'_>,
    ) -> Result<f64> {
        let (Some(bounds), Some(pool), Some(scene)) = (
            self.bounds.as_mut(),
            self.streamed.as_ref().map(StreamedWorld::ram),
            ctx.gpu.as_deref_mut(),
        ) else {
            return Ok(0.0);
        };
        let t = Instant::now();
        for rect in changed {
            bounds.update(pool, *rect);
            scene.update_streamed_bounds(*rect, |r| bounds.metres(pool, r))?;
        }
        let ms = ms_since(t);
        ctx.timings.add(Step::Lod, ms);
        Ok(ms)
    }
}
