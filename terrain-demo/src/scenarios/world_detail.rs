//! The world scenario's footprints (`--detail parallax|refine`): a walker beside the vehicle's path
//! presses footprints into the streamed world's detail tiles (Flower 2010, sec. 2.3-2.4), 8-bit
//! tiles refined x[`REFINE`] over level 0, held by terrain-cache's `DetailCache` (the band
//! regions of fig. 2.4 around the camera, read and written back on its own threads into the
//! world's `detail/` files).
//!
//! With a GPU the footprints are stamped into the GPU's detail slots only, and the stamped rects
//! come back into the cache through the asynchronous readback ring (the cache's copy is the one
//! written back); without one they are stamped into the cache on the CPU. Both are the same
//! stamp arithmetic (terrain-gpu's detail stamp against `DetailLayer::apply_stamp`), so both
//! runs leave the same files. A footprint saturates at the detail's ±0.5 m range: on a world
//! the excess is not spilled into the coarse tiles (the default scenario's coarse-map does it).

use crate::gpu_scene::GpuScene;
use crate::timings::{Step, Timings, ms_since};
use crate::usage_error::usage;
use anyhow::{Context, Result, anyhow};
use glam::Vec2;
use std::time::Instant;
use terrain_cache::detail::DetailCache;
use terrain_cache::{BandSelection, Manifest, World};
use terrain_core::detail::DetailLayout;
use terrain_core::{Blend, GaussianStamp, StampPlacement};

/// Detail texels per level-0 texel: 6.25 cm texels on the default 0.5 m world.
pub const REFINE: u32 = 8;
/// Detail tile side in detail texels (64 m on the default world; 1 MiB a tile). The band holds
/// at least two thirds of a tile around the camera, beyond the detail's 22 m fade.
pub const TILE: u32 = 1024;
/// Samples the cache uploads per frame at most: the nine tiles of a band.
const UPLOAD_BUDGET: u64 = 9 * (TILE as u64) * (TILE as u64);
/// Metres between footprints, each foot this far beside the walker's line.
const STRIDE_M: f32 = 0.7;
const GAIT_M: f32 = 0.16;
/// A footprint's size (across, along) and depth in metres.
const FOOT_M: Vec2 = Vec2::new(0.22, 0.45);
const FOOT_DEPTH_M: f32 = -0.12;
/// The most footprints one frame stamps: a faster walker skips the rest (bounded work for
/// every `--speed`).
const MAX_STEPS_PER_FRAME: u32 = 16;
/// Tiles within this distance of a footprint are read ahead by the cache's loaders.
const READ_AHEAD_M: f32 = 8.0;

/// The bytes the world's footprints may hold at most: the cache's tiles (the band's nine, the
/// walker's and those being written back, three bands' worth) and, with a GPU, its tile slots.
pub fn memory_bytes(gpu: bool) -> u64 {
    let tile = u64::from(TILE) * u64::from(TILE);
    let slots = u64::from(crate::gpu_scene::DETAIL_SLOTS);
    // A byte a texel on the GPU too (packed four to a u32 word).
    3 * 9 * tile + if gpu { slots * tile } else { 0 }
}

/// The detail layout over `manifest`'s level 0.
pub fn layout_for(manifest: &Manifest) -> Result<DetailLayout> {
    DetailLayout::new(manifest.world_size, manifest.texel_size, REFINE, TILE)
        .map_err(|e| usage(anyhow!("--detail: the world's detail layer: {e}")))
}

/// Gives `world` a detail layer if it has none (its manifest rewritten atomically): call it
/// before anything else opens the world. A world whose detail layer is another is refused.
pub fn ensure_layer(world: &mut World) -> Result<()> {
    let layout = layout_for(world.manifest())?;
    match terrain_cache::detail::ensure_detail_layer(world, &layout) {
        Err(e @ terrain_cache::CacheError::OutOfRange { .. }) => Err(usage(anyhow!(
            "--detail: this world's detail layer is not the demo's ({REFINE} texels per \
             level-0 texel, {TILE}-texel tiles; {e}): use another --world"
        ))),
        done => Ok(done?),
    }
}

/// What the footprints did this frame, for the report.
#[derive(Debug, Clone, Copy, Default)]
pub struct DetailStats {
    /// Footprints stamped.
    pub footprints: u32,
    /// Detail tiles held (the GPU's slots, or the cache's working set).
    pub tiles: u32,
    /// Detail texels the footprints covered.
    pub texels: u64,
}

