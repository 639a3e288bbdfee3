//! Integer texel rectangles: dirty rects, stamp footprints and their toroidal split.

use glam::{IVec2, UVec2};

/// A half-open rectangle of texels: columns `min.x .. min.x + size.x`, rows `min.y .. min.y + size.y`.
///
/// `min` may be negative or past the map's size: on a toroidally addressed map that means the
/// rect wraps, and [`Rect::split_toroidal`] cuts it into the pieces that lie inside the map.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Rect {
    /// First column and row.
    pub min: IVec2,
    /// Width and height in texels.
    pub size: UVec2,
}

/// The region a deformation changed: normals, density and collision follow it.
pub type DirtyRect = Rect;

/// One piece of a wrapped rect: where it lies in the map, and where it lies in the unwrapped
/// plane the rect was defined in (`unwrapped.min - map.min` is a multiple of the map size).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WrappedPiece {
    /// The piece in map coordinates, inside `0..map_size`.
    pub map: Rect,
    /// The same texels in the rect's own, unwrapped coordinates.
    pub unwrapped: Rect,
}

impl Rect {
    /// A rect from its first texel and its size.
    pub const fn new(min: IVec2, size: UVec2) -> Self {
        Self { min, size }
    }

    /// A rect from its corners, `min` inclusive and `max` exclusive; empty if `max <= min`.
    pub fn from_min_max(min: IVec2, max: IVec2) -> Self {
        // i64: `max - min` may not fit i32 for rects near the ends of the range.
        let side =
            |a: i32, b: i32| (i64::from(b) - i64::from(a)).clamp(0, i64::from(u32::MAX)) as u32;
        Self {
            min,
            size: UVec2::new(side(min.x, max.x), side(min.y, max.y)),
        }
    }

    /// The whole of a map of `size` texels.
    pub const fn from_size(size: UVec2) -> Self {
        Self {
            min: IVec2::ZERO,
            size,
        }
    }

    /// One past the last column and row (saturating at `i32::MAX`).
    pub fn max(&self) -> IVec2 {
        let end = |m: i32, s: u32| (i64::from(m) + i64::from(s)).min(i64::from(i32::MAX)) as i32;
        IVec2::new(end(self.min.x, self.size.x), end(self.min.y, self.size.y))
    }

    /// Whether every texel of `size` has coordinates in `i32` (`min + size` does not pass
    /// `i32::MAX`). Where not, [`Rect::max`] saturates and the texels past it do not exist:
    /// an API that takes data of `size` for the rect refuses it.
    pub fn is_representable(&self) -> bool {
        let fits = |m: i32, s: u32| i64::from(m) + i64::from(s) <= i64::from(i32::MAX);
        fits(self.min.x, self.size.x) && fits(self.min.y, self.size.y)
    }

    /// Whether the rect holds no texel.
    pub fn is_empty(&self) -> bool {
        self.size.x == 0 || self.size.y == 0
    }

    /// Number of texels.
    pub fn area(&self) -> u64 {
        u64::from(self.size.x) * u64::from(self.size.y)
    }

    /// Whether texel `p` lies inside.
    pub fn contains(&self, p: IVec2) -> bool {
        p.cmpge(self.min).all() && p.cmplt(self.max()).all()
    }

    /// Whether `other` lies wholly inside `self`.
    pub fn contains_rect(&self, other: &Rect) -> bool {
        other.is_empty() || (other.min.cmpge(self.min).all() && other.max().cmple(self.max()).all())
    }

    /// The overlap of two rects, or `None` if they do not overlap.
    pub fn intersect(&self, other: &Rect) -> Option<Rect> {
        let r = Rect::from_min_max(self.min.max(other.min), self.max().min(other.max()));
        (!r.is_empty()).then_some(r)
    }

    /// The smallest rect holding both (an empty rect is ignored).
    pub fn union(&self, other: &Rect) -> Rect {
        if self.is_empty() {
            return *other;
        }
        if other.is_empty() {
            return *self;
        }
        Rect::from_min_max(self.min.min(other.min), self.max().max(other.max()))
    }

