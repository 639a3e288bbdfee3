//! Handing columns of a u16 coarse-map (a streamed world's resident tiles) to a granular
//! scratch map in u32 fixed point and back, with the volume exact in the world's own stored
//! units (Persson 2019, sec. 4.3 keeps integer heights so that no step loses material; this
//! keeps the hand-over from losing any either).
//!
//! The rule, for `k` fixed-point units per stored unit (a whole number, [`Handover::k`]):
//! - **in**: `u = k * h` for every column, exact; the area holds `k * sum(h)` units.
//! - **out**: each column gets `floor(u / k)`; what is left over, `sum(u mod k)` units, is a
//!   whole number `R` of stored units (granular steps only move units), and goes one stored
//!   unit each to the `R` columns with the largest remainders `u mod k`, ties to the lower
//!   row-major index (largest-remainder rounding, deterministic). Every column ends within one stored unit of
//!   `u / k`, and `sum(h_out) = sum(u) / k` exactly.
//!
//! The scratch map's encoding is fixed point with `U = round(k / scale)` units per metre, its
//! heights metres above the world's offset. `U` may differ from `k / scale` by half a unit:
//! the granular step then sees heights scaled by at most `0.5 / U` (relative), which changes
//! where material goes by less than a unit, never how much there is.

use super::error::GranularError;
use crate::grid::Grid;
use crate::map::HeightEncoding;

/// The fixed-point scale of a hand-over between a world of u16 stored heights and a granular
/// scratch map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Handover {
    k: u32,
}

impl Handover {
    /// `k` fixed-point units per stored unit, 1 to 65 537 (so `k * 65 535` fits a u32).
    pub fn new(k: u32) -> Result<Self, GranularError> {
        if !(1..=65_537).contains(&k) {
            return Err(GranularError::ParamOutOfRange {
                name: "fixed-point units per stored unit",
                value: f64::from(k),
                range: "1 to 65537",
            });
        }
        Ok(Self { k })
    }

    /// The whole number of units per stored unit nearest to `units_per_metre` metres for a world
    /// whose stored unit is `world.scale` metres (at least 1): 10 000 units per metre
    /// (Persson 2019's choice) gives `k = 9` for a world spanning 60 m in u16.
    pub fn for_world(world: HeightEncoding, units_per_metre: u32) -> Result<Self, GranularError> {
        let k = (f64::from(world.scale) * f64::from(units_per_metre)).round();
        Self::new(k.clamp(1.0, 65_537.0) as u32)
    }

    /// Fixed-point units per stored unit.
    pub fn k(&self) -> u32 {
        self.k
    }

    /// The scratch map's encoding for a world of encoding `world`: fixed point (offset 0) with
    /// `round(k / scale)` units per metre (see the module docs).
    pub fn scratch_encoding(&self, world: HeightEncoding) -> Result<HeightEncoding, GranularError> {
        let units = (f64::from(self.k) / f64::from(world.scale)).round();
        if !(1.0..=f64::from(u32::MAX)).contains(&units) {
            return Err(GranularError::ParamOutOfRange {
                name: "scratch units per metre",
                value: units,
                range: "1 to 2^32 - 1 (k / the world's scale)",
            });
        }
        Ok(HeightEncoding::fixed_point(units as u32)?)
    }

    /// The columns of `heights` in fixed point: `k * h` each.
    pub fn to_fixed(&self, heights: &Grid<u16>) -> Grid<u32> {
        heights.map(|&h| u32::from(h) * self.k)
    }

