//! Building and updating a [`TessHierarchy`]: the true height, saturated sphere radius,
//! density and error of every grid vertex (each vertex's bounds cover its descendants', so
//! the split decisions stay nested), and the patches' height bounds, recomputed only around a
//! changed rect after a deformation.

use super::{MAX_GRID_SIDE, TessConfig, TessHierarchy};
use crate::density::DensityMap;
use crate::error::LodError;
use glam::{IVec2, UVec2};
use terrain_core::{HeightMap, HeightSample, Rect, WrapMode};

impl TessHierarchy {
    /// The hierarchy of `map` with the densities of `density` (or 1 everywhere without one).
    ///
    /// Fails on a bad config, a density map made for another size, or a grid too large to
    /// address (sides past 2^30 vertices) or to allocate (16 bytes per vertex).
    pub fn from_map<T: HeightSample>(
        map: &HeightMap<T>,
        density: Option<&DensityMap>,
        config: TessConfig,
    ) -> Result<Self, LodError> {
        config.validate()?;
        let size = map.size();
        let ps = config.patch_size;
        let tiles = map.wrap() == WrapMode::Repeat
            && size.x.is_multiple_of(ps)
            && size.y.is_multiple_of(ps);
        let (patches, grid, grid_wrap) = if tiles {
            (size / ps, size, WrapMode::Repeat)
        } else {
            // Clamped: the cells between texels; repeating: one period of texels, the vertex
            // after the last being the first's copy.
            let cells = match map.wrap() {
                WrapMode::Repeat => size.as_u64vec2(),
                WrapMode::Clamp => (size.max(UVec2::splat(2)) - 1).as_u64vec2(),
            };
            let patches = UVec2::new(
                cells.x.div_ceil(u64::from(ps)) as u32,
                cells.y.div_ceil(u64::from(ps)) as u32,
            );
            let side = |p: u32| u64::from(p) * u64::from(ps) + 1;
            let (w, h) = (side(patches.x), side(patches.y));
            if w.max(h) > MAX_GRID_SIDE {
                return Err(LodError::Core(terrain_core::CoreError::GridTooLarge {
                    width: w.min(u64::from(u32::MAX)) as u32,
                    height: h.min(u64::from(u32::MAX)) as u32,
                }));
            }
            (patches, UVec2::new(w as u32, h as u32), WrapMode::Clamp)
        };
        if u64::from(grid.max_element()) > MAX_GRID_SIDE {
            return Err(LodError::Core(terrain_core::CoreError::GridTooLarge {
                width: grid.x,
                height: grid.y,
            }));
        }
        if let Some(d) = density
            && d.map_size() != size
        {
            return Err(LodError::SizeMismatch {
                expected: size,
                actual: d.map_size(),
            });
        }
        let count = grid.x as usize * grid.y as usize;
        let too_large = || {
            LodError::Core(terrain_core::CoreError::GridTooLarge {
                width: grid.x,
                height: grid.y,
            })
        };
        let mut heights = Vec::new();
        heights.try_reserve_exact(count).map_err(|_| too_large())?;
        heights.resize(count, 0.0);
        let mut bounds = Vec::new();
        bounds.try_reserve_exact(count).map_err(|_| too_large())?;
        bounds.resize(count, [0.0; 3]);
        let mut out = Self {
            config,
            map_size: size,
            wrap: map.wrap(),
            grid_wrap,
            texel_size: map.texel_size(),
            p: ps.trailing_zeros(),
            patches,
            grid,
            heights,
            bounds,
            patch_bounds: vec![[0.0, 0.0]; patches.x as usize * patches.y as usize],
            density_reach: density.map_or(0, |d| {
                (d.params().filter_radii().1 + 2) * crate::density::DENSITY_DOWNSAMPLE
            }),
        };
        out.refresh(map, density, IVec2::ZERO, grid.as_ivec2() - 1);
        Ok(out)
    }

