//! `GpuGranularStep`: one granular step on the GPU over the merged active areas of a list of
//! objects, as `terrain_core::granular::GranularSim::step`.

use super::depth::{DepthArea, DepthFromBelowPass};
use super::passes::{DisplacePass, JumpFloodPass, PenetrationPass, SlopePass, SlopeSettings};
use super::scratch::{GranularArea, GranularScratch};
use super::trail::{Trail, TrailEffectPass};
use crate::error::GpuError;
use crate::resources::maps::GpuHeightMap;
use terrain_core::Grid;
use terrain_core::granular::{
    ActiveArea, AreaMode, DisplacementMethod, GranularObject, GranularParams, NO_OBJECT,
    SlopeMethod, depth_from_below_into, merge_active_areas, object_active_area,
};

/// What one GPU step did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GpuStepReport {
    /// Material removed by compression this step, in height units (read back).
    pub removed: u64,
    /// The (merged) areas the step ran over.
    pub active_areas: Vec<ActiveArea>,
}

/// Where a step's depth from below comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DepthSource {
    /// Rasterised on the GPU by [`DepthFromBelowPass`] (the CPU reference's integer program:
    /// the same columns bit for bit).
    #[default]
    Gpu,
    /// Rasterised on the CPU ([`depth_from_below_into`]) and uploaded: the whole step then
    /// equals [`terrain_core::granular::GranularSim::step`] bit for bit.
    Cpu,
}

/// Chains [`DepthFromBelowPass`] (or the CPU rasterizer), [`PenetrationPass`],
/// [`JumpFloodPass`], [`DisplacePass`] and [`SlopePass`] over the active areas of a step, with
/// the settings of [`terrain_core::granular::GranularSim`], and optionally a
/// [`TrailEffectPass`] ([`Self::encode_with_trail`]).
///
/// The passes are built in [`Self::new`]; the scratch buffers on the first step, and again only
/// when an area has more columns than they hold. A recorded step only writes uniforms (and, with
/// [`DepthSource::Cpu`], the depth grids) and records commands. [`Self::encode`] leaves the
/// submit to the caller, who then calls [`Self::recall`]; [`Self::step`] does all three.
#[derive(Debug)]
pub struct GpuGranularStep {
    penetration: PenetrationPass,
    jfa: JumpFloodPass,
    displace: DisplacePass,
    slope_pass: SlopePass,
    depth_pass: DepthFromBelowPass,
    /// Built on the first step that paints a trail.
    trail_pass: Option<TrailEffectPass>,
    scratch: Option<GranularScratch>,
    params: GranularParams,
    /// Where the depth from below comes from.
    pub depth_source: DepthSource,
    /// Displacement method, with its settings (checked at each step).
    pub displacement: DisplacementMethod,
    /// Slope method.
    pub slope: SlopeMethod,
    /// Area mode.
    pub area_mode: AreaMode,
}

impl GpuGranularStep {
    /// Builds the passes, with validated `params`, closest-seed displacement, scatter slopes
    /// and active areas (the defaults of `GranularSim`).
    pub fn new(device: &wgpu::Device, params: GranularParams) -> Result<Self, GpuError> {
        params.validate()?;
        Ok(Self {
            penetration: PenetrationPass::new(device)?,
            jfa: JumpFloodPass::new(device)?,
            displace: DisplacePass::new(device)?,
            slope_pass: SlopePass::new(device)?,
            depth_pass: DepthFromBelowPass::new(device)?,
            trail_pass: None,
            scratch: None,
            params,
            depth_source: DepthSource::default(),
            displacement: DisplacementMethod::default(),
            slope: SlopeMethod::default(),
            area_mode: AreaMode::default(),
        })
    }

    /// The parameters.
    pub fn params(&self) -> &GranularParams {
        &self.params
    }

    /// The scratch buffers of the last step (none before the first).
    pub fn scratch(&self) -> Option<&GranularScratch> {
        self.scratch.as_ref()
    }

    /// Frees what every pass recorded (uniform slots, uploads): call it after the submit that
    /// carries a step recorded by [`Self::encode`].
    pub fn recall(&mut self) {
        self.penetration.recall();
        self.jfa.recall();
        self.displace.recall();
        self.slope_pass.recall();
        self.depth_pass.recall();
        if let Some(trail) = self.trail_pass.as_mut() {
            trail.recall();
        }
    }

