//! The error type of terrain-gpu.

use glam::UVec2;
use terrain_core::{CoreError, Rect};

/// Errors from creating the context, resources and passes, and from reading results back.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// No adapter matched the backends and name asked for.
    #[error(
        "no GPU adapter found (backends {backends}{}); install mesa-vulkan-drivers for a software Vulkan adapter, or set WGPU_BACKEND=gl",
        name_filter.as_ref().map(|n| format!(", WGPU_ADAPTER_NAME={n}")).unwrap_or_default()
    )]
    NoAdapter {
        /// The backends searched.
        backends: String,
        /// The adapter name filter, if any.
        name_filter: Option<String>,
    },
    /// The adapter refused to create a device.
    #[error("the adapter could not create a device: {0}")]
    RequestDevice(#[from] wgpu::RequestDeviceError),
    /// wgpu reported a validation error.
    #[error("GPU validation error in {context}: {message}")]
    Validation {
        /// What was being done.
        context: &'static str,
        /// wgpu's message.
        message: String,
    },
    /// The device ran out of memory.
    #[error("GPU out of memory in {context}: {message}")]
    OutOfMemory {
        /// What was being done.
        context: &'static str,
        /// wgpu's message.
        message: String,
    },
    /// A map is larger than the device can hold in one storage buffer.
    #[error("a {size} map needs {bytes} bytes, over the device's storage buffer limit of {limit}")]
    MapTooLarge {
        /// Map size in texels.
        size: UVec2,
        /// Bytes needed.
        bytes: u64,
        /// The device limit.
        limit: u64,
    },
    /// The sample type cannot be processed exactly by these passes.
    #[error("{what}: maps of {max_raw} as largest stored value are not supported (u8 and u16 are)")]
    UnsupportedSample {
        /// What refused it.
        what: &'static str,
        /// The sample type's largest value.
        max_raw: f64,
    },
    /// Two resources that must match in size do not.
    #[error("size mismatch: {expected} expected, {actual} given")]
    SizeMismatch {
        /// Size required.
        expected: UVec2,
        /// Size given.
        actual: UVec2,
    },
    /// A readback rect is empty, off a clamped map, or larger than a repeating map.
    #[error("readback region {rect:?} is not valid on a map of {map_size}")]
    BadRegion {
        /// The rect asked for.
        rect: Rect,
        /// The map's size.
        map_size: UVec2,
    },
    /// Every readback buffer of the ring is in flight.
    #[error("all {ring} readback buffers are in flight; poll before requesting more")]
    ReadbackBusy {
        /// Ring size.
        ring: usize,
    },
    /// Mapping a buffer for reading failed, or the device was lost while waiting.
    #[error("reading back from the GPU failed: {0}")]
    Readback(String),
    /// A camera with a non-finite field, a zero direction, or planes out of order.
    #[error(
        "invalid camera {camera:?}: needs finite values, a non-zero direction, 0 < fov < pi and 0 < near < far"
    )]
    InvalidCamera {
        /// The camera given.
        camera: crate::camera::Camera,
    },
    /// An input the operation does not handle.
    #[error("{what}: {reason}")]
    Unsupported {
        /// What refused it.
        what: &'static str,
        /// Why.
        reason: &'static str,
    },
    /// A user shader did not compile.
    #[error("user shader rejected: {0}")]
    Shader(String),
    /// A parameter error from terrain-core (placement, region, encoding).
    #[error(transparent)]
    Core(#[from] CoreError),
}