    /// Brings the bounds up to date with `map` (and `density`, already updated) after a height
    /// change inside `dirty` (texels; wrapped on a repeating map). The result equals
    /// [`TessHierarchy::from_map`] of the changed map. Returns the grid rows whose vertices it
    /// may have changed (a few ranges; none for an empty rect), for a GPU copy to follow.
    pub fn update_rect<T: HeightSample>(
        &mut self,
        map: &HeightMap<T>,
        density: Option<&DensityMap>,
        dirty: Rect,
    ) -> Result<Vec<std::ops::Range<u32>>, LodError> {
        if map.size() != self.map_size {
            return Err(LodError::SizeMismatch {
                expected: self.map_size,
                actual: map.size(),
            });
        }
        if dirty.is_empty() {
            return Ok(Vec::new());
        }
        let reach = if density.is_some() {
            self.density_reach
        } else {
            0
        };
        let r = dirty.expand(reach);
        let g = self.grid.as_ivec2() - 1;
        // The changed vertices as rects of the grid: the rect itself on a grid that wraps as
        // the map; otherwise clamped to the grid, with each copy of it a repeating map's
        // period further (a repeating map drawn past its side).
        let mut pieces = Vec::new();
        let n = self.map_size.as_ivec2();
        match (self.grid_wrap, self.wrap) {
            (WrapMode::Repeat, _) => {
                // One period at most, starting inside the map (so no margin overflows).
                let lo = r.min.rem_euclid(n);
                let size = r.size.min(self.map_size).as_ivec2();
                pieces.push((lo, lo + size - 1));
            }
            (WrapMode::Clamp, WrapMode::Clamp) => {
                let last = self.map_size.as_ivec2() - 1;
                let (lo, hi) = (r.min.max(IVec2::ZERO), r.max() - 1);
                // Vertices past the map's last texel repeat it.
                let hi = IVec2::new(
                    if hi.x >= last.x { g.x } else { hi.x },
                    if hi.y >= last.y { g.y } else { hi.y },
                )
                .min(g);
                pieces.push((lo, hi));
            }
            (WrapMode::Clamp, WrapMode::Repeat) => {
                // The grid holds `g / n + 1` copies of the map along each axis.
                let copies = g / n + 1;
                for piece in r.split_toroidal(self.map_size) {
                    let (lo, hi) = (piece.map.min, piece.map.max() - 1);
                    for ky in 0..copies.y {
                        for kx in 0..copies.x {
                            let k = IVec2::new(kx, ky) * n;
                            pieces.push(((lo + k).min(g + 1), (hi + k).min(g)));
                        }
                    }
                }
            }
        }
        pieces.retain(|(lo, hi)| lo.cmple(*hi).all());
        // Pieces whose windows (reaching `3 P / 2` further) meet are refreshed as one: a small
        // repeating map's copies would otherwise each refresh most of the grid.
        let reach = 3 * (self.config.patch_size as i32 / 2);
        let mut merged: Vec<(IVec2, IVec2)> = Vec::new();
        for (lo, hi) in pieces {
            let (mut lo, mut hi) = (lo, hi);
            while let Some(i) = merged.iter().position(|&(a, b)| {
                (lo - 2 * reach).cmple(b).all() && (hi + 2 * reach).cmpge(a).all()
            }) {
                let (a, b) = merged.swap_remove(i);
                (lo, hi) = (lo.min(a), hi.max(b));
            }
            merged.push((lo, hi));
        }
        let pieces = merged;
        let mut ranges: Vec<std::ops::Range<u32>> = Vec::new();
        for (lo, hi) in pieces {
            self.refresh(map, density, lo, hi);
            // The coarsest vertices read `3 P / 2` rows either side (see `refresh`).
            for y in axis(lo.y - reach, hi.y + reach, 1, g.y + 1, self.grid_wrap) {
                let y = y as u32;
                match ranges.iter_mut().find(|r| r.contains(&y) || r.end == y) {
                    Some(r) => r.end = r.end.max(y + 1),
                    None => ranges.push(y..y + 1),
                }
            }
        }
        Ok(ranges)
    }

