//! Blocking buffer downloads for tests and CPU-side users (the frame loop uses `RegionReadback`).

use crate::error::GpuError;

/// The longest a blocking call waits for the GPU before it reports [`GpuError::Poll`] (a lost
/// or hung device must not hang the caller). Generous: a software adapter renders a large
/// frame in about a second.
pub const WAIT_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(60);

/// A blocking poll for the latest submission, bounded by [`WAIT_TIMEOUT`].
pub fn wait_bounded() -> wgpu::PollType {
    wgpu::PollType::Wait {
        submission_index: None,
        timeout: Some(WAIT_TIMEOUT),
    }
}

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
    device.poll(wait_bounded())?;
    rx.recv().map_err(|_| GpuError::MapDropped)??;
    let bytes = staging.get_mapped_range(..)?.to_vec();
    staging.unmap();
    Ok(bytes)
}
