//! The row span of a placement's footprint: which texels of a row the exact stamp program
//! ([`super::fixed`]) visits. The inside test is the program's own, per texel; the span only
//! skips texels that cannot pass it.

use super::fixed::{FixedFrame, LOCAL_ONE};

impl FixedFrame {
    /// The texels `[a, b)` of row `uy` within `[lo, hi)` that are inside the footprint
    /// ([`super::fixed::inside`]). Each of the four half-tests is an integer affine function
    /// of x (monotone while nothing wraps: [`FixedFrame::monotone`]), so it holds on a prefix
    /// or a suffix, found by bisection: `O(log(hi - lo))` evaluations. Without `monotone`, the
    /// whole range (the caller tests every texel).
    pub(super) fn row_span(&self, uy: i32, lo: i32, hi: i32) -> (i32, i32) {
        if !self.monotone {
            return (lo, hi.max(lo));
        }
        let tests: [&dyn Fn(i32) -> bool; 4] = [
            &|x| self.local_q(x, uy)[0] <= LOCAL_ONE,
            &|x| self.local_q(x, uy)[0] >= -LOCAL_ONE,
            &|x| self.local_q(x, uy)[1] <= LOCAL_ONE,
            &|x| self.local_q(x, uy)[1] >= -LOCAL_ONE,
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
