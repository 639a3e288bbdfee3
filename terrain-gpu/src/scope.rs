//! Turns wgpu's validation and out-of-memory errors into `Result`s instead of panics.

use crate::error::GpuError;

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
    let validation_error = pollster::block_on(validation.pop());
    let oom_error = pollster::block_on(oom.pop());
    if let Some(e) = oom_error {
        return Err(GpuError::OutOfMemory {
            context,
            message: e.to_string(),
        });
    }
    if let Some(e) = validation_error {
        return Err(GpuError::Validation {
            context,
            message: e.to_string(),
        });
    }
    Ok(value)
}
