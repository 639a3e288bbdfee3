//! Turns wgpu's validation and out-of-memory errors into `Result`s instead of panics.

use crate::error::GpuError;
use std::future::Future;
use std::task::{Context, Poll, Waker};

/// Runs `f` inside validation and out-of-memory error scopes and returns its result, or the
/// first error wgpu reported while it ran. `context` names the operation in the error.
pub fn scoped<T>(
    device: &wgpu::Device,
    context: &'static str,
    f: impl FnOnce() -> T,
) -> Result<T, GpuError> {
    let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let value = f();
    // Scopes pop in reverse order of their creation.
    let validation_error = ready(validation.pop());
    let oom_error = ready(oom.pop());
    if let Some(source) = oom_error {
        return Err(GpuError::OutOfMemory { context, source });
    }
    if let Some(source) = validation_error {
        return Err(GpuError::Validation { context, source });
    }
    Ok(value)
}

/// The value of a future that is already complete. wgpu's native backends resolve error scopes
/// at once (validation is synchronous), so this needs no executor; a future that is still
/// pending (a browser backend, which this crate does not build) counts as "no error".
fn ready<F: Future<Output = Option<wgpu::Error>>>(future: F) -> Option<wgpu::Error> {
    let mut future = std::pin::pin!(future);
    match future
        .as_mut()
        .poll(&mut Context::from_waker(Waker::noop()))
    {
        Poll::Ready(value) => value,
        Poll::Pending => None,
    }
}

/// A buffer made with `contents`, like `wgpu::util::DeviceExt::create_buffer_init`, but a
/// failed mapping (a lost device) is an error, not the panic of wgpu's helper. The size is
/// rounded up to a multiple of 4 (at least 4) as wgpu requires of mapped buffers.
pub(crate) fn buffer_init(
    device: &wgpu::Device,
    label: &'static str,
    contents: &[u8],
    usage: wgpu::BufferUsages,
) -> Result<wgpu::Buffer, GpuError> {
    let size = (contents.len() as u64).max(4).next_multiple_of(4);
    let buffer = scoped(device, label, || {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage,
            mapped_at_creation: true,
        })
    })?;
    {
        let mut padded = contents.to_vec();
        padded.resize(size as usize, 0);
        let mut view = buffer.get_mapped_range_mut(..)?;
        view.copy_from_slice(&padded);
    }
    buffer.unmap();
    Ok(buffer)
}
