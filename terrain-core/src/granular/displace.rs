//! Displacing intersected material to the contour (Persson 2019, sec. 4.1.4): the iterative method
//! (listing 4.2), the closest-seed scatter (listing 4.4) and multiple targets (listing 4.5).
//!
//! Common rules. Inputs are the penetration texture and the seed grid of an area (grids of
//! `area.size`); heights are the map's, addressed in map coordinates. A penetrating column with
//! penetration `p` keeps `h - p` (the object's bottom) and displaces
//! `disp = floor(p * keep / 32768)` ([`super::mul_q15`], `keep = round((1 - compression) *
//! 32768)`); `p - disp` is removed and counted. Scatters are sums of u32 contributions
//! (wrapping adds, as GPU atomics), so the result does not depend on the order. Displaced
//! material only lands on seed columns (whose own seed is themselves), except where an area
//! has no seed at all: then it stays on its column.

use super::{ColumnKind, DistanceMetric, GranularError, NO_SEED, Penetration, check_area, mul_q15};
use crate::{FixedPointMap, Grid, Rect};

/// Penetration units per target of the multiple-targets method (listing 4.5: 1000, which is
/// 0.1 m at 10 000 units per metre).
pub const MULTI_TARGET_CHUNK: u32 = 1000;
/// Most targets one column spreads its material over (listing 4.5 has no bound).
pub const MAX_TARGETS: u32 = 64;

fn check_inputs(
    map: &FixedPointMap,
    pen: &Grid<Penetration>,
    seeds: &Grid<[u32; 2]>,
    area: Rect,
) -> Result<(), GranularError> {
    check_area(area, map.size())?;
    for g in [pen.size(), seeds.size()] {
        if g != area.size {
            return Err(GranularError::SizeMismatch {
                expected: area.size,
                actual: g,
            });
        }
    }
    Ok(())
}

/// Local index of a map coordinate inside `area`, or `None` outside it.
fn local(area: Rect, x: i64, y: i64) -> Option<usize> {
    let (i, j) = (x - i64::from(area.min.x), y - i64::from(area.min.y));
    if i < 0 || j < 0 || i >= i64::from(area.size.x) || j >= i64::from(area.size.y) {
        None
    } else {
        Some(j as usize * area.size.x as usize + i as usize)
    }
}

/// Copies the area's heights out of the map (the SSBO is initialised with zeros and each column
/// adds its own remaining height: the same sum).
fn area_heights(map: &FixedPointMap, area: Rect) -> Vec<u32> {
    let (ox, oy, w) = (area.min.x as u32, area.min.y as u32, area.size.x as usize);
    let mut out = Vec::with_capacity(area.area() as usize);
    for j in 0..area.size.y {
        out.extend_from_slice(&map.grid().row(oy + j)[ox as usize..ox as usize + w]);
    }
    out
}

fn write_back(map: &mut FixedPointMap, area: Rect, data: &[u32]) {
    let (ox, oy, w) = (area.min.x as u32, area.min.y as u32, area.size.x as usize);
    for j in 0..area.size.y {
        let src = &data[j as usize * w..(j as usize + 1) * w];
        map.grid_mut().row_mut(oy + j)[ox as usize..ox as usize + w].copy_from_slice(src);
    }
}

/// Method 2 (listing 4.4): every penetrating column with a seed adds `h - p` to itself and
/// `disp` to its seed; all other columns add their height to themselves. Returns the removed
/// amount.
pub fn displace_closest_seed(
    map: &mut FixedPointMap,
    pen: &Grid<Penetration>,
    seeds: &Grid<[u32; 2]>,
    area: Rect,
    keep_q15: u32,
) -> Result<u64, GranularError> {
    check_inputs(map, pen, seeds, area)?;
    let heights = area_heights(map, area);
    let mut acc = vec![0u32; heights.len()];
    let mut removed = 0u64;
    for (idx, (&h, p)) in heights.iter().zip(pen.as_slice()).enumerate() {
        let s = seeds.as_slice()[idx];
        let target = if p.column_kind() == ColumnKind::Penetrating && s[0] != NO_SEED {
            local(area, i64::from(s[0]), i64::from(s[1]))
        } else {
            None
        };
        match target {
            Some(t) => {
                let disp = mul_q15(p.penetration, keep_q15);
                removed += u64::from(p.penetration - disp);
                acc[idx] = acc[idx].wrapping_add(h - p.penetration);
                acc[t] = acc[t].wrapping_add(disp);
            }
            None => acc[idx] = acc[idx].wrapping_add(h),
        }
    }
    write_back(map, area, &acc);
    Ok(removed)
}

