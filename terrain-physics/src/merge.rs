//! Dirty-rect merging on the toroidal coarse-map: [`DirtyRegions`] keeps a short list of
//! disjoint rects whose union covers every rect inserted, each at most one map in size.
//!
//! Policy: rects live in the map's period (`0 <= min < size`) and may cross its far edges (they
//! wrap). Inserting a rect unions it with every kept rect within `merge_distance` texels of it
//! (Chebyshev gap, measured around the torus, so rects on both sides of the wrap edge merge into
//! one rect that crosses it), repeating until nothing is that close. If more than `max_rects`
//! remain, the two closest are merged. A union that would span the map on an axis becomes the
//! whole axis, so no rect is ever larger than the map.

use glam::{IVec2, UVec2};
use terrain_core::Rect;

/// A short list of disjoint dirty rects on a toroidal map.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DirtyRegions {
    rects: Vec<Rect>,
    map_size: UVec2,
    merge_distance: u32,
    max_rects: usize,
}

/// One axis of a rect: start in `0..n`, length in `1..=n`.
type Span = (i64, i64);

impl DirtyRegions {
    /// An empty set for a map of `map_size` texels (both sides at least 1). Rects closer than
    /// `merge_distance` texels merge; at most `max_rects` (at least 1) are kept.
    pub fn new(map_size: UVec2, merge_distance: u32, max_rects: usize) -> Self {
        Self {
            rects: Vec::new(),
            map_size: map_size.max(UVec2::ONE),
            merge_distance,
            max_rects: max_rects.max(1),
        }
    }

    /// The rects kept: disjoint, `0 <= min < map_size`, `size <= map_size` (they may wrap).
    pub fn rects(&self) -> &[Rect] {
        &self.rects
    }

    /// How many rects are kept.
    pub fn len(&self) -> usize {
        self.rects.len()
    }

    /// Whether no rect is kept.
    pub fn is_empty(&self) -> bool {
        self.rects.is_empty()
    }

    /// Removes and returns the rects kept.
    pub fn take(&mut self) -> Vec<Rect> {
        std::mem::take(&mut self.rects)
    }

    /// Adds `rect` (any position: it is wrapped into the map's period; an empty one is
    /// ignored), merging as the module describes.
    pub fn insert(&mut self, rect: Rect) {
        if rect.is_empty() {
            return;
        }
        let n = self.map_size;
        let size = rect.size.min(n);
        let min = IVec2::new(
            rect.min.x.rem_euclid(n.x as i32),
            rect.min.y.rem_euclid(n.y as i32),
        );
        let mut cur = Rect::new(min, size);
        // Union with everything close, until nothing close is left.
        while let Some(i) = self.rects.iter().position(|r| {
            let (gx, gy) = self.gaps(cur, *r);
            gx <= i64::from(self.merge_distance) && gy <= i64::from(self.merge_distance)
        }) {
            let other = self.rects.swap_remove(i);
            cur = self.union(cur, other);
        }
        self.rects.push(cur);
        while self.rects.len() > self.max_rects {
            let (i, j) = self.closest_pair();
            let b = self.rects.swap_remove(j.max(i));
            let a = self.rects.swap_remove(j.min(i));
            let u = self.union(a, b);
            self.insert(u);
        }
    }

    /// Indices of the two rects with the smallest gap (then the smallest union).
    fn closest_pair(&self) -> (usize, usize) {
        let mut best = (i64::MAX, u64::MAX, 0, 1);
        for i in 0..self.rects.len() {
            for j in i + 1..self.rects.len() {
                let (a, b) = (self.rects[i], self.rects[j]);
                let (gx, gy) = self.gaps(a, b);
                let key = (gx.max(gy), self.union(a, b).area());
                if key < (best.0, best.1) {
                    best = (key.0, key.1, i, j);
                }
            }
        }
        (best.2, best.3)
    }

    /// The toroidal gaps between two rects on each axis (0 where they overlap or touch).
    fn gaps(&self, a: Rect, b: Rect) -> (i64, i64) {
        let (gx, _) = join(span_x(a), span_x(b), i64::from(self.map_size.x));
        let (gy, _) = join(span_y(a), span_y(b), i64::from(self.map_size.y));
        (gx, gy)
    }

    /// The smallest rect covering both around the torus, clipped to one period per axis.
    fn union(&self, a: Rect, b: Rect) -> Rect {
        let (_, (x0, w)) = join(span_x(a), span_x(b), i64::from(self.map_size.x));
        let (_, (y0, h)) = join(span_y(a), span_y(b), i64::from(self.map_size.y));
        Rect::new(
            IVec2::new(x0 as i32, y0 as i32),
            UVec2::new(w as u32, h as u32),
        )
    }
}