/// The footprints' detail tiles and the walker who makes them.
pub struct WorldDetail {
    cache: DetailCache,
    foot: GaussianStamp,
    /// Distance along the walker's line of the next footprint (metres), and its count.
    next_step_m: f32,
    steps: u64,
}

impl std::fmt::Debug for WorldDetail {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WorldDetail")
            .field("steps", &self.steps)
            .finish_non_exhaustive()
    }
}

impl WorldDetail {
    /// The detail cache of `world`, which [`ensure_layer`] gave its layer.
    pub fn open(world: &World) -> Result<Self> {
        let layout = layout_for(world.manifest())?;
        let own = World::open(world.store().clone())?;
        let cache = DetailCache::open(own, layout, BandSelection::default(), UPLOAD_BUDGET)
            .context("opening the world's detail tiles")?;
        Ok(Self {
            cache,
            foot: GaussianStamp::default(),
            next_step_m: 0.0,
            steps: 0,
        })
    }

    /// The detail layout (for the GPU's tiles).
    pub fn layout(&self) -> DetailLayout {
        *self.cache.layout()
    }

    /// The detail height (metres) at `xz`: bilinear over the cache's tiles (the band around
    /// the camera; 0 m over tiles not in RAM). Added to the coarse ground for collision.
    pub fn height_m(&self, xz: Vec2) -> f32 {
        self.cache.layer().height_m(xz)
    }

    /// The footprints a walker left since the last call, having walked `walked_m` metres in
    /// all along `line` (its position at a distance, in metres): left and right feet in turn,
    /// at most [`MAX_STEPS_PER_FRAME`].
    fn steps(&mut self, walked_m: f32, line: &dyn Fn(f32) -> Vec2) -> Result<Vec<StampPlacement>> {
        let mut out = Vec::new();
        if !walked_m.is_finite() {
            return Ok(out);
        }
        while self.next_step_m <= walked_m && out.len() < MAX_STEPS_PER_FRAME as usize {
            let d = self.next_step_m;
            let at = line(d);
            let dir = (line(d + 0.5) - at).normalize_or(Vec2::X);
            let side = if self.steps.is_multiple_of(2) {
                GAIT_M
            } else {
                -GAIT_M
            };
            let center = at + dir.perp() * side;
            // The foot's long side (its local y) along the walk.
            let rotation = dir.y.atan2(dir.x) - std::f32::consts::FRAC_PI_2;
            out.push(StampPlacement::new(center, FOOT_M, FOOT_DEPTH_M)?.with_rotation(rotation)?);
            self.steps += 1;
            self.next_step_m += STRIDE_M;
        }
        // Steps a fast walker could not take this frame are skipped.
        if self.next_step_m <= walked_m {
            self.next_step_m = walked_m + STRIDE_M;
        }
        Ok(out)
    }

    /// One frame: the camera's band and this frame's footprints' tiles in the cache (the GPU's
    /// slots following it), then the footprints of a walker at `walked_m` along `line`,
    /// stamped on `gpu` when there is one (and read back without waiting), else on the CPU.
    pub fn advance(
        &mut self,
        camera_xz: Vec2,
        walked_m: f32,
        line: &dyn Fn(f32) -> Vec2,
        gpu: Option<&mut GpuScene>,
        timings: &mut Timings,
    ) -> Result<DetailStats> {
        let t = Instant::now();
        let steps = self.steps(walked_m, line)?;
        // Tiles whose stamped rects are still on their way back stay in RAM for them.
        let keep = gpu
            .as_deref()
            .map_or_else(Vec::new, GpuScene::detail_tiles_in_flight);
        let frame = (self.cache).update_for_stamps(camera_xz, &steps, &keep, READ_AHEAD_M)?;
        if let Some((tile, e)) = frame.failed.first() {
            return Err(anyhow!("detail tile {tile}: {e}"));
        }
        timings.add(Step::Detail, ms_since(t));
        let mut stats = DetailStats {
            footprints: steps.len() as u32,
            ..DetailStats::default()
        };
        match gpu {
            Some(scene) => {
                scene.stream_detail(&self.cache, &frame, timings)?;
                stats.texels = scene.stamp_detail(&mut self.foot, &steps, timings)?;
                scene.take_detail_readbacks(&mut self.cache, false, timings)?;
                stats.tiles = scene.detail_stats().map_or(0, |(tiles, _)| tiles);
            }
            None => {
                let t = Instant::now();
                for p in &steps {
                    let change = self.cache.apply_stamp(&mut self.foot, p, Blend::Add)?;
                    stats.texels += change.tiles.iter().map(|(_, r)| r.area()).sum::<u64>();
                }
                timings.add(Step::StampCpu, ms_since(t));
                stats.tiles = self.cache.loaded_tiles().len() as u32;
            }
        }
        Ok(stats)
    }

