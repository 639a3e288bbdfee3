//! [`QueuedReadback`]: a GPU map's changed rects brought back to the CPU in request order,
//! never waiting inside a frame. A rect that finds every buffer of the [`RegionReadback`] ring
//! in flight waits in a queue and is requested again with the next rects (nothing is dropped);
//! [`QueuedReadback::poll`] hands over what arrived, and [`QueuedReadback::flush`] (the end of
//! a map's changes: a granular window that moves on) waits, bounded, for everything.

use crate::device::readback::{RegionData, RegionReadback};
use crate::error::GpuError;
use crate::resources::maps::GpuHeightMap;
use terrain_core::{HeightSample, Rect};

/// A ring of region readbacks with a queue in front of it (see the module docs).
#[derive(Debug)]
pub struct QueuedReadback {
    ring: RegionReadback,
    /// Rects not requested yet (the ring was busy), oldest first.
    waiting: Vec<Rect>,
}

impl QueuedReadback {
    /// A ring of `ring` (1 to [`crate::MAX_READBACK_RING`]) staging buffers.
    pub fn new(device: &wgpu::Device, ring: usize) -> Result<Self, GpuError> {
        Ok(Self {
            ring: RegionReadback::new(device, ring)?,
            waiting: Vec::new(),
        })
    }

    /// Records the copies of the rects waiting and of `rects` of `map` into `encoder`, as many
    /// as the ring has room for; the rest wait for the next call. Rects are requested in order.
    pub fn request<T: HeightSample>(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        map: &GpuHeightMap<T>,
        rects: impl IntoIterator<Item = Rect>,
    ) -> Result<(), GpuError> {
        self.waiting.extend(rects);
        let mut still = Vec::new();
        for rect in std::mem::take(&mut self.waiting) {
            // Once the ring is full, everything after waits too: the order is kept.
            if !still.is_empty() {
                still.push(rect);
                continue;
            }
            match self.ring.request(device, encoder, map, rect) {
                Ok(_) => {}
                Err(GpuError::ReadbackBusy { .. }) => still.push(rect),
                Err(e) => {
                    self.waiting = still;
                    return Err(e);
                }
            }
        }
        self.waiting = still;
        Ok(())
    }

    /// The regions that have arrived, in request order, never waiting.
    pub fn poll(&mut self, device: &wgpu::Device) -> Result<Vec<RegionData>, GpuError> {
        self.ring.poll(device)
    }

    /// Rects waiting for a free buffer of the ring (requested by the next `request`).
    pub fn waiting(&self) -> usize {
        self.waiting.len()
    }

    /// Whether a rect is still waiting or on its way.
    pub fn in_flight(&self) -> bool {
        !self.waiting.is_empty() || self.ring.in_flight() > 0
    }

    /// Requests every rect waiting and waits until all of them have arrived (each round waits,
    /// bounded, for the GPU; the queue only shrinks), handing them over in request order.
    pub fn flush<T: HeightSample>(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        map: &GpuHeightMap<T>,
    ) -> Result<Vec<RegionData>, GpuError> {
        let mut arrived = self.poll(device)?;
        while self.in_flight() {
            let mut encoder = device.create_command_encoder(&Default::default());
            self.request(device, &mut encoder, map, [])?;
            queue.submit([encoder.finish()]);
            arrived.extend(self.ring.wait(device)?);
        }
        Ok(arrived)
    }
}
