//! Jump flooding distance transform (Persson 2019, sec. 2.3.1, 4.1.4): the closest seed of every
//! column of an active area, with a hashed neighbour order, and a brute-force reference.
//!
//! Data: a grid of `[seed_x, seed_y]` in map coordinates ([`NO_SEED`] when none is known),
//! initialised from the penetration texture. Pass `p` with step `k` reads only the previous
//! pass's grid (ping-pong): for column `c`, the best starts as the column's own entry; then the
//! 8 offsets `(i, j) * k`, `i, j in {-1, 0, 1}` minus `(0, 0)`, are visited in the order
//! [`jfa_neighbour_order`]`(x, y, p)`; a neighbour inside the area whose seed is strictly closer
//! to `c` (per [`seed_distance`]) replaces the best, so ties keep the earlier candidate.
//! Steps are `2^(m-1), ..., 2, 1` with `2^m` the smallest power of two `>= max(w, h)` of the
//! area (`log2 n` passes), then one extra pass of step 1 when asked.

use glam::UVec2;

use super::{DistanceMetric, GranularError, NO_SEED, Penetration};
use crate::{Grid, Rect};

/// The 8 neighbour offsets in their base order, indexed by [`jfa_neighbour_order`].
pub const JFA_OFFSETS: [[i32; 2]; 8] = [
    [-1, -1],
    [0, -1],
    [1, -1],
    [-1, 0],
    [1, 0],
    [-1, 1],
    [0, 1],
    [1, 1],
];

/// The PCG hash (`pcg_hash` of Jarzynski and Olano 2020), u32 arithmetic with wrapping:
/// `s = v * 747796405 + 2891336453; w = ((s >> ((s >> 28) + 4)) ^ s) * 277803737;
/// (w >> 22) ^ w`.
pub fn pcg_hash(v: u32) -> u32 {
    let s = v.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let w = ((s >> ((s >> 28) + 4)) ^ s).wrapping_mul(277_803_737);
    (w >> 22) ^ w
}

/// The hash of a column and pass: `pcg(x + pcg(y + pcg(pass)))` (wrapping adds).
pub fn jfa_hash(x: u32, y: u32, pass: u32) -> u32 {
    pcg_hash(x.wrapping_add(pcg_hash(y.wrapping_add(pcg_hash(pass)))))
}

/// The visiting order of the 8 neighbours (indices into [`JFA_OFFSETS`]): a Fisher-Yates
/// shuffle of `0..8` driven by `h = jfa_hash(x, y, pass)`: for `i = 7` down to `1`, swap
/// `order[i]` with `order[h % (i + 1)]`, then `h = pcg_hash(h)`.
pub fn jfa_neighbour_order(x: u32, y: u32, pass: u32) -> [u8; 8] {
    let mut order = [0u8, 1, 2, 3, 4, 5, 6, 7];
    let mut h = jfa_hash(x, y, pass);
    for i in (1..8usize).rev() {
        let j = (h % (i as u32 + 1)) as usize;
        order.swap(i, j);
        h = pcg_hash(h);
    }
    order
}

/// The distance between a column and a seed under `metric` (Euclidean squared, so exact);
/// `u32::MAX` when `seed` is `NO_SEED`. Coordinates must be below [`super::MAX_SIDE`] apart.
#[inline]
pub fn seed_distance(metric: DistanceMetric, column: [u32; 2], seed: [u32; 2]) -> u32 {
    if seed[0] == NO_SEED {
        return u32::MAX;
    }
    let dx = column[0].abs_diff(seed[0]);
    let dy = column[1].abs_diff(seed[1]);
    match metric {
        DistanceMetric::Euclidean => dx * dx + dy * dy,
        DistanceMetric::Manhattan => dx + dy,
        DistanceMetric::Chebyshev => dx.max(dy),
    }
}

/// The step of every pass for an area of `size`: `log2 n` halving steps, then a 1 if `extra`.
pub fn jfa_steps(size: UVec2, extra: bool) -> Vec<u32> {
    let n = size.max_element().max(1).next_power_of_two();
    let mut steps = Vec::new();
    let mut k = n / 2;
    while k >= 1 {
        steps.push(k);
        k /= 2;
    }
    if extra {
        steps.push(1);
    }
    steps
}

/// The initial seed grid: each texel's `[seed_x, seed_y]` from the penetration texture.
pub fn jfa_init(pen: &Grid<Penetration>) -> Grid<[u32; 2]> {
    pen.map(|p| [p.seed_x, p.seed_y])
}

