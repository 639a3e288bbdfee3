//! Exact nearest-seed transforms on the CPU (Meijster, Roerdink and Hesselink 2000, "A general
//! algorithm for computing distance transforms in linear time"): for every column of an area,
//! a seed at the smallest distance under the Euclidean, Manhattan or Chebyshev metric, in two
//! separable phases of linear time. The alternative to jump flooding for CPU users
//! ([`super::DistanceTransform::Exact`]); jump flooding stays what the GPU runs.
//!
//! Phase 1 (per map column, swept row by row down then up): `g(x, y)`, the distance to the
//! nearest seed in the same column, and that seed's row. Phase 2 (per row, rows in parallel):
//! for each column `x` the column `i` minimising `f(x, i) = F(x - i, g(i))`, with `F` the metric
//! (`dx^2 + g^2`, `|dx| + g`, `max(|dx|, g)`). The row is cut at its own seeds (`g = 0`): no
//! column beyond one is nearer than it, so each stretch between them is solved alone, a short
//! one by comparing every column with every candidate, a long one by the lower envelope
//! (scanned left to right with the metric's separator, read back right to left). Integer
//! arithmetic throughout, so the distances are exact. Where several seeds are equally near,
//! the one returned follows two rules, both pinned by tests: along a column the seed above
//! wins, along the row the leftmost column.

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
/// run in parallel and the result does not depend on the thread count. Of several equally near
/// seeds it returns the one in the leftmost column, and of that column's the upper one.
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
    // fresh pages cost more than the sweeps), then each row's seeds after phase 2. Zeroed (the
    // allocator can hand out fresh zero pages without a fill): phase 1 writes every cell.
    let cells = pen.as_slice();
    let mut out =
        Grid::new(area.size.x, area.size.y, [0u32; 2]).map_err(|_| GranularError::TooLarge {
            side: area.size.max_element(),
            limit: super::MAX_SIDE,
        })?;
    // Phase 1: per column `g` (distance along the column) and the seed row (local), in bands
    // of `BAND` columns swept in parallel: each band gets its piece of every row.
    let mut bands: Vec<Vec<&mut [[u32; 2]]>> = (0..w.div_ceil(BAND))
        .map(|_| Vec::with_capacity(h))
        .collect();
    for row in out.as_mut_slice().chunks_mut(w) {
        for (band, piece) in bands.iter_mut().zip(row.chunks_mut(BAND)) {
            band.push(piece);
        }
    }
    let any_bad = std::sync::atomic::AtomicBool::new(false);
    crate::par::for_each_item(bands, |b, mut rows| {
        if sweep_columns(cells, w, b * BAND, (ox, oy), &mut rows) {
            any_bad.store(true, std::sync::atomic::Ordering::Relaxed);
        }
    });
    if any_bad.into_inner() {
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
    // Phase 2: per row (in parallel), the lower envelope of the columns that have a seed, with
    // per-thread scratch (every row overwrites what it reads of it).
    let o = (ox, oy);
    crate::par::for_each_chunk_init(
        out.as_mut_slice(),
        w,
        || Scratch::new(w),
        |sc, _, row| match metric {
            DistanceMetric::Euclidean => row_transform::<Euclid>(sc, o, row),
            DistanceMetric::Manhattan => row_transform::<Manhattan>(sc, o, row),
            DistanceMetric::Chebyshev => row_transform::<Chebyshev>(sc, o, row),
        },
    );
    Ok(out)
}

/// Columns a phase-1 band sweeps (its `last` seed rows stay in registers and L1).
const BAND: usize = 64;

