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
    // The output grid holds `[g, seed row]` after phase 1 (no other buffer of the area's size:
    // fresh pages cost more than the sweeps), then each row's seeds after phase 2.
    let cells = pen.as_slice();
    let mut out =
        Grid::new(area.size.x, area.size.y, [NONE; 2]).map_err(|_| GranularError::TooLarge {
            side: area.size.max_element(),
            limit: super::MAX_SIDE,
        })?;
    // Phase 1: per column `g` (distance along the column) and the seed row (local), swept down
    // then up, branch-free (selects instead of data-dependent jumps).
    let o = out.as_mut_slice();
    let mut last = vec![NONE; w];
    let mut any_bad = false;
    for y in 0..h {
        let row = &cells[y * w..(y + 1) * w];
        let orow = &mut o[y * w..(y + 1) * w];
        for (x, (p, o)) in row.iter().zip(orow.iter_mut()).enumerate() {
            let is_seed = p.seed_x != NO_SEED;
            any_bad |= is_seed & ((p.seed_x != ox + x as u32) | (p.seed_y != oy + y as u32));
            last[x] = if is_seed { y as u32 } else { last[x] };
            let g = if last[x] == NONE {
                NONE
            } else {
                y as u32 - last[x]
            };
            *o = [g, last[x]];
        }
    }
    if any_bad {
        let i = cells
            .iter()
            .enumerate()
            .position(|(i, p)| {
                p.seed_x != NO_SEED
                    && [p.seed_x, p.seed_y] != [ox + (i % w) as u32, oy + (i / w) as u32]
            })
            .unwrap_or(0);
        return Err(GranularError::SeedNotAtColumn {
            column: [ox + (i % w) as u32, oy + (i / w) as u32],
            seed: [cells[i].seed_x, cells[i].seed_y],
        });
    }
    last.fill(NONE);
    for y in (0..h).rev() {
        for (x, o) in o[y * w..(y + 1) * w].iter_mut().enumerate() {
            let [g, above] = *o;
            last[x] = if g == 0 { y as u32 } else { last[x] };
            let below = if last[x] == NONE {
                NONE
            } else {
                last[x] - y as u32
            };
            // Ties keep the seed above; either is as near.
            *o = if below < g {
                [below, last[x]]
            } else {
                [g, above]
            };
        }
    }
    // Phase 2: per row (in parallel), the lower envelope of the columns that have a seed.
    crate::par::for_each_chunk(out.as_mut_slice(), w, |_, row| {
        let gr: Vec<u32> = row.iter().map(|v| v[0]).collect();
        let sr: Vec<u32> = row.iter().map(|v| v[1]).collect();
        let o = (ox, oy);
        match metric {
            DistanceMetric::Euclidean => row_transform::<Euclid>(&gr, &sr, w, o, row),
            DistanceMetric::Manhattan => row_transform::<Manhattan>(&gr, &sr, w, o, row),
            DistanceMetric::Chebyshev => row_transform::<Chebyshev>(&gr, &sr, w, o, row),
        }
    });
    Ok(out)
}

/// A metric of phase 2: `f(x, i)` and Meijster's separator (monomorphised per metric).
trait Metric {
    fn f(x: i64, i: i64, g: i64) -> i64;
    fn sep(i: i64, u: i64, gi: i64, gu: i64) -> i64;
}

struct Euclid;
struct Manhattan;
struct Chebyshev;

impl Metric for Euclid {
    #[inline(always)]
    fn f(x: i64, i: i64, g: i64) -> i64 {
        envelope_f(DistanceMetric::Euclidean, x, i as u32, g)
    }
    #[inline(always)]
    fn sep(i: i64, u: i64, gi: i64, gu: i64) -> i64 {
        separator(DistanceMetric::Euclidean, i as u32, u as u32, gi, gu)
    }
}