    /// Ends the run: the GPU's last stamped rects come back, and every deformed tile is
    /// written into the world. Returns the tiles written by this call.
    pub fn finish(&mut self, gpu: Option<&mut GpuScene>) -> Result<u64> {
        if let Some(scene) = gpu {
            let mut timings = Timings::default();
            scene.take_detail_readbacks(&mut self.cache, true, &mut timings)?;
        }
        Ok(self.cache.flush()? as u64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::UVec2;
    use std::sync::Arc;
    use terrain_cache::{ObjectTileStore, TileStore};
    use terrain_core::{HeightEncoding, WrapMode};

    fn world() -> World {
        let store: Arc<dyn TileStore> = Arc::new(ObjectTileStore::in_memory().unwrap());
        let enc = HeightEncoding::spanning::<u16>(0.0, 100.0).unwrap();
        let m = Manifest::new(UVec2::splat(512), 256, 0.5, enc, WrapMode::Clamp).unwrap();
        World::create(store, m).unwrap()
    }

    #[test]
    fn a_world_gets_the_layer_once_and_another_layer_is_refused() {
        let mut w = world();
        ensure_layer(&mut w).unwrap();
        let generation = w.manifest().generation;
        ensure_layer(&mut w).unwrap();
        assert_eq!(w.manifest().generation, generation, "rewritten for nothing");
        let mut other = *w.manifest().detail.as_ref().unwrap();
        other.tile_size = 512;
        w.update_manifest(|m| m.detail = Some(other)).unwrap();
        let err = ensure_layer(&mut w).unwrap_err();
        assert!(err.to_string().contains("another --world"), "{err}");
    }

    #[test]
    fn footprints_follow_the_line_and_a_fast_walker_is_bounded() {
        let mut w = world();
        ensure_layer(&mut w).unwrap();
        let mut d = WorldDetail::open(&w).unwrap();
        let line = |s: f32| Vec2::new(10.0 + s, 20.0);
        let steps = d.steps(3.0, &line).unwrap();
        // 0, 0.7, 1.4, 2.1, 2.8 m, feet alternating either side of the line.
        assert_eq!(steps.len(), 5);
        for (i, p) in steps.iter().enumerate() {
            assert!((p.center.x - (10.0 + 0.7 * i as f32)).abs() < 1e-4);
            let side = if i % 2 == 0 { GAIT_M } else { -GAIT_M };
            assert!(
                (p.center.y - (20.0 + side)).abs() < 1e-4,
                "{i}: {}",
                p.center
            );
        }
        assert!(d.steps(3.0, &line).unwrap().is_empty(), "no step twice");
        // A kilometre in one frame: at most the cap, and the walker goes on from there.
        assert_eq!(
            d.steps(1000.0, &line).unwrap().len(),
            MAX_STEPS_PER_FRAME as usize
        );
        assert!(d.steps(1000.5, &line).unwrap().is_empty());
        // From 1000.7 m on: 1000.7 and 1001.4.
        assert_eq!(d.steps(1001.5, &line).unwrap().len(), 2);
        assert!(d.steps(f32::NAN, &line).unwrap().is_empty());
    }

    #[test]
    fn cpu_footprints_reach_the_worlds_detail_files() {
        let mut w = world();
        ensure_layer(&mut w).unwrap();
        let store = w.store().clone();
        let mut d = WorldDetail::open(&w).unwrap();
        let line = |s: f32| Vec2::new(40.0 + s, 40.0);
        let mut timings = Timings::default();
        let stats = d
            .advance(Vec2::new(40.0, 40.0), 5.0, &line, None, &mut timings)
            .unwrap();
        assert_eq!(stats.footprints, 8);
        assert!(stats.texels > 0);
        // The first foot, left of the line, is pressed in (collision walks on it); the ground
        // away from the walk is untouched.
        let first = d.height_m(Vec2::new(40.0, 40.0 + GAIT_M));
        assert!(first < -0.06, "footprint depth {first}");
        assert_eq!(d.height_m(Vec2::new(60.0, 60.0)), 0.0);
        assert!(d.finish(None).unwrap() >= 1);
        let files = store.list(terrain_cache::Layer::Detail.folder()).unwrap();
        assert!(!files.is_empty(), "no detail tile written");
    }
}
