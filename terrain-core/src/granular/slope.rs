//! Evening out steep slopes (Persson 2019, sec. 4.1.5, eq. 4.1-4.2, after Sumner et al.): material
//! moves from a column down to neighbours it is too steep above, never into non-seed columns.
//!
//! Outflow of a column `c` with height `h_c` (the same in both methods): its receivers are the
//! 8 neighbours `q` (in [`super::JFA_OFFSETS`] order) inside the area that are seed columns
//! of this step's penetration texture and with `dh_q = h_c - h_q > T` (`T` the orthogonal or
//! diagonal threshold of [`super::GranularParams::slope_thresholds_units`]). With `n`
//! receivers: `avg = sum(dh_q / n) + sum(dh_q % n) / n` (= `floor(sum dh_q / n)` without u32
//! overflow, eq. 4.2), each receiver gets `a = mul_q15(avg, roughness_q15) / n` and `c` loses
//! `n * a` (never more than `h_c`). Integer throughout, so the volume is exactly conserved.

use super::{ColumnKind, GranularError, JFA_OFFSETS, Penetration, check_area, mul_q15};
use crate::{FixedPointMap, Grid, Rect};

/// The outflow of one column: `(amount per receiver, receiver bit mask)`; bit `k` is
/// [`JFA_OFFSETS`]`[k]`.
pub fn column_outflow(
    heights: &[u32],
    pen: &[Penetration],
    size: (usize, usize),
    at: (usize, usize),
    thresholds: [u32; 2],
    roughness_q15: u32,
) -> (u32, u8) {
    let (w, h) = size;
    let (x, y) = at;
    let hc = heights[y * w + x];
    let mut mask = 0u8;
    let mut deltas = [0u32; 8];
    let mut n = 0u32;
    for (k, [ox, oy]) in JFA_OFFSETS.iter().enumerate() {
        let (nx, ny) = (x as i64 + i64::from(*ox), y as i64 + i64::from(*oy));
        if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
            continue;
        }
        let q = ny as usize * w + nx as usize;
        if pen[q].column_kind() != ColumnKind::Seed {
            continue;
        }
        let t = thresholds[usize::from(*ox != 0 && *oy != 0)];
        let hq = heights[q];
        if hc > hq && hc - hq > t {
            mask |= 1 << k;
            deltas[n as usize] = hc - hq;
            n += 1;
        }
    }
    if n == 0 {
        return (0, 0);
    }
    let ds = &deltas[..n as usize];
    let avg = ds.iter().map(|d| d / n).sum::<u32>() + ds.iter().map(|d| d % n).sum::<u32>() / n;
    let a = mul_q15(avg, roughness_q15) / n;
    if a == 0 { (0, 0) } else { (a, mask) }
}

/// The outflow of one column from its height and mask of receivers (see [`column_outflow`]).
#[inline]
fn outflow_of(hc: u32, mask: u8, hq: [u32; 8], roughness_q15: u32) -> (u32, u8) {
    if mask == 0 {
        return (0, 0);
    }
    let n = mask.count_ones();
    let (mut q, mut r) = (0u32, 0u32);
    for (k, &h) in hq.iter().enumerate() {
        if mask & (1 << k) != 0 {
            let d = hc - h;
            q += d / n;
            r += d % n;
        }
    }
    let a = mul_q15(q + r / n, roughness_q15) / n;
    if a == 0 { (0, 0) } else { (a, mask) }
}

/// What the outflow of every column of an area reads: its heights and seed flags (row-major,
/// `size.0` wide; `seed[q]` is 1 for seed columns), and the step's thresholds and roughness.
#[derive(Debug, Clone, Copy)]
struct OutflowInput<'a> {
    heights: &'a [u32],
    seed: &'a [u8],
    size: (usize, usize),
    thresholds: [u32; 2],
    roughness_q15: u32,
}