impl Metric for Manhattan {
    #[inline(always)]
    fn f(x: i64, i: i64, g: i64) -> i64 {
        envelope_f(DistanceMetric::Manhattan, x, i as u32, g)
    }
    #[inline(always)]
    fn sep(i: i64, u: i64, gi: i64, gu: i64) -> i64 {
        separator(DistanceMetric::Manhattan, i as u32, u as u32, gi, gu)
    }
}

impl Metric for Chebyshev {
    #[inline(always)]
    fn f(x: i64, i: i64, g: i64) -> i64 {
        envelope_f(DistanceMetric::Chebyshev, x, i as u32, g)
    }
    #[inline(always)]
    fn sep(i: i64, u: i64, gi: i64, gu: i64) -> i64 {
        separator(DistanceMetric::Chebyshev, i as u32, u as u32, gi, gu)
    }
}

/// Phase 2 of one row. Where the row's seed columns are near (the windows below cost at most
/// a few times the row), each column `x` scans only `[x - g(x), x + g(x)]`: a nearer seed
/// column `i` needs `f(x, i) <= f(x, x) = g(x)`-ish, which for all three metrics implies
/// `|x - i| <= g(x)`. Otherwise the linear-time envelope.
fn row_transform<M: Metric>(gr: &[u32], sr: &[u32], w: usize, o: (u32, u32), row: &mut [[u32; 2]]) {
    let mut cost = 0usize;
    for &g in gr {
        if g == NONE {
            return envelope::<M>(gr, sr, w, o, row);
        }
        cost += 2 * (g as usize).min(w) + 1;
    }
    if cost > 4 * w {
        return envelope::<M>(gr, sr, w, o, row);
    }
    for (x, out) in row.iter_mut().enumerate() {
        let gx = gr[x];
        let mut best_i = x;
        if gx > 0 {
            let xi = x as i64;
            let mut best = M::f(xi, xi, i64::from(gx));
            let r = gx as usize;
            let lo = x.saturating_sub(r);
            for (i, &gi) in gr.iter().enumerate().take((x + r + 1).min(w)).skip(lo) {
                let v = M::f(xi, i as i64, i64::from(gi));
                if v < best {
                    best = v;
                    best_i = i;
                }
            }
        }
        *out = [o.0 + best_i as u32, o.1 + sr[best_i]];
    }
}

/// Phase 2 of one row: the lower envelope of the columns with a seed (`gr[i] != NONE`),
/// scanned left to right, then read back right to left into `row`.
fn envelope<M: Metric>(
    gr: &[u32],
    sr: &[u32],
    w: usize,
    (ox, oy): (u32, u32),
    row: &mut [[u32; 2]],
) {
    let mut s = vec![0i64; w];
    let mut t = vec![0i64; w];
    let mut gs = vec![0i64; w];
    let mut q: isize = -1;
    let m = w as i64;
    for (u, &g) in gr.iter().enumerate() {
        if g == NONE {
            continue;
        }
        let (u, gu) = (u as i64, i64::from(g));
        while q >= 0 {
            let k = q as usize;
            if M::f(t[k], s[k], gs[k]) > M::f(t[k], u, gu) {
                q -= 1;
            } else {
                break;
            }
        }
        if q < 0 {
            q = 0;
            (s[0], t[0], gs[0]) = (u, 0, gu);
        } else {
            let k = q as usize;
            let wsep = 1 + M::sep(s[k], u, gs[k], gu);
            if wsep < m {
                q += 1;
                let k = q as usize;
                (s[k], t[k], gs[k]) = (u, wsep, gu);
            }
        }
    }
    if q < 0 {
        return;
    }
    let mut k = q as usize;
    for x in (0..w).rev() {
        let c = s[k] as usize;
        row[x] = [ox + c as u32, oy + sr[c]];
        if x as i64 == t[k] && k > 0 {
            k -= 1;
        }
    }
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
        // Equal column distances (every seed column of a dense mask): the midpoint, no division.
        DistanceMetric::Euclidean if gi == gu => (u + i) >> 1,
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
