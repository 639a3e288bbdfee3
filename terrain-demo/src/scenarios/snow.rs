//! The snow scenario (`--scenario snow`): a vehicle and a walker cross a snow field deformed by
//! volume-preserving granular deformation; the camera walks on it behind the vehicle.
//!
//! With a GPU the step runs there (`GpuGranularStep`, depth from below on the GPU) and the
//! frame is drawn straight from the GPU map; the areas a step changed come back by region
//! readback a frame later and update the CPU copy (overview, collision, `terrain_final.png`).
//! Without one, terrain-core's `GranularSim` steps on the CPU. Either way only the changed
//! areas are copied to the coarse-map, its normals and the collision mirror.

use super::snow_field::SnowField;
use super::{FRAME_DT, FinishStats, FrameContext, FrameOutcome, Scenario, ScenarioInfo};
use crate::camera_rig::CameraRig;
use crate::cli::Cli;
use crate::config::DemoParams;
use crate::gpu_scene::GpuScene;
use crate::report::FrameStats;
use crate::timings::{GranularFigure, Step, ms_since};
use crate::usage_error::UsageExt;
use anyhow::Result;
use glam::{UVec2, Vec2};
use std::time::Instant;
use terrain_core::granular::StepMeasure;
use terrain_core::{CoarseMap, Rect, bilinear};
use terrain_physics::CollisionMirror;

/// Side of the snow field in texels by default (25.6 m at 0.05 m).
pub const SNOW_SIZE: u32 = 512;

/// The snow scenario.
#[derive(Debug)]
pub struct SnowScenario {
    info: ScenarioInfo,
    field: SnowField,
    /// The field's heights as a coarse-map, kept equal to the simulation's over the active areas.
    coarse: CoarseMap,
    /// Collision reads the field directly (it is deformed on the CPU: no readback needed).
    mirror: CollisionMirror,
    rig: CameraRig,
    /// Material removed by compression so far on the GPU, in height units.
    gpu_removed: u64,
    /// Whether the GPU scene runs the granular steps (set by `prepare_gpu`).
    on_gpu: bool,
}

impl SnowScenario {
    /// Generates the snow field of `--size` (512 by default) and places the camera.
    pub fn new(cli: &Cli, params: &DemoParams) -> Result<Self> {
        let size = cli.size.unwrap_or(SNOW_SIZE);
        let t = Instant::now();
        let field = SnowField::new(size, cli.seed, params.granular).usage()?;
        let coarse = field.coarse_map()?;
        let load_ms = ms_since(t);
        let mirror = CollisionMirror::from_map(&coarse)?;
        let start = Vec2::new(coarse.extent_m().x * 0.45, 0.5);
        let rig = CameraRig::new(
            start,
            bilinear(&coarse, start)?,
            coarse.extent_m().max_element(),
            &params.camera,
        )?;
        Ok(Self {
            info: ScenarioInfo {
                name: "snow",
                source: "procedural snow field".into(),
                load_ms,
                // The overview shades from the heights: no normal map on the CPU.
                initial_normals_ms: 0.0,
                heights: Some(super::heightmap::HeightsInfo::of_encoding(
                    coarse.encoding(),
                    terrain_core::hillshade_range(&coarse),
                    "snow field",
                )),
                camera: None,
            },
            field,
            coarse,
            mirror,
            rig,
            gpu_removed: 0,
            on_gpu: false,
        })
    }

    /// The report's figures of GPU steps' measures, in step order: the volume and the material
    /// removed so far.
    fn figures(&mut self, measured: &[StepMeasure]) -> Vec<GranularFigure> {
        measured
            .iter()
            .map(|m| {
                self.gpu_removed += m.removed;
                GranularFigure {
                    frame: m.tag,
                    volume: m.volume,
                    volume_taken: None,
                    removed: Some(self.gpu_removed),
                }
            })
            .collect()
    }
}

impl Scenario for SnowScenario {
    fn info(&self) -> &ScenarioInfo {
        &self.info
    }

    fn map(&self) -> &CoarseMap {
        &self.coarse
    }

    fn prepare_gpu(&mut self, scene: &mut GpuScene) -> Result<()> {
        // A snow field is white at any height; only steep rims shade to rock.
        scene.set_ramp(-20.0, -10.0);
        scene.enable_granular(self.field.map(), *self.field.params())?;
        self.on_gpu = true;
        Ok(())
    }