    /// Recomputes heights, bounds and patch bounds of everything the grid vertices `lo ..= hi`
    /// (unwrapped on a repeating map, clamped to the grid otherwise) reach.
    fn refresh<T: HeightSample>(
        &mut self,
        map: &HeightMap<T>,
        density: Option<&DensityMap>,
        lo: IVec2,
        hi: IVec2,
    ) {
        let enc = map.encoding();
        let gx = self.grid.x as usize;
        let g = self.grid.as_ivec2();
        let cols = axis(lo.x, hi.x, 1, g.x, self.grid_wrap);
        for y in axis(lo.y, hi.y, 1, g.y, self.grid_wrap) {
            for &x in &cols {
                let t = self.texel_of(IVec2::new(x, y));
                let raw = map
                    .grid()
                    .get(t.x as u32, t.y as u32)
                    .map_or(0.0, |s| s.to_raw_f64() as f32);
                // As the GPU computes it: offset + scale * stored, in f32.
                self.heights[y as usize * gx + x as usize] = enc.offset + enc.scale * raw;
            }
        }
        // Bounds level by level, finest first: every vertex reads only finer ones. The
        // descendants of a vertex whose edge is `2s` long reach `s + s / 2 + R(s / 2)`, under
        // `3s`, from it (its children are shared with the neighbouring diamonds).
        for tz in 0..self.p {
            let s = 1i32 << tz;
            let g = self.grid.as_ivec2();
            let xs = axis(lo.x - 3 * s, hi.x + 3 * s, s, g.x, self.grid_wrap);
            let ys = axis(lo.y - 3 * s, hi.y + 3 * s, s, g.y, self.grid_wrap);
            for odd_both in [false, true] {
                // Rows in parallel: each reads only finer vertices, written before.
                let updates = crate::par::map_collect(&ys, |&y| {
                    let mut row = Vec::new();
                    for &x in &xs {
                        let v = IVec2::new(x, y);
                        if self.tz(v) == tz && self.is_square_centre(v, tz) == odd_both {
                            row.push((v, self.vertex_bounds(v, tz, density)));
                        }
                    }
                    row
                });
                for (v, b) in updates.into_iter().flatten() {
                    let i = self.index(v);
                    self.bounds[i] = b;
                }
            }
        }
        // Patches whose closed square holds a changed vertex.
        let ps = self.config.patch_size as i32;
        let n = self.patches.as_ivec2();
        let pxs = axis(
            (lo.x - 1).div_euclid(ps),
            hi.x.div_euclid(ps),
            1,
            n.x,
            self.grid_wrap,
        );
        let pys = axis(
            (lo.y - 1).div_euclid(ps),
            hi.y.div_euclid(ps),
            1,
            n.y,
            self.grid_wrap,
        );
        for &py in &pys {
            for &px in &pxs {
                let mut b = [f32::INFINITY, f32::NEG_INFINITY];
                for y in 0..=ps {
                    for x in 0..=ps {
                        let h = self.heights[self.index(IVec2::new(px * ps + x, py * ps + y))];
                        b = [b[0].min(h), b[1].max(h)];
                    }
                }
                self.patch_bounds[(py * n.x + px) as usize] = b;
            }
        }
    }
}

/// The coordinates `lo ..= hi` that are multiples of `step`, inside `0 .. n`: clamped, or
/// wrapped (each once) on a repeating map.
fn axis(lo: i32, hi: i32, step: i32, n: i32, wrap: WrapMode) -> Vec<i32> {
    let (lo, hi) = match wrap {
        WrapMode::Clamp => (lo.max(0), hi.min(n - 1)),
        WrapMode::Repeat if hi - lo >= n - 1 => (0, n - 1),
        WrapMode::Repeat => (lo, hi),
    };
    let mut out = Vec::new();
    let mut c = lo.div_euclid(step) * step;
    if c < lo {
        c += step;
    }
    while c <= hi {
        out.push(c.rem_euclid(n));
        c += step;
    }
    out
}