/// [`column_outflow`] for every column of row `y` into `(amount, mask)` rows, with the seed
/// test precomputed; `only_parity` limits senders to map parity `(x + y) & 1` (others get
/// `(0, 0)`). Interior columns take a branch-free path.
fn outflow_row(
    input: &OutflowInput<'_>,
    y: usize,
    only_parity: Option<(u32, i64)>,
    amount: &mut [u32],
    masks: &mut [u8],
) {
    let OutflowInput {
        heights,
        seed,
        size: (w, h),
        thresholds,
        roughness_q15,
    } = *input;
    let t: [u32; 8] = JFA_OFFSETS.map(|[ox, oy]| thresholds[usize::from(ox != 0 && oy != 0)]);
    let rows = [y.checked_sub(1), Some(y), (y + 1 < h).then_some(y + 1)];
    let here = &heights[y * w..(y + 1) * w];
    // Interior columns of interior rows: the receiver masks direction by direction over the
    // whole row (contiguous, vectorisable loops), then the amounts where a mask is set.
    let inner = if y >= 1 && y + 1 < h && w >= 3 {
        1..w - 1
    } else {
        0..0
    };
    if !inner.is_empty() {
        masks[inner.clone()].fill(0);
        for (k, &[ox, oy]) in JFA_OFFSETS.iter().enumerate() {
            let ny = (y as isize + oy as isize) as usize;
            let (a, b) = ((1 + ox) as usize, (w as isize - 1 + ox as isize) as usize);
            let hq = &heights[ny * w + a..ny * w + b];
            let sq = &seed[ny * w + a..ny * w + b];
            let tk = t[k];
            for (((m, &hc), &hq), &sq) in masks[inner.clone()]
                .iter_mut()
                .zip(&here[inner.clone()])
                .zip(hq)
                .zip(sq)
            {
                let steep = (sq != 0) & (hc > hq) & (hc.wrapping_sub(hq) > tk);
                *m |= u8::from(steep) << k;
            }
        }
    }
    for x in 0..w {
        let sender = match only_parity {
            Some((parity, base)) => ((base + x as i64 + y as i64) & 1) as u32 == parity,
            None => true,
        };
        let hc = here[x];
        let cols = [x.checked_sub(1), Some(x), (x + 1 < w).then_some(x + 1)];
        let mut hq = [0u32; 8];
        let mut mask = 0u8;
        if inner.contains(&x) {
            mask = masks[x];
            if mask != 0 {
                for (k, [ox, oy]) in JFA_OFFSETS.iter().enumerate() {
                    let q = (y as isize + *oy as isize) as usize * w
                        + (x as isize + *ox as isize) as usize;
                    hq[k] = heights[q];
                }
            }
        } else {
            for (k, [ox, oy]) in JFA_OFFSETS.iter().enumerate() {
                let (Some(ny), Some(nx)) = (rows[(oy + 1) as usize], cols[(ox + 1) as usize])
                else {
                    continue;
                };
                let q = ny * w + nx;
                hq[k] = heights[q];
                let steep = (seed[q] != 0) & (hc > hq[k]) & (hc.wrapping_sub(hq[k]) > t[k]);
                mask |= u8::from(steep) << k;
            }
        }
        (amount[x], masks[x]) = if sender {
            outflow_of(hc, mask, hq, roughness_q15)
        } else {
            (0, 0)
        };
    }
}

