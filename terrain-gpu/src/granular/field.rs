//! A granular map on the GPU, whole (Persson 2019, ch. 4): the fixed-point heights that the
//! step deforms, the normals and float heights they are drawn with, the volume sum, and the
//! readback of the areas each step changed, all without a wait. This is what an application
//! drives once per frame; the passes it chains are this module's siblings.
//!
//! A frame is two submits, so that an application can time the step apart from what follows
//! it: [`GranularField::encode_step`] and [`GranularField::encode_follow_up`] (normals of the
//! changed areas, volume sum, readback requests), each followed by its `recall_*` once
//! submitted; [`GranularField::step`] does both with plain submits. What comes back arrives
//! in a later frame's [`GranularField::poll`]; [`GranularField::drain`] waits for the rest.
//! [`GranularField::finish`] drains it and keeps the compiled passes for the next map (building them
//! again took llvmpipe 45-48 ms).
//!
//! **Moving on without a wait.** A window that follows moving objects moves on while steps are
//! still on their way. [`GranularField::shift`] moves the field onto the next window in one
//! submit: the columns the two windows share are copied from the current map on the GPU, after
//! every step recorded so far, so nothing is waited for; the old map's readbacks go on arriving
//! through the [`RetiredField`] it returns.

use super::{
    GpuGranularNormals, GpuGranularStep, GranularNormalsPass, StepMeasures, Trail, VolumePass,
};
use crate::{GpuError, GpuHeightMap, GpuMaterialLayer, PlainSubmit, QueuedReadback, Submit};
use glam::{IVec2, UVec2};
use terrain_core::granular::{GranularArrivals, GranularObject, GranularParams};
use terrain_core::{FixedPointMap, MaterialEffect, Rect};

/// Readbacks of changed areas in flight at most (staging buffers of the ring).
const AREA_RING: usize = 8;

/// A granular map on the GPU and the passes that step, shade and measure it (module docs).
#[derive(Debug)]
pub struct GranularField {
    map: GpuHeightMap<u32>,
    normals: GpuGranularNormals,
    passes: GranularPasses,
    /// The material layer the steps paint where they press (`set_trail`).
    trail: Option<(GpuMaterialLayer, MaterialEffect)>,
    /// A retired map whose readbacks have all arrived, and the normals a shift replaced: the
    /// next shift writes into them instead of allocating (`recycle`).
    spare: Option<RetiredField>,
    spare_normals: Option<GpuGranularNormals>,
}

/// What a [`GranularField`] keeps from one map to the next: its compiled passes and its
/// readback rings (drained), for one set of parameters.
#[derive(Debug)]
pub struct GranularPasses {
    step: GpuGranularStep,
    normal_pass: GranularNormalsPass,
    volume: VolumePass,
    rings: Rings,
    params: GranularParams,
}

/// A map's two readback rings: the areas its steps changed, and their measures.
#[derive(Debug)]
struct Rings {
    readback: QueuedReadback,
    measures: StepMeasures,
}

impl Rings {
    fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        Ok(Self {
            readback: QueuedReadback::new(device, AREA_RING)?,
            measures: StepMeasures::new(device)?,
        })
    }

    /// What has arrived, never waiting.
    fn poll(&mut self, device: &wgpu::Device) -> Result<GranularArrivals, GpuError> {
        let areas = self.readback.poll(device)?;
        let measured = self.measures.poll(device)?;
        Ok(GranularArrivals {
            areas: areas.into_iter().map(|r| (r.rect, r.raw)).collect(),
            measured,
            in_flight: self.readback.in_flight() || self.measures.in_flight(),
        })
    }

    /// Requests the areas of `map` still waiting for a buffer and waits (bounded) for all.
    fn drain(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        map: &GpuHeightMap<u32>,
    ) -> Result<GranularArrivals, GpuError> {
        let areas = self.readback.flush(device, queue, map)?;
        Ok(GranularArrivals {
            areas: areas.into_iter().map(|r| (r.rect, r.raw)).collect(),
            measured: self.measures.flush(device)?,
            in_flight: false,
        })
    }
}

impl GranularPasses {
    /// Builds every pass for `params` (checked) and the readback rings.
    pub fn new(device: &wgpu::Device, params: GranularParams) -> Result<Self, GpuError> {
        Ok(Self {
            step: GpuGranularStep::new(device, params)?,
            normal_pass: GranularNormalsPass::new(device)?,
            volume: VolumePass::new(device)?,
            rings: Rings::new(device)?,
            params,
        })
    }

    /// The parameters the passes step with.
    pub fn params(&self) -> GranularParams {
        self.params
    }
}

