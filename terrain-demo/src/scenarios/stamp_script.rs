//! The script of the default scenario: which stamps land where each frame (a trail of
//! footprints, Gaussian craters, and a shockwave started next to the map's corner so its
//! footprint crosses the wrap edges), and applying them to a CPU map.

use anyhow::{Context, Result};
use glam::Vec2;
use terrain_core::HeightEncoding;
use terrain_core::io::{ReadLimits, decode_png8};
use terrain_core::{
    Blend, CoarseMap, DirtyRect, GaussianStamp, Shockwave, Stamp, StampPlacement, TextureStamp,
    apply_stamp,
};
use terrain_physics::DeformationBound;

use crate::config::StampParams;
use crate::frame_plan::{Deformation, FramePlan, StampKind};

/// The footprint image: white where the foot presses hardest (see `TextureStamp`).
const FOOTPRINT_PNG: &[u8] = include_bytes!("../../assets/footprint.png");

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
    params: StampParams,
}

impl StampScript {
    /// A script for a map of `extent` metres, seeded, shaped by `params` (`[stamps]`).
    pub fn new(extent: Vec2, seed: u64, params: StampParams) -> Result<Self> {
        let image = decode_png8(FOOTPRINT_PNG, &ReadLimits::default())
            .context("the embedded footprint image")?;
        Ok(Self {
            extent,
            rng: Rng(seed ^ 0xD1B5_4A32_D192_ED03),
            footprint: TextureStamp::from_gray8(&image),
            crater: GaussianStamp::default(),
            shockwave: None,
            frame: 0,
            params,
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
        let p = self.params;
        for k in 0..p.steps_per_frame {
            let s = (u64::from(frame) * u64::from(p.steps_per_frame) + u64::from(k)) as f32
                * p.stride_m;
            let angle = s / radius + std::f32::consts::PI;
            let heading = Vec2::new(-angle.sin(), angle.cos());
            let side = if k % 2 == 0 { 0.2 } else { -0.2 };
            let pos = self.extent * 0.5
                + Vec2::new(angle.cos(), angle.sin()) * radius
                + heading.perp() * side;
            // At most half the map, as craters and the hole (a footprint larger than a small
            // repeating map would overlap itself).
            let foot = p.foot_size_m.min(Vec2::splat(min_side * 0.5));
            let placement = StampPlacement::new(pos, foot, -p.foot_depth_m)?
                .with_rotation(heading.y.atan2(heading.x))?;
            plan.deformations.push(Deformation {
                kind: StampKind::Footprint,
                placement,
            });
            plan.walker = (pos, heading);
        }

        // A crater now and then on the walker's path 25 m ahead (so the camera walks through it),
        // 6 to 14 m wide, 0.3 times as deep by default.
        if p.crater_every > 0 && frame % p.crater_every == 2 % p.crater_every {
            let (walker, heading) = plan.walker;
            let side = (self.rng.next_f32() - 0.5) * 6.0;
            let pos = walker + heading * 25.0 + heading.perp() * side;
            let (lo, hi) = (p.crater_size_m.x, p.crater_size_m.y);
            let size = (lo + (hi - lo) * self.rng.next_f32()).min(min_side * 0.5);
            plan.deformations.push(Deformation {
                kind: StampKind::Crater,
                placement: StampPlacement::new(
                    pos,
                    Vec2::splat(size),
                    -p.crater_depth_ratio * size,
                )?,
            });
        }

        // The hole: cut once, beside the path ahead on the outside of its curve (the path bends
        // away from it), so the camera walks past and looks in.
        if p.hole_frame > 0 && frame == p.hole_frame {
            let (walker, heading) = plan.walker;
            let pos = walker + heading * 30.0 - heading.perp() * 10.0;
            let size = p.hole_size_m.min(min_side * 0.5);
            plan.hole = Some(StampPlacement::new(pos, Vec2::splat(size), 0.0)?);
        }

        // The shockwave starts on frame 1 and is stamped as its change every frame.
        if frame == 1 && p.shock_size_fraction > 0.0 {
            self.shockwave = Some(Shockwave::new(p.shockwave)?);
        }
        if let Some(wave) = self.shockwave.as_mut() {
            for _ in 0..p.shock_steps_per_frame {
                wave.step();
            }
            let size = min_side * p.shock_size_fraction;
            // Centred near the (0, 0) corner: the footprint wraps over both edges.
            plan.deformations.push(Deformation {
                kind: StampKind::Shockwave,
                placement: StampPlacement::new(
                    Vec2::splat(size * 0.2),
                    Vec2::splat(size),
                    p.shock_amplitude_m,
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

    /// Applies `plan` to a CPU map with terrain-core's reference stamps, the footprints to
    /// the detail layer instead when there is one (stamped here, or read back from the GPU's);
    /// returns the rects of each deformation on the map, in plan order (none for a footprint
    /// in the detail layer), and the detail texels inside the rects the footprints stamped here.
    pub fn apply_cpu(
        &mut self,
        map: &mut CoarseMap,
        plan: &mut FramePlan,
        mut detail: DetailTarget<'_>,
    ) -> Result<(Vec<Vec<DirtyRect>>, u64)> {
        let mut dirty = Vec::new();
        let mut detail_texels = 0;
        for d in &plan.deformations {
            if d.kind == StampKind::Footprint {
                match &mut detail {
                    DetailTarget::None => {}
                    DetailTarget::Cpu(cache) => {
                        // A footprint deeper than the tiles' range spills into the coarse-map
                        // (its rects are then dirty there: normals, collision).
                        let p = &d.placement;
                        let (change, spilled) =
                            cache.apply_stamp_spilling(map, &mut self.footprint, p, Blend::Add)?;
                        detail_texels += change.tiles.iter().map(|(_, r)| r.area()).sum::<u64>();
                        dirty.push(spilled);
                        continue;
                    }
                }
            }
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
        Ok((dirty, detail_texels))
    }
}

/// Where [`StampScript::apply_cpu`] puts the footprints.
#[derive(Debug)]
pub enum DetailTarget<'a> {
    /// No detail layer: into the coarse-map.
    None,
    /// Stamped into this detail cache on the CPU (beside a GPU too: the GPU's tiles are read
    /// back over it afterwards), spilling into the map.
    Cpu(&'a mut terrain_cache::detail::DetailCache),
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On a map smaller than the stamps asked for (0.64 m, footprints of 7 m), every stamp is
    /// at most half the map, so none overlaps itself on a repeating map: each fits a 64^2
    /// map at 0.01 m.
    #[test]
    fn stamps_fit_a_map_smaller_than_they_ask() {
        let params = StampParams {
            foot_size_m: Vec2::splat(7.0),
            ..StampParams::default()
        };
        let mut script = StampScript::new(Vec2::splat(0.64), 1, params).unwrap();
        for _ in 0..12 {
            let plan = script.plan_next_frame().unwrap();
            for d in &plan.deformations {
                if d.kind != StampKind::Shockwave {
                    assert!(d.placement.scale.max_element() <= 0.32, "{d:?}");
                }
                let region = terrain_core::stamp_region(
                    glam::UVec2::splat(64),
                    terrain_core::WrapMode::Repeat,
                    0.01,
                    &d.placement,
                );
                assert!(region.is_ok(), "{d:?}: {region:?}");
            }
        }
    }
}
