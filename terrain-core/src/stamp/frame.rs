//! The per-placement state the reference and the fast paths of a stamp share: the local frame
//! of the footprint in texel units (with the row span it covers) and the blend of a stamp value
//! into a stored height. Both compute exactly what the GPU pass computes.

use crate::map::HeightSample;
use glam::Vec2;

/// A placement's local frame in texel units (see [`StampPlacement::local_frame`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct Frame {
    pub(super) center: Vec2,
    pub(super) inv_half: Vec2,
    pub(super) sin: f32,
    pub(super) cos: f32,
}

impl Frame {
    /// Local coordinates of the texel at unwrapped coordinates `(ux, uy)`, in f32 exactly as
    /// the GPU pass computes them.
    #[inline(always)]
    pub(super) fn local(&self, ux: i32, uy: i32) -> Vec2 {
        let dx = ux as f32 - self.center.x;
        let dy = uy as f32 - self.center.y;
        Vec2::new(dx * self.cos + dy * self.sin, dy * self.cos - dx * self.sin) * self.inv_half
    }

    /// The texels `[a, b)` of row `uy` within `[lo, hi)` that are inside the footprint
    /// (`!(|local.x| > 1 || |local.y| > 1)`, the per-texel test). Each of the four half-tests
    /// is monotone along a row (an f32 affine function of x, every rounding monotone), so each
    /// holds on a prefix or a suffix, found by bisection: `O(log(hi - lo))` evaluations.
    pub(super) fn row_span(&self, uy: i32, lo: i32, hi: i32) -> (i32, i32) {
        // `!(v > 1)` rather than `v <= 1`: NaN passes, as in the per-texel test.
        use std::cmp::Ordering::Greater;
        use std::cmp::Ordering::Less;
        let tests: [&dyn Fn(i32) -> bool; 4] = [
            &|x| self.local(x, uy).x.partial_cmp(&1.0) != Some(Greater),
            &|x| self.local(x, uy).x.partial_cmp(&-1.0) != Some(Less),
            &|x| self.local(x, uy).y.partial_cmp(&1.0) != Some(Greater),
            &|x| self.local(x, uy).y.partial_cmp(&-1.0) != Some(Less),
        ];
        let (mut a, mut b) = (lo, hi);
        for t in tests {
            let (ta, tb) = monotone_span(lo, hi, t);
            a = a.max(ta);
            b = b.min(tb);
        }
        if a >= b { (lo, lo) } else { (a, b) }
    }
}

/// Where a predicate that is monotone over `[lo, hi)` holds: a prefix or a suffix (or all,
/// or nothing), by bisection.
fn monotone_span(lo: i32, hi: i32, p: &dyn Fn(i32) -> bool) -> (i32, i32) {
    if lo >= hi {
        return (lo, lo);
    }
    match (p(lo), p(hi - 1)) {
        (true, true) => (lo, hi),
        (false, false) => (lo, lo),
        (first, _) => {
            // p(l) == first and p(h) != first; bisect to adjacent l, h.
            let (mut l, mut h) = (lo, hi - 1);
            while h - l > 1 {
                let m = l + (h - l) / 2;
                if p(m) == first { l = m } else { h = m }
            }
            if first { (lo, h) } else { (h, hi) }
        }
    }
}

/// The blend of one stamp value into a stored height, in f64 stored units.
#[derive(Debug, Clone, Copy)]
pub(super) struct BlendOp {
    /// 0 add, 1 min, 2 max.
    pub(super) kind: u8,
    pub(super) add_scale: f64,
    pub(super) base_raw: f64,
}

impl BlendOp {
    /// The stored-unit term of value `v`, or the value that leaves a texel unchanged when `v`
    /// is NaN or infinite (0 for add, +inf for min, -inf for max).
    #[inline(always)]
    pub(super) fn z(&self, v: f32) -> f64 {
        if v.is_finite() {
            self.add_scale * f64::from(v)
        } else {
            [0.0, f64::INFINITY, f64::NEG_INFINITY][usize::from(self.kind)]
        }
    }

    /// Blends the terms `z` into `dst`: `round(old + z)`, `round(min(old, base + z))` or
    /// `round(max(old, base + z))`, rounded half up and clamped to the sample's range.
    #[inline(always)]
    pub(super) fn apply<T: HeightSample>(&self, dst: &mut [T], z: &[f64]) {
        let base = self.base_raw;
        match self.kind {
            0 => {
                for (d, &z) in dst.iter_mut().zip(z) {
                    *d = T::from_raw_f64_floor_clamped(d.to_raw_f64() + z + 0.5);
                }
            }
            1 => {
                for (d, &z) in dst.iter_mut().zip(z) {
                    *d = T::from_raw_f64_floor_clamped(d.to_raw_f64().min(base + z) + 0.5);
                }
            }
            _ => {
                for (d, &z) in dst.iter_mut().zip(z) {
                    *d = T::from_raw_f64_floor_clamped(d.to_raw_f64().max(base + z) + 0.5);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `monotone_span` finds the prefix or suffix where a monotone predicate holds, as a scan
    /// does, and asks the predicate only inside `[lo, hi)` (its contract says nothing of
    /// the values outside).
    #[test]
    fn monotone_span_equals_a_scan_and_stays_inside_the_range() {
        for lo in [-37, -1, 0, 3, 250] {
            for len in 0..40 {
                let hi = lo + len;
                for t in lo - 2..=hi + 2 {
                    for prefix in [true, false] {
                        let asked = std::cell::RefCell::new(Vec::new());
                        let p = |x: i32| {
                            let mut a = asked.borrow_mut();
                            assert!(a.len() < 64, "a bisection that does not end");
                            a.push(x);
                            if prefix { x < t } else { x >= t }
                        };
                        let got = monotone_span(lo, hi, &p);
                        let held: Vec<i32> = (lo..hi)
                            .filter(|&x| if prefix { x < t } else { x >= t })
                            .collect();
                        let want = match (held.first(), held.last()) {
                            (Some(&a), Some(&b)) => (a, b + 1),
                            _ => (lo, lo),
                        };
                        assert_eq!(got, want, "[{lo}, {hi}) t {t} prefix {prefix}");
                        let asked = asked.borrow();
                        assert!(
                            asked.iter().all(|x| (lo..hi).contains(x)),
                            "[{lo}, {hi}): asked {asked:?}"
                        );
                        // Bisection: a logarithmic number of questions.
                        assert!(asked.len() <= 2 + 7, "{} questions", asked.len());
                    }
                }
            }
        }
    }
}
