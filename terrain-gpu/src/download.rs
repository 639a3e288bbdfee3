//! Blocking buffer downloads for tests and CPU-side users (the frame loop uses `RegionReadback`).

use crate::error::GpuError;

/// Copies `size` bytes from `offset` of `buffer` (which needs `COPY_SRC`) to the CPU, waiting
/// for the GPU. `offset` and `size` must be multiples of 4.
pub fn download_bytes(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    buffer: &wgpu::Buffer,
    offset: u64,
    size: u64,
) -> Result<Vec<u8>, GpuError> {
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("download staging"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_buffer_to_buffer(buffer, offset, &staging, 0, size);
    queue.submit([encoder.finish()]);
    map_and_read(device, &staging)
}

/// Maps a `MAP_READ` staging buffer whose copy has been submitted, waits for the GPU, and
/// returns its bytes (unmapping it again).
pub fn map_and_read(device: &wgpu::Device, staging: &wgpu::Buffer) -> Result<Vec<u8>, GpuError> {
    let (tx, rx) = std::sync::mpsc::channel();
    staging.map_async(wgpu::MapMode::Read, .., move |r| {
        let _ = tx.send(r);
    });
    device.poll(wgpu::PollType::wait_indefinitely())?;
    rx.recv().map_err(|_| GpuError::MapDropped)??;
    let bytes = staging.get_mapped_range(..)?.to_vec();
    staging.unmap();
    Ok(bytes)
}
