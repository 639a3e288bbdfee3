//! The error type of granular deformation: bad parameters, meshes, transforms and regions.

use glam::UVec2;

use crate::{CoreError, Rect};

/// Errors from granular deformation. Every variant carries the offending values.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GranularError {
    /// A grid or map operation failed.
    #[error(transparent)]
    Core(#[from] CoreError),
    /// A parameter is NaN, infinite or outside the range the algorithm accepts.
    #[error("parameter `{name}` = {value} is outside {range}")]
    ParamOutOfRange {
        /// The parameter's name (as in Persson 2019, table 4.4 where it comes from there).
        name: &'static str,
        /// The value given.
        value: f64,
        /// The accepted range, in words.
        range: &'static str,
    },
    /// A mesh has no vertices or no triangles.
    #[error("mesh is empty: {vertices} vertices, {triangles} triangles")]
    EmptyMesh {
        /// Number of vertices given.
        vertices: usize,
        /// Number of triangles given.
        triangles: usize,
    },
    /// A mesh has more vertices or triangles than [`super::MAX_MESH_ELEMENTS`].
    #[error("mesh has {count} {what}, more than the limit of {limit}")]
    MeshTooLarge {
        /// "vertices" or "triangles".
        what: &'static str,
        /// Number given.
        count: usize,
        /// The limit.
        limit: usize,
    },
    /// A vertex is NaN or infinite, or lies farther than [`super::MAX_COORDINATE_M`] from the
    /// origin (after the transform when reported by [`super::GranularObject::validate`]).
    #[error("vertex {index} = {value:?} is not finite or lies beyond {limit} m")]
    BadVertex {
        /// Vertex index.
        index: usize,
        /// The vertex.
        value: [f32; 3],
        /// The coordinate limit in metres.
        limit: f32,
    },
    /// A triangle names a vertex the mesh does not have.
    #[error("triangle {triangle} names vertex {index}, but the mesh has {vertices} vertices")]
    IndexOutOfRange {
        /// Triangle number.
        triangle: usize,
        /// The vertex index named.
        index: u32,
        /// Number of vertices.
        vertices: usize,
    },
    /// An object's transform holds NaN or infinite values.
    #[error("object transform is not finite: {0:?}")]
    NonFiniteTransform([f32; 12]),
    /// A region does not lie inside the map.
    #[error("region {rect:?} is not inside the map of size {map_size}")]
    RegionOutsideMap {
        /// The offending region.
        rect: Rect,
        /// The map size in texels.
        map_size: UVec2,
    },
    /// A per-region texture does not have the region's size.
    #[error("texture of size {actual} does not match the region size {expected}")]
    SizeMismatch {
        /// The region size.
        expected: UVec2,
        /// The texture size given.
        actual: UVec2,
    },
    /// A region or map side is larger than [`super::MAX_SIDE`] (distances must fit in u32).
    #[error("side of {side} texels exceeds the limit of {limit}")]
    TooLarge {
        /// The side given.
        side: u32,
        /// The limit.
        limit: u32,
    },
    /// A seed texel of a penetration texture names a column other than its own (the exact
    /// transform places each seed at its column).
    #[error(
        "seed texel at column {column:?} names seed {seed:?}; the exact transform needs seeds at their own columns"
    )]
    SeedNotAtColumn {
        /// The texel's column (map coordinates).
        column: [u32; 2],
        /// The seed it names.
        seed: [u32; 2],
    },
    /// The map's height encoding is not a fixed-point encoding (offset 0, whole units per metre).
    #[error("map encoding (scale {scale}, offset {offset}) is not a fixed-point encoding")]
    NotFixedPoint {
        /// Metres per unit.
        scale: f32,
        /// Metres at 0.
        offset: f32,
    },
}
