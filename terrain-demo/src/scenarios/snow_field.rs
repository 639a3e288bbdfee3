//! The snow field of the snow scenario: a four-wheeled vehicle and a walker cross it, deformed
//! by volume-preserving granular deformation (Persson 2019): trails with raised rims.

use anyhow::{Result, bail};
use glam::{Affine3A, Quat, UVec2, Vec2, Vec3};
use terrain_core::granular::{GranularObject, GranularParams, GranularSim, StepReport, TriMesh};
use terrain_core::{CoarseMap, FixedPointMap, Grid, HeightEncoding, Rect, TerrainParams};

/// Metres per texel of the snow field.
pub const SNOW_TEXEL: f32 = 0.05;
/// Fixed-point units per metre (Persson 2019, sec. 4.3).
const UNITS_PER_M: u32 = 10_000;
/// Depth of the snow layer in metres, and the height of the gentle ground undulation under it.
const SNOW_DEPTH: f32 = 0.5;
const UNDULATION: f32 = 0.3;
/// Vehicle: wheel radius and half width, wheelbase and track (metres); how deep the wheels sink.
const WHEEL_RADIUS: f32 = 0.4;
const WHEEL_HALF_WIDTH: f32 = 0.12;
const WHEELBASE: f32 = 2.4;
const TRACK: f32 = 1.5;
const WHEEL_SINK: f32 = 0.18;
/// Walker: foot size and how deep a step presses; stride.
const FOOT: Vec3 = Vec3::new(0.11, 0.3, 0.12); // width, length, height
const FOOT_SINK: f32 = 0.12;
const STRIDE: f32 = 0.7;
/// Distance per frame of the vehicle and of the walker.
const VEHICLE_STEP: f32 = 0.35;

/// Where the objects are in one frame.
#[derive(Debug, Clone, Copy)]
pub struct SnowPoses {
    /// The four wheels.
    wheels: [Affine3A; 4],
    /// The walker's foot down this frame.
    foot: Affine3A,
    /// Where the vehicle is (metres, X Z) and its unit heading.
    pub vehicle: (Vec2, Vec2),
}

/// The snow field, the objects and the simulation.
#[derive(Debug)]
pub struct SnowField {
    sim: GranularSim,
    initial: FixedPointMap,
    wheel: TriMesh,
    foot: TriMesh,
    frame: u32,
    extent: Vec2,
}

impl SnowField {
    /// A snow field of `size` x `size` texels, seeded ground undulation.
    pub fn new(size: u32, seed: u64, params: GranularParams) -> Result<Self> {
        let ground = terrain_core::generate_heights(&TerrainParams {
            size: UVec2::splat(size),
            seed,
            octaves: 3,
            ..TerrainParams::default()
        })?;
        let units = |m: f32| (m * UNITS_PER_M as f32).round() as u32;
        let heights = ground.map(|g| units(SNOW_DEPTH + UNDULATION * g));
        let map = FixedPointMap::fixed_point(heights, UNITS_PER_M, SNOW_TEXEL)?;
        let extent = map.extent_m();
        Ok(Self {
            initial: map.clone(),
            sim: GranularSim::new(map, params)?,
            wheel: TriMesh::wheel(WHEEL_RADIUS, WHEEL_HALF_WIDTH, 32)?,
            foot: TriMesh::foot(FOOT.y, FOOT.x, FOOT.z)?,
            frame: 0,
            extent,
        })
    }

    /// Ground height in metres under `xz` (bilinear over the current heights).
    pub fn height(&self, xz: Vec2) -> f32 {
        terrain_core::bilinear(self.sim.map(), xz).unwrap_or(0.0)
    }

    /// The vehicle's centre and heading at frame `f`: a gentle S-curve across the field.
    fn vehicle_at(&self, f: f32) -> (Vec2, Vec2) {
        let z = self.extent.y * 0.15 + f * VEHICLE_STEP;
        let x = self.extent.x * 0.45 + (z * 0.12).sin() * 2.0;
        let dx = (z * 0.12).cos() * 2.0 * 0.12;
        (Vec2::new(x, z), Vec2::new(dx, 1.0).normalize())
    }