/// Gathers row `y` of the apply step: `h - popcount(mask) * a + sum of a_q over neighbours
/// q whose mask names this column` (wrapping adds, so equal to any scatter order).
fn gather_row(
    heights: &[u32],
    amount: &[u32],
    masks: &[u8],
    size: (usize, usize),
    y: usize,
    out: &mut [u32],
) {
    let (w, h) = size;
    let rows = [y.checked_sub(1), Some(y), (y + 1 < h).then_some(y + 1)];
    let r = y * w..(y + 1) * w;
    for ((o, &hv), (&a, &m)) in out
        .iter_mut()
        .zip(&heights[r.clone()])
        .zip(amount[r.clone()].iter().zip(&masks[r]))
    {
        *o = hv - a * m.count_ones();
    }
    // Interior columns of interior rows: direction by direction over the row (vectorisable).
    let inner = if y >= 1 && y + 1 < h && w >= 3 {
        1..w - 1
    } else {
        0..0
    };
    if !inner.is_empty() {
        for (k, &[ox, oy]) in JFA_OFFSETS.iter().enumerate() {
            let ny = (y as isize + oy as isize) as usize;
            let (a, b) = ((1 + ox) as usize, (w as isize - 1 + ox as isize) as usize);
            let qa = &amount[ny * w + a..ny * w + b];
            let qm = &masks[ny * w + a..ny * w + b];
            let shift = 7 - k;
            for ((o, &qa), &qm) in out[inner.clone()].iter_mut().zip(qa).zip(qm) {
                *o = o.wrapping_add(qa * u32::from((qm >> shift) & 1));
            }
        }
    }
    for x in (0..w).filter(|x| !inner.contains(x)) {
        let cols = [x.checked_sub(1), Some(x), (x + 1 < w).then_some(x + 1)];
        for (k, [ox, oy]) in JFA_OFFSETS.iter().enumerate() {
            let (Some(ny), Some(nx)) = (rows[(oy + 1) as usize], cols[(ox + 1) as usize]) else {
                continue;
            };
            let q = ny * w + nx;
            if masks[q] & (1 << (7 - k)) != 0 {
                out[x] = out[x].wrapping_add(amount[q]);
            }
        }
    }
}

fn seed_flags(pen: &[Penetration]) -> Vec<u8> {
    pen.iter()
        .map(|p| u8::from(p.column_kind() == ColumnKind::Seed))
        .collect()
}

fn check(map: &FixedPointMap, pen: &Grid<Penetration>, area: Rect) -> Result<(), GranularError> {
    check_area(area, map.size())?;
    if pen.size() != area.size {
        return Err(GranularError::SizeMismatch {
            expected: area.size,
            actual: pen.size(),
        });
    }
    Ok(())
}

fn read_area(map: &FixedPointMap, area: Rect) -> Vec<u32> {
    let (ox, oy, w) = (area.min.x as usize, area.min.y as u32, area.size.x as usize);
    (0..area.size.y)
        .flat_map(|j| map.grid().row(oy + j)[ox..ox + w].iter().copied())
        .collect()
}

fn write_area(map: &mut FixedPointMap, area: Rect, data: &[u32]) {
    let (ox, oy, w) = (area.min.x as usize, area.min.y as u32, area.size.x as usize);
    for j in 0..area.size.y {
        map.grid_mut().row_mut(oy + j)[ox..ox + w]
            .copy_from_slice(&data[j as usize * w..(j as usize + 1) * w]);
    }
}

/// Method 1, pass A (table 4.3): the amounts texture `(a, mask)` of the columns whose map
/// parity `(x + y) & 1` equals `parity` (others `(0, 0)`), read from `heights` only.
pub fn slope_amounts_pass(
    heights: &[u32],
    pen: &[Penetration],
    area: Rect,
    parity: u32,
    thresholds: [u32; 2],
    roughness_q15: u32,
    out: &mut [(u32, u8)],
) {
    let (w, h) = (area.size.x as usize, area.size.y as usize);
    let seed = seed_flags(pen);
    let base = i64::from(area.min.x) + i64::from(area.min.y);
    let mut amount = vec![0u32; w * h];
    let mut masks = vec![0u8; w * h];
    let input = OutflowInput {
        heights,
        seed: &seed,
        size: (w, h),
        thresholds,
        roughness_q15,
    };
    crate::par::for_each_chunk2(&mut amount, w, &mut masks, w, |y, a, m| {
        outflow_row(&input, y, Some((parity, base)), a, m)
    });
    for (o, (a, m)) in out.iter_mut().zip(amount.into_iter().zip(masks)) {
        *o = (a, m);
    }
}