    /// `self` less `other`, as at most four disjoint rects (none when `other` covers it): the
    /// rows above and below the overlap, then the columns left and right of it.
    pub fn minus(&self, other: &Rect) -> Vec<Rect> {
        let Some(inner) = self.intersect(other) else {
            return if self.is_empty() {
                Vec::new()
            } else {
                vec![*self]
            };
        };
        let mut out = Vec::with_capacity(4);
        let (o0, o1, i0, i1) = (self.min, self.max(), inner.min, inner.max());
        let mut push = |min: IVec2, max: IVec2| {
            if max.x > min.x && max.y > min.y {
                out.push(Rect::from_min_max(min, max));
            }
        };
        push(o0, IVec2::new(o1.x, i0.y));
        push(IVec2::new(o0.x, i1.y), o1);
        push(IVec2::new(o0.x, i0.y), IVec2::new(i0.x, i1.y));
        push(IVec2::new(i1.x, i0.y), IVec2::new(o1.x, i1.y));
        out
    }

    /// The rect grown by `margin` texels on every side (the 2-texel apron of the normal map).
    pub fn expand(&self, margin: u32) -> Rect {
        let m = margin.min(i32::MAX as u32) as i32;
        Rect::from_min_max(
            self.min.saturating_sub(IVec2::splat(m)),
            self.max().saturating_add(IVec2::splat(m)),
        )
    }

    /// Cuts a rect on a toroidally addressed map of `map_size` texels into the (up to 4) pieces
    /// that lie inside it: one if it is inside, two across an edge, four across a corner
    /// (Flower 2010, sec. 3.2.1). A rect wider than the map is first limited to one period, so every
    /// map texel appears at most once. A rect past `i32::MAX` holds the texels up to
    /// [`Rect::max`] (see [`Rect::is_representable`]), so every piece's `unwrapped` is exact.
    pub fn split_toroidal(&self, map_size: UVec2) -> Vec<WrappedPiece> {
        if self.is_empty() || map_size.x == 0 || map_size.y == 0 {
            return Vec::new();
        }
        let existing =
            |m: i32, s: u32| (i64::from(i32::MAX) - i64::from(m)).min(i64::from(s)) as u32;
        let size = UVec2::new(
            existing(self.min.x, self.size.x),
            existing(self.min.y, self.size.y),
        )
        .min(map_size);
        if size.x == 0 || size.y == 0 {
            return Vec::new();
        }
        let xs = split_axis(self.min.x, size.x, map_size.x);
        let ys = split_axis(self.min.y, size.y, map_size.y);
        let mut pieces = Vec::with_capacity(xs.len() * ys.len());
        for &(my, uy, h) in &ys {
            for &(mx, ux, w) in &xs {
                let size = UVec2::new(w, h);
                pieces.push(WrappedPiece {
                    map: Rect::new(IVec2::new(mx, my), size),
                    unwrapped: Rect::new(IVec2::new(ux, uy), size),
                });
            }
        }
        pieces
    }
}

