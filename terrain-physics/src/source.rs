//! [`CpuRegionSource`], which serves regions from a coarse-map in memory (tests, GPU-less
//! users), through the readback contract the scheduler asks for regions through
//! ([`RegionSource`], defined in terrain-core and re-exported here).
//!
//! terrain-gpu implements [`RegionSource`] with its `RegionReadback` (a ring of staging buffers
//! mapped asynchronously); this crate names no GPU type.

use crate::error::{PhysicsError, check_region};
use std::collections::VecDeque;
pub use terrain_core::{ArrivedRegion, RegionSource, RequestId};
use terrain_core::{CoarseMap, Grid, Rect};

/// A [`RegionSource`] over a coarse-map the caller keeps current (apply deformations to
/// [`CpuRegionSource::map_mut`]).
///
/// A request copies the rect at request time (as a GPU copy recorded then would) and delivers
/// it on the `latency`-th poll after the request (`latency` 1: the next poll), to simulate a
/// readback in flight.
#[derive(Debug, Clone)]
pub struct CpuRegionSource {
    map: CoarseMap,
    latency: u32,
    queue: VecDeque<(u32, ArrivedRegion)>,
    requests: Vec<Rect>,
}

impl CpuRegionSource {
    /// A source over `map` delivering each region on the next poll.
    pub fn new(map: CoarseMap) -> Self {
        Self {
            map,
            latency: 1,
            queue: VecDeque::new(),
            requests: Vec::new(),
        }
    }

    /// The same source delivering each region on the `polls`-th poll after its request
    /// (at least 1).
    pub fn with_latency(self, polls: u32) -> Result<Self, PhysicsError> {
        if polls == 0 {
            return Err(PhysicsError::OutOfRange {
                what: "readback latency (polls)",
                value: 0.0,
                expected: "at least 1 poll",
            });
        }
        Ok(Self {
            latency: polls,
            ..self
        })
    }

    /// The map regions are read from.
    pub fn map(&self) -> &CoarseMap {
        &self.map
    }

    /// The map, to deform it.
    pub fn map_mut(&mut self) -> &mut CoarseMap {
        &mut self.map
    }

    /// Every rect requested so far, in order.
    pub fn requests(&self) -> &[Rect] {
        &self.requests
    }

    /// Requests not yet delivered.
    pub fn in_flight(&self) -> usize {
        self.queue.len()
    }
}

/// Copies `rect` (which may wrap) out of `map`, row-major in the rect's unwrapped coordinates.
pub fn read_region(map: &CoarseMap, rect: Rect) -> Result<Grid<u16>, PhysicsError> {
    let size = map.size();
    check_region(rect, size)?;
    let mut out = Grid::new(rect.size.x, rect.size.y, 0u16)?;
    let src = map.grid();
    for piece in rect.split_toroidal(size) {
        let off = (piece.unwrapped.min - rect.min).as_uvec2();
        let (x0, w) = (piece.map.min.x as usize, piece.map.size.x as usize);
        for row in 0..piece.map.size.y {
            let s = &src.row(piece.map.min.y as u32 + row)[x0..x0 + w];
            out.row_mut(off.y + row)[off.x as usize..off.x as usize + w].copy_from_slice(s);
        }
    }
    Ok(out)
}

impl RegionSource for CpuRegionSource {
    type Error = PhysicsError;

    fn request(&mut self, rect: Rect) -> Result<RequestId, PhysicsError> {
        let heights = read_region(&self.map, rect)?;
        let id = RequestId::fresh();
        self.requests.push(rect);
        self.queue
            .push_back((self.latency, ArrivedRegion { id, rect, heights }));
        Ok(id)
    }

    fn poll(&mut self) -> Result<Vec<ArrivedRegion>, PhysicsError> {
        let mut out = Vec::new();
        let mut keep = VecDeque::with_capacity(self.queue.len());
        for (polls_left, region) in self.queue.drain(..) {
            if polls_left <= 1 {
                out.push(region);
            } else {
                keep.push_back((polls_left - 1, region));
            }
        }
        self.queue = keep;
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{IVec2, UVec2};
    use terrain_core::{HeightEncoding, WrapMode};

    fn map() -> CoarseMap {
        let g = Grid::from_fn(8, 6, |x, y| (x + 10 * y) as u16).expect("grid");
        CoarseMap::coarse(g, HeightEncoding::new(0.01, 0.0).expect("enc"), 1.0).expect("map")
    }

    #[test]
    fn regions_wrap_and_arrive_after_the_latency() {
        let mut s = CpuRegionSource::new(map())
            .with_latency(2)
            .expect("latency");
        let rect = Rect::new(IVec2::new(6, -1), UVec2::new(4, 3));
        let id = s.request(rect).expect("request");
        assert!(s.poll().expect("poll").is_empty());
        let got = s.poll().expect("poll");
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].id, id);
        for y in 0..3 {
            for x in 0..4 {
                let p = rect.min + IVec2::new(x, y);
                let want = s.map().grid().get_wrapped(p, WrapMode::Repeat);
                assert_eq!(got[0].heights.get(x as u32, y as u32), Some(want));
            }
        }
        assert!(s.poll().expect("poll").is_empty());
        assert_eq!(s.requests(), &[rect]);
    }

    #[test]
    fn data_is_taken_at_request_time() {
        let mut s = CpuRegionSource::new(map());
        let rect = Rect::new(IVec2::ZERO, UVec2::new(2, 2));
        s.request(rect).expect("request");
        *s.map_mut().grid_mut().get_mut(0, 0).expect("texel") = 999;
        let got = s.poll().expect("poll");
        assert_eq!(got[0].heights.get(0, 0), Some(0));
    }

    #[test]
    fn bad_requests_are_errors() {
        let mut s = CpuRegionSource::new(map());
        assert!(matches!(
            s.request(Rect::new(IVec2::new(100, 0), UVec2::new(2, 2))),
            Err(PhysicsError::RegionOffMap { .. })
        ));
        assert!(s.request(Rect::new(IVec2::ZERO, UVec2::new(9, 1))).is_err());
        assert!(s.clone().with_latency(0).is_err());
        assert_eq!(s.in_flight(), 0);
    }
}