impl GranularField {
    /// The name of a step's first submit ([`Self::step_with`]): the step itself.
    pub const STEP: &'static str = "granular_step";
    /// The name of a step's second submit: normals, volume sum, readback requests.
    pub const FOLLOW_UP: &'static str = "granular_follow_up";

    /// Uploads `map` (after this, the GPU map is the one deformed and drawn) and computes its
    /// first normals in one submit, with `passes` when they step with `params` (else new ones).
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        map: &FixedPointMap,
        params: GranularParams,
        passes: Option<GranularPasses>,
    ) -> Result<Self, GpuError> {
        let gpu_map = GpuHeightMap::from_map(device, queue, map)?;
        let normals = GpuGranularNormals::for_map(device, &gpu_map)?;
        let mut passes = match passes {
            Some(p) if p.params == params => p,
            _ => GranularPasses::new(device, params)?,
        };
        let full = Rect::from_size(map.size());
        let blur = params.num_iterations_blur_normals;
        let mut encoder = device.create_command_encoder(&Default::default());
        let pass = &mut passes.normal_pass;
        pass.encode(device, queue, &mut encoder, &gpu_map, &normals, full)?;
        pass.encode_blur(device, queue, &mut encoder, &normals, full, blur)?;
        queue.submit([encoder.finish()]);
        pass.recall();
        Ok(Self {
            map: gpu_map,
            normals,
            passes,
            trail: None,
            spare: None,
            spare_normals: None,
        })
    }

    /// The fixed-point heights, deformed in place by each step.
    pub fn map(&self) -> &GpuHeightMap<u32> {
        &self.map
    }

    /// The normals and float heights the map is drawn with.
    pub fn normals(&self) -> &GpuGranularNormals {
        &self.normals
    }

    /// The step pass, to choose its methods (displacement, slope, depth source).
    pub fn step_pass_mut(&mut self) -> &mut GpuGranularStep {
        &mut self.passes.step
    }

    /// The parameters the field steps with.
    pub fn params(&self) -> GranularParams {
        self.passes.params
    }

    /// Paints `effect` on `layer` where later steps press the material down; `None` stops.
    /// A layer of another size than the map is refused at the next step.
    pub fn set_trail(&mut self, trail: Option<(GpuMaterialLayer, MaterialEffect)>) {
        self.trail = trail;
    }

    /// The trail's material layer, if any (for the renderer that shades with it).
    pub fn trail_layer(&self) -> Option<&GpuMaterialLayer> {
        self.trail.as_ref().map(|(layer, _)| layer)
    }

    /// Records one step with `objects` into `encoder` and returns the merged active areas it
    /// runs over. Submit, then [`Self::recall_step`].
    pub fn encode_step(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        objects: &[GranularObject<'_>],
    ) -> Result<Vec<Rect>, GpuError> {
        let trail = self.trail.as_ref().map(|(layer, effect)| Trail {
            layer,
            effect: *effect,
        });
        let areas = self
            .passes
            .step
            .encode_with_trail(device, queue, encoder, &self.map, objects, trail)?;
        Ok(areas.iter().map(|a| a.rect).collect())
    }

    /// Frees the step's uniform slots once its submit is done.
    pub fn recall_step(&mut self) {
        self.passes.step.recall();
    }

    /// Records what follows the step whose `areas` [`Self::encode_step`] returned: the normals
    /// there (one texel past them, and one more per blur iteration), the volume sum, the
    /// measures' and the areas' readback requests, the measures tagged `tag` (the frame, say).
    /// Record it after the step's commands; submit, then [`Self::recall_follow_up`].
    pub fn encode_follow_up(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        areas: &[Rect],
        tag: u64,
    ) -> Result<(), GpuError> {
        let p = &mut self.passes;
        let full = Rect::from_size(self.map.size());
        let blur = p.params.num_iterations_blur_normals;
        for rect in areas {
            let Some(r) = rect.expand(1 + blur).intersect(&full) else {
                continue;
            };
            p.normal_pass
                .encode(device, queue, encoder, &self.map, &self.normals, r)?;
            p.normal_pass
                .encode_blur(device, queue, encoder, &self.normals, r, blur)?;
        }
        p.volume.encode(device, queue, encoder, &self.map)?;
        p.rings
            .measures
            .request(device, encoder, tag, &p.volume, p.step.scratch())?;
        p.rings
            .readback
            .request(device, encoder, &self.map, areas.iter().copied())
    }

    /// Frees the follow-up's uniform slots once its submit is done.
    pub fn recall_follow_up(&mut self) {
        self.passes.normal_pass.recall();
        self.passes.volume.recall();
    }

    /// One whole step with `objects` in two plain submits: [`Self::encode_step`], then
    /// [`Self::encode_follow_up`] tagged `tag`. Returns the step's areas.
    pub fn step(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        objects: &[GranularObject<'_>],
        tag: u64,
    ) -> Result<Vec<Rect>, GpuError> {
        let mut plain = PlainSubmit { device, queue };
        self.step_with(device, queue, &mut plain, objects, tag)
    }

    /// [`Self::step`] with its two submits, named [`Self::STEP`] and [`Self::FOLLOW_UP`], made
    /// through `submit` (to time them, say).
    pub fn step_with(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        submit: &mut dyn Submit,
        objects: &[GranularObject<'_>],
        tag: u64,
    ) -> Result<Vec<Rect>, GpuError> {
        let mut areas = Vec::new();
        submit.submit(Self::STEP, &mut |encoder| {
            areas = self.encode_step(device, queue, encoder, objects)?;
            Ok(())
        })?;
        self.recall_step();
        submit.submit(Self::FOLLOW_UP, &mut |encoder| {
            self.encode_follow_up(device, queue, encoder, &areas, tag)
        })?;
        self.recall_follow_up();
        Ok(areas)
    }

    /// The areas and measures of earlier steps that have arrived, never waiting.
    pub fn poll(&mut self, device: &wgpu::Device) -> Result<GranularArrivals, GpuError> {
        self.passes.rings.poll(device)
    }

    /// Requests the areas still waiting for a ring slot and waits (bounded) for every area
    /// and measure on its way: the end of the field's steps.
    pub fn drain(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<GranularArrivals, GpuError> {
        self.passes.rings.drain(device, queue, &self.map)
    }

    /// Moves the field onto `map`, the next window: same size and encoding, its origin at
    /// `offset` texels from the current map's. In one submit: uploads `map`, copies the texels
    /// the two windows share from the current map over it (the GPU's heights after every step
    /// recorded so far, whatever `map` holds there), computes its normals, and requests its
    /// volume sum (a measure tagged `tag`) and the shared texels back, so that what the old
    /// steps did there reaches the caller through this field. Never waits: the old map's areas
    /// and measures still on their way arrive through the returned [`RetiredField`]. Returns it
    /// and the shared texels (in `map`'s frame), if any. Refused while a trail layer is set (it
    /// does not move with the map).
    pub fn shift(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        map: &FixedPointMap,
        offset: IVec2,
        tag: u64,
    ) -> Result<(RetiredField, Option<Rect>), GpuError> {
        let size = self.map.size();
        if map.size() != size {
            return Err(GpuError::SizeMismatch {
                expected: size,
                actual: map.size(),
            });
        }
        let old = &self.map;
        if (map.encoding(), map.texel_size(), map.wrap())
            != (old.encoding(), old.texel_size(), old.wrap())
        {
            return Err(GpuError::Unsupported {
                what: "GranularField::shift",
                reason: "the next map's encoding, texel size or wrap differs from the field's",
            });
        }
        if self.trail.is_some() {
            return Err(GpuError::Unsupported {
                what: "GranularField::shift",
                reason: "a trail layer is set, and it does not move with the map",
            });
        }
        // Everything is made and recorded first, and the field changes only once submitted:
        // a failure leaves it stepping the current map. A recycled map and its rings, and the
        // normals the last shift replaced, are written over instead of allocated anew: queue
        // order puts these writes after every frame already submitted that read them.
        let (new_map, mut rings) = match self.spare.take() {
            Some(spare) => {
                spare.map.write(queue, map)?;
                (spare.map, spare.rings)
            }
            None => (
                GpuHeightMap::from_map(device, queue, map)?,
                Rings::new(device)?,
            ),
        };
        let new_normals = match self.spare_normals.take() {
            Some(normals) => normals,
            None => GpuGranularNormals::for_map(device, &new_map)?,
        };
        let shared = shared_texels(size, offset);
        let mut encoder = device.create_command_encoder(&Default::default());
        if let Some(r) = shared {
            // One row at a time: u32 columns, row-major, so each row is one contiguous range.
            let bytes = u64::from(r.size.x) * 4;
            for y in r.min.y..r.max().y {
                let to = (y as u64 * u64::from(size.x) + r.min.x as u64) * 4;
                let from_y = (y + offset.y) as u64;
                let from = (from_y * u64::from(size.x) + (r.min.x + offset.x) as u64) * 4;
                encoder.copy_buffer_to_buffer(old.buffer(), from, new_map.buffer(), to, bytes);
            }
        }
        let p = &mut self.passes;
        let full = Rect::from_size(size);
        let blur = p.params.num_iterations_blur_normals;
        let recorded = (|| {
            let (n, enc) = (&new_normals, &mut encoder);
            p.normal_pass
                .encode(device, queue, enc, &new_map, n, full)?;
            p.normal_pass
                .encode_blur(device, queue, enc, n, full, blur)?;
            p.volume.encode(device, queue, enc, &new_map)?;
            rings.measures.request(device, enc, tag, &p.volume, None)?;
            rings.readback.request(device, enc, &new_map, shared)
        })();
        if recorded.is_ok() {
            queue.submit([encoder.finish()]);
        }
        p.normal_pass.recall();
        p.volume.recall();
        recorded?;
        let retired = RetiredField {
            map: std::mem::replace(&mut self.map, new_map),
            rings: std::mem::replace(&mut p.rings, rings),
        };
        self.spare_normals = Some(std::mem::replace(&mut self.normals, new_normals));
        Ok((retired, shared))
    }

    /// Takes back a [`RetiredField`] whose readbacks have all arrived (its `poll` says nothing
    /// is in flight, or it was drained): the next [`Self::shift`] writes its map into the
    /// retired buffers and reuses its readback rings instead of allocating. One with something
    /// still on its way, or of another size, is not kept: it comes back, to poll on.
    #[must_use = "a retired field not kept still has readbacks to poll"]
    pub fn recycle(&mut self, retired: RetiredField) -> Option<RetiredField> {
        let idle = !retired.rings.readback.in_flight()
            && retired.rings.readback.waiting() == 0
            && !retired.rings.measures.in_flight();
        if idle && retired.map.size() == self.map.size() {
            self.spare = Some(retired);
            None
        } else {
            Some(retired)
        }
    }

    /// Drains the field ([`Self::drain`]) and frees its map, keeping the passes for the next
    /// one (nothing of this map's can then arrive with the next map's).
    pub fn finish(
        mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<(GranularArrivals, GranularPasses), GpuError> {
        let arrivals = self.drain(device, queue)?;
        Ok((arrivals, self.passes))
    }
}

/// The texels a window of `size` shares with the one whose origin lies `offset` texels before
/// it, in its own frame (`None` when they do not overlap, however far apart).
fn shared_texels(size: UVec2, offset: IVec2) -> Option<Rect> {
    let far = |d: i32, side: u32| d.unsigned_abs() >= side;
    if far(offset.x, size.x) || far(offset.y, size.y) {
        return None;
    }
    // Both within the side, so the negation and the sums fit.
    Rect::from_size(size).intersect(&Rect::new(-offset, size))
}

/// The readbacks a [`GranularField`] left on their way when it moved onto another map
/// ([`GranularField::shift`]): the old map's areas and measures, in step order. Poll it each
/// frame until nothing is in flight, then hand it back ([`GranularField::recycle`]: the next
/// shift reuses its buffers) or drop it (the old map is freed with it).
#[derive(Debug)]
pub struct RetiredField {
    map: GpuHeightMap<u32>,
    rings: Rings,
}

impl RetiredField {
    /// The old map's areas (in its own frame) and measures that have arrived, never waiting;
    /// `in_flight` is false once all have. Areas that waited for a free readback buffer are
    /// requested as buffers free up (a small submit of copies).
    pub fn poll(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<GranularArrivals, GpuError> {
        let arrived = self.rings.poll(device)?;
        if self.rings.readback.waiting() > 0 {
            let mut encoder = device.create_command_encoder(&Default::default());
            (self.rings.readback).request(device, &mut encoder, &self.map, [])?;
            queue.submit([encoder.finish()]);
        }
        Ok(arrived)
    }

    /// Waits (bounded) for everything still on its way.
    pub fn drain(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<GranularArrivals, GpuError> {
        self.rings.drain(device, queue, &self.map)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shared_texels_of_near_and_far_windows() {
        let s = UVec2::splat(8);
        assert_eq!(shared_texels(s, IVec2::ZERO), Some(Rect::from_size(s)));
        let r = shared_texels(s, IVec2::new(3, -2)).unwrap();
        assert_eq!(r, Rect::new(IVec2::new(0, 2), UVec2::new(5, 6)));
        assert_eq!(shared_texels(s, IVec2::new(8, 0)), None);
        assert_eq!(shared_texels(s, IVec2::new(i32::MIN, i32::MAX)), None);
    }
}