/// Method 1, pass B: `new[c] = h[c] - popcount(mask_c) * a_c + sum of a_q over neighbours q
/// whose mask names c` (gathered; reads the amounts and old heights, writes `new`).
pub fn slope_apply_pass(heights: &[u32], amounts: &[(u32, u8)], area: Rect, new: &mut [u32]) {
    let (w, h) = (area.size.x as usize, area.size.y as usize);
    let amount: Vec<u32> = amounts.iter().map(|a| a.0).collect();
    let masks: Vec<u8> = amounts.iter().map(|a| a.1).collect();
    crate::par::for_each_chunk(new, w, |y, row| {
        gather_row(heights, &amount, &masks, (w, h), y, row)
    });
}

/// Method 1 (two interleaved programs): `iterations` times, for parity 0 then 1, an
/// amounts pass and an apply pass over `area`.
pub fn even_out_slopes_interleaved(
    map: &mut FixedPointMap,
    pen: &Grid<Penetration>,
    area: Rect,
    thresholds: [u32; 2],
    roughness_q15: u32,
    iterations: u32,
) -> Result<(), GranularError> {
    check(map, pen, area)?;
    let mut h = read_area(map, area);
    let mut next = h.clone();
    let mut amounts = vec![(0u32, 0u8); h.len()];
    for _ in 0..iterations {
        for parity in 0..2 {
            slope_amounts_pass(
                &h,
                pen.as_slice(),
                area,
                parity,
                thresholds,
                roughness_q15,
                &mut amounts,
            );
            slope_apply_pass(&h, &amounts, area, &mut next);
            std::mem::swap(&mut h, &mut next);
        }
    }
    write_area(map, area, &h);
    Ok(())
}

/// One scatter pass (method 2): every column adds `h - n * a` to itself and `a` to each
/// receiver in `acc`, all from the old heights. Computed as an outflow pass then a gather
/// (rows in parallel): the same wrapping sums as the scatter, in any order, so the same bits.
pub fn slope_scatter_pass(
    heights: &[u32],
    pen: &[Penetration],
    area: Rect,
    thresholds: [u32; 2],
    roughness_q15: u32,
    acc: &mut [u32],
) {
    let mut amount = vec![0u32; heights.len()];
    let mut masks = vec![0u8; heights.len()];
    scatter_pass_with(
        heights,
        &seed_flags(pen),
        area,
        thresholds,
        roughness_q15,
        (&mut amount, &mut masks),
        acc,
    );
}

fn scatter_pass_with(
    heights: &[u32],
    seed: &[u8],
    area: Rect,
    thresholds: [u32; 2],
    roughness_q15: u32,
    (amount, masks): (&mut [u32], &mut [u8]),
    acc: &mut [u32],
) {
    let (w, h) = (area.size.x as usize, area.size.y as usize);
    let input = OutflowInput {
        heights,
        seed,
        size: (w, h),
        thresholds,
        roughness_q15,
    };
    crate::par::for_each_chunk2(amount, w, masks, w, |y, a, m| {
        outflow_row(&input, y, None, a, m)
    });
    let (amount, masks) = (&*amount, &*masks);
    crate::par::for_each_chunk(acc, w, |y, row| {
        gather_row(heights, amount, masks, (w, h), y, row)
    });
}

/// Method 2 (SSBO): `iterations` [`slope_scatter_pass`]es over `area`.
pub fn even_out_slopes_scatter(
    map: &mut FixedPointMap,
    pen: &Grid<Penetration>,
    area: Rect,
    thresholds: [u32; 2],
    roughness_q15: u32,
    iterations: u32,
) -> Result<(), GranularError> {
    check(map, pen, area)?;
    let mut h = read_area(map, area);
    let mut acc = h.clone();
    let seed = seed_flags(pen.as_slice());
    let mut amount = vec![0u32; h.len()];
    let mut masks = vec![0u8; h.len()];
    for _ in 0..iterations {
        scatter_pass_with(
            &h,
            &seed,
            area,
            thresholds,
            roughness_q15,
            (&mut amount, &mut masks),
            &mut acc,
        );
        std::mem::swap(&mut h, &mut acc);
    }
    write_area(map, area, &h);
    Ok(())
}