/// Phase 1 over one band of columns starting at area column `x0`, given as its piece of every
/// row: `[g, seed row]` per cell, swept down then up, branch-free (selects instead of
/// data-dependent jumps; compiled for AVX2 too). Returns whether a seed names a column other
/// than its own.
#[multiversion::multiversion(targets("x86_64+avx2+fma"))]
fn sweep_columns(
    cells: &[Penetration],
    w: usize,
    x0: usize,
    (ox, oy): (u32, u32),
    rows: &mut [&mut [[u32; 2]]],
) -> bool {
    let bw = rows.first().map_or(0, |r| r.len()).min(BAND);
    let mut last = [NONE; BAND];
    let last = &mut last[..bw];
    let mut bad = false;
    for (y, orow) in rows.iter_mut().enumerate() {
        let row = &cells[y * w + x0..y * w + x0 + bw];
        for (x, ((p, o), last)) in row
            .iter()
            .zip(orow.iter_mut())
            .zip(last.iter_mut())
            .enumerate()
        {
            let is_seed = p.seed_x != NO_SEED;
            bad |= is_seed & ((p.seed_x != ox + (x0 + x) as u32) | (p.seed_y != oy + y as u32));
            *last = if is_seed { y as u32 } else { *last };
            let g = if *last == NONE {
                NONE
            } else {
                y as u32 - *last
            };
            *o = [g, *last];
        }
    }
    last.fill(NONE);
    for (y, orow) in rows.iter_mut().enumerate().rev() {
        for (o, last) in orow.iter_mut().zip(last.iter_mut()) {
            let [g, above] = *o;
            *last = if g == 0 { y as u32 } else { *last };
            let below = if *last == NONE {
                NONE
            } else {
                *last - y as u32
            };
            // Ties keep the seed above; either is as near.
            *o = if below < g {
                [below, *last]
            } else {
                [g, above]
            };
        }
    }
    bad
}

/// Per-thread stacks of phase 2's envelope.
struct Scratch {
    env_s: Vec<i64>,
    env_t: Vec<i64>,
    env_g: Vec<i64>,
    /// The seed row of each stack entry's column.
    env_r: Vec<u32>,
    /// Each stack entry's distance at the start of its segment.
    env_f: Vec<i64>,
}

