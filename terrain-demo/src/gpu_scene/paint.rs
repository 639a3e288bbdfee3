//! Material effects of the default scenario's deformations: a crater exposes dirt, a
//! footprint presses the cover down to the dirt under it. Painted on the GPU by
//! `MaterialEffectPass` into a material layer the renderers blend over the autoshader.

use super::GpuScene;
use crate::frame_plan::StampKind;
use anyhow::Result;
use terrain_core::{Grid, MaterialEffect, StampPlacement};
use terrain_gpu::GpuError;
use terrain_gpu::{EffectOp, GpuHeightMap, GpuMaterialLayer, MaterialEffectPass};

/// The material layer over the coarse-map and the pass that paints it.
pub struct Paint {
    layer: GpuMaterialLayer,
    pass: MaterialEffectPass,
}

/// What each kind of deformation paints: dirt (material 1) under craters and, less of it,
/// under footprints. The shockwave paints nothing: its footprint is a ring, and an effect
/// fades from the footprint's centre.
fn effect(kind: StampKind) -> Option<MaterialEffect> {
    let strength = match kind {
        StampKind::Crater => 0.85,
        StampKind::Footprint => 0.45,
        StampKind::Shockwave => return None,
    };
    Some(MaterialEffect {
        material: 1,
        strength,
    })
}

impl Paint {
    /// Records the effect of a `kind` deformation at `placement` on `map` into `encoder`.
    pub fn encode(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuHeightMap<u16>,
        kind: StampKind,
        placement: &StampPlacement,
    ) -> Result<(), GpuError> {
        if let Some(effect) = effect(kind) {
            let op = EffectOp {
                placement: *placement,
                effect,
            };
            self.pass
                .encode(device, queue, encoder, &self.layer, map, &op)?;
        }
        Ok(())
    }

    /// Frees the pass's uniform slots after the submit that carried its effects.
    pub fn recall(&mut self) {
        self.pass.recall();
    }
}

impl GpuScene {
    /// Paints the default scenario's deformations into a material layer of the map's size
    /// (unpainted: the autoshader's weights show) that every LOD mode draws. Call it after
    /// the LOD mode is chosen. Fails, with nothing changed, where the GPU cannot hold the
    /// layer (4 bytes per texel in one storage buffer, and a texture as large).
    pub fn enable_material_effects(&mut self) -> Result<()> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let size = self.map.size();
        let layer = GpuMaterialLayer::new(device, queue, &Grid::new(size.x, size.y, [0; 4])?)?;
        self.terrain.set_material_layer(Some(&layer));
        if let Some(refined) = self.refined.as_mut() {
            refined.renderer.set_material_layer(Some(&layer));
        }
        self.paint = Some(Paint {
            layer,
            pass: MaterialEffectPass::new(device)?,
        });
        Ok(())
    }
}
