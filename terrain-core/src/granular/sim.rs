//! The CPU driver of one granular step: depth from below, penetration, jump flooding,
//! displacement and slope evening over the merged active areas.

use super::{
    ActiveArea, DisplacementMethod, DistanceTransform, GranularError, GranularObject,
    GranularParams, Penetration, SlopeMethod, depth_from_below, displace_closest_seed,
    displace_iterative, displace_multiple_targets, even_out_slopes_interleaved,
    even_out_slopes_scatter, jump_flood, merge_active_areas, object_active_area,
    penetration_texture,
};
use crate::{FixedPointMap, Grid};

/// Which columns a step simulates (sec. 4.5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum AreaMode {
    /// One active area per object (footprint plus margin), nearby ones merged.
    #[default]
    ActiveAreas,
    /// The whole map every step (for comparison, as table 5.7).
    FullMap,
}

/// What one step did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StepReport {
    /// Material removed by compression this step, in height units.
    pub removed: u64,
    /// The (merged) areas the step ran over.
    pub active_areas: Vec<ActiveArea>,
    /// The u64 sum of all heights after the step (the conserved volume).
    pub volume: u64,
}

/// Owns a fixed-point map and runs granular deformation steps on it.
#[derive(Debug, Clone)]
pub struct GranularSim {
    map: FixedPointMap,
    params: GranularParams,
    /// Displacement method used by [`GranularSim::step`].
    pub displacement: DisplacementMethod,
    /// Slope method used by [`GranularSim::step`].
    pub slope: SlopeMethod,
    /// Nearest-seed transform used by [`GranularSim::step`] (jump flooding by default, as the
    /// GPU runs; [`DistanceTransform::Exact`] for exact nearest seeds on the CPU).
    pub distance: DistanceTransform,
    /// Area mode used by [`GranularSim::step`].
    pub area_mode: AreaMode,
    total_removed: u64,
}

impl GranularSim {
    /// A simulation over `map` (its encoding must be fixed point: offset 0, a whole number
    /// of units per metre) with validated `params`, closest-seed displacement, scatter slope
    /// evening and active areas.
    pub fn new(map: FixedPointMap, params: GranularParams) -> Result<Self, GranularError> {
        params.validate()?;
        let enc = map.encoding();
        let units = 1.0 / f64::from(enc.scale);
        if enc.offset != 0.0
            || !units.is_finite()
            || (units - units.round()).abs() > 1e-3 * units
            || units < 1.0
        {
            return Err(GranularError::NotFixedPoint {
                scale: enc.scale,
                offset: enc.offset,
            });
        }
        super::jfa::check_side(map.size())?;
        Ok(Self {
            map,
            params,
            displacement: DisplacementMethod::default(),
            slope: SlopeMethod::default(),
            distance: DistanceTransform::default(),
            area_mode: AreaMode::default(),
            total_removed: 0,
        })
    }

    /// Builder: sets the methods.
    pub fn with_methods(mut self, displacement: DisplacementMethod, slope: SlopeMethod) -> Self {
        self.displacement = displacement;
        self.slope = slope;
        self
    }

    /// Builder: sets the nearest-seed transform.
    pub fn with_distance_transform(mut self, distance: DistanceTransform) -> Self {
        self.distance = distance;
        self
    }

    /// Builder: sets the area mode.
    pub fn with_area_mode(mut self, mode: AreaMode) -> Self {
        self.area_mode = mode;
        self
    }

    /// The map.
    pub fn map(&self) -> &FixedPointMap {
        &self.map
    }

    /// The map, mutable (e.g. to paint initial material).
    pub fn map_mut(&mut self) -> &mut FixedPointMap {
        &mut self.map
    }

    /// Gives up the simulation and returns its map.
    pub fn into_map(self) -> FixedPointMap {
        self.map
    }

    /// The parameters.
    pub fn params(&self) -> &GranularParams {
        &self.params
    }

    /// Replaces the parameters (validated first).
    pub fn set_params(&mut self, params: GranularParams) -> Result<(), GranularError> {
        params.validate()?;
        self.params = params;
        Ok(())
    }

