//! The region readback contract shared by the crate that reads regions back (terrain-gpu) and
//! the one that consumes them (terrain-physics' scheduler): [`RegionSource`], [`ArrivedRegion`]
//! and [`RequestId`].
//!
//! Only the contract lives here; implementations live with what they read from (terrain-gpu's
//! `GpuRegionSource` over its `RegionReadback`, terrain-physics' `CpuRegionSource` over a map in
//! memory), and each reports failures in its own [`RegionSource::Error`].

use crate::grid::Grid;
use crate::rect::Rect;

/// Identifies one request; a region arrives with the id it was requested with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct RequestId(pub u64);

impl RequestId {
    /// An id never handed out before in this process (a process-wide counter): sources
    /// take their ids from it, so a source made again (after a device loss, say) never reuses
    /// the id of a request an older one may still deliver.
    pub fn fresh() -> RequestId {
        use std::sync::atomic::{AtomicU64, Ordering};
        static NEXT: AtomicU64 = AtomicU64::new(0);
        RequestId(NEXT.fetch_add(1, Ordering::Relaxed))
    }
}

/// A region that arrived: the stored u16 heights of `rect`, row-major in the rect's own
/// (unwrapped) coordinates.
#[derive(Debug, Clone, PartialEq)]
pub struct ArrivedRegion {
    /// The request it answers.
    pub id: RequestId,
    /// The rect requested (as requested: it may cross the map's edges).
    pub rect: Rect,
    /// The heights, `rect.size` in size, in the map's own encoding.
    pub heights: Grid<u16>,
}

/// Where region readbacks come from.
///
/// Contract for implementers:
/// - `request` never blocks: it records or queues the copy and returns an id, unique among
///   the source's requests. The heights delivered must be the map's state at the time of the
///   request or later (so a deformation submitted before the request is included).
/// - `rect` may cross the map's edges (the coarse-map wraps; at most one map in size, as the
///   scheduler guarantees); the heights come back in the rect's own unwrapped coordinates.
/// - `poll` never blocks: it returns the regions that have arrived since the last call (possibly
///   none), each exactly once, in any order.
/// - Failures are reported as the implementation's own [`RegionSource::Error`], which callers
///   (terrain-physics' scheduler) hand back unchanged; a request refused only because the
///   source is busy is told apart by [`RegionSource::is_busy`].
pub trait RegionSource {
    /// What a failed request or poll reports.
    type Error: std::error::Error + Send + Sync + 'static;

    /// Asks for the heights of `rect`.
    fn request(&mut self, rect: Rect) -> Result<RequestId, Self::Error>;
    /// Hands over the regions that have arrived, without waiting for the others.
    fn poll(&mut self) -> Result<Vec<ArrivedRegion>, Self::Error>;

    /// Whether `error`, returned by [`request`](Self::request), only says the source is busy
    /// (every staging buffer still on its way): back-pressure, not a failure. The caller keeps
    /// the rect and asks again later (terrain-physics' scheduler does). `false` by default.
    fn is_busy(&self, error: &Self::Error) -> bool {
        let _ = error;
        false
    }
}