/// Method 3 (listing 4.5): a penetrating column with a seed splits `disp` over
/// `n = clamp(ceil(disp / MULTI_TARGET_CHUNK), 1, MAX_TARGETS)` targets
/// `t_i = seed + (dx * i / m, dy * i / m)`, `i = 0..n`, where `(dx, dy) = seed - column`,
/// `m = max(|dx|, |dy|)` and `/` truncates toward zero (so `t_0` is the seed and the march
/// continues away from the object). Target `i` gets `disp / n`, plus 1 if `i < disp % n`. The
/// march stops at the first target outside the area or not a seed column: its share and all
/// later ones go to the last valid target. Returns the removed amount.
pub fn displace_multiple_targets(
    map: &mut FixedPointMap,
    pen: &Grid<Penetration>,
    seeds: &Grid<[u32; 2]>,
    area: Rect,
    keep_q15: u32,
) -> Result<u64, GranularError> {
    check_inputs(map, pen, seeds, area)?;
    let heights = area_heights(map, area);
    let w = area.size.x as usize;
    let mut acc = vec![0u32; heights.len()];
    let mut removed = 0u64;
    let pens = pen.as_slice();
    for (idx, (&h, p)) in heights.iter().zip(pens).enumerate() {
        let s = seeds.as_slice()[idx];
        let seed_idx = if p.column_kind() == ColumnKind::Penetrating && s[0] != NO_SEED {
            local(area, i64::from(s[0]), i64::from(s[1]))
        } else {
            None
        };
        let Some(seed_idx) = seed_idx else {
            acc[idx] = acc[idx].wrapping_add(h);
            continue;
        };
        let disp = mul_q15(p.penetration, keep_q15);
        removed += u64::from(p.penetration - disp);
        acc[idx] = acc[idx].wrapping_add(h - p.penetration);
        let n = disp.div_ceil(MULTI_TARGET_CHUNK).clamp(1, MAX_TARGETS);
        let (base, rem) = (disp / n, disp % n);
        let cx = i64::from(area.min.x) + (idx % w) as i64;
        let cy = i64::from(area.min.y) + (idx / w) as i64;
        let (dx, dy) = (i64::from(s[0]) - cx, i64::from(s[1]) - cy);
        let m = dx.abs().max(dy.abs()).max(1);
        let mut last = seed_idx;
        let mut left = disp;
        for i in 0..i64::from(n) {
            let share = base + u32::from((i as u32) < rem);
            let t = local(
                area,
                i64::from(s[0]) + dx * i / m,
                i64::from(s[1]) + dy * i / m,
            )
            .filter(|&t| pens[t].column_kind() == ColumnKind::Seed);
            match t {
                Some(t) => {
                    acc[t] = acc[t].wrapping_add(share);
                    left -= share;
                    last = t;
                }
                None => break,
            }
        }
        acc[last] = acc[last].wrapping_add(left);
    }
    write_back(map, area, &acc);
    Ok(removed)
}

/// The receiver count of the iterative method (table 4.2 red channel): for each column, the
/// number of its 8 neighbours inside the area whose distance is strictly lower.
pub fn lower_neighbour_counts(dist: &Grid<u32>) -> Grid<u32> {
    let (w, h) = (dist.width() as i64, dist.height() as i64);
    let d = dist.as_slice();
    Grid::from_fn(dist.width(), dist.height(), |x, y| {
        let me = d[(i64::from(y) * w + i64::from(x)) as usize];
        let mut n = 0;
        for [ox, oy] in super::JFA_OFFSETS {
            let (nx, ny) = (i64::from(x) + i64::from(ox), i64::from(y) + i64::from(oy));
            if nx >= 0 && ny >= 0 && nx < w && ny < h && d[(ny * w + nx) as usize] < me {
                n += 1;
            }
        }
        n
    })
    .unwrap_or_else(|_| dist.map(|_| 0))
}

/// One iteration of the iterative method (listing 4.2), reading `carried` and writing `next`:
/// `next[c] = (n_c > 0 ? carried[c] % n_c : carried[c]) + sum over neighbours q with
/// dist[q] > dist[c] of carried[q] / n_q`.
pub fn iterative_pass(
    dist: &Grid<u32>,
    counts: &Grid<u32>,
    carried: &Grid<u32>,
    next: &mut Grid<u32>,
) {
    let (w, h) = (dist.width() as i64, dist.height() as i64);
    let (d, n, c) = (dist.as_slice(), counts.as_slice(), carried.as_slice());
    for y in 0..h {
        for x in 0..w {
            let me = (y * w + x) as usize;
            let mut v = if n[me] > 0 { c[me] % n[me] } else { c[me] };
            for [ox, oy] in super::JFA_OFFSETS {
                let (nx, ny) = (x + i64::from(ox), y + i64::from(oy));
                if nx < 0 || ny < 0 || nx >= w || ny >= h {
                    continue;
                }
                let q = (ny * w + nx) as usize;
                if d[q] > d[me] {
                    v = v.wrapping_add(c[q] / n[q]);
                }
            }
            next.as_mut_slice()[me] = v;
        }
    }
}