    /// Material removed by compression over all steps.
    pub fn total_removed(&self) -> u64 {
        self.total_removed
    }

    /// Fixed-point units per metre of the map.
    pub fn units_per_metre(&self) -> f64 {
        (1.0 / f64::from(self.map.encoding().scale)).round()
    }

    /// The areas a step with `objects` runs over.
    pub fn active_areas(
        &self,
        objects: &[GranularObject<'_>],
    ) -> Result<Vec<ActiveArea>, GranularError> {
        for o in objects {
            o.validate()?;
        }
        match self.area_mode {
            AreaMode::FullMap => Ok(vec![ActiveArea::full_map(self.map.size())]),
            AreaMode::ActiveAreas => {
                let mut areas = Vec::with_capacity(objects.len());
                for o in objects {
                    if let Some(a) = object_active_area(
                        o,
                        self.map.texel_size(),
                        self.map.size(),
                        self.params.active_area_margin,
                    )? {
                        areas.push(a);
                    }
                }
                Ok(merge_active_areas(&areas, self.params.merge_distance))
            }
        }
    }

    /// One step: per merged active area, depth from below -> penetration -> jump flooding ->
    /// displacement -> slope evening. Objects are checked first; on error the map is untouched.
    /// Fails with [`GranularError::ParamOutOfRange`] when the displacement method's settings
    /// are out of range ([`DisplacementMethod::validate`]).
    pub fn step(&mut self, objects: &[GranularObject<'_>]) -> Result<StepReport, GranularError> {
        #[cfg(feature = "cpu-work")]
        crate::cpu_work::count(|w| w.granular_steps += 1);
        self.displacement.validate()?;
        let areas = self.active_areas(objects)?;
        let p = self.params;
        let units = self.units_per_metre();
        let margin_units = (f64::from(p.obstacle_margin_m) * units)
            .round()
            .min(f64::from(u32::MAX)) as u32;
        let thresholds = p.slope_thresholds_units(self.map.texel_size(), units);
        let keep = p.keep_q15();
        let mut removed = 0u64;
        for area in &areas {
            let rect = area.rect;
            let depth = depth_from_below(objects, &self.map, rect)?;
            let mut pen = Grid::new(
                rect.size.x,
                rect.size.y,
                Penetration {
                    seed_x: 0,
                    seed_y: 0,
                    kind: 0,
                    penetration: 0,
                },
            )?;
            penetration_texture(&self.map, &depth, rect, margin_units, &mut pen)?;
            if !pen.as_slice().iter().any(|t| t.penetration > 0)
                && p.num_iterations_even_out_slopes == 0
            {
                continue;
            }
            let seeds = match self.distance {
                DistanceTransform::JumpFlood => jump_flood(&pen, rect, p.metric, p.jfa_extra_pass)?,
                DistanceTransform::Exact => super::exact_nearest_seed(&pen, rect, p.metric)?,
            };
            removed += match self.displacement {
                DisplacementMethod::Iterative { iterations } => displace_iterative(
                    &mut self.map,
                    &pen,
                    &seeds,
                    rect,
                    keep,
                    iterations,
                    p.metric,
                )?,
                DisplacementMethod::ClosestSeed => {
                    displace_closest_seed(&mut self.map, &pen, &seeds, rect, keep)?
                }
                DisplacementMethod::MultipleTargets => {
                    displace_multiple_targets(&mut self.map, &pen, &seeds, rect, keep)?
                }
            };
            let r = p.roughness_q15();
            let it = p.num_iterations_even_out_slopes;
            match self.slope {
                SlopeMethod::Interleaved => {
                    even_out_slopes_interleaved(&mut self.map, &pen, rect, thresholds, r, it)?
                }
                SlopeMethod::Scatter => {
                    even_out_slopes_scatter(&mut self.map, &pen, rect, thresholds, r, it)?
                }
            }
        }
        self.total_removed += removed;
        Ok(StepReport {
            removed,
            active_areas: areas,
            volume: self.map.raw_sum(),
        })
    }
}
