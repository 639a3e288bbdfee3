//! The error type of terrain-physics: bad query input, bad regions, and regions a readback
//! source delivered wrongly. (A source's own failures come back in its own error type, wrapped
//! by [`crate::scheduler::UpdateError`].)

use glam::{UVec2, Vec3};
use terrain_core::{CoreError, Rect, RequestId, WrapMode};

/// Errors from collision queries, the mirror, the readback scheduler and the bodies.
///
/// Every variant carries the offending values so a caller can report them as they are.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PhysicsError {
    /// A position, direction, time step or parameter was NaN or infinite.
    #[error("{what} must be finite, got {value}")]
    NonFinite {
        /// Which input.
        what: &'static str,
        /// The offending component.
        value: f32,
    },
    /// A ray direction of zero length.
    #[error("ray direction {dir} has zero length")]
    ZeroDirection {
        /// The direction given.
        dir: Vec3,
    },
    /// A sphere of negative radius.
    #[error("sphere radius {radius} is negative")]
    NegativeRadius {
        /// The radius given.
        radius: f32,
    },
    /// A ray crossed more cells of the repeating field than one cast walks (four times around
    /// it) without meeting the surface or leaving its height range: whether and where it hits
    /// is not decided (a nearly horizontal ray over a repeating field). Cast a shorter ray.
    #[error(
        "the ray crossed {cells} cells within the terrain's height range without an answer: \
         cast it with a shorter maximum distance"
    )]
    RayTooLong {
        /// Cells walked.
        cells: u64,
    },
    /// [`crate::ReadbackScheduler::flush`] waited its whole timeout for regions that did not
    /// arrive (a source that stopped delivering: a lost device, say).
    #[error(
        "the readback flush timed out after {timeout:?}: {in_flight} request(s) in flight and \
         {dirty} dirty rect(s) not yet requested"
    )]
    FlushTimedOut {
        /// The timeout given.
        timeout: std::time::Duration,
        /// Requests still in flight.
        in_flight: usize,
        /// Merged dirty rects not yet requested.
        dirty: usize,
    },
    /// A parameter lies outside the range accepted.
    #[error("{what} = {value} is out of range: {expected}")]
    OutOfRange {
        /// Which parameter.
        what: &'static str,
        /// The value given.
        value: f64,
        /// The range accepted, in words.
        expected: &'static str,
    },
    /// A rect is empty, larger than the map, or starts more than one map period away from it.
    #[error(
        "region {rect:?} is off the map of size {map_size}: it must be non-empty, at most the \
         map's size, and start within one map period of the map (-size <= min < 2 * size)"
    )]
    RegionOffMap {
        /// The offending rect.
        rect: Rect,
        /// Size of the map in texels.
        map_size: UVec2,
    },
    /// Two sizes that must agree do not (a region's data and its rect, a mirror and a source).
    #[error("sizes differ: {expected} expected, {actual} given")]
    SizeMismatch {
        /// Size required.
        expected: UVec2,
        /// Size given.
        actual: UVec2,
    },
    /// The collision mirror addresses its map toroidally; a clamped map cannot be mirrored.
    #[error("the collision mirror needs a toroidal (WrapMode::Repeat) coarse-map, got {wrap:?}")]
    NotToroidal {
        /// The map's wrap mode.
        wrap: WrapMode,
    },
    /// A region update older than (or as old as) what the mirror already holds.
    #[error("update version {version} is not newer than the mirror's version {current}")]
    StaleVersion {
        /// Version of the rejected update.
        version: u64,
        /// Version the mirror holds.
        current: u64,
    },
    /// A readback source delivered a region nobody asked for (or delivered it twice).
    #[error("readback source delivered {id:?}, which is not in flight")]
    UnknownRequest {
        /// The id delivered.
        id: RequestId,
    },
    /// A readback source delivered a different rect than the one requested.
    #[error("readback {id:?} delivered rect {delivered:?}, but {requested:?} was requested")]
    WrongRegion {
        /// The request.
        id: RequestId,
        /// The rect asked for.
        requested: Rect,
        /// The rect delivered.
        delivered: Rect,
    },
    /// A snapshot handed to a `ParryTerrain` has another texel size or height encoding than
    /// the one it was built from (feature `parry`).
    #[error("snapshot {what} is {actual}, but the terrain was built with {expected}")]
    SnapshotMismatch {
        /// Which property.
        what: &'static str,
        /// The terrain's value.
        expected: f64,
        /// The snapshot's value.
        actual: f64,
    },
    /// An error from terrain-core (building a grid or map).
    #[error(transparent)]
    Core(#[from] CoreError),
}

/// Checks that every component of `v` is finite.
pub(crate) fn check_finite3(what: &'static str, v: Vec3) -> Result<(), PhysicsError> {
    for value in v.to_array() {
        check_finite(what, value)?;
    }
    Ok(())
}

/// Checks that both components of `v` are finite.
pub(crate) fn check_finite2(what: &'static str, v: glam::Vec2) -> Result<(), PhysicsError> {
    for value in v.to_array() {
        check_finite(what, value)?;
    }
    Ok(())
}

/// Checks that `value` is finite.
pub(crate) fn check_finite(what: &'static str, value: f32) -> Result<(), PhysicsError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(PhysicsError::NonFinite { what, value })
    }
}

/// Checks that a region lies on a toroidal map of `map_size`: non-empty, at most the map's
/// size on each axis, with `min` within one period (`-size <= min < 2 * size`).
pub(crate) fn check_region(rect: Rect, map_size: UVec2) -> Result<(), PhysicsError> {
    let axis_ok = |min: i32, size: u32, n: u32| {
        let (min, n64) = (i64::from(min), i64::from(n));
        size >= 1 && size <= n && min >= -n64 && min < 2 * n64
    };
    if axis_ok(rect.min.x, rect.size.x, map_size.x) && axis_ok(rect.min.y, rect.size.y, map_size.y)
    {
        Ok(())
    } else {
        Err(PhysicsError::RegionOffMap { rect, map_size })
    }
}