    /// The areas a step with `objects` runs over on `map`.
    pub fn active_areas(
        &self,
        map: &GpuHeightMap<u32>,
        objects: &[GranularObject<'_>],
    ) -> Result<Vec<ActiveArea>, GpuError> {
        for o in objects {
            o.validate()?;
        }
        if self.area_mode == AreaMode::FullMap {
            return Ok(vec![ActiveArea::full_map(map.size())]);
        }
        let mut areas = Vec::with_capacity(objects.len());
        for o in objects {
            if let Some(a) = object_active_area(
                o,
                map.texel_size(),
                map.size(),
                self.params.active_area_margin,
            )? {
                areas.push(a);
            }
        }
        Ok(merge_active_areas(&areas, self.params.merge_distance))
    }

    /// Makes the scratch hold areas of `columns` columns (of a map of `map_columns`): regrown
    /// by half again at least, so areas that grow a little every frame do not reallocate every
    /// frame. The passes drop their bind groups over the old buffers.
    fn reserve(
        &mut self,
        device: &wgpu::Device,
        columns: u64,
        map_columns: u64,
    ) -> Result<(), GpuError> {
        let old = self.scratch.as_ref().map_or(0, GranularScratch::capacity);
        if old >= columns {
            return Ok(());
        }
        let capacity = columns.max(old + old / 2).min(map_columns.max(columns));
        self.scratch = Some(GranularScratch::new(device, capacity)?);
        // The passes' cached bind groups would keep the old buffers alive (their `bindings`
        // are visible to the granular module for this).
        self.penetration.bindings.clear_bind_groups();
        self.jfa.bindings.clear_bind_groups();
        self.displace.bindings.clear_bind_groups();
        self.slope_pass.bindings.clear_bind_groups();
        self.depth_pass.bindings.clear_bind_groups();
        if let Some(trail) = self.trail_pass.as_mut() {
            trail.bindings.clear_bind_groups();
        }
        Ok(())
    }

    /// Records a step into `encoder` and returns its areas; the removed amount accumulates in
    /// the scratch's counter ([`GranularScratch::read_removed`]), zeroed at the start. Submit
    /// the encoder, then call [`Self::recall`]. Objects and settings are checked before
    /// anything is recorded.
    pub fn encode(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuHeightMap<u32>,
        objects: &[GranularObject<'_>],
    ) -> Result<Vec<ActiveArea>, GpuError> {
        self.encode_with_trail(device, queue, encoder, map, objects, None)
    }

    /// [`Self::encode`], painting `trail` (if any) on the columns the step presses down
    /// ([`TrailEffectPass`], between the penetration and the jump flooding passes of each
    /// area). A trail whose effect or layer size does not fit the map is refused with nothing
    /// recorded.
    pub fn encode_with_trail(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuHeightMap<u32>,
        objects: &[GranularObject<'_>],
        trail: Option<Trail<'_>>,
    ) -> Result<Vec<ActiveArea>, GpuError> {
        self.displacement.validate()?;
        if let Some(trail) = &trail {
            TrailEffectPass::check(trail, map.size())?;
            if self.trail_pass.is_none() {
                self.trail_pass = Some(TrailEffectPass::new(device)?);
            }
        }
        let areas = self.active_areas(map, objects)?;
        let need = areas.iter().map(|a| a.columns()).max().unwrap_or(1);
        let map_columns = u64::from(map.size().x) * u64::from(map.size().y);
        self.reserve(device, need, map_columns)?;
        let Some(scratch) = self.scratch.as_ref() else {
            return Ok(areas);
        };
        scratch.clear_removed(encoder);
        let p = self.params;
        let units = map.units_per_metre();
        let margin = (f64::from(p.obstacle_margin_m) * units)
            .round()
            .min(f64::from(u32::MAX)) as u32;
        let slopes = SlopeSettings::from_params(&p, map.texel_size(), units);
        for active in &areas {
            let rect = active.rect;
            let area = GranularArea::new(device, map, rect, scratch)?;
            match self.depth_source {
                DepthSource::Gpu => self.depth_pass.encode(
                    device,
                    queue,
                    encoder,
                    objects,
                    &DepthArea::for_map(map, rect)?,
                    &scratch.depth,
                )?,
                DepthSource::Cpu => {
                    let mut depth = Grid::new(rect.size.x, rect.size.y, NO_OBJECT)?;
                    depth_from_below_into(
                        objects,
                        map.encoding(),
                        map.texel_size(),
                        rect,
                        &mut depth,
                    )?;
                    self.penetration
                        .upload_depth(device, queue, encoder, &area, &depth)?;
                }
            }
            self.penetration
                .encode(device, queue, encoder, &area, margin)?;
            if let (Some(trail), Some(pass)) = (&trail, self.trail_pass.as_mut()) {
                pass.encode(device, queue, encoder, &area, trail)?;
            }
            let flooded =
                self.jfa
                    .encode(device, queue, encoder, &area, p.metric, p.jfa_extra_pass)?;
            self.displace.encode(
                device,
                queue,
                encoder,
                &flooded,
                self.displacement,
                p.keep_q15(),
            )?;
            self.slope_pass
                .encode(device, queue, encoder, &area, self.slope, &slopes)?;
        }
        Ok(areas)
    }

    /// Runs a step: records it, submits it, recalls the passes, and reads back the removed
    /// amount (8 bytes, through the scratch's readback buffer).
    pub fn step(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        map: &GpuHeightMap<u32>,
        objects: &[GranularObject<'_>],
    ) -> Result<GpuStepReport, GpuError> {
        let mut encoder = device.create_command_encoder(&Default::default());
        let recorded = self.encode(device, queue, &mut encoder, map, objects);
        if recorded.is_ok() {
            queue.submit([encoder.finish()]);
            crate::device::trace::record("granular step: submitted", 0);
        }
        self.recall();
        let active_areas = recorded?;
        let removed = match &self.scratch {
            Some(s) => s.read_removed(device, queue)?,
            None => 0,
        };
        Ok(GpuStepReport {
            removed,
            active_areas,
        })
    }
}
