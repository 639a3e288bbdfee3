//! `GpuRegionSource`: terrain-core's readback contract ([`RegionSource`]) over a
//! [`GpuHeightMap`], through a [`RegionReadback`] ring, so a collision mirror (terrain-physics'
//! scheduler) follows the GPU map without stalls.

use crate::device::readback::RegionReadback;
use crate::error::GpuError;
use crate::resources::maps::GpuHeightMap;
use terrain_core::{ArrivedRegion, Rect, RegionSource, RequestId};

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
    type Error = GpuError;

    /// Records the copy and submits it at once (after every deformation already submitted, so
    /// the region includes them); the staging buffer maps when the GPU gets there.
    fn request(&mut self, rect: Rect) -> Result<RequestId, GpuError> {
        let mut encoder = self.device.create_command_encoder(&Default::default());
        let ticket = self
            .readback
            .request(self.device, &mut encoder, self.map, rect)?;
        self.queue.submit([encoder.finish()]);
        Ok(RequestId(ticket.0))
    }

    /// Every staging buffer of the ring still on its way ([`GpuError::ReadbackBusy`]).
    fn is_busy(&self, error: &GpuError) -> bool {
        matches!(error, GpuError::ReadbackBusy { .. })
    }

    /// The arrived regions as u16 rows, converted straight from the staging buffers.
    fn poll(&mut self) -> Result<Vec<ArrivedRegion>, GpuError> {
        self.readback
            .poll_with(self.device, |r| {
                Ok(ArrivedRegion {
                    id: RequestId(r.ticket.0),
                    rect: r.rect,
                    heights: r.to_u16()?,
                })
            })?
            .into_iter()
            .collect()
    }
}
