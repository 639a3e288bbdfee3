//! Material effects of the scenarios' deformations, painted on the GPU into a material layer
//! the renderers blend over the autoshader. The default scenario's stamps paint with
//! `MaterialEffectPass`: a crater exposes dirt, a footprint presses the cover down to the dirt
//! under it, a shockwave scorches the ground around its centre. The snow scenario's granular
//! steps paint their trails with `TrailEffectPass`: pressed snow darkens. A hole cut into the
//! ground (`terrain_core::holes`) is left out of every renderer's frame. A streamed world's
//! paint and colour are drawn from overlay atlases its scenario streams.

use super::GpuScene;
use crate::frame_plan::StampKind;
use anyhow::{Context, Result};
use terrain_core::{DirtyRect, Grid, MaterialEffect, StampPlacement, TileLayout};
use terrain_gpu::GpuError;
use terrain_gpu::{
    EffectOp, GpuHeightMap, GpuHoleMask, GpuMaterialLayer, GpuOverlayAtlas, MaterialEffectPass,
};

/// The material layer over the coarse-map and the pass that paints it.
pub struct Paint {
    layer: GpuMaterialLayer,
    pass: MaterialEffectPass,
}

/// What each kind of deformation paints: dirt (material 1) under craters and, less of it,
/// under footprints. The shockwave scorches: its change is stamped on every frame the wave
/// runs, and each paints a little rock-grey (material 2) fading from the blast's centre, so
/// the mark darkens while the wave travels (to about 70 % at the centre after 30 frames).
fn effect(kind: StampKind) -> MaterialEffect {
    let (material, strength) = match kind {
        StampKind::Crater => (CRATER_DIRT.material, CRATER_DIRT.strength),
        StampKind::Footprint => (1, 0.45),
        StampKind::Shockwave => (2, 0.04),
    };
    MaterialEffect { material, strength }
}

/// What a crater paints: dirt (material 1), most of the cover at its centre.
pub const CRATER_DIRT: MaterialEffect = MaterialEffect {
    material: 1,
    strength: 0.85,
};

/// What a granular trail paints on every column it presses: a third of dirt's colour over the
/// snow (compressed snow is darker and shows the ground through it).
pub const TRAIL: MaterialEffect = MaterialEffect {
    material: 1,
    strength: 0.35,
};

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
        let op = EffectOp {
            placement: *placement,
            effect: effect(kind),
        };
        self.pass
            .encode(device, queue, encoder, &self.layer, map, &op)?;
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
        let size = self.ground.heights().size();
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

    /// Uploads the `rects` of `mask` (the coarse-map's hole mask as the CPU holds it, after a
    /// cut changed them); the first call makes the GPU's mask and hands it to the renderers.
    pub fn update_holes(&mut self, mask: &Grid<u8>, rects: &[DirtyRect]) -> Result<()> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        match &self.holes {
            Some(holes) => {
                for rect in rects {
                    holes.write(queue, mask, *rect)?;
                }
            }
            None => {
                let holes = GpuHoleMask::new(device, queue, mask)?;
                self.terrain.set_hole_mask(Some(&holes));
                if let Some(refined) = self.refined.as_mut() {
                    refined.renderer.set_hole_mask(Some(&holes));
                }
                self.holes = Some(holes);
            }
        }
        Ok(())
    }

    /// The hole window the renderers draw (`side` cells, made on the first call) as
    /// terrain-core's `HoleWindowTarget`: a streamed world's holes around the camera, placed
    /// by terrain-cache's `HoleWindow`.
    pub fn hole_window(&mut self, side: u32) -> Result<terrain_gpu::HoleWindowUpload<'_>> {
        let device = &self.ctx.device;
        if !self
            .holes
            .as_ref()
            .is_some_and(|h| h.is_window() && h.size().x == side)
        {
            let holes = GpuHoleMask::window(device, side)?;
            self.terrain.set_hole_mask(Some(&holes));
            if let Some(refined) = self.refined.as_mut() {
                refined.renderer.set_hole_mask(Some(&holes));
            }
            self.holes = Some(holes);
        }
        let mask = self.holes.as_ref().context("the hole window")?;
        Ok(terrain_gpu::HoleWindowUpload {
            queue: &self.ctx.queue,
            mask,
        })
    }

    /// Draws a streamed world's paint, and its colour with `colored`, from overlay atlases of
    /// `slots` tile slots over `layout` (made now), which the scenario's overlay streams fill
    /// ([`GpuScene::streamed_layers_mut`]).
    pub fn enable_streamed_layers(
        &mut self,
        layout: TileLayout,
        slots: u32,
        colored: bool,
    ) -> Result<()> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let paint = GpuOverlayAtlas::new(device, queue, layout, slots)?;
        let color = match colored {
            true => Some(GpuOverlayAtlas::new(device, queue, layout, slots)?),
            false => None,
        };
        self.terrain
            .set_streamed_layers(Some(&paint), color.as_ref());
        if let Some(refined) = self.refined.as_mut() {
            refined
                .renderer
                .set_streamed_layers(Some(&paint), color.as_ref());
        }
        self.streamed_paint = Some(paint);
        self.streamed_color = color;
        Ok(())
    }

    /// The streamed paint and colour atlases (`None` until enabled, or without colour).
    pub fn streamed_layers_mut(
        &mut self,
    ) -> (Option<&mut GpuOverlayAtlas>, Option<&mut GpuOverlayAtlas>) {
        (self.streamed_paint.as_mut(), self.streamed_color.as_mut())
    }

    /// Whether the renderers have a hole mask.
    #[cfg(test)]
    pub fn has_holes(&self) -> bool {
        self.holes.is_some()
    }

    /// Darkens the snow where granular steps press it ([`TRAIL`]): a material layer of the
    /// granular map's size that every GPU step paints and every LOD mode draws. Call it after
    /// `enable_granular` and after the LOD mode is chosen. Fails, with nothing changed,
    /// without granular deformation on the GPU or where the GPU cannot hold the layer.
    pub fn enable_granular_trails(&mut self) -> Result<()> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let g = self
            .granular
            .as_mut()
            .context("granular deformation was not enabled on the GPU scene")?;
        let size = g.map().size();
        let layer = GpuMaterialLayer::new(device, queue, &Grid::new(size.x, size.y, [0; 4])?)?;
        self.terrain.set_material_layer(Some(&layer));
        if let Some(refined) = self.refined.as_mut() {
            refined.renderer.set_material_layer(Some(&layer));
        }
        g.set_trail(Some((layer, TRAIL)));
        Ok(())
    }
}
