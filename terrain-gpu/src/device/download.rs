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
    crate::device::trace::record("download: submitted copy (bytes)", size);
    map_and_read(device, &staging)
}

/// Maps a `MAP_READ` staging buffer whose copy has been submitted, waits for the GPU, and
/// returns its bytes (unmapping it again).
pub fn map_and_read(device: &wgpu::Device, staging: &wgpu::Buffer) -> Result<Vec<u8>, GpuError> {
    let (tx, rx) = std::sync::mpsc::channel();
    staging.map_async(wgpu::MapMode::Read, .., move |r| {
        let _ = tx.send(r);
    });
    crate::device::trace::record("map_and_read: blocking poll (bytes)", staging.size());
    device.poll(wait_bounded())?;
    crate::device::trace::record("map_and_read: poll returned, waiting for the map", 0);
    rx.recv().map_err(|_| GpuError::MapDropped)??;
    let bytes = staging.get_mapped_range(..)?.to_vec();
    staging.unmap();
    crate::device::trace::record("map_and_read: mapped and read (bytes)", bytes.len() as u64);
    Ok(bytes)
}

/// Copies a 2D colour texture (`COPY_SRC`, one sample) of an 8-bit RGBA or BGRA format to the
/// CPU as RGBA8 rows from the top, waiting for the GPU: for frames an engine rendered into its
/// own target (the capture path of [`crate::OffscreenTarget`] keeps its own staging buffer).
pub fn read_texture_rgba8(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
) -> Result<terrain_core::Grid<[u8; 4]>, GpuError> {
    use wgpu::TextureFormat as F;
    let bgra = match texture.format() {
        F::Rgba8Unorm | F::Rgba8UnormSrgb => false,
        F::Bgra8Unorm | F::Bgra8UnormSrgb => true,
        _ => {
            return Err(GpuError::Unsupported {
                what: "read_texture_rgba8",
                reason: "the texture is not 8-bit RGBA or BGRA",
            });
        }
    };
    let (w, h) = (texture.width(), texture.height());
    let row = w * 4;
    let padded =
        row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("texture readback"),
        size: u64::from(padded) * u64::from(h),
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_texture_to_buffer(
        texture.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &staging,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(padded),
                rows_per_image: Some(h),
            },
        },
        wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        },
    );
    queue.submit([encoder.finish()]);
    let bytes = map_and_read(device, &staging)?;
    let pixels = (0..h as usize)
        .flat_map(|y| {
            let start = y * padded as usize;
            bytes[start..start + row as usize]
                .chunks_exact(4)
                .map(|p| {
                    if bgra {
                        [p[2], p[1], p[0], p[3]]
                    } else {
                        [p[0], p[1], p[2], p[3]]
                    }
                })
                .collect::<Vec<_>>()
        })
        .collect();
    Ok(terrain_core::Grid::from_vec(w, h, pixels)?)
}