    /// No larger than the field: a small field is not blown up.
    fn overview_size(&self, side: u32) -> UVec2 {
        self.coarse.size().min(UVec2::splat(side))
    }

    /// The last steps' areas come back from the GPU before `terrain_final.png` is written.
    fn finish(&mut self, gpu: Option<&mut GpuScene>) -> Result<FinishStats> {
        let mut granular = Vec::new();
        if let Some(scene) = gpu
            && self.on_gpu
        {
            let drained = scene.drain_granular()?;
            for (rect, heights) in drained.areas {
                self.field.write_region(rect, &heights)?;
                self.field.copy_to_coarse(&mut self.coarse, rect)?;
            }
            granular = self.figures(&drained.measured);
        }
        Ok(FinishStats {
            granular,
            ..FinishStats::default()
        })
    }

    fn advance(&mut self, ctx: &mut FrameContext<'_>) -> Result<FrameOutcome> {
        let poses = self.field.next_poses();
        // The step, and the areas whose heights reached the CPU this frame: on the GPU those
        // of earlier steps as their readback arrives, on the CPU this step's active areas.
        let (volume, removed, deformed_texels, dirty, backend) = match ctx.gpu.as_deref_mut() {
            Some(scene) if self.on_gpu => {
                let objects = self.field.objects(&poses);
                let (areas, arrived) = scene.granular_step(&objects, ctx.timings)?;
                // The volumes of earlier steps, read back without a wait, go to their frames.
                for figure in self.figures(&arrived.measured) {
                    ctx.timings.add_late_granular(figure);
                }
                let mut dirty = Vec::with_capacity(arrived.areas.len());
                for (rect, heights) in &arrived.areas {
                    self.field.write_region(*rect, heights)?;
                    self.field.copy_to_coarse(&mut self.coarse, *rect)?;
                    dirty.push(*rect);
                }
                let deformed: u64 = areas.iter().map(Rect::area).sum();
                (None, None, deformed, dirty, "gpu")
            }
            _ => ctx.timings.time(Step::GranularCpu, || -> Result<_> {
                let report = self.field.step(&poses)?;
                let dirty: Vec<Rect> = report.active_areas.iter().map(|a| a.rect).collect();
                for rect in &dirty {
                    self.field.copy_to_coarse(&mut self.coarse, *rect)?;
                }
                let deformed = dirty.iter().map(Rect::area).sum();
                let removed = Some(self.field.removed());
                Ok((Some(report.volume), removed, deformed, dirty, "cpu"))
            })?,
        };

        let t = Instant::now();
        for rect in &dirty {
            self.mirror
                .apply_next(*rect, &self.coarse.grid().copy_rect(*rect)?)?;
        }
        let collider = self.mirror.collider();
        let field = &self.field;
        let camera = self
            .rig
            .step(poses.vehicle, FRAME_DT as f32, &collider, |p| {
                field.height(p)
            })?;
        let eye = self.rig.eye();
        let camera_clearance_m = eye.y - bilinear(&self.coarse, Vec2::new(eye.x, eye.z))?;
        ctx.timings.add(Step::Physics, ms_since(t));
        Ok(FrameOutcome {
            camera,
            camera_clearance_m,
            stats: FrameStats {
                dirty_texels: deformed_texels,
                granular_volume: volume,
                granular_removed: removed,
                granular_backend: Some(backend),
                ..FrameStats::default()
            },
            dirty,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[test]
    fn the_coarse_map_follows_the_field_through_its_active_areas() {
        let cli = Cli::try_parse_from(["demo", "--scenario", "snow", "--size", "128"]).unwrap();
        let mut snow = SnowScenario::new(&cli, &DemoParams::default()).unwrap();
        let mut timings = crate::timings::Timings::default();
        for _ in 0..3 {
            let mut ctx = FrameContext {
                now: Instant::now(),
                gpu: None,
                timings: &mut timings,
            };
            let out = snow.advance(&mut ctx).unwrap();
            assert!(!out.dirty.is_empty());
        }
        let full = snow.field.coarse_map().unwrap();
        assert_eq!(snow.coarse.grid(), full.grid());
        assert_eq!(snow.mirror.snapshot().heights(), full.grid());
    }
}
