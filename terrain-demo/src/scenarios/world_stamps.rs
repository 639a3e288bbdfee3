//! What the streamed world's level-0 tiles are stamped with (through terrain-cache's
//! `TileStamps`): the flyover's craters, and the world scenario's shockwave (Flower 2010, sec.
//! 3.4.3: the wave texture stepped each frame and stamped as its change since the last
//! stamp), both terrain-core `TileStamp`s. [`WorldDeformer`] puts either into a tile's atlas
//! slot on the GPU (timed) or into its RAM copy on the CPU.

use crate::config::DemoParams;
use crate::gpu_scene::{GpuScene, TileSlot};
use crate::timings::{Timings, ms_since};
use anyhow::Result;
use glam::Vec2;
use std::sync::Arc;
use std::time::Instant;
use terrain_core::{CoarseMap, Rect, Shockwave, StampPlacement, TileDeformer, TileStamp};

/// Puts terrain-core's `TileStamp`s into one level-0 tile: its atlas slot on the GPU (the
/// scene times the submit and reads the changed rects back), or its RAM copy on the CPU.
pub struct WorldDeformer<'a> {
    /// The GPU, when there is one.
    pub scene: Option<&'a mut GpuScene>,
    /// The frame's timings (the GPU stamps time themselves as `stamp_gpu`).
    pub timings: &'a mut Timings,
    /// Milliseconds spent in GPU stamp submits (not cache work).
    pub gpu_ms: f64,
}

impl TileDeformer<TileStamp> for WorldDeformer<'_> {
    type Error = anyhow::Error;

    fn stamp_slot(
        &mut self,
        slot: u32,
        kind: &TileStamp,
        placement: &StampPlacement,
    ) -> Result<Option<Vec<(u64, Rect)>>> {
        let Some(scene) = self.scene.as_deref_mut() else {
            return Ok(None);
        };
        let t = Instant::now();
        let tile = TileSlot { slot, level: 0 };
        let stamped = scene.stamp_tile(tile, *placement, kind, self.timings);
        self.gpu_ms += ms_since(t);
        stamped
    }

    fn stamp_ram(
        &mut self,
        kind: &TileStamp,
        tile: &mut CoarseMap,
        placement: &StampPlacement,
    ) -> Result<Vec<Rect>> {
        Ok(kind.apply(tile, placement)?)
    }
}

/// The level-0 texels (`texel_size` metres each) a stamp at `placement` may change (its
/// footprint's circumscribed square, whatever its rotation).
pub fn reach(placement: &StampPlacement, texel_size: f32) -> Rect {
    let half = Vec2::splat(placement.scale.length() * 0.5);
    let lo = ((placement.center - half) / texel_size).floor();
    let hi = ((placement.center + half) / texel_size).ceil() + 1.0;
    // Saturating casts: a placement is finite, its rect at worst clipped by the caller.
    Rect::from_min_max(lo.as_ivec2(), hi.as_ivec2().max(lo.as_ivec2()))
}

/// Frame at which the world scenario's shockwave starts.
const SHOCK_START: u32 = 4;
/// Where it starts, from the camera's path at that frame: ahead and to the left (metres).
const SHOCK_AHEAD: f32 = 110.0;
const SHOCK_ASIDE: f32 = -75.0;
/// Side of its square (metres): clear of the path (75 - 30 > the granular window's half).
const SHOCK_SIZE: f32 = 60.0;

/// The world scenario's shockwave: started beside the path, stepped every frame and stamped
/// as its change since the last stamp (a frame whose stamp would reach the granular window
/// is skipped; its change goes with the next one).
#[derive(Debug)]
pub struct WorldShock {
    wave: Option<Shockwave>,
    center: Vec2,
    params: terrain_core::ShockwaveParams,
    steps_per_frame: u32,
    amplitude_m: f32,
}

impl WorldShock {
    /// The shockwave of the default scenario's parameters (`[stamps]` of the config).
    pub fn new(params: &DemoParams) -> Self {
        let s = &params.stamps;
        Self {
            wave: None,
            center: Vec2::ZERO,
            params: s.shockwave,
            steps_per_frame: s.shock_steps_per_frame,
            amplitude_m: s.shock_amplitude_m,
        }
    }

    /// Frame `frame` of the wave, the camera on `path` heading `heading` (metres): the change
    /// to stamp, where; `None` before it starts, without amplitude, or where `keep_out`
    /// (level-0 texels of `texel_size` metres) would be reached.
    pub fn next(
        &mut self,
        frame: u32,
        (path, heading): (Vec2, Vec2),
        texel_size: f32,
        keep_out: Option<Rect>,
    ) -> Result<Option<(TileStamp, StampPlacement)>> {
        if frame == SHOCK_START && self.amplitude_m != 0.0 {
            self.wave = Some(Shockwave::new(self.params)?);
            self.center = path + heading * SHOCK_AHEAD + heading.perp() * SHOCK_ASIDE;
        }
        let Some(wave) = self.wave.as_mut() else {
            return Ok(None);
        };
        for _ in 0..self.steps_per_frame {
            wave.step();
        }
        let placement =
            StampPlacement::new(self.center, Vec2::splat(SHOCK_SIZE), self.amplitude_m)?;
        let r = reach(&placement, texel_size);
        if keep_out.is_some_and(|k| k.intersect(&r).is_some()) {
            return Ok(None);
        }
        let delta = wave.take_delta()?;
        Ok(Some((TileStamp::Texture(Arc::new(delta)), placement)))
    }
}
