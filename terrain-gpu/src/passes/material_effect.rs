//! `MaterialEffectPass`: a stamp's material effect (a crater exposing dirt, a footprint
//! pressing snow away, a blast scorching rock) painted on a [`GpuMaterialLayer`] on the GPU,
//! recorded in the same command encoder as the stamp's height change, so the look and the
//! shape change in one submission with no CPU copy. Its CPU reference is
//! [`terrain_core::apply_material_effect`]; the two agree to one step of 255 per channel (see
//! `terrain_core::material_effect` for why not bit for bit).

use crate::device::compute::{
    PassBindings, StorageBinding, compute_pipeline, dispatch, dispatch_size, shader_module,
};
use crate::error::GpuError;
use crate::resources::maps::GpuHeightMap;
use crate::resources::material_layer::GpuMaterialLayer;
use bytemuck::{Pod, Zeroable};
use terrain_core::{
    CoreError, DirtyRect, EffectFrame, HeightSample, MaterialEffect, StampPlacement, stamp_region,
};

/// One material effect to paint: where (the placement of the stamp it goes with) and what.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EffectOp {
    /// The stamp's placement.
    pub placement: StampPlacement,
    /// The material and its strength.
    pub effect: MaterialEffect,
}

/// The uniform block of `material_effect.wgsl` (`EffectParams`), byte for byte.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct EffectParams {
    map_min: [u32; 2],
    size: [u32; 2],
    unwrapped_min: [i32; 2],
    pitch: u32,
    material: u32,
    center: [f32; 2],
    inv_half: [f32; 2],
    sin_cos: [f32; 2],
    strength: f32,
    pad: u32,
}

const _: () = assert!(std::mem::size_of::<EffectParams>() == 64);

/// Paints material effects on a [`GpuMaterialLayer`] (see the module docs).
#[derive(Debug)]
pub struct MaterialEffectPass {
    pipeline: wgpu::ComputePipeline,
    bindings: PassBindings<EffectParams>,
}

impl MaterialEffectPass {
    /// Builds the pipeline and its bindings.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let bindings = PassBindings::new(
            device,
            "MaterialEffectPass",
            wgpu::ShaderStages::COMPUTE,
            &[StorageBinding::compute(false)],
        );
        let module = shader_module(
            device,
            "material_effect.wgsl",
            terrain_shaders::MATERIAL_EFFECT,
        )?;
        let pipeline = compute_pipeline(
            device,
            "MaterialEffectPass",
            &module,
            bindings.layout(),
            "main",
        )?;
        Ok(Self { pipeline, bindings })
    }

    /// Frees the uniform slots of the effects recorded so far: call it after the submit that
    /// carries them.
    pub fn recall(&mut self) {
        self.bindings.recall();
    }

    /// Records `op`'s effect on `layer`, the material layer over `map` (the map its stamp
    /// changes: its size, wrap and texel size place the effect), and the copy of the painted
    /// rects to the layer's texture, and returns those rects (as
    /// [`terrain_core::apply_material_effect`]). Fails, with nothing recorded, where that
    /// function fails and on a layer of another size than the map.
    pub fn encode<T: HeightSample>(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        layer: &GpuMaterialLayer,
        map: &GpuHeightMap<T>,
        op: &EffectOp,
    ) -> Result<Vec<DirtyRect>, GpuError> {
        let EffectOp { placement, effect } = op;
        effect.validate()?;
        layer.check_paintable()?;
        if layer.size != map.size() {
            return Err(CoreError::SizeMismatch {
                expected: map.size(),
                actual: layer.size,
            }
            .into());
        }
        let texel_size = map.texel_size();
        let Some(region) = stamp_region(layer.size, map.wrap(), texel_size, placement)? else {
            return Ok(Vec::new());
        };
        let frame = EffectFrame::new(placement, texel_size);
        let mut recorded = Vec::with_capacity(region.pieces.len());
        for piece in &region.pieces {
            let groups = dispatch_size(device, piece.map.size)?;
            let params = EffectParams {
                map_min: piece.map.min.as_uvec2().to_array(),
                size: piece.map.size.to_array(),
                unwrapped_min: piece.unwrapped.min.to_array(),
                pitch: layer.pitch,
                material: effect.material,
                center: frame.center.to_array(),
                inv_half: frame.inv_half.to_array(),
                sin_cos: [frame.sin, frame.cos],
                strength: 255.0 * effect.strength,
                pad: 0,
            };
            let (group, offset) = self
                .bindings
                .bind(device, queue, &params, &[&layer.buffer])?;
            recorded.push((groups, group, offset));
        }
        for (groups, group, offset) in &recorded {
            dispatch(
                encoder,
                "MaterialEffectPass",
                *groups,
                &[(&self.pipeline, group, *offset)],
            );
        }
        for piece in &region.pieces {
            layer.copy_to_texture(encoder, piece.map);
        }
        Ok(region.pieces.iter().map(|p| p.map).collect())
    }
}
