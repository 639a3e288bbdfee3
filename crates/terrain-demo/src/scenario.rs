//! The scripted deformations of the default scenario: a trail of footprints, Gaussian craters
//! and a shockwave started next to the map's corner so its footprint crosses the wrap edges.

use anyhow::{Context, Result};
use glam::Vec2;
use terrain_core::io::{ReadLimits, decode_png8};
use terrain_core::{
    Blend, CoarseMap, DirtyRect, GaussianStamp, Shockwave, ShockwaveParams, StampPlacement,
    TextureStamp, apply_stamp,
};

/// The footprint image: white where the foot presses hardest (see `TextureStamp`).
const FOOTPRINT_PNG: &[u8] = include_bytes!("../assets/footprint.png");

/// Footprint size in metres (length along the walking direction, width).
const FOOT_SIZE: Vec2 = Vec2::new(1.1, 0.45);
/// How deep a footprint presses, in metres.
const FOOT_DEPTH: f32 = 0.12;
/// Footprints per frame.
const STEPS_PER_FRAME: u32 = 2;
/// Walking stride in metres.
const STRIDE: f32 = 0.9;
/// A crater lands every this many frames.
const CRATER_EVERY: u32 = 5;
/// Shockwave footprint as a fraction of the map's smaller side.
const SHOCK_SIZE_FRACTION: f32 = 0.45;
/// Shockwave amplitude in metres.
const SHOCK_AMPLITUDE: f32 = 2.5;
/// Wave steps (eq. 3.7) per frame.
const SHOCK_STEPS_PER_FRAME: u32 = 2;

/// What one frame of the scenario did to the map.
#[derive(Debug, Default)]
pub struct FrameDeformations {
    /// Number of stamps by kind.
    pub footprints: u32,
    /// Craters stamped.
    pub craters: u32,
    /// Shockwave stamps (0 or 1).
    pub shockwaves: u32,
    /// The map rects the stamps covered.
    pub dirty: Vec<DirtyRect>,
}

/// Deterministic choices for the scenario (splitmix64).
#[derive(Debug)]
struct Rng(u64);

impl Rng {
    fn next_f32(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// The default scenario over a map of `extent` metres.
#[derive(Debug)]
pub struct Scenario {
    extent: Vec2,
    rng: Rng,
    footprint: TextureStamp,
    crater: GaussianStamp,
    shockwave: Option<Shockwave>,
    frame: u32,
}

impl Scenario {
    /// A scenario for a map of `extent` metres, seeded.
    pub fn new(extent: Vec2, seed: u64) -> Result<Self> {
        let image = decode_png8(FOOTPRINT_PNG, &ReadLimits::default())
            .context("the embedded footprint image")?;
        Ok(Self {
            extent,
            rng: Rng(seed ^ 0xD1B5_4A32_D192_ED03),
            footprint: TextureStamp::from_gray8(&image),
            crater: GaussianStamp::default(),
            shockwave: None,
            frame: 0,
        })
    }

    /// Applies the next frame's deformations to `map`.
    pub fn apply_next_frame(&mut self, map: &mut CoarseMap) -> Result<FrameDeformations> {
        let frame = self.frame;
        self.frame += 1;
        let mut out = FrameDeformations::default();
        let min_side = self.extent.min_element();

        // The walker loops around the map's middle, alternating left and right feet.
        let radius = min_side * 0.3;
        for k in 0..STEPS_PER_FRAME {
            let s = (frame * STEPS_PER_FRAME + k) as f32 * STRIDE;
            let angle = s / radius;
            let heading = Vec2::new(-angle.sin(), angle.cos());
            let side = if k % 2 == 0 { 0.2 } else { -0.2 };
            let pos = self.extent * 0.5
                + Vec2::new(angle.cos(), angle.sin()) * radius
                + heading.perp() * side;
            let placement = StampPlacement::new(pos, FOOT_SIZE, -FOOT_DEPTH)?
                .with_rotation(heading.y.atan2(heading.x))?;
            out.dirty.extend(apply_stamp(
                map,
                &mut self.footprint,
                &placement,
                Blend::Add,
            )?);
            out.footprints += 1;
        }

        // A crater now and then at a random spot, 6 to 14 m wide, 0.3 times as deep.
        if frame % CRATER_EVERY == 2 {
            let pos = Vec2::new(self.rng.next_f32(), self.rng.next_f32()) * self.extent;
            let size = (6.0 + 8.0 * self.rng.next_f32()).min(min_side * 0.5);
            let placement = StampPlacement::new(pos, Vec2::splat(size), -0.3 * size)?;
            out.dirty
                .extend(apply_stamp(map, &mut self.crater, &placement, Blend::Add)?);
            out.craters += 1;
        }

        // The shockwave starts on frame 1 and is stamped as its change every frame.
        if frame == 1 {
            self.shockwave = Some(Shockwave::new(ShockwaveParams {
                resolution: 128,
                initial_sigma: 3.0,
                damping: 0.002,
                ..ShockwaveParams::default()
            })?);
        }
        if let Some(wave) = self.shockwave.as_mut() {
            for _ in 0..SHOCK_STEPS_PER_FRAME {
                wave.step();
            }
            let size = min_side * SHOCK_SIZE_FRACTION;
            // Centred near the (0, 0) corner: the footprint wraps over both edges.
            let placement =
                StampPlacement::new(Vec2::splat(size * 0.2), Vec2::splat(size), SHOCK_AMPLITUDE)?;
            let mut delta = wave.take_delta()?;
            out.dirty
                .extend(apply_stamp(map, &mut delta, &placement, Blend::Add)?);
            out.shockwaves += 1;
        }
        Ok(out)
    }
}
