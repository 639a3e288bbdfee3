//! What the streamed world's level-0 tiles are stamped with (through terrain-cache's
//! `TileStamps`): the flyover's craters, and the world scenario's shockwave (Flower 2010, sec.
//! 3.4.3: the wave texture stepped each frame and stamped as its change since the last
//! stamp), both terrain-core `TileStamp`s, which terrain-gpu's `AtlasDeformer` puts into a
//! tile's atlas slot (`GpuScene::with_tile_deformer`, timed) and terrain-core's `RamDeformer`
//! into its RAM copy.

use crate::config::DemoParams;
use anyhow::Result;
use glam::Vec2;
use std::sync::Arc;
use terrain_core::{Rect, Shockwave, StampPlacement, TileStamp};

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
