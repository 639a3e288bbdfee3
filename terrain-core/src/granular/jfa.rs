//! Jump flooding distance transform (seed 001 sec 2.3.1, 4.1.4): the closest seed of every
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
/// Rows run in parallel. Each column first computes all 8 candidates' distances; the hashed
/// visiting order only decides between distinct seeds tied at the smallest distance, so it is
/// computed only then. The result is the one the sequential visit in
/// [`jfa_neighbour_order`] gives (strictly closer replaces, so the first of the tied minima in
/// that order wins, and only if it beats the column's own entry), bit for bit.
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
    let (w, h) = (area.size.x as usize, area.size.y as usize);
    let k = step as usize;
    let src = prev.as_slice();
    crate::par::for_each_chunk(next.as_mut_slice(), w, |j, out| {
        let gy = (i64::from(area.min.y) + j as i64) as u32;
        let rows: [Option<&[[u32; 2]]>; 3] = [
            j.checked_sub(k).map(|r| &src[r * w..(r + 1) * w]),
            Some(&src[j * w..(j + 1) * w]),
            (j + k < h).then(|| &src[(j + k) * w..(j + k + 1) * w]),
        ];
        let full_rows = match rows {
            [Some(a), Some(b), Some(c)] => Some([a, b, c]),
            _ => None,
        };
        for (i, o) in out.iter_mut().enumerate() {
            let gx = (i64::from(area.min.x) + i as i64) as u32;
            let col = [gx, gy];
            let mut cand = [[NO_SEED; 2]; 8];
            let own;
            match full_rows {
                // Interior: all 8 candidates exist; no bounds tests.
                Some(r) if i >= k && i + k < w => {
                    own = r[1][i];
                    let cs = [i - k, i, i + k];
                    for (n, [ox, oy]) in JFA_OFFSETS.iter().enumerate() {
                        cand[n] = r[(oy + 1) as usize][cs[(ox + 1) as usize]];
                    }
                }
                _ => {
                    own = rows[1].map_or([NO_SEED; 2], |r| r[i]);
                    let cols = [i.checked_sub(k), Some(i), (i + k < w).then_some(i + k)];
                    for (n, [ox, oy]) in JFA_OFFSETS.iter().enumerate() {
                        if let (Some(r), Some(c)) =
                            (rows[(oy + 1) as usize], cols[(ox + 1) as usize])
                        {
                            cand[n] = r[c];
                        }
                    }
                }
            }
            let own_d = seed_distance(metric, col, own);
            let mut d = [u32::MAX; 8];
            for n in 0..8 {
                d[n] = seed_distance(metric, col, cand[n]);
            }
            let m = d.iter().copied().min().unwrap_or(u32::MAX);
            if m >= own_d {
                *o = own;
                continue;
            }
            // Branch-free: the first candidate at distance m, and whether another seed ties.
            let mut first = 7;
            for n in (0..8).rev() {
                first = if d[n] == m { n } else { first };
            }
            let mut tied = false;
            for n in 0..8 {
                tied |= (d[n] == m) & (cand[n] != cand[first]);
            }
            let pick = if tied {
                jfa_neighbour_order(gx, gy, pass)
                    .into_iter()
                    .map(usize::from)
                    .find(|&n| d[n] == m)
            } else {
                Some(first)
            };
            *o = pick.map_or(own, |n| cand[n]);
        }
    });
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
    let mut a = jfa_init(pen);
    let mut b = a.clone();
    for (pass, step) in jfa_steps(area.size, extra_pass).into_iter().enumerate() {
        jfa_pass(&a, &mut b, area, step, pass as u32, metric)?;
        std::mem::swap(&mut a, &mut b);
    }
    Ok(a)
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