    /// The objects' poses of the next frame (and advances the frame counter).
    pub fn next_poses(&mut self) -> SnowPoses {
        let f = self.frame as f32;
        self.frame += 1;
        let (centre, heading) = self.vehicle_at(f);
        let rotation = Quat::from_rotation_y(heading.x.atan2(heading.y));
        let side = heading.perp();
        let corners = [(1.0f32, 1.0f32), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)];
        let wheels = corners.map(|(along, across)| {
            let xz = centre + heading * (along * WHEELBASE * 0.5) + side * (across * TRACK * 0.5);
            // The wheel's centre sits so its bottom is WHEEL_SINK under the undisturbed snow.
            let y = self.undisturbed(xz) - WHEEL_SINK + WHEEL_RADIUS;
            Affine3A::from_rotation_translation(rotation, Vec3::new(xz.x, y, xz.y))
        });
        // The walker goes beside the vehicle, one foot down per frame, left and right.
        let walk_z = self.extent.y * 0.2 + f * STRIDE * 0.5;
        let foot_side = if self.frame.is_multiple_of(2) {
            0.12
        } else {
            -0.12
        };
        let foot_xz = Vec2::new(self.extent.x * 0.7 + foot_side, walk_z);
        let foot_y = self.undisturbed(foot_xz) - FOOT_SINK;
        SnowPoses {
            wheels,
            foot: Affine3A::from_translation(Vec3::new(foot_xz.x, foot_y, foot_xz.y)),
            vehicle: (centre, heading),
        }
    }

    /// The granular objects at `poses`.
    pub fn objects(&self, poses: &SnowPoses) -> Vec<GranularObject<'_>> {
        let mut objects: Vec<GranularObject<'_>> = poses
            .wheels
            .iter()
            .map(|t| GranularObject::new(&self.wheel, *t))
            .collect();
        objects.push(GranularObject::new(&self.foot, poses.foot));
        objects
    }

    /// Runs one granular step on the CPU with the objects at `poses`.
    pub fn step(&mut self, poses: &SnowPoses) -> Result<StepReport> {
        let objects: Vec<GranularObject<'_>> = poses
            .wheels
            .iter()
            .map(|t| GranularObject::new(&self.wheel, *t))
            .chain(std::iter::once(GranularObject::new(&self.foot, poses.foot)))
            .collect();
        Ok(self.sim.step(&objects)?)
    }

    /// The fixed-point heights (the CPU simulation's, or the GPU's as they arrive).
    pub fn map(&self) -> &FixedPointMap {
        self.sim.map()
    }

    /// The simulation's parameters.
    pub fn params(&self) -> &GranularParams {
        self.sim.params()
    }

    /// Writes heights that a GPU step made (read back) into the field's map at `rect`.
    pub fn write_region(&mut self, rect: Rect, heights: &Grid<u32>) -> Result<()> {
        if heights.size() != rect.size {
            bail!("region {rect:?} came with {} heights", heights.size());
        }
        self.sim.map_mut().grid_mut().paste(heights, rect.min)?;
        Ok(())
    }

    /// The snow surface before any deformation: the objects' reference height, so a wheel
    /// sinks by the same depth whatever the trail in front of it already did.
    fn undisturbed(&self, xz: Vec2) -> f32 {
        terrain_core::bilinear(&self.initial, xz).unwrap_or(0.0)
    }

    /// The total removed so far (compression), in height units.
    pub fn removed(&self) -> u64 {
        self.sim.total_removed()
    }

    /// The heights as a 16-bit coarse-map for rendering and collision (same 0.1 mm scale;
    /// snow heights stay well under the 6.5 m that u16 holds at that scale).
    pub fn coarse_map(&self) -> Result<CoarseMap> {
        let map = self.sim.map();
        let grid: Grid<u16> = map.grid().map(|&v| to_coarse(v));
        let enc = HeightEncoding::new(map.encoding().scale, 0.0)?;
        Ok(CoarseMap::coarse(grid, enc, map.texel_size())?)
    }

    /// Copies the heights of `rect` (inside the field, e.g. an active area of the last step)
    /// into `coarse`, a map from [`SnowField::coarse_map`]: only what a step changed.
    pub fn copy_to_coarse(&self, coarse: &mut CoarseMap, rect: Rect) -> Result<()> {
        let src = self.sim.map().grid();
        if coarse.size() != src.size() || !src.rect().contains_rect(&rect) {
            bail!(
                "rect {rect:?} of a {} snow field cannot go into a {} map",
                src.size(),
                coarse.size()
            );
        }
        let (x0, x1) = (rect.min.x as usize, rect.max().x as usize);
        for y in rect.min.y as u32..rect.max().y as u32 {
            let dst = &mut coarse.grid_mut().row_mut(y)[x0..x1];
            for (d, s) in dst.iter_mut().zip(&src.row(y)[x0..x1]) {
                *d = to_coarse(*s);
            }
        }
        Ok(())
    }
}

/// A fixed-point height as the coarse-map's u16 (same scale, saturating).
fn to_coarse(v: u32) -> u16 {
    v.min(u32::from(u16::MAX)) as u16
}