/// One jump flooding pass with step `step` and pass index `pass` over `area` (grids are of
/// `area.size`, indexed relative to `area.min`).
///
/// Rows run in parallel, a block of columns at a time over planar copies of the grids (see
/// [`jump_flood`], which keeps them planar from pass to pass). Each column finds its nearest
/// candidate among the 8; the hashed visiting order only decides between distinct seeds tied
/// at the smallest distance, so it is computed only then. The result is the one the
/// sequential visit in [`jfa_neighbour_order`] gives (strictly closer replaces, so the first
/// of the tied minima in that order wins, and only if it beats the column's own entry), bit
/// for bit.
pub fn jfa_pass(
    prev: &Grid<[u32; 2]>,
    next: &mut Grid<[u32; 2]>,
    area: Rect,
    step: u32,
    pass: u32,
    metric: DistanceMetric,
) -> Result<(), GranularError> {
    for g in [prev.size(), next.size()] {
        if g != area.size {
            return Err(GranularError::SizeMismatch {
                expected: area.size,
                actual: g,
            });
        }
    }
    let src = Planar::from_pairs(prev.as_slice().iter().copied());
    let mut dst = Planar::from_pairs(next.as_slice().iter().copied());
    planar_pass(&src, &mut dst, area, step, pass, metric);
    for (o, (&x, &y)) in next.as_mut_slice().iter_mut().zip(dst.x.iter().zip(&dst.y)) {
        *o = [x, y];
    }
    Ok(())
}

/// The sequential form of [`jfa_pass`] (each column visits its neighbours in
/// [`jfa_neighbour_order`] and keeps a strictly closer one), as the seed describes it and as
/// the GPU pass runs; kept as the reference the fast pass is tested against.
pub fn jfa_pass_reference(
    prev: &Grid<[u32; 2]>,
    next: &mut Grid<[u32; 2]>,
    area: Rect,
    step: u32,
    pass: u32,
    metric: DistanceMetric,
) -> Result<(), GranularError> {
    for g in [prev.size(), next.size()] {
        if g != area.size {
            return Err(GranularError::SizeMismatch {
                expected: area.size,
                actual: g,
            });
        }
    }
    let (w, h) = (area.size.x as i64, area.size.y as i64);
    let k = i64::from(step);
    let src = prev.as_slice();
    for j in 0..h {
        for i in 0..w {
            let gx = (area.min.x as i64 + i) as u32;
            let gy = (area.min.y as i64 + j) as u32;
            let col = [gx, gy];
            let mut best = src[(j * w + i) as usize];
            let mut best_d = seed_distance(metric, col, best);
            for o in jfa_neighbour_order(gx, gy, pass) {
                let [ox, oy] = JFA_OFFSETS[o as usize];
                let (ni, nj) = (i + i64::from(ox) * k, j + i64::from(oy) * k);
                if ni < 0 || nj < 0 || ni >= w || nj >= h {
                    continue;
                }
                let cand = src[(nj * w + ni) as usize];
                let d = seed_distance(metric, col, cand);
                if d < best_d {
                    best = cand;
                    best_d = d;
                }
            }
            next.as_mut_slice()[(j * w + i) as usize] = best;
        }
    }
    Ok(())
}

/// The whole jump flooding over `area`: [`jfa_init`], then [`jfa_pass`] for each of
/// [`jfa_steps`] with pass index `0, 1, ...`. Returns the closest seed per column.
pub fn jump_flood(
    pen: &Grid<Penetration>,
    area: Rect,
    metric: DistanceMetric,
    extra_pass: bool,
) -> Result<Grid<[u32; 2]>, GranularError> {
    check_side(area.size)?;
    if pen.size() != area.size {
        return Err(GranularError::SizeMismatch {
            expected: area.size,
            actual: pen.size(),
        });
    }
    // Planar x and y seed coordinates (two ping-pong pairs) so a row's candidates are plain
    // u32 lanes; the same passes as `jfa_pass`, bit for bit.
    let cells = pen.as_slice();
    let mut a = Planar::from_pairs(cells.iter().map(|p| [p.seed_x, p.seed_y]));
    let mut b = Planar {
        x: vec![0; cells.len()],
        y: vec![0; cells.len()],
    };
    for (pass, step) in jfa_steps(area.size, extra_pass).into_iter().enumerate() {
        planar_pass(&a, &mut b, area, step, pass as u32, metric);
        std::mem::swap(&mut a, &mut b);
    }
    let seeds = a.x.iter().zip(&a.y).map(|(&x, &y)| [x, y]).collect();
    Grid::from_vec(area.size.x, area.size.y, seeds).map_err(|_| GranularError::TooLarge {
        side: area.size.max_element(),
        limit: super::MAX_SIDE,
    })
}

/// A seed grid as two planes, `x` and `y`, row-major over the area.
struct Planar {
    x: Vec<u32>,
    y: Vec<u32>,
}

impl Planar {
    fn from_pairs(pairs: impl Iterator<Item = [u32; 2]> + Clone) -> Self {
        Self {
            x: pairs.clone().map(|p| p[0]).collect(),
            y: pairs.map(|p| p[1]).collect(),
        }
    }
}

