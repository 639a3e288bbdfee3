//! The streamed world's LOD data under `--lod cdlod` and `--lod tessellated`: the world's
//! quadtree, built from its level-0 bounds (exact where tiles are in RAM, the pyramid's
//! `bounds.bin` elsewhere) and kept current after every change. terrain-gpu's
//! `TerrainRenderer` draws CDLOD from it, and decides the tessellation's splits from it
//! (terrain-lod's `StreamedTessellation`).

use super::*;

/// The lowest and highest height (metres) under `rect`, for the quadtree.
fn leaf_metres(
    bounds: &RegionBounds,
    pool: &RamPool,
    rect: Rect,
    enc: terrain_core::HeightEncoding,
) -> (f32, f32) {
    let [lo, hi] = bounds.of(pool, rect).unwrap_or([0, u16::MAX]);
    (enc.to_metres(f64::from(lo)), enc.to_metres(f64::from(hi)))
}

/// The quadtree a tessellation with patches of `patch_size` texels is decided from: leaves of
/// 16 texels (the splits of the finest triangles see the heights of a few leaves: coarser
/// leaves split them far beyond where their edges ask), and the LODs it takes for a node to
/// hold the square a patch's first split looks at (about 3 patches).
pub(super) fn tess_tree_config(patch_size: u32) -> CdlodConfig {
    const LEAF: u32 = 16;
    let lod_count = (1..terrain_lod::cdlod::MAX_CDLOD_LODS)
        .find(|&n| u64::from(LEAF) << (n - 1) >= 3 * u64::from(patch_size))
        .unwrap_or(terrain_lod::cdlod::MAX_CDLOD_LODS);
    CdlodConfig {
        leaf_size: LEAF,
        grid_size: LEAF,
        lod_count,
        ..CdlodConfig::default()
    }
}

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
        let Some(pool) = self.pool.as_ref() else {
            bail!("the world's pool was shut down");
        };
        let bounds = RegionBounds::open(pool.world())?;
        let enc = self.manifest.encoding;
        let tree = terrain_lod::CdlodTree::from_leaf_bounds(
            config,
            self.manifest.world_size,
            self.manifest.texel_size,
            |r| leaf_metres(&bounds, pool, r, enc),
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
            self.pool.as_ref(),
            ctx.gpu.as_deref_mut(),
        ) else {
            return Ok(0.0);
        };
        let t = Instant::now();
        let enc = self.manifest.encoding;
        for rect in changed {
            bounds.update(pool, *rect);
            scene.update_streamed_bounds(*rect, |r| leaf_metres(bounds, pool, r, enc))?;
        }
        let ms = ms_since(t);
        ctx.timings.add(Step::Lod, ms);
        Ok(ms)
    }
}
