//! `GpuGranularStep`: one granular step on the GPU over the merged active areas of a list of
//! objects, as `terrain_core::granular::GranularSim::step`.

use super::depth::DepthFromBelowPass;
use super::map::GpuGranularMap;
use super::passes::{DisplacePass, JumpFloodPass, PenetrationPass, SlopePass};
use super::scratch::GranularScratch;
use crate::error::GpuError;
use terrain_core::Grid;
use terrain_core::granular::{
    ActiveArea, AreaMode, DisplacementMethod, GranularError, GranularObject, GranularParams,
    NO_OBJECT, SlopeMethod, depth_from_below_into, merge_active_areas, object_active_area,
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
    /// Rendered on the GPU by [`DepthFromBelowPass`] (coverage may differ from the CPU
    /// rasterizer on exactly grid-aligned edges: see its tests).
    #[default]
    Gpu,
    /// Rasterised on the CPU ([`depth_from_below_into`]) and uploaded: the whole step then
    /// equals [`terrain_core::granular::GranularSim::step`] bit for bit.
    Cpu,
}

/// Chains [`DepthFromBelowPass`] (or the CPU rasterizer), [`PenetrationPass`],
/// [`JumpFloodPass`], [`DisplacePass`] and [`SlopePass`] over the active areas of a step, with
/// the settings of [`terrain_core::granular::GranularSim`].
#[derive(Debug)]
pub struct GpuGranularStep {
    penetration: PenetrationPass,
    jfa: JumpFloodPass,
    displace: DisplacePass,
    slope_pass: SlopePass,
    depth_pass: DepthFromBelowPass,
    scratch: Option<GranularScratch>,
    params: GranularParams,
    /// Where the depth from below comes from.
    pub depth_source: DepthSource,
    /// Displacement method.
    pub displacement: DisplacementMethod,
    /// Slope method.
    pub slope: SlopeMethod,
    /// Area mode.
    pub area_mode: AreaMode,
}

/// A CPU-side granular error (objects, parameters) as a [`GpuError`]: core errors as they are,
/// others as a validation error carrying the message.
fn granular_error(e: GranularError) -> GpuError {
    match e {
        GranularError::Core(c) => GpuError::Core(c),
        other => GpuError::Validation {
            context: "granular step",
            message: other.to_string(),
        },
    }
}

impl GpuGranularStep {
    /// Builds the passes, with validated `params`, closest-seed displacement, scatter slopes
    /// and active areas (the defaults of `GranularSim`).
    pub fn new(device: &wgpu::Device, params: GranularParams) -> Result<Self, GpuError> {
        params.validate().map_err(granular_error)?;
        Ok(Self {
            penetration: PenetrationPass::new(device)?,
            jfa: JumpFloodPass::new(device)?,
            displace: DisplacePass::new(device)?,
            slope_pass: SlopePass::new(device)?,
            depth_pass: DepthFromBelowPass::new(device)?,
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

    /// The areas a step with `objects` runs over on `map`.
    pub fn active_areas(
        &self,
        map: &GpuGranularMap,
        objects: &[GranularObject<'_>],
    ) -> Result<Vec<ActiveArea>, GpuError> {
        if self.area_mode == AreaMode::FullMap {
            return Ok(vec![ActiveArea::full_map(map.size())]);
        }
        let mut areas = Vec::with_capacity(objects.len());
        for o in objects {
            o.validate().map_err(granular_error)?;
            if let Some(a) = object_active_area(
                o,
                map.texel_size(),
                map.size(),
                self.params.active_area_margin,
            )
            .map_err(granular_error)?
            {
                areas.push(a);
            }
        }
        Ok(merge_active_areas(&areas, self.params.merge_distance))
    }

    /// Records a step into `encoder` and returns its areas;
    /// the removed amount accumulates in the scratch counter, zeroed at the start.
    pub fn encode(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuGranularMap,
        objects: &[GranularObject<'_>],
    ) -> Result<Vec<ActiveArea>, GpuError> {
        let areas = self.active_areas(map, objects)?;
        let need = areas.iter().map(|a| a.columns()).max().unwrap_or(1);
        if self.scratch.as_ref().is_none_or(|s| s.capacity() < need) {
            self.scratch = Some(GranularScratch::new(device, need)?);
        }
        let Some(scratch) = self.scratch.as_ref() else {
            return Err(GpuError::Unsupported {
                what: "GpuGranularStep",
                reason: "no scratch buffers",
            });
        };
        scratch.clear_removed(encoder);
        let p = self.params;
        let units = map.units_per_metre();
        let margin = (f64::from(p.obstacle_margin_m) * units)
            .round()
            .min(f64::from(u32::MAX)) as u32;
        let thresholds = p.slope_thresholds_units(map.texel_size(), units);
        for area in &areas {
            let rect = area.rect;
            let depth_buf = match self.depth_source {
                DepthSource::Gpu => {
                    let out = DepthFromBelowPass::create_output(device, rect)?;
                    self.depth_pass.encode(
                        device,
                        encoder,
                        objects,
                        map.encoding(),
                        map.texel_size(),
                        rect,
                        &out,
                    )?;
                    out
                }
                DepthSource::Cpu => {
                    let mut depth = Grid::new(rect.size.x, rect.size.y, NO_OBJECT)?;
                    depth_from_below_into(
                        objects,
                        map.encoding(),
                        map.texel_size(),
                        rect,
                        &mut depth,
                    )
                    .map_err(granular_error)?;
                    PenetrationPass::upload_depth(device, &depth)
                }
            };
            self.penetration
                .encode(device, encoder, map, &depth_buf, rect, margin, scratch)?;
            let seeds = self.jfa.encode(
                device,
                encoder,
                map.size(),
                rect,
                p.metric,
                p.jfa_extra_pass,
                scratch,
            )?;
            match self.displacement {
                DisplacementMethod::Iterative => self.displace.encode_iterative(
                    device,
                    encoder,
                    map,
                    rect,
                    p.keep_q15(),
                    p.num_iterations_displace_material_to_contour,
                    p.metric,
                    seeds,
                    scratch,
                )?,
                method => self.displace.encode(
                    device,
                    encoder,
                    map,
                    rect,
                    method,
                    p.keep_q15(),
                    seeds,
                    scratch,
                )?,
            }
            self.slope_pass.encode(
                device,
                encoder,
                map,
                rect,
                self.slope,
                thresholds,
                p.roughness_q15(),
                p.num_iterations_even_out_slopes,
                scratch,
            )?;
        }
        Ok(areas)
    }

    /// Runs a step: records it, submits it, and reads back the removed amount.
    pub fn step(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        map: &GpuGranularMap,
        objects: &[GranularObject<'_>],
    ) -> Result<GpuStepReport, GpuError> {
        let mut encoder = device.create_command_encoder(&Default::default());
        let active_areas = self.encode(device, &mut encoder, map, objects)?;
        queue.submit([encoder.finish()]);
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