/// [`seed_distance`] with the metric as a constant (0 Euclidean, 1 Manhattan, 2 Chebyshev),
/// branch-free, for vectorised loops.
#[inline(always)]
fn seed_distance_const<const METRIC: u8>(cx: u32, cy: u32, sx: u32, sy: u32) -> u32 {
    let (dx, dy) = (cx.abs_diff(sx), cy.abs_diff(sy));
    let d = match METRIC {
        0 => dx.wrapping_mul(dx).wrapping_add(dy.wrapping_mul(dy)),
        1 => dx.wrapping_add(dy),
        _ => dx.max(dy),
    };
    if sx == NO_SEED { u32::MAX } else { d }
}

/// Columns [`planar_row`] processes at once.
const JFA_BLOCK: usize = 64;

/// [`jfa_pass`] on planar grids (of `area.size`), rows in parallel.
fn planar_pass(
    prev: &Planar,
    next: &mut Planar,
    area: Rect,
    step: u32,
    pass: u32,
    metric: DistanceMetric,
) {
    match metric {
        DistanceMetric::Euclidean => planar_pass_for::<0>(prev, next, area, step, pass),
        DistanceMetric::Manhattan => planar_pass_for::<1>(prev, next, area, step, pass),
        DistanceMetric::Chebyshev => planar_pass_for::<2>(prev, next, area, step, pass),
    }
}

/// [`planar_pass`] for one metric (see [`seed_distance_const`]).
fn planar_pass_for<const METRIC: u8>(
    prev: &Planar,
    next: &mut Planar,
    area: Rect,
    step: u32,
    pass: u32,
) {
    let (w, h) = (area.size.x as usize, area.size.y as usize);
    let k = step as usize;
    let row_of = |r: usize| (&prev.x[r * w..(r + 1) * w], &prev.y[r * w..(r + 1) * w]);
    crate::par::for_each_chunk2(&mut next.x, w, &mut next.y, w, |j, ox, oy| {
        let gy = (i64::from(area.min.y) + j as i64) as u32;
        let rows = [
            j.checked_sub(k).map(row_of),
            Some(row_of(j)),
            (j + k < h).then(|| row_of(j + k)),
        ];
        planar_row::<METRIC>(rows, (ox, oy), area.min.x, gy, k, pass);
    });
}

/// One row of [`planar_pass`]: `rows` are the rows `k` above, at and `k` below (`None`
/// outside the area). A block of columns at a time, each of the 8 offsets in turn over the
/// block's columns (those whose candidate is inside the area) keeps the minimum, its first
/// candidate and whether another seed ties with it (reset whenever the minimum drops): what
/// `jfa_pass` computes per column; a tie is then broken per column in the hashed order.
/// Compiled for AVX2 too (integer operations only: the same bits).
#[multiversion::multiversion(targets("x86_64+avx2+fma"))]
fn planar_row<const METRIC: u8>(
    rows: [Option<(&[u32], &[u32])>; 3],
    (out_x, out_y): (&mut [u32], &mut [u32]),
    min_x: i32,
    gy: u32,
    k: usize,
    pass: u32,
) {
    let w = out_x.len();
    let col_x = |i: usize| (i64::from(min_x) + i as i64) as u32;
    // The candidate of offset `n` at column `i`, if inside the area.
    let cand = |n: usize, i: usize| -> Option<(u32, u32)> {
        let [ox, oy] = JFA_OFFSETS[n];
        let (rx, ry) = rows[(oy + 1) as usize]?;
        let c = (i as i64 + i64::from(ox) * k as i64) as usize;
        (c < w).then(|| (rx[c], ry[c]))
    };
    let Some(here) = rows[1] else {
        return;
    };
    // A column whose minimum (below its own entry's distance) is held by several distinct
    // seeds: the first of them in the hashed order, as `jfa_pass_reference` visits them.
    let tie = |i: usize| -> (u32, u32) {
        let gx = col_x(i);
        let mut cs = [(NO_SEED, NO_SEED); 8];
        let mut d = [u32::MAX; 8];
        for n in 0..8 {
            if let Some((sx, sy)) = cand(n, i) {
                cs[n] = (sx, sy);
                d[n] = seed_distance_const::<METRIC>(gx, gy, sx, sy);
            }
        }
        let m = d.iter().copied().min().unwrap_or(u32::MAX);
        jfa_neighbour_order(gx, gy, pass)
            .into_iter()
            .map(usize::from)
            .find(|&n| d[n] == m)
            .map_or((here.0[i], here.1[i]), |n| cs[n])
    };
    for i0 in (0..w).step_by(JFA_BLOCK) {
        let len = (w - i0).min(JFA_BLOCK);
        let x0 = col_x(i0);
        let mut m = [u32::MAX; JFA_BLOCK];
        let (mut bx, mut by) = ([NO_SEED; JFA_BLOCK], [NO_SEED; JFA_BLOCK]);
        let mut tied = [0u32; JFA_BLOCK];
        let cols: [u32; JFA_BLOCK] = std::array::from_fn(|t| x0.wrapping_add(t as u32));
        for [ox, oy] in JFA_OFFSETS {
            // A candidate outside the area is never closer, never tied at a minimum that
            // beats the column's own entry: its lanes are skipped.
            let Some((px, py)) = rows[(oy + 1) as usize] else {
                continue;
            };
            let shift = i64::from(ox) * k as i64;
            let lo = (-(i0 as i64) - shift).clamp(0, len as i64) as usize;
            let hi = (w as i64 - i0 as i64 - shift).clamp(lo as i64, len as i64) as usize;
            if lo == hi {
                continue;
            }
            let start = (i0 as i64 + lo as i64 + shift) as usize;
            let n = hi - lo;
            let lanes = m[lo..hi]
                .iter_mut()
                .zip(&mut bx[lo..hi])
                .zip(&mut by[lo..hi])
                .zip(&mut tied[lo..hi])
                .zip(px[start..start + n].iter().zip(&py[start..start + n]))
                .zip(&cols[lo..hi]);
            for (((((m, bx), by), tied), (&sx, &sy)), &cx) in lanes {
                let d = seed_distance_const::<METRIC>(cx, gy, sx, sy);
                let (less, same) = (d < *m, d == *m);
                let other = (sx != *bx) | (sy != *by);
                *tied = if less {
                    0
                } else {
                    *tied | u32::from(same & other)
                };
                *m = if less { d } else { *m };
                *bx = if less { sx } else { *bx };
                *by = if less { sy } else { *by };
            }
        }
        let (own_x, own_y) = (&here.0[i0..i0 + len], &here.1[i0..i0 + len]);
        for t in 0..len {
            let own_d = seed_distance_const::<METRIC>(cols[t], gy, own_x[t], own_y[t]);
            let (x, y) = if m[t] >= own_d {
                (own_x[t], own_y[t])
            } else if tied[t] == 0 {
                (bx[t], by[t])
            } else {
                tie(i0 + t)
            };
            (out_x[i0 + t], out_y[i0 + t]) = (x, y);
        }
    }
}

