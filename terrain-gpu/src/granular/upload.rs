//! `UploadRing`: per-frame data (depth grids, object triangles) uploaded into one persistent
//! buffer at increasing offsets, freed by `recall` after the submit that carried it.

use crate::device::scope::scoped;
use crate::error::GpuError;

/// Bytes an upload ring starts with, and the most it grows to before it asks for a `recall`.
const START_BYTES: u64 = 64 * 1024;
const MAX_BYTES: u64 = 256 << 20;

/// A persistent buffer that takes every upload recorded between two recalls at the next free
/// offset. `queue.write_buffer` lands before the commands of the next submit run, so two
/// uploads recorded into one submission must not share bytes; each takes its own range, and
/// [`UploadRing::recall`] frees them all once the submission is made (the shape of the uniform
/// ring in [`crate::compute::PassBindings`]). A submission that needs more than the buffer holds
/// gets a new, larger buffer (commands recorded earlier keep the old one alive), so the steady
/// state allocates nothing.
#[derive(Debug)]
pub(crate) struct UploadRing {
    label: &'static str,
    usage: wgpu::BufferUsages,
    buffer: Option<wgpu::Buffer>,
    cursor: u64,
}

impl UploadRing {
    /// An empty ring whose buffer will have `usage` (plus `COPY_DST`).
    pub fn new(label: &'static str, usage: wgpu::BufferUsages) -> Self {
        Self {
            label,
            usage: usage | wgpu::BufferUsages::COPY_DST,
            buffer: None,
            cursor: 0,
        }
    }

    /// Writes `data` (a multiple of 4 bytes) at the next free offset and returns the buffer and
    /// the offset.
    pub fn push(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        data: &[u8],
    ) -> Result<(wgpu::Buffer, u64), GpuError> {
        let len = data.len() as u64;
        let start = self.cursor.next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT);
        let (buffer, start) = match &self.buffer {
            Some(b) if start + len <= b.size() => (b.clone(), start),
            old => {
                // One upload may be larger than the usual bound; none beyond the device's.
                let cap = MAX_BYTES.max(len).min(device.limits().max_buffer_size);
                let old = old.as_ref().map_or(0, wgpu::Buffer::size);
                if len > cap || (self.cursor > 0 && old >= cap) {
                    return Err(GpuError::UploadRingFull {
                        pass: self.label,
                        bytes: start + len,
                    });
                }
                let size = (old * 2).max(len).max(START_BYTES).min(cap);
                let buffer = scoped(device, self.label, || {
                    device.create_buffer(&wgpu::BufferDescriptor {
                        label: Some(self.label),
                        size: size.next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT),
                        usage: self.usage,
                        mapped_at_creation: false,
                    })
                })?;
                self.buffer = Some(buffer.clone());
                (buffer, 0)
            }
        };
        if len > 0 {
            queue.write_buffer(&buffer, start, data);
        }
        self.cursor = start + len;
        Ok((buffer, start))
    }

    /// Frees every upload: call it after the submit that carries them.
    pub fn recall(&mut self) {
        self.cursor = 0;
    }
}
