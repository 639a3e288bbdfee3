//! Exact nearest-seed transforms on the CPU (Meijster, Roerdink and Hesselink 2000, "A general
//! algorithm for computing distance transforms in linear time"): for every column of an area,
//! a seed at the smallest distance under the Euclidean, Manhattan or Chebyshev metric, in two
//! separable phases of linear time. The alternative to jump flooding for CPU users
//! ([`super::DistanceTransform::Exact`]); jump flooding stays what the GPU runs.
//!
//! Phase 1 (per map column, swept row by row down then up): `g(x, y)`, the distance to the
//! nearest seed in the same column, and that seed's row. Phase 2 (per row, rows in parallel):
//! the lower envelope of `f(x, i) = F(x - i, g(i))` over the columns `i` that have a seed,
//! with `F` the metric (`dx^2 + g^2`, `|dx| + g`, `max(|dx|, g)`), scanned left to right with
//! the metric's separator and read back right to left. Integer arithmetic throughout, so the
//! distances are exact; where several seeds are equally near, the one returned may differ
//! from the brute force's (it is as near).

use super::{DistanceMetric, GranularError, NO_SEED, Penetration};
use crate::{Grid, Rect};

/// A column with no seed in it (phase 1); larger than any distance inside an area.
const NONE: u32 = u32::MAX;

/// The nearest seed of every column of `area` under `metric`, exactly: a grid of
/// `[seed_x, seed_y]` in map coordinates over `area.size` ([`NO_SEED`] everywhere when the
/// area has no seed), the same shape [`super::jump_flood`] returns.
///
/// Seeds are the texels of `pen` whose `seed_x` is not [`NO_SEED`]; each must name its own
/// column (as [`super::penetration_texture`] writes them), else
/// [`GranularError::SeedNotAtColumn`]. Time and memory are linear in the area; rows of phase 2
/// run in parallel and the result does not depend on the thread count.
pub fn exact_nearest_seed(
    pen: &Grid<Penetration>,
    area: Rect,
    metric: DistanceMetric,
) -> Result<Grid<[u32; 2]>, GranularError> {
    super::jfa::check_side(area.size)?;
    if pen.size() != area.size {
        return Err(GranularError::SizeMismatch {
            expected: area.size,
            actual: pen.size(),
        });
    }
    let (w, h) = (area.size.x as usize, area.size.y as usize);
    let (ox, oy) = (area.min.x as u32, area.min.y as u32);
    // Phase 1: `g` (distance along the column) and the seed row (local), swept down then up.
    let mut g = vec![NONE; w * h];
    let mut srow = vec![NONE; w * h];
    let cells = pen.as_slice();
    let mut last = vec![NONE; w];
    for y in 0..h {
        for x in 0..w {
            let p = &cells[y * w + x];
            if p.seed_x != NO_SEED {
                let at = [ox + x as u32, oy + y as u32];
                if [p.seed_x, p.seed_y] != at {
                    return Err(GranularError::SeedNotAtColumn {
                        column: at,
                        seed: [p.seed_x, p.seed_y],
                    });
                }
                last[x] = y as u32;
            }
            if last[x] != NONE {
                g[y * w + x] = y as u32 - last[x];
                srow[y * w + x] = last[x];
            }
        }
    }
    last.fill(NONE);
    for y in (0..h).rev() {
        for x in 0..w {
            let i = y * w + x;
            if g[i] == 0 {
                last[x] = y as u32;
            } else if last[x] != NONE && last[x] - y as u32 <= g[i] {
                // Ties keep the seed above; either is as near.
                if last[x] - (y as u32) < g[i] {
                    g[i] = last[x] - y as u32;
                    srow[i] = last[x];
                }
            }
        }
    }
    // Phase 2: per row, the lower envelope of the columns that have a seed.
    let mut out =
        Grid::new(area.size.x, area.size.y, [NO_SEED; 2]).map_err(|_| GranularError::TooLarge {
            side: area.size.max_element(),
            limit: super::MAX_SIDE,
        })?;
    crate::par::for_each_chunk(out.as_mut_slice(), w, |y, row| {
        let gr = &g[y * w..(y + 1) * w];
        let sr = &srow[y * w..(y + 1) * w];
        let mut s: Vec<u32> = Vec::with_capacity(w);
        let mut t: Vec<i64> = Vec::with_capacity(w);
        let gi = |i: u32| i64::from(gr[i as usize]);
        let m = w as i64;
        for u in (0..w as u32).filter(|&u| gr[u as usize] != NONE) {
            loop {
                match (s.last(), t.last()) {
                    (Some(&sq), Some(&tq))
                        if envelope_f(metric, tq, sq, gi(sq))
                            > envelope_f(metric, tq, u, gi(u)) =>
                    {
                        s.pop();
                        t.pop();
                    }
                    _ => break,
                }
            }
            match s.last() {
                None => {
                    s.push(u);
                    t.push(0);
                }
                Some(&sq) => {
                    let wsep = 1 + separator(metric, sq, u, gi(sq), gi(u));
                    if wsep < m {
                        s.push(u);
                        t.push(wsep);
                    }
                }
            }
        }
        if s.is_empty() {
            return;
        }
        let mut q = s.len() - 1;
        for x in (0..w).rev() {
            let c = s[q];
            row[x] = [ox + c, oy + sr[c as usize]];
            if x as i64 == t[q] && q > 0 {
                q -= 1;
            }
        }
    });
    Ok(out)
}

/// `f(x, i)`: the distance from column `x` of the row to the nearest seed of column `i`, whose
/// distance along its column is `g`.
#[inline]
fn envelope_f(metric: DistanceMetric, x: i64, i: u32, g: i64) -> i64 {
    let dx = (x - i64::from(i)).abs();
    match metric {
        DistanceMetric::Euclidean => dx * dx + g * g,
        DistanceMetric::Manhattan => dx + g,
        DistanceMetric::Chebyshev => dx.max(g),
    }
}

/// Meijster's `Sep(i, u)` for `i < u`: the last `x` at which column `i` is at least as near as
/// column `u` (floor division; `i64::MAX / 4` for "never", `i64::MIN / 4` for "nowhere").
#[inline]
fn separator(metric: DistanceMetric, i: u32, u: u32, gi: i64, gu: i64) -> i64 {
    let (i, u) = (i64::from(i), i64::from(u));
    match metric {
        DistanceMetric::Euclidean => (u * u - i * i + gu * gu - gi * gi).div_euclid(2 * (u - i)),
        DistanceMetric::Manhattan => {
            if gu >= gi + u - i {
                i64::MAX / 4
            } else if gi > gu + u - i {
                i64::MIN / 4
            } else {
                (gu - gi + u + i).div_euclid(2)
            }
        }
        DistanceMetric::Chebyshev => {
            if gi <= gu {
                (i + gu).max((i + u).div_euclid(2))
            } else {
                (u - gi).min((i + u).div_euclid(2))
            }
        }
    }
}
