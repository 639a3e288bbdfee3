//! The error type of terrain-core's grid, encoding, normal-map and stamp operations.

use crate::rect::Rect;
use glam::UVec2;

/// Errors from building maps, sampling them and deforming them.
///
/// Every variant carries the offending values so a caller can report them as they are.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CoreError {
    /// A grid of zero width or height was requested.
    #[error("grid size {width}x{height} is empty: both sides must be at least 1")]
    EmptyGrid {
        /// Requested width.
        width: u32,
        /// Requested height.
        height: u32,
    },
    /// A grid is smaller than an operation needs.
    #[error("grid size {size} is too small for {what}: at least {min} needed")]
    GridTooSmall {
        /// What needed the larger grid.
        what: &'static str,
        /// Actual size.
        size: UVec2,
        /// Minimum size per side.
        min: u32,
    },
    /// A grid's sample count does not fit in memory (`width * height` overflows `usize`).
    #[error("grid size {width}x{height} is too large to address")]
    GridTooLarge {
        /// Requested width.
        width: u32,
        /// Requested height.
        height: u32,
    },
    /// A vector's length does not match the grid size it was given with.
    #[error("data length {len} does not match grid size {width}x{height}")]
    DataLength {
        /// Length of the data given.
        len: usize,
        /// Grid width.
        width: u32,
        /// Grid height.
        height: u32,
    },
    /// Two grids that must have the same size do not.
    #[error("grid sizes differ: {expected} expected, {actual} given")]
    SizeMismatch {
        /// Size required.
        expected: UVec2,
        /// Size given.
        actual: UVec2,
    },
    /// A rect lies partly or wholly outside a clamped map.
    #[error("region {rect:?} is not inside the map of size {map_size}")]
    RegionOutOfBounds {
        /// The offending rect.
        rect: Rect,
        /// Size of the map.
        map_size: UVec2,
    },
    /// A parameter was NaN or infinite.
    #[error("{what} must be finite, got {value}")]
    NonFinite {
        /// Which parameter.
        what: &'static str,
        /// The value given.
        value: f32,
    },
    /// A parameter lies outside the range the algorithm accepts.
    #[error("{what} = {value} is out of range: {expected}")]
    OutOfRange {
        /// Which parameter.
        what: &'static str,
        /// The value given.
        value: f64,
        /// The range accepted, in words.
        expected: &'static str,
    },
}