fn span_x(r: Rect) -> Span {
    (i64::from(r.min.x), i64::from(r.size.x))
}

fn span_y(r: Rect) -> Span {
    (i64::from(r.min.y), i64::from(r.size.y))
}

/// The gap between two spans on a circle of length `n`, and their smallest covering span
/// (start wrapped into `0..n`, length at most `n`).
fn join(a: Span, b: Span, n: i64) -> (i64, Span) {
    if a.1 >= n || b.1 >= n {
        return (0, (0, n));
    }
    let mut best: Option<(i64, i64, i64)> = None; // (gap, union length, union start)
    for shift in [-n, 0, n] {
        let bs = b.0 + shift;
        let gap = (bs - (a.0 + a.1)).max(a.0 - (bs + b.1)).max(0);
        let lo = a.0.min(bs);
        let hi = (a.0 + a.1).max(bs + b.1);
        let cand = (gap, hi - lo, lo);
        if best.is_none_or(|b| (cand.0, cand.1) < (b.0, b.1)) {
            best = Some(cand);
        }
    }
    let (gap, len, lo) = best.unwrap_or((0, n, 0));
    if len >= n {
        (gap, (0, n))
    } else {
        (gap, (lo.rem_euclid(n), len))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn r(x: i32, y: i32, w: u32, h: u32) -> Rect {
        Rect::new(IVec2::new(x, y), UVec2::new(w, h))
    }

    #[test]
    fn overlapping_and_nearby_rects_merge_far_ones_do_not() {
        let mut d = DirtyRegions::new(UVec2::splat(100), 4, 8);
        d.insert(r(10, 10, 5, 5));
        d.insert(r(12, 12, 5, 5));
        assert_eq!(d.rects(), &[r(10, 10, 7, 7)]);
        d.insert(r(20, 10, 2, 2)); // gap 3 <= 4
        assert_eq!(d.rects(), &[r(10, 10, 12, 7)]);
        d.insert(r(60, 60, 2, 2));
        assert_eq!(d.rects().len(), 2);
    }

    #[test]
    fn rects_on_both_sides_of_the_wrap_edge_merge_into_one_crossing_it() {
        let mut d = DirtyRegions::new(UVec2::new(64, 32), 2, 8);
        d.insert(r(60, 5, 3, 3)); // columns 60..63
        d.insert(r(1, 6, 2, 2)); // columns 1..3, gap 1 across the edge
        assert_eq!(d.rects(), &[r(60, 5, 7, 3)]);
        // An unwrapped rect starting left of the map lands in the same place.
        let mut e = DirtyRegions::new(UVec2::new(64, 32), 2, 8);
        e.insert(r(-4, 5, 3, 3));
        assert_eq!(e.rects(), &[r(60, 5, 3, 3)]);
    }

    #[test]
    fn unions_never_exceed_the_map() {
        let mut d = DirtyRegions::new(UVec2::new(16, 16), 0, 8);
        d.insert(r(0, 0, 10, 2));
        d.insert(r(8, 0, 10, 2)); // together they go round: the whole axis
        assert_eq!(d.rects(), &[r(0, 0, 16, 2)]);
        d.insert(r(3, -40, 200, 1)); // oversized input is clipped to one period
        for rect in d.rects() {
            assert!(rect.size.cmple(UVec2::splat(16)).all());
            assert!(rect.min.cmpge(IVec2::ZERO).all() && rect.min.cmplt(IVec2::splat(16)).all());
        }
    }

    #[test]
    fn too_many_rects_merge_the_closest_pair() {
        let mut d = DirtyRegions::new(UVec2::splat(1000), 0, 2);
        d.insert(r(0, 0, 1, 1));
        d.insert(r(500, 500, 1, 1));
        d.insert(r(10, 0, 1, 1));
        assert_eq!(d.rects().len(), 2);
        assert!(d.rects().contains(&r(0, 0, 11, 1)));
        // Every inserted texel is covered.
        let covered = |p: IVec2| {
            d.rects().iter().any(|q| {
                q.split_toroidal(UVec2::splat(1000))
                    .iter()
                    .any(|w| w.map.contains(p))
            })
        };
        assert!(covered(IVec2::new(500, 500)) && covered(IVec2::new(10, 0)));
    }
}