impl Scratch {
    fn new(w: usize) -> Self {
        Self {
            env_s: vec![0; w],
            env_t: vec![0; w],
            env_g: vec![0; w],
            env_r: vec![0; w],
            env_f: vec![0; w],
        }
    }
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

/// A row seed (a column whose own row holds its seed, `g = 0`): its column in the row and its
/// seed row.
type RowSeed = Option<(usize, u32)>;

/// Stretches between row seeds up to this long are solved by comparing every column with
/// every candidate (at most `SMALL + 2` each); longer ones by the envelope.
const SMALL: usize = 16;

/// Phase 2 of one row, split at its row seeds: for a column between two of them, any column
/// beyond either is strictly farther than that one in every metric (`f(x, i) >= |x - i|`), so
/// each stretch between row seeds is solved alone, from its own columns and its two bounds.
/// Ties go to the leftmost candidate.
fn row_transform<M: Metric>(sc: &mut Scratch, o: (u32, u32), row: &mut [[u32; 2]]) {
    let w = row.len();
    let (mut x, mut left): (usize, RowSeed) = (0, None);
    while x < w {
        if row[x][0] == 0 {
            let r = row[x][1];
            row[x] = [o.0 + x as u32, o.1 + r];
            (x, left) = (x + 1, Some((x, r)));
            continue;
        }
        let start = x;
        x = next_row_seed(row, x);
        let right = (x < w).then(|| (x, row[x][1]));
        if x - start <= SMALL {
            stretch_by_comparison::<M>(o, row, start..x, left, right);
        } else {
            // The envelope reads its bounds from the row: the left one was already written.
            let lo = left.map_or(start, |(a, r)| {
                row[a] = [0, r];
                a
            });
            let hi = right.map_or(x, |(b, _)| b + 1);
            envelope::<M>(sc, (o.0 + lo as u32, o.1), &mut row[lo..hi]);
            // It wrote over its right bound too: restored, the loop's top takes it (column
            // `x`) as the row seed it is.
            if let Some((b, r)) = right {
                row[b] = [0, r];
            }
        }
    }
}

/// The first row seed at or after column `from` (the row's length if none).
fn next_row_seed(row: &[[u32; 2]], from: usize) -> usize {
    row[from..]
        .iter()
        .position(|c| c[0] == 0)
        .map_or(row.len(), |n| from + n)
}

/// A short stretch of columns between row seeds (`left` and `right`, either may be missing):
/// every column compared with the bounds and every column of the stretch with a seed.
fn stretch_by_comparison<M: Metric>(
    o: (u32, u32),
    row: &mut [[u32; 2]],
    cols: std::ops::Range<usize>,
    left: RowSeed,
    right: RowSeed,
) {
    // The stretch's input, copied before its output overwrites it.
    let mut seg = [[NONE; 2]; SMALL];
    let seg = &mut seg[..cols.len()];
    seg.copy_from_slice(&row[cols.clone()]);
    for x in cols.clone() {
        let xi = x as i64;
        let mut best = (i64::MAX, [NO_SEED; 2]);
        let mut consider = |i: usize, g: u32, r: u32| {
            let v = M::f(xi, i as i64, i64::from(g));
            if v < best.0 {
                best = (v, [o.0 + i as u32, o.1 + r]);
            }
        };
        if let Some((a, r)) = left {
            consider(a, 0, r);
        }
        for (i, &[g, r]) in cols.clone().zip(seg.iter()) {
            if g != NONE {
                consider(i, g, r);
            }
        }
        if let Some((b, r)) = right {
            consider(b, 0, r);
        }
        row[x] = best.1;
    }
}

/// Phase 2 of one row: the lower envelope of the columns with a seed (`g != NONE`), scanned
/// left to right from the row itself (each stack entry keeps its seed row and its distance
/// where its segment starts), then read back right to left into `row`.
fn envelope<M: Metric>(sc: &mut Scratch, (ox, oy): (u32, u32), row: &mut [[u32; 2]]) {
    let w = row.len();
    let (s, t, gs) = (&mut sc.env_s, &mut sc.env_t, &mut sc.env_g);
    let (sr, fs) = (&mut sc.env_r, &mut sc.env_f);
    let mut q: isize = -1;
    let m = w as i64;
    for (u, &[g, srow]) in row.iter().enumerate() {
        if g == NONE {
            continue;
        }
        let (u, gu) = (u as i64, i64::from(g));
        while q >= 0 {
            let k = q as usize;
            if fs[k] > M::f(t[k], u, gu) {
                q -= 1;
            } else {
                break;
            }
        }
        let k = if q < 0 {
            q = 0;
            (s[0], t[0]) = (u, 0);
            0
        } else {
            let k = q as usize;
            let wsep = 1 + M::sep(s[k], u, gs[k], gu);
            if wsep >= m {
                continue;
            }
            q += 1;
            (s[k + 1], t[k + 1]) = (u, wsep);
            k + 1
        };
        (gs[k], sr[k], fs[k]) = (gu, srow, M::f(t[k], u, gu));
    }
    if q < 0 {
        return;
    }
    // Read back right to left a segment at a time: segment `k` runs from `t[k]` to where the
    // one after it starts; the first (and any whose start is not left of that) to column 0.
    let (mut k, mut end) = (q as usize, w);
    loop {
        let tk = t[k];
        let start = if k > 0 && tk >= 0 && (tk as usize) < end {
            tk as usize
        } else {
            0
        };
        row[start..end].fill([ox + s[k] as u32, oy + sr[k]]);
        if start == 0 {
            break;
        }
        (k, end) = (k - 1, start);
    }
}

/// `f(x, i)`: the distance from column `x` of the row to the nearest seed of column `i`, whose
/// distance along its column is `g`.
#[inline(always)]
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
#[inline(always)]
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
