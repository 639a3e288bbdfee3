//! [`DeformableMap`]: a coarse-map on the GPU with its derivative (normal) map, deformed by
//! stamps whose changed rects get their normals regenerated in the same encoder (Flower 2010,
//! sec. 3.2: the normal map follows each stamp's region only). It is what an engine that keeps
//! one map in memory drives each frame, instead of wiring [`StampPass`] and [`NormalPass`]
//! over a [`GpuHeightMap`] and a [`GpuDerivativeMap`] itself; the CPU sees the heights only
//! through a region readback of the changed rects ([`crate::GpuRegionSource`] over
//! [`DeformableMap::heights`]).

use crate::error::GpuError;
use crate::maps::{GpuDerivativeMap, GpuHeightMap};
use crate::normals::NormalPass;
use crate::stamp::{StampOp, StampPass};
use crate::submit::Submit;
use terrain_core::{CoarseMap, DirtyRect};

/// A u16 coarse-map on the GPU, its normals and the passes that deform it (see the module
/// docs).
#[derive(Debug)]
pub struct DeformableMap {
    heights: GpuHeightMap<u16>,
    normals: GpuDerivativeMap,
    stamps: StampPass,
    normal_pass: NormalPass,
}

impl DeformableMap {
    /// The name of [`Self::deform_with`]'s submit.
    pub const DEFORM: &'static str = "deform";

    /// Uploads `map` and computes all its normals (one submit, not waited for). Fails on a
    /// map the device cannot hold.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        map: &CoarseMap,
    ) -> Result<Self, GpuError> {
        let heights = GpuHeightMap::from_map(device, queue, map)?;
        let normals = GpuDerivativeMap::for_map(device, &heights)?;
        let mut normal_pass = NormalPass::new(device)?;
        let mut encoder = device.create_command_encoder(&Default::default());
        normal_pass.encode_full(device, queue, &mut encoder, &heights, &normals)?;
        queue.submit([encoder.finish()]);
        normal_pass.recall();
        Ok(Self {
            heights,
            normals,
            stamps: StampPass::new(device)?,
            normal_pass,
        })
    }

    /// The heights, for the renderers and the region readback.
    pub fn heights(&self) -> &GpuHeightMap<u16> {
        &self.heights
    }

    /// The derivative map the renderers shade with.
    pub fn normals(&self) -> &GpuDerivativeMap {
        &self.normals
    }

    /// Records one stamp into `encoder`; returns the rects it covers (none off a clamped map).
    /// Their normals are not regenerated: pass them to [`Self::encode_normals`], after every
    /// stamp of the frame (a rect's normals read its neighbours' heights).
    pub fn encode_stamp(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        op: &StampOp<'_>,
    ) -> Result<Vec<DirtyRect>, GpuError> {
        self.stamps
            .encode(device, queue, encoder, &self.heights, op)
    }

    /// Records the regeneration of the normals that heights changed inside `rects` affect.
    pub fn encode_normals(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        rects: &[DirtyRect],
    ) -> Result<(), GpuError> {
        for r in rects {
            let (heights, normals) = (&self.heights, &self.normals);
            self.normal_pass
                .encode(device, queue, encoder, heights, normals, *r)?;
        }
        Ok(())
    }

    /// The heights and the stamp pass, for passes that stamp the map themselves (the detail
    /// layer's spill into it); their rects go to [`Self::encode_normals`] too.
    pub fn stamp_target(&mut self) -> (&GpuHeightMap<u16>, &mut StampPass) {
        (&self.heights, &mut self.stamps)
    }

    /// Frees the passes' uniform slots once every encoder recorded since the last call is
    /// submitted.
    pub fn recall(&mut self) {
        self.stamps.recall();
        self.normal_pass.recall();
    }

    /// Stamps `ops` in order and regenerates the normals of every rect they changed, in one
    /// submit; returns the rects. Nothing is waited for. It recalls the passes' uniform slots
    /// after its submit: call it with no encoder of yours holding `encode_*` calls unsubmitted.
    pub fn deform(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        ops: &[StampOp<'_>],
    ) -> Result<Vec<DirtyRect>, GpuError> {
        let mut plain = crate::submit::PlainSubmit { device, queue };
        self.deform_with(device, queue, &mut plain, ops)
    }

    /// [`Self::deform`] with its submit, named [`Self::DEFORM`], made through `submit` (to
    /// time it, say).
    pub fn deform_with(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        submit: &mut dyn Submit,
        ops: &[StampOp<'_>],
    ) -> Result<Vec<DirtyRect>, GpuError> {
        let mut dirty = Vec::new();
        let done = submit.submit(Self::DEFORM, &mut |encoder| {
            dirty.clear();
            for op in ops {
                dirty.extend(self.encode_stamp(device, queue, encoder, op)?);
            }
            self.encode_normals(device, queue, encoder, &dirty)
        });
        self.recall();
        done.map(|()| dirty)
    }

    /// The map as it is on the GPU now, downloaded (waits, bounded): for tests and tools.
    pub fn read(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Result<CoarseMap, GpuError> {
        self.heights.read(device, queue)
    }
}
