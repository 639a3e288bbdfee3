//! The error type of terrain-gpu.

use glam::UVec2;
use terrain_core::{CoreError, Rect};

/// Errors from creating the context, resources and passes, and from reading results back.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// No adapter matched the backends and name asked for.
    #[error(
        "no GPU adapter found (backends {backends:?}{}); install mesa-vulkan-drivers for a software Vulkan adapter, or set WGPU_BACKEND=gl",
        name_filter.as_ref().map(|n| format!(", WGPU_ADAPTER_NAME={n}")).unwrap_or_default()
    )]
    NoAdapter {
        /// The backends searched.
        backends: wgpu::Backends,
        /// The adapter name filter, if any.
        name_filter: Option<String>,
    },
    /// The adapter refused to create a device.
    #[error("the adapter could not create a device: {0}")]
    RequestDevice(#[from] wgpu::RequestDeviceError),
    /// wgpu reported a validation error while a resource or pipeline was created.
    #[error("GPU validation error in {context}: {source}")]
    Validation {
        /// What was being done.
        context: &'static str,
        /// wgpu's error.
        source: wgpu::Error,
    },
    /// The device ran out of memory while a resource was created.
    #[error("GPU out of memory in {context}: {source}")]
    OutOfMemory {
        /// What was being done.
        context: &'static str,
        /// wgpu's error.
        source: wgpu::Error,
    },
    /// Errors wgpu reported for submitted work (outside any error scope); the first is the
    /// source, all are listed.
    #[error("{} error(s) in submitted GPU work: {}", errors.len(), errors.iter().map(|e| e.to_string()).collect::<Vec<_>>().join("; "))]
    Submitted {
        /// Every error, in the order wgpu reported them.
        errors: Vec<wgpu::Error>,
    },
    /// The device was lost (destroyed, a driver reset, dropped): nothing more can run on it.
    /// wgpu reports no errors for work on a lost device (as WebGPU specifies), so this comes
    /// from the device-lost callback ([`crate::GpuContext::check`]).
    #[error("the GPU device was lost ({reason}): {message}")]
    DeviceLost {
        /// wgpu's reason, in words.
        reason: String,
        /// The driver's or wgpu's message.
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
    /// Waiting for the device failed (device lost, or the wait timed out).
    #[error("waiting for the GPU failed: {0}")]
    Poll(#[from] wgpu::PollError),
    /// Mapping a staging buffer for reading failed (device lost).
    #[error("mapping a buffer for reading failed: {0}")]
    Map(#[from] wgpu::BufferAsyncError),
    /// A mapped buffer's range could not be viewed.
    #[error("viewing a mapped buffer failed: {0}")]
    MapRange(#[from] wgpu::MapRangeError),
    /// The device dropped a map request without answering it.
    #[error("the device dropped a buffer map request without answering it")]
    MapDropped,
    /// Region readbacks whose mapping failed (device lost); regions that did arrive were
    /// handed over first.
    #[error("reading back regions {rects:?} failed")]
    ReadbackFailed {
        /// The regions that did not arrive.
        rects: Vec<Rect>,
    },
    /// Mapping a [`crate::SmallReadback`] staging buffer failed (device lost).
    #[error("reading back a counter failed: the staging buffer could not be mapped")]
    SmallReadbackFailed,
    /// A pass recorded more dispatches than its uniform ring holds without a
    /// `recall()` after the submit that carried them.
    #[error("{pass} recorded {slots} dispatches without recall(): call recall() after each submit")]
    UniformRingFull {
        /// The pass.
        pass: &'static str,
        /// The ring's size in slots.
        slots: u32,
    },
    /// A pass uploaded more data than its upload buffer may grow to without a `recall()`
    /// after the submit that carried it.
    #[error("{pass} uploaded {bytes} bytes without recall(): call recall() after each submit")]
    UploadRingFull {
        /// The pass.
        pass: &'static str,
        /// Bytes uploaded since the last recall, including the refused upload.
        bytes: u64,
    },
    /// A view the renderers cannot draw (see [`crate::RenderView`] for what they take).
    #[error(
        "invalid view: {reason} (a Camera needs finite values, a non-zero direction, 0 < fov < pi and 0 < near < far)"
    )]
    InvalidView {
        /// What is wrong with it.
        reason: &'static str,
    },
    /// A view whose projection follows the other depth convention than the target the
    /// renderer was built for.
    #[error(
        "the view's projection has {view:?} depth but the renderer was built for a {target:?} depth target (TargetFormat::depth_convention)"
    )]
    DepthConventionMismatch {
        /// The view's convention.
        view: crate::render::camera::DepthConvention,
        /// The target's.
        target: crate::render::camera::DepthConvention,
    },
    /// An input the operation does not handle.
    #[error("{what}: {reason}")]
    Unsupported {
        /// What refused it.
        what: &'static str,
        /// Why.
        reason: &'static str,
    },
    /// A region left to another renderer (the refined cells of a detail layer) cannot be left
    /// out this frame: it reaches where the LOD morphs, or where its triangles stop short of
    /// the texels, so its edge would not meet the other mesh. [`crate::TerrainRenderer`] then
    /// draws the frame whole ([`crate::TerrainRenderer::excluding`]).
    #[error("{what}: {reason}")]
    CannotExclude {
        /// What refused it.
        what: &'static str,
        /// Why.
        reason: &'static str,
    },
    /// A user's WGSL (a procedural stamp's, or a renderer's `surface_weights`) did not compile
    /// into its shader.
    #[error("user shader rejected: {source}")]
    UserShader {
        /// Why (the shader module's or pipeline's validation error).
        source: Box<GpuError>,
    },
    /// Granular parameters or objects were invalid.
    #[error(transparent)]
    Granular(#[from] terrain_core::granular::GranularError),
    /// A renderer cannot draw into a pass of these formats.
    #[error("cannot render into {format:?}: {reason}")]
    UnsupportedTarget {
        /// The formats asked for.
        format: crate::render::target::TargetFormat,
        /// Why not.
        reason: &'static str,
    },
    /// A renderer cannot draw into a pass with this many samples per pixel.
    #[error(
        "cannot render {count}x multisampled into {color:?} with depth {depth:?}: {whose} \
         sample counts {color_allows:?} for {color:?} and {depth_allows:?} for {depth:?}"
    )]
    UnsupportedSampleCount {
        /// The colour format.
        color: wgpu::TextureFormat,
        /// The depth format.
        depth: wgpu::TextureFormat,
        /// The sample count asked for.
        count: u32,
        /// Whose capabilities were checked (every adapter's guaranteed ones, or this one's).
        whose: &'static str,
        /// The counts the colour format allows.
        color_allows: Vec<u32>,
        /// The counts the depth format allows.
        depth_allows: Vec<u32>,
    },
    /// A detail tile a stamp or read needs is not loaded (its texels are in the cache or on
    /// disk): load it first.
    #[error("detail tile {tile} is not loaded: load it before stamping over or reading it")]
    DetailTileNotLoaded {
        /// The tile.
        tile: glam::UVec2,
    },
    /// A stamp needs more detail tile slots than are free.
    #[error(
        "a stamp needs {needed} new detail tile slots, {free} are free: unload tiles or make more slots"
    )]
    DetailSlotsFull {
        /// Slots the stamp needs.
        needed: usize,
        /// Slots free.
        free: usize,
    },
    /// A parameter error from terrain-core (placement, region, encoding).
    #[error(transparent)]
    Core(#[from] CoreError),
    /// A level-of-detail parameter error from terrain-lod (density map parameters).
    #[error(transparent)]
    Lod(#[from] terrain_lod::LodError),
}

impl GpuError {
    /// `source`, the error of compiling a shader with a user's WGSL in it, as
    /// [`GpuError::UserShader`].
    pub(crate) fn user_shader(source: GpuError) -> Self {
        Self::UserShader {
            source: Box::new(source),
        }
    }
}