/// Calls `f(k, index)` for each of the 8 neighbours (`JFA_OFFSETS[k]`) of `(x, y)` inside a
/// `size` grid.
#[inline]
fn for_neighbours(size: (usize, usize), (x, y): (usize, usize), mut f: impl FnMut(usize, usize)) {
    let (w, h) = size;
    let rows = [y.checked_sub(1), Some(y), (y + 1 < h).then_some(y + 1)];
    let cols = [x.checked_sub(1), Some(x), (x + 1 < w).then_some(x + 1)];
    for (k, [ox, oy]) in super::JFA_OFFSETS.iter().enumerate() {
        if let (Some(ny), Some(nx)) = (rows[(oy + 1) as usize], cols[(ox + 1) as usize]) {
            f(k, ny * w + nx);
        }
    }
}

/// Method 1 (listing 4.2): penetrating columns drop to `h - p` and carry `disp`; `iterations`
/// [`iterative_pass`]es move carried material to neighbours closer to a seed (remainders
/// stay); finally each column's carried material is added to the column itself if it is a seed,
/// else to its seed (else, with no seed, to itself). Returns the removed amount.
pub fn displace_iterative(
    map: &mut FixedPointMap,
    pen: &Grid<Penetration>,
    seeds: &Grid<[u32; 2]>,
    area: Rect,
    keep_q15: u32,
    iterations: u32,
    metric: DistanceMetric,
) -> Result<u64, GranularError> {
    check_inputs(map, pen, seeds, area)?;
    let dist = super::distance_grid(seeds, area, metric);
    let (w, h) = (area.size.x as usize, area.size.y as usize);
    let d = dist.as_slice();
    // Per column, once: the receiver count (lower neighbours) and the mask of the higher
    // neighbours it gathers from (bit k: JFA_OFFSETS[k]).
    let mut counts = vec![0u32; w * h];
    let mut higher = vec![0u8; w * h];
    crate::par::for_each_chunk2(&mut counts, w, &mut higher, w, |y, crow, hrow| {
        for x in 0..w {
            let me = d[y * w + x];
            let (mut n, mut mask) = (0u32, 0u8);
            for_neighbours((w, h), (x, y), |k, q| {
                n += u32::from(d[q] < me);
                mask |= u8::from(d[q] > me) << k;
            });
            crow[x] = n;
            hrow[x] = mask;
        }
    });
    let mut heights = area_heights(map, area);
    let mut removed = 0u64;
    let mut carried = pen.map(|_| 0u32);
    for (idx, p) in pen.as_slice().iter().enumerate() {
        if p.column_kind() == ColumnKind::Penetrating {
            let disp = mul_q15(p.penetration, keep_q15);
            removed += u64::from(p.penetration - disp);
            heights[idx] -= p.penetration;
            carried.as_mut_slice()[idx] = disp;
        }
    }
    // Each iteration (listing 4.2): a column keeps `c % n` (all of it without receivers) and
    // gathers `c_q / n_q` from every higher neighbour q; wrapping sums, rows in parallel.
    let mut next = carried.clone();
    let mut share = vec![0u32; w * h];
    let mut keep = vec![0u32; w * h];
    for _ in 0..iterations {
        let c = carried.as_slice();
        crate::par::for_each_chunk2(&mut share, w, &mut keep, w, |y, srow, krow| {
            for x in 0..w {
                let (cv, n) = (c[y * w + x], counts[y * w + x]);
                (srow[x], krow[x]) = match (cv.checked_div(n), cv.checked_rem(n)) {
                    (Some(q), Some(r)) => (q, r),
                    _ => (0, cv),
                };
            }
        });
        let (share, keep, higher) = (&share, &keep, &higher);
        crate::par::for_each_chunk(next.as_mut_slice(), w, |y, row| {
            for (x, o) in row.iter_mut().enumerate() {
                let me = y * w + x;
                let mut v = keep[me];
                let mask = higher[me];
                if mask != 0 {
                    for_neighbours((w, h), (x, y), |k, q| {
                        if mask & (1 << k) != 0 {
                            v = v.wrapping_add(share[q]);
                        }
                    });
                }
                *o = v;
            }
        });
        std::mem::swap(&mut carried, &mut next);
    }
    for (idx, (&c, p)) in carried.as_slice().iter().zip(pen.as_slice()).enumerate() {
        if c == 0 {
            continue;
        }
        let s = seeds.as_slice()[idx];
        let t = if p.column_kind() == ColumnKind::Seed || s[0] == NO_SEED {
            idx
        } else {
            local(area, i64::from(s[0]), i64::from(s[1])).unwrap_or(idx)
        };
        heights[t] = heights[t].wrapping_add(c);
    }
    write_back(map, area, &heights);
    Ok(removed)
}