    /// The columns of `fixed` back in stored units by largest-remainder rounding (see the
    /// module docs): their sum is exactly `sum(fixed) / k`.
    ///
    /// Fails, with nothing returned, when `sum(fixed)` is not a multiple of `k` (units were
    /// added or removed: the area is not the one handed in, or compression removed material,
    /// which the caller must account as whole stored units) or when a column holds more than
    /// `k * 65 535` units (it would not fit a u16).
    pub fn from_fixed(&self, fixed: &Grid<u32>) -> Result<Grid<u16>, GranularError> {
        let k = self.k;
        let max = 65_535 * u64::from(k);
        let mut total = 0u64;
        // Histogram of the remainders, to find the threshold without sorting.
        let mut count = vec![0u64; k as usize];
        for &u in fixed.as_slice() {
            if u64::from(u) > max {
                return Err(GranularError::ParamOutOfRange {
                    name: "fixed-point column height (units)",
                    value: f64::from(u),
                    range: "at most k * 65535 (a u16 stored height)",
                });
            }
            total += u64::from(u);
            count[(u % k) as usize] += 1;
        }
        if !total.is_multiple_of(u64::from(k)) {
            return Err(GranularError::ParamOutOfRange {
                name: "fixed-point area volume (units)",
                value: total as f64,
                range: "a whole number of stored units (a multiple of k)",
            });
        }
        let floors: u64 = fixed.as_slice().iter().map(|&u| u64::from(u / k)).sum();
        // Stored units left to hand out, one per column: fewer than the columns with a
        // remainder, since each remainder is below k.
        let mut left = total / u64::from(k) - floors;
        // Remainders from `full_from` up get one unit each; of the bucket `partial` below it,
        // its first `partial_left` columns in row-major order.
        let (mut full_from, mut partial, mut partial_left) = (k, 0, 0);
        for r in (1..k).rev() {
            if left == 0 {
                break;
            }
            let c = count[r as usize];
            if c <= left {
                left -= c;
                full_from = r;
            } else {
                (partial, partial_left) = (r, left);
                left = 0;
            }
        }
        debug_assert_eq!(left, 0);
        let mut out = Vec::with_capacity(fixed.as_slice().len());
        for &u in fixed.as_slice() {
            let (q, r) = (u / k, u % k);
            let up = if r >= full_from {
                1
            } else if r == partial && partial_left > 0 {
                partial_left -= 1;
                1
            } else {
                0
            };
            // q + up <= 65 535: u <= k * 65 535, and up = 1 needs r > 0.
            out.push((q + up) as u16);
        }
        Ok(Grid::from_vec(fixed.width(), fixed.height(), out)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(seed: &mut u64) -> u64 {
        *seed = seed
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        *seed >> 33
    }

    #[test]
    fn a_round_trip_is_the_identity() {
        for k in [1, 2, 9, 10_000, 65_537] {
            let h = Handover::new(k).unwrap();
            let g =
                Grid::from_fn(17, 9, |x, y| ((x * 7919 + y * 104_729) % 65_536) as u16).unwrap();
            assert_eq!(h.from_fixed(&h.to_fixed(&g)).unwrap(), g, "k {k}");
        }
        let g = Grid::new(3, 3, u16::MAX).unwrap();
        let h = Handover::new(65_537).unwrap();
        assert_eq!(h.from_fixed(&h.to_fixed(&g)).unwrap(), g);
    }

    /// Units moved between columns (as a granular step does) come back with the volume exact,
    /// every column within one stored unit of its share, ties to the lower index.
    #[test]
    fn moved_units_come_back_with_the_volume_exact() {
        let mut seed = 7u64;
        for k in [1u32, 2, 3, 9, 100, 10_000] {
            let h = Handover::new(k).unwrap();
            for _ in 0..50 {
                let (w, hh) = (
                    1 + (lcg(&mut seed) % 20) as u32,
                    1 + (lcg(&mut seed) % 20) as u32,
                );
                let g = Grid::from_fn(w, hh, |_, _| (lcg(&mut seed) % 60_000) as u16).unwrap();
                let mut f = h.to_fixed(&g);
                let n = f.as_slice().len();
                // Random moves of units between columns, never below 0.
                for _ in 0..(n * 3) {
                    let (a, b) = (lcg(&mut seed) as usize % n, lcg(&mut seed) as usize % n);
                    let amount = (lcg(&mut seed) as u32 % (2 * k + 3)).min(f.as_slice()[a]);
                    f.as_mut_slice()[a] -= amount;
                    f.as_mut_slice()[b] += amount;
                }
                let back = h.from_fixed(&f).unwrap();
                let sum_in: u64 = g.as_slice().iter().map(|&v| u64::from(v)).sum();
                let sum_out: u64 = back.as_slice().iter().map(|&v| u64::from(v)).sum();
                assert_eq!(sum_in, sum_out, "k {k}");
                for (&u, &o) in f.as_slice().iter().zip(back.as_slice()) {
                    let share = f64::from(u) / f64::from(k);
                    assert!((f64::from(o) - share).abs() < 1.0, "k {k}: {u} -> {o}");
                }
            }
        }
        // Ties: two columns each half a unit over, one unit to hand out: the first gets it.
        let h = Handover::new(2).unwrap();
        let f = Grid::from_vec(3, 1, vec![3, 3, 2]).unwrap();
        assert_eq!(h.from_fixed(&f).unwrap().as_slice(), &[2, 1, 1]);
    }

    #[test]
    fn what_cannot_be_exact_is_refused() {
        assert!(Handover::new(0).is_err());
        assert!(Handover::new(65_538).is_err());
        let h = Handover::new(4).unwrap();
        // One unit lost: not a whole number of stored units.
        assert!(
            h.from_fixed(&Grid::from_vec(2, 1, vec![4, 3]).unwrap())
                .is_err()
        );
        // A column beyond a u16.
        assert!(
            h.from_fixed(&Grid::from_vec(1, 1, vec![4 * 65_536]).unwrap())
                .is_err()
        );
        // Fixed point for a 60 m world: k = 9, about 9 830 units per metre, offset 0.
        let world = HeightEncoding::spanning::<u16>(0.0, 60.0).unwrap();
        let h = Handover::for_world(world, 10_000).unwrap();
        assert_eq!(h.k(), 9);
        let enc = h.scratch_encoding(world).unwrap();
        assert_eq!(enc.offset, 0.0);
        assert!((1.0 / f64::from(enc.scale) - 9.0 / f64::from(world.scale)).abs() <= 0.51);
    }
}
