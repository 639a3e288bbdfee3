//! `TrailEffectPass`: a granular trail that darkens the ground where it goes. Every column a
//! step presses down (`Penetrating` in the step's penetration texture) gets a material effect's
//! whole amount painted on a [`GpuMaterialLayer`] over the granular map, recorded in the step's
//! encoder between the penetration and the jump flooding passes, so look and shape change in
//! one submission. Bit for bit as its CPU reference, [`terrain_core::apply_trail_effect`].

use super::scratch::GranularArea;
use crate::device::compute::{
    PassBindings, StorageBinding, compute_pipeline, dispatch, shader_module,
};
use crate::error::GpuError;
use crate::resources::material_layer::GpuMaterialLayer;
use bytemuck::{Pod, Zeroable};
use glam::Vec2;
use terrain_core::{CoreError, MaterialEffect, effect_amount};

/// A trail to paint while a granular step runs: the material layer over the granular map, and
/// the effect painted on every column the step presses down.
#[derive(Debug, Clone, Copy)]
pub struct Trail<'a> {
    /// The layer painted (the granular map's size).
    pub layer: &'a GpuMaterialLayer,
    /// The material painted and its amount (`effect_amount` at the centre).
    pub effect: MaterialEffect,
}

/// The uniform block of `granular_trail.wgsl` (`TrailParams`), byte for byte.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub(super) struct TrailParams {
    area_min: [u32; 2],
    area_size: [u32; 2],
    pitch: u32,
    material: u32,
    amount: u32,
    pad: u32,
}

/// Paints a granular trail on a material layer (see the module docs).
#[derive(Debug)]
pub struct TrailEffectPass {
    pipeline: wgpu::ComputePipeline,
    pub(super) bindings: PassBindings<TrailParams>,
}

impl TrailEffectPass {
    /// Builds the pipeline and its bindings.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let bindings = PassBindings::new(
            device,
            "TrailEffectPass",
            wgpu::ShaderStages::COMPUTE,
            &[
                StorageBinding::compute(true),
                StorageBinding::compute(false),
            ],
        );
        let module = shader_module(
            device,
            "granular_trail.wgsl",
            terrain_shaders::GRANULAR_TRAIL,
        )?;
        let pipeline = compute_pipeline(
            device,
            "TrailEffectPass",
            &module,
            bindings.layout(),
            "main",
        )?;
        Ok(Self { pipeline, bindings })
    }

    /// Frees the uniform slots recorded so far: call it after the submit that carries them.
    pub fn recall(&mut self) {
        self.bindings.recall();
    }

    /// Checks `trail` against the map it paints over: a valid effect on a layer of the map's
    /// size.
    pub(super) fn check(trail: &Trail<'_>, map_size: glam::UVec2) -> Result<(), GpuError> {
        trail.effect.validate()?;
        trail.layer.check_paintable()?;
        if trail.layer.size != map_size {
            return Err(CoreError::SizeMismatch {
                expected: map_size,
                actual: trail.layer.size,
            }
            .into());
        }
        Ok(())
    }

    /// Records the trail of `area`, whose penetration texture the scratch holds (recorded by
    /// `PenetrationPass` before this), and the copy of the area to the layer's texture. Fails,
    /// with nothing recorded, on an invalid effect and on a layer of another size than the
    /// area's map.
    pub fn encode(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        area: &GranularArea<'_>,
        trail: &Trail<'_>,
    ) -> Result<(), GpuError> {
        Self::check(trail, area.map().size())?;
        let amount = effect_amount(Vec2::ZERO, trail.effect.strength);
        if amount == 0 {
            return Ok(());
        }
        let rect = area.rect();
        let params = TrailParams {
            area_min: rect.min.as_uvec2().to_array(),
            area_size: rect.size.to_array(),
            pitch: trail.layer.pitch,
            material: trail.effect.material,
            amount,
            pad: 0,
        };
        let (group, offset) = self.bindings.bind(
            device,
            queue,
            &params,
            &[&area.scratch().pen, &trail.layer.buffer],
        )?;
        dispatch(
            encoder,
            "TrailEffectPass",
            area.groups(),
            &[(&self.pipeline, &group, offset)],
        );
        trail.layer.copy_to_texture(encoder, rect);
        Ok(())
    }
}
