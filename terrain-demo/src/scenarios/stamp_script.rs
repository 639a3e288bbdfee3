//! The script of the default scenario: which stamps land where each frame (a trail of
//! footprints, Gaussian craters, and a shockwave started next to the map's corner so its
//! footprint crosses the wrap edges), and applying them to a CPU map.

use anyhow::{Context, Result};
use glam::Vec2;
use terrain_core::HeightEncoding;
use terrain_core::io::{ReadLimits, decode_png8};
use terrain_core::{
    Blend, CoarseMap, DirtyRect, GaussianStamp, Shockwave, ShockwaveParams, Stamp, StampPlacement,
    TextureStamp, apply_stamp,
};
use terrain_physics::DeformationBound;

/// The footprint image: white where the foot presses hardest (see `TextureStamp`).
const FOOTPRINT_PNG: &[u8] = include_bytes!("../../assets/footprint.png");

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

/// Which pattern a deformation uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StampKind {
    /// The footprint texture stamp.
    Footprint,
    /// The Gaussian crater.
    Crater,
    /// The shockwave's change since the last frame (a dynamic texture stamp).
    Shockwave,
}

/// One stamp to apply this frame (always an additive blend).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Deformation {
    /// The pattern.
    pub kind: StampKind,
    /// Where.
    pub placement: StampPlacement,
}

/// Everything one frame deforms.
#[derive(Debug, Default)]
pub struct FramePlan {
    /// Stamps in order.
    pub deformations: Vec<Deformation>,
    /// The shockwave's change this frame, used by [`StampKind::Shockwave`].
    pub shock_delta: Option<TextureStamp>,
    /// The walker's position (metres, X Z) and unit heading after this frame's steps.
    pub walker: (Vec2, Vec2),
}

impl FramePlan {
    /// Number of stamps of `kind`.
    pub fn count(&self, kind: StampKind) -> u32 {
        self.deformations.iter().filter(|d| d.kind == kind).count() as u32
    }
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

/// The default scenario's script over a map of `extent` metres.
#[derive(Debug)]
pub struct StampScript {
    extent: Vec2,
    rng: Rng,
    footprint: TextureStamp,
    crater: GaussianStamp,
    shockwave: Option<Shockwave>,
    frame: u32,
}

impl StampScript {
    /// A script for a map of `extent` metres, seeded.
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

    /// The footprint stamp (uploaded once to the GPU).
    pub fn footprint(&self) -> &TextureStamp {
        &self.footprint
    }

    /// The crater stamp.
    pub fn crater(&self) -> &GaussianStamp {
        &self.crater
    }

    /// Plans the next frame's deformations.
    pub fn plan_next_frame(&mut self) -> Result<FramePlan> {
        let frame = self.frame;
        self.frame += 1;
        let mut plan = FramePlan::default();
        let min_side = self.extent.min_element();

        // The walker loops around the map's middle, alternating left and right feet. It starts
        // on the side nearest the (0, 0) corner so it meets the shockwave within the default run.
        let radius = min_side * 0.3;
        for k in 0..STEPS_PER_FRAME {
            let s = (frame * STEPS_PER_FRAME + k) as f32 * STRIDE;
            let angle = s / radius + std::f32::consts::PI;
            let heading = Vec2::new(-angle.sin(), angle.cos());
            let side = if k % 2 == 0 { 0.2 } else { -0.2 };
            let pos = self.extent * 0.5
                + Vec2::new(angle.cos(), angle.sin()) * radius
                + heading.perp() * side;
            let placement = StampPlacement::new(pos, FOOT_SIZE, -FOOT_DEPTH)?
                .with_rotation(heading.y.atan2(heading.x))?;
            plan.deformations.push(Deformation {
                kind: StampKind::Footprint,
                placement,
            });
            plan.walker = (pos, heading);
        }

        // A crater now and then on the walker's path 25 m ahead (so the camera walks through it),
        // 6 to 14 m wide, 0.3 times as deep.
        if frame % CRATER_EVERY == 2 {
            let (walker, heading) = plan.walker;
            let side = (self.rng.next_f32() - 0.5) * 6.0;
            let pos = walker + heading * 25.0 + heading.perp() * side;
            let size = (6.0 + 8.0 * self.rng.next_f32()).min(min_side * 0.5);
            plan.deformations.push(Deformation {
                kind: StampKind::Crater,
                placement: StampPlacement::new(pos, Vec2::splat(size), -0.3 * size)?,
            });
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
            plan.deformations.push(Deformation {
                kind: StampKind::Shockwave,
                placement: StampPlacement::new(
                    Vec2::splat(size * 0.2),
                    Vec2::splat(size),
                    SHOCK_AMPLITUDE,
                )?,
            });
            plan.shock_delta = Some(wave.take_delta()?);
        }
        Ok(plan)
    }

    /// How far a deformation can move the ground before its readback arrives: footprint and
    /// crater values lie in [0, 1] (an additive stamp moves by at most its intensity); the
    /// shockwave's change lies in [-1, 1], so its intensity bounds both ways.
    pub fn bound(d: &Deformation, encoding: HeightEncoding) -> Result<DeformationBound> {
        let i = d.placement.intensity;
        Ok(match d.kind {
            StampKind::Shockwave => {
                DeformationBound::new(i.abs() + encoding.scale, i.abs() + encoding.scale)?
            }
            _ => DeformationBound::additive(i, encoding)?,
        })
    }

    /// Where the walker starts (metres, X Z).
    pub fn walker_start(&self) -> Vec2 {
        let radius = self.extent.min_element() * 0.3;
        self.extent * 0.5 - Vec2::new(radius, 0.0)
    }

    /// Applies `plan` to a CPU map with terrain-core's reference stamps; returns the rects of
    /// each deformation, in plan order.
    pub fn apply_cpu(
        &mut self,
        map: &mut CoarseMap,
        plan: &mut FramePlan,
    ) -> Result<Vec<Vec<DirtyRect>>> {
        let mut dirty = Vec::new();
        for d in &plan.deformations {
            let stamp: &mut dyn Stamp = match d.kind {
                StampKind::Footprint => &mut self.footprint,
                StampKind::Crater => &mut self.crater,
                StampKind::Shockwave => match plan.shock_delta.as_mut() {
                    Some(s) => s,
                    None => {
                        dirty.push(Vec::new());
                        continue;
                    }
                },
            };
            dirty.push(apply_stamp(map, stamp, &d.placement, Blend::Add)?);
        }
        Ok(dirty)
    }
}
