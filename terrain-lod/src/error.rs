//! The error type of terrain-lod: bad clipmap sizes, level counts and per-frame placement input.

use glam::{UVec2, Vec2};

/// Errors from building a clipmap layout and placing it for a frame.
///
/// Every variant carries the offending values so a caller can report them as they are.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LodError {
    /// The clipmap side `n` is not `2^k - 1` with `3 <= k <= 10`.
    #[error(
        "clipmap size {n} is not 2^k - 1 with 3 <= k <= 10: use one of 7, 15, 31, 63, 127, 255, 511, 1023"
    )]
    InvalidClipmapSize {
        /// The requested number of vertices per level side.
        n: u32,
    },
    /// The number of clipmap levels is outside `1..=16`.
    #[error("clipmap level count {levels} is outside 1..=16")]
    InvalidLevelCount {
        /// The requested number of levels.
        levels: u32,
    },
    /// An input that must be a finite number is NaN or infinite.
    #[error("{what} is {value}: it must be a finite number")]
    NonFinite {
        /// Which input (for example `"camera.x"`).
        what: &'static str,
        /// The value given.
        value: f32,
    },
    /// The texel size is zero or negative.
    #[error("texel size {texel_size} m must be greater than zero")]
    InvalidTexelSize {
        /// The texel size given, in metres per texel.
        texel_size: f32,
    },
    /// The height range is reversed.
    #[error("height range ({min} m, {max} m) is reversed: min must not exceed max")]
    InvalidHeightRange {
        /// Lower bound given, in metres.
        min: f32,
        /// Upper bound given, in metres.
        max: f32,
    },
    /// A refinement radius is not above zero or spans more texels than a refined region
    /// holds.
    #[error(
        "refine radius {radius_m} m at {texel_size} m per texel must be above 0 and at most \
         {max_texels} texels"
    )]
    InvalidRefineRadius {
        /// The radius given, in metres.
        radius_m: f32,
        /// The texel size given, in metres per texel.
        texel_size: f32,
        /// The most texels a radius may span.
        max_texels: u32,
    },
    /// The camera is so far from the origin (in texels) that the clipmap's texel coordinates
    /// would not fit in `i32`.
    #[error(
        "camera at {camera} m with {texel_size} m per texel lies beyond +-2^30 texels: \
         wrap the camera position into the map before placing the clipmap"
    )]
    CameraOutOfRange {
        /// The camera position given (world X, world Z), in metres.
        camera: Vec2,
        /// The texel size given, in metres per texel.
        texel_size: f32,
    },
    /// A density map parameter is out of range.
    #[error("density map parameter {what} = {value} is out of range: it must be {allowed}")]
    InvalidDensityParam {
        /// Which parameter.
        what: &'static str,
        /// The value given.
        value: f64,
        /// What is accepted.
        allowed: &'static str,
    },
    /// A density map or CDLOD tree was updated from a heightfield of another size than it was
    /// made for.
    #[error(
        "the heightfield is {actual} texels but the density map or tree was made for {expected}"
    )]
    SizeMismatch {
        /// The size the density map was made for.
        expected: UVec2,
        /// The size of the heightfield given.
        actual: UVec2,
    },
    /// A CDLOD parameter is out of range.
    #[error("CDLOD parameter {what} = {value} is out of range: it must be {allowed}")]
    InvalidCdlodParam {
        /// Which parameter.
        what: &'static str,
        /// The value given.
        value: f64,
        /// What is accepted.
        allowed: &'static str,
    },
    /// A tessellation parameter is out of range.
    #[error("tessellation parameter {what} = {value} is out of range: it must be {allowed}")]
    InvalidTessParam {
        /// Which parameter.
        what: &'static str,
        /// The value given.
        value: f64,
        /// What is accepted.
        allowed: &'static str,
    },
    /// A CDLOD selection would visit more nodes, or a tessellation emit more triangles, than
    /// the bound: the ranges are far larger than the leaves, or the triangle width far too
    /// small for the view.
    #[error(
        "the LOD selection exceeds its bound of {limit} nodes or triangles: lower finest_range or the view distance, use larger leaves, or a larger triangle width"
    )]
    SelectionTooLarge {
        /// The bound ([`crate::cdlod::MAX_VISITED_NODES`]).
        limit: usize,
    },
    /// A [`crate::LodUpdater`]'s worker thread could not start, or stopped (a panic in an
    /// update): the updater can no longer take changes.
    #[error("the LOD updater's worker thread {0}")]
    UpdaterStopped(&'static str),
    /// A terrain-core operation failed (for example a grid too large to allocate).
    #[error(transparent)]
    Core(#[from] terrain_core::CoreError),
}