/// [`jump_flood`] with [`jfa_pass_reference`]: the sequential form, for tests and benches.
pub fn jump_flood_reference(
    pen: &Grid<Penetration>,
    area: Rect,
    metric: DistanceMetric,
    extra_pass: bool,
) -> Result<Grid<[u32; 2]>, GranularError> {
    check_side(area.size)?;
    let mut a = jfa_init(pen);
    let mut b = a.clone();
    for (pass, step) in jfa_steps(area.size, extra_pass).into_iter().enumerate() {
        jfa_pass_reference(&a, &mut b, area, step, pass as u32, metric)?;
        std::mem::swap(&mut a, &mut b);
    }
    Ok(a)
}

/// The exact distance to the nearest seed of every column of `area` by brute force
/// (`u32::MAX` where the area has no seed). For tests and error tables.
pub fn brute_force_distance(
    pen: &Grid<Penetration>,
    area: Rect,
    metric: DistanceMetric,
) -> Grid<u32> {
    let seeds: Vec<[u32; 2]> = pen
        .as_slice()
        .iter()
        .filter(|p| p.seed_x != NO_SEED)
        .map(|p| [p.seed_x, p.seed_y])
        .collect();
    Grid::from_fn(area.size.x, area.size.y, |i, j| {
        let col = [area.min.x as u32 + i, area.min.y as u32 + j];
        seeds
            .iter()
            .map(|&s| seed_distance(metric, col, s))
            .min()
            .unwrap_or(u32::MAX)
    })
    .unwrap_or_else(|_| pen.map(|_| u32::MAX))
}

/// The distance grid of a seed grid over `area` (`u32::MAX` where no seed is known).
pub fn distance_grid(seeds: &Grid<[u32; 2]>, area: Rect, metric: DistanceMetric) -> Grid<u32> {
    let w = area.size.x.max(1) as usize;
    let mut out = seeds.map(|_| 0u32);
    let src = seeds.as_slice();
    crate::par::for_each_chunk(out.as_mut_slice(), w, |j, row| {
        let y = area.min.y as u32 + j as u32;
        for (i, d) in row.iter_mut().enumerate() {
            *d = seed_distance(metric, [area.min.x as u32 + i as u32, y], src[j * w + i]);
        }
    });
    out
}

pub(crate) fn check_side(size: UVec2) -> Result<(), GranularError> {
    let side = size.max_element();
    if side > super::MAX_SIDE {
        return Err(GranularError::TooLarge {
            side,
            limit: super::MAX_SIDE,
        });
    }
    Ok(())
}