/// Splits `[start, start + len)` on an axis of period `n` (`len <= n`) into at most two spans:
/// (start in the map, start unwrapped, length).
fn split_axis(start: i32, len: u32, n: u32) -> Vec<(i32, i32, u32)> {
    let n_i = n as i64;
    let m = (start as i64).rem_euclid(n_i) as u32;
    let first = len.min(n - m);
    // `m < n <= u32::MAX`, but a map coordinate is an i32; and `start + len <= i32::MAX`
    // (split_toroidal's rects end at `Rect::max`), so the second span's start is exact.
    let to_i32 = |v: i64| v.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32;
    let mut spans = vec![(to_i32(i64::from(m)), start, first)];
    if first < len {
        spans.push((0, to_i32(i64::from(start) + i64::from(first)), len - first));
    }
    spans
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn minus_covers_each_texel_outside_the_other_exactly_once() {
        let a = Rect::new(IVec2::new(2, 3), UVec2::new(6, 5));
        for (x, y, w, h) in [
            (0, 0, 3, 3),
            (4, 4, 2, 2),
            (-5, -5, 30, 30),
            (9, 9, 2, 2),
            (5, 1, 9, 4),
        ] {
            let b = Rect::new(IVec2::new(x, y), UVec2::new(w, h));
            let pieces = a.minus(&b);
            assert!(pieces.len() <= 4);
            for py in -6..16 {
                for px in -6..16 {
                    let p = IVec2::new(px, py);
                    let n = pieces.iter().filter(|r| r.contains(p)).count();
                    let want = usize::from(a.contains(p) && !b.contains(p));
                    assert_eq!(n, want, "{p} in {a:?} minus {b:?}");
                }
            }
        }
        assert!(Rect::new(IVec2::ZERO, UVec2::ZERO).minus(&a).is_empty());
    }

    /// A rect reaching past `i32::MAX` is cut at `Rect::max`: each piece's unwrapped place
    /// is where its texels are in the rect (they used to be clamped, misplacing the second).
    #[test]
    fn rects_past_i32_max_keep_exact_unwrapped_places() {
        let map = UVec2::new(80, 48);
        let r = Rect::new(IVec2::new(i32::MAX - 2, 0), UVec2::new(40, 8));
        assert!(!r.is_representable());
        assert!(Rect::new(IVec2::new(i32::MAX - 40, 0), UVec2::new(40, 8)).is_representable());
        let pieces = r.split_toroidal(map);
        let cols: u32 = pieces
            .iter()
            .filter(|p| p.map.min.y == 0)
            .map(|p| p.map.size.x)
            .sum();
        assert_eq!(cols, 2, "only the texels before i32::MAX exist");
        for p in &pieces {
            let m = (i64::from(p.unwrapped.min.x)).rem_euclid(80);
            assert_eq!(m, i64::from(p.map.min.x), "{p:?}");
            assert!(p.unwrapped.min.x >= r.min.x);
        }
        let edge = Rect::new(IVec2::new(i32::MAX - 1, 0), UVec2::new(1, 1));
        assert_eq!(edge.split_toroidal(map).len(), 1);
        let none = Rect::new(IVec2::new(i32::MAX, 0), UVec2::new(5, 1));
        assert!(none.split_toroidal(map).is_empty());
    }

    #[test]
    fn inside_is_one_piece() {
        let r = Rect::new(IVec2::new(2, 3), UVec2::new(4, 5));
        let p = r.split_toroidal(UVec2::new(16, 16));
        assert_eq!(p.len(), 1);
        assert_eq!(p[0].map, r);
        assert_eq!(p[0].unwrapped, r);
    }

    #[test]
    fn edge_and_corner_split_into_two_and_four() {
        let map = UVec2::new(10, 8);
        let edge = Rect::new(IVec2::new(8, 2), UVec2::new(4, 3)).split_toroidal(map);
        assert_eq!(edge.len(), 2);
        let corner = Rect::new(IVec2::new(-2, 6), UVec2::new(5, 4)).split_toroidal(map);
        assert_eq!(corner.len(), 4);
        let total: u64 = corner.iter().map(|p| p.map.area()).sum();
        assert_eq!(total, 20);
        for p in &corner {
            assert!(Rect::from_size(map).contains_rect(&p.map));
            let d = p.unwrapped.min - p.map.min;
            assert_eq!(d.x.rem_euclid(10), 0);
            assert_eq!(d.y.rem_euclid(8), 0);
        }
    }

    #[test]
    fn oversized_rect_covers_map_once() {
        let map = UVec2::new(6, 6);
        let pieces = Rect::new(IVec2::new(-3, 1), UVec2::new(20, 2)).split_toroidal(map);
        let total: u64 = pieces.iter().map(|p| p.map.area()).sum();
        assert_eq!(total, 12);
    }

    #[test]
    fn extreme_rects_saturate_instead_of_overflowing() {
        let r = Rect::new(IVec2::splat(i32::MAX - 2), UVec2::splat(u32::MAX));
        assert_eq!(r.max(), IVec2::splat(i32::MAX));
        let e = Rect::new(IVec2::splat(i32::MIN + 1), UVec2::splat(3)).expand(5);
        assert_eq!(e.min, IVec2::splat(i32::MIN));
        let wide = Rect::from_min_max(IVec2::splat(i32::MIN), IVec2::splat(i32::MAX));
        assert_eq!(wide.size, UVec2::splat(u32::MAX));
        assert_eq!(
            wide.split_toroidal(UVec2::splat(8))
                .iter()
                .map(|p| p.map.area())
                .sum::<u64>(),
            64
        );
    }

    #[test]
    fn intersect_union_expand() {
        let a = Rect::new(IVec2::new(0, 0), UVec2::new(4, 4));
        let b = Rect::new(IVec2::new(2, 2), UVec2::new(4, 4));
        assert_eq!(
            a.intersect(&b),
            Some(Rect::new(IVec2::new(2, 2), UVec2::new(2, 2)))
        );
        assert_eq!(a.union(&b), Rect::new(IVec2::ZERO, UVec2::new(6, 6)));
        assert_eq!(a.expand(2), Rect::new(IVec2::new(-2, -2), UVec2::new(8, 8)));
        let far = Rect::new(IVec2::new(10, 10), UVec2::new(1, 1));
        assert_eq!(a.intersect(&far), None);
    }
}
