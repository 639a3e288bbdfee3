//! `GpuRegionSource`: terrain-physics' [`RegionSource`] over a [`GpuHeightMap`], through a
//! [`RegionReadback`] ring, so the collision mirror follows the GPU map without stalls.

use crate::maps::GpuHeightMap;
use crate::readback::RegionReadback;
use terrain_core::Rect;
use terrain_physics::{ArrivedRegion, PhysicsError, RegionSource, RequestId};

/// Borrows what a readback needs for one scheduler update: create one per frame and pass it
/// to `ReadbackScheduler::update`.
#[derive(Debug)]
pub struct GpuRegionSource<'a> {
    device: &'a wgpu::Device,
    queue: &'a wgpu::Queue,
    map: &'a GpuHeightMap<u16>,
    readback: &'a mut RegionReadback,
}

impl<'a> GpuRegionSource<'a> {
    /// A source reading `map` through `readback`.
    pub fn new(
        device: &'a wgpu::Device,
        queue: &'a wgpu::Queue,
        map: &'a GpuHeightMap<u16>,
        readback: &'a mut RegionReadback,
    ) -> Self {
        Self {
            device,
            queue,
            map,
            readback,
        }
    }
}

impl RegionSource for GpuRegionSource<'_> {
    /// Records the copy and submits it at once (after every deformation already submitted, so
    /// the region includes them); the staging buffer maps when the GPU gets there.
    fn request(&mut self, rect: Rect) -> Result<RequestId, PhysicsError> {
        let mut encoder = self.device.create_command_encoder(&Default::default());
        let ticket = self
            .readback
            .request(self.device, &mut encoder, self.map, rect)
            .map_err(|e| PhysicsError::Source(e.to_string()))?;
        self.queue.submit([encoder.finish()]);
        Ok(RequestId(ticket.0))
    }

    fn poll(&mut self) -> Result<Vec<ArrivedRegion>, PhysicsError> {
        let arrived = self
            .readback
            .poll(self.device)
            .map_err(|e| PhysicsError::Source(e.to_string()))?;
        Ok(arrived
            .into_iter()
            .map(|r| ArrivedRegion {
                id: RequestId(r.ticket.0),
                rect: r.rect,
                heights: r.to_u16(),
            })
            .collect())
    }
}
