//! Adaptive tessellation (Cervin 2012, sec. 2.3 and algorithm 3.1) as an implicit subdivision:
//! longest-edge bisection of right triangles over square patches (a 4-8 mesh), where every
//! edge decides for itself whether it is split, from the clip-space size of a sphere around it
//! for a target triangle width in pixels, scaled by the density map and clamped to a minimum
//! horizontal size. wgpu has no tessellation stage: `terrain-gpu`'s `TessellationPass` runs the
//! same decisions in a compute pass that writes the triangles and the indirect draw arguments;
//! [`TessHierarchy::select`] is its CPU reference (the same f32 operations in the same order:
//! on lavapipe the two emit the same triangles; a driver that fuses multiply-adds or rounds a
//! square root differently may flip a decision that lies within rounding of its threshold).
//!
//! Why bisection, how the split decisions stay nested (conforming), the split criterion of
//! the size and error metrics and the morph are derived in the repository's
//! `docs/derivations.md` ("Adaptive tessellation"). In short: a vertex is split in when its
//! saturated sphere projects above one, so every edge is decided once for both its triangles
//! and the mesh has no T-junctions by construction.

use crate::cdlod::CdlodView;
use crate::density::DensityMap;
use crate::error::LodError;
use glam::{IVec2, UVec2, Vec2, Vec3};
use terrain_core::{HeightMap, HeightSample, Rect, WrapMode};

/// `R / h` of a flat edge's saturated sphere for an edge (hypotenuse) `h` long, as the
/// hierarchy gets deep: `1 / (2 sqrt 2) / (1 - 1 / sqrt 2)`.
pub const FLAT_SPHERE: f32 = 1.207_106_8;

/// The smallest distance (metres) from the camera to a sphere that the ratio uses (the camera
/// inside a sphere asks for the finest level there).
pub const NEAR_M: f32 = 1e-3;

/// How much the split threshold rises per level: the ratios nest in exact arithmetic, and a
/// threshold `1 - (MAX_LEVELS - level) * SPLIT_MARGIN` keeps them nested under f32 rounding
/// (relative errors below `SPLIT_MARGIN`) while staying at most 1 (so the error metric's bound
/// holds).
pub const SPLIT_MARGIN: f32 = 1e-4;

/// The most triangle levels: `2 log2 MAX_PATCH_SIZE`.
pub const MAX_LEVELS: u32 = 16;

/// The ratio a vertex split in by triangles of `level` must exceed.
#[inline]
pub fn split_threshold(level: u32) -> f32 {
    1.0 - (MAX_LEVELS - level.min(MAX_LEVELS)) as f32 * SPLIT_MARGIN
}

/// The largest patch side in texels.
pub const MAX_PATCH_SIZE: u32 = 256;

/// The most grid vertices along a side (coordinates, doubled for a neighbour, fit in `i32`).
pub const MAX_GRID_SIDE: u64 = 1 << 30;

/// Parameters of the tessellation.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(default, deny_unknown_fields))]
pub struct TessConfig {
    /// Texels per side of a patch (two triangles at level 0): a power of two, 2 to 256
    /// (default 32).
    pub patch_size: u32,
    /// The target projected length of a triangle edge, pixels (Cervin 2012: "desired triangle
    /// width", 6 the lowest practical; default 8).
    pub triangle_width_px: f32,
    /// Triangles are not split below this horizontal hypotenuse length, metres (the "minimum
    /// horizontal size" of Cervin 2012, sec. 2.3; default 0: down to the texels).
    pub min_triangle_m: f32,
    /// Scale the edges' factors by the density map (default on).
    pub use_density: bool,
    /// Vertices move in from their edge instead of popping in (default on).
    pub morph: bool,
    /// How far past the split threshold a vertex reaches its true height: at
    /// `r = 1 + morph_range` (default 1).
    pub morph_range: f32,
    /// The most triangles one selection may emit (default 2^22): memory stays bounded for
    /// every view.
    pub max_triangles: usize,
    /// Split by projected geometric error instead of edge size: a vertex is split in while
    /// the saturated error of its triangles (see [`TessHierarchy::bounds`]) projects to more
    /// than this many pixels; the density map and the triangle width are then unused
    /// (default `None`: Cervin 2012's edge size).
    pub max_error_px: Option<f32>,
}

impl Default for TessConfig {
    fn default() -> Self {
        Self {
            patch_size: 32,
            triangle_width_px: 8.0,
            min_triangle_m: 0.0,
            use_density: true,
            morph: true,
            morph_range: 1.0,
            max_triangles: 1 << 22,
            max_error_px: None,
        }
    }
}

impl TessConfig {
    /// Checks every field, naming the first that is out of range.
    pub fn validate(&self) -> Result<(), LodError> {
        let bad = |what: &'static str, value: f64, allowed: &'static str| {
            Err(LodError::InvalidTessParam {
                what,
                value,
                allowed,
            })
        };
        if !(self.patch_size.is_power_of_two() && (2..=MAX_PATCH_SIZE).contains(&self.patch_size)) {
            return bad(
                "patch_size",
                self.patch_size.into(),
                "a power of two from 2 to 256",
            );
        }
        if !(self.triangle_width_px.is_finite()
            && (0.01..=10_000.0).contains(&self.triangle_width_px))
        {
            return bad(
                "triangle_width_px",
                self.triangle_width_px.into(),
                "0.01 to 10 000 pixels",
            );
        }
        if !(self.min_triangle_m.is_finite() && self.min_triangle_m >= 0.0) {
            return bad(
                "min_triangle_m",
                self.min_triangle_m.into(),
                "a finite number >= 0",
            );
        }
        if !(self.morph_range.is_finite() && (0.01..=100.0).contains(&self.morph_range)) {
            return bad("morph_range", self.morph_range.into(), "0.01 to 100");
        }
        if let Some(e) = self.max_error_px
            && !(e.is_finite() && (0.01..=1000.0).contains(&e))
        {
            return bad("max_error_px", e.into(), "0.01 to 1000 pixels");
        }
        if !(1..=(1usize << 28)).contains(&self.max_triangles) {
            return bad(
                "max_triangles",
                self.max_triangles as f64,
                "1 to 2^28 triangles",
            );
        }
        Ok(())
    }
}

/// A drawn vertex: texel position (unwrapped) and drawn height in metres. The GPU pass writes
/// the same layout.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TessVertex {
    /// Texel position `(x, y)`: world `(x * texel_size, height, y * texel_size)`.
    pub texel: [f32; 2],
    /// Drawn (morphed) height, metres.
    pub height: f32,
}

/// A drawn triangle, wound counter-clockwise seen from above.
pub type TessTriangle = [TessVertex; 3];

/// The triangles of one frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TessFrame {
    /// In patch order, depth first within a patch.
    pub triangles: Vec<TessTriangle>,
    /// Triangles dropped by the frustum (with everything they would have split into).
    pub culled: u32,
}

impl TessFrame {
    /// Triangles drawn.
    pub fn triangle_count(&self) -> u64 {
        self.triangles.len() as u64
    }

    /// Distinct vertices drawn (what a tessellator's domain shader would run on).
    pub fn vertex_count(&self) -> u64 {
        let mut keys: Vec<u64> = self
            .triangles
            .iter()
            .flatten()
            .map(|v| ((v.texel[1] as i64 as u64) << 32) | (v.texel[0] as i64 as u32 as u64))
            .collect();
        keys.sort_unstable();
        keys.dedup();
        keys.len() as u64
    }
}

/// A triangle of the hierarchy while it is refined: right-angle apex `a`, hypotenuse from `l`
/// to `r` (`(l, r, a)` counter-clockwise seen from above), their drawn heights, its level.
#[derive(Debug, Clone, Copy)]
struct Tri {
    a: IVec2,
    l: IVec2,
    r: IVec2,
    ha: f32,
    hl: f32,
    hr: f32,
    level: u32,
}

impl Tri {
    /// The two children: apex at the hypotenuse's midpoint `v` (drawn at `hv`).
    fn children(&self, v: IVec2, hv: f32) -> [Tri; 2] {
        let level = self.level + 1;
        [
            Tri {
                a: v,
                l: self.a,
                r: self.l,
                ha: hv,
                hl: self.ha,
                hr: self.hl,
                level,
            },
            Tri {
                a: v,
                l: self.r,
                r: self.a,
                ha: hv,
                hl: self.hr,
                hr: self.ha,
                level,
            },
        ]
    }

    fn emit(&self) -> TessTriangle {
        let v = |p: IVec2, h: f32| TessVertex {
            texel: [p.x as f32, p.y as f32],
            height: h,
        };
        [v(self.l, self.hl), v(self.r, self.hr), v(self.a, self.ha)]
    }
}

/// What one frame's decisions are made from: the camera and the precomputed factors.
#[derive(Debug, Clone, Copy)]
pub struct TessDecision {
    /// Camera position, metres.
    pub camera: Vec3,
    /// `K / (FLAT_SPHERE * triangle_width_px)`: the ratio is `scale * R * density / distance`;
    /// with the error metric `K / max_error_px`, and the ratio `scale * E / distance`.
    pub scale: f32,
    /// Whether the ratio is the projected error rather than the edge size.
    pub error_metric: bool,
    /// Triangles of this level and finer are not split (`2 log2 P` or the minimum size's).
    pub split_levels: u32,
    /// Whether densities scale the ratio.
    pub use_density: bool,
    /// `1 / morph_range`, or 0 with the morph off (vertices drawn at their true height).
    pub inv_morph_range: f32,
}

/// The saturated bounds of every grid vertex of a heightfield's patches, kept current after
/// deformations, from which a frame's tessellation is decided.
#[derive(Debug, Clone)]
pub struct TessHierarchy {
    config: TessConfig,
    map_size: UVec2,
    wrap: WrapMode,
    /// How grid coordinates wrap: as the map when the patches tile a repeating map, clamped
    /// otherwise (a repeating map whose sides the patch does not divide is tessellated over
    /// whole patches, past its side, with wrapped heights).
    grid_wrap: WrapMode,
    texel_size: f32,
    /// log2 of the patch size.
    p: u32,
    /// Patches per axis.
    patches: UVec2,
    /// Vertices per axis (`patches * P + 1` on a clamped map, the map size on a repeating one).
    grid: UVec2,
    /// True height of every grid vertex (metres; clamped past a clamped map's edge).
    heights: Vec<f32>,
    /// Saturated sphere radius (metres), density (0 to 1) and error (metres) of every grid
    /// vertex.
    bounds: Vec<[f32; 3]>,
    /// Lowest and highest height over each patch (its edges included), metres.
    patch_bounds: Vec<[f32; 2]>,
    /// The density map's reach in texels: how far a height change moves densities.
    density_reach: u32,
}

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

    /// `min(trailing zeros of x, of y)`, at most log2 P (patch corners).
    fn tz(&self, v: IVec2) -> u32 {
        let t = |c: i32| {
            if c == 0 {
                self.p
            } else {
                c.trailing_zeros().min(self.p)
            }
        };
        t(v.x).min(t(v.y))
    }

    fn is_square_centre(&self, v: IVec2, tz: u32) -> bool {
        (v.x >> tz) & 1 == 1 && (v.y >> tz) & 1 == 1
    }

    /// The endpoints of the edge whose midpoint is `v` (of `tz < log2 P`).
    fn edge_of(&self, v: IVec2, tz: u32) -> [IVec2; 2] {
        let s = 1i32 << tz;
        let (ox, oy) = ((v.x >> tz) & 1, (v.y >> tz) & 1);
        match (ox, oy) {
            (1, 1) => {
                // A square's centre: the diagonal of the 4-8 mesh's checkerboard.
                if ((v.x >> (tz + 1)) + (v.y >> (tz + 1))) & 1 == 0 {
                    [v - s, v + s]
                } else {
                    [v + IVec2::new(s, -s), v + IVec2::new(-s, s)]
                }
            }
            (1, _) => [v - IVec2::new(s, 0), v + IVec2::new(s, 0)],
            _ => [v - IVec2::new(0, s), v + IVec2::new(0, s)],
        }
    }

    /// The vertices split in by the triangles that split at `v`.
    fn children_of(&self, v: IVec2, tz: u32) -> impl Iterator<Item = IVec2> + use<> {
        let s = 1i32 << tz;
        let offsets: [IVec2; 4] = if self.is_square_centre(v, tz) {
            [
                IVec2::new(s, 0),
                IVec2::new(-s, 0),
                IVec2::new(0, s),
                IVec2::new(0, -s),
            ]
        } else if tz == 0 {
            [IVec2::ZERO; 4]
        } else {
            let h = s / 2;
            [
                IVec2::new(h, h),
                IVec2::new(-h, h),
                IVec2::new(h, -h),
                IVec2::new(-h, -h),
            ]
        };
        let leaf = !self.is_square_centre(v, tz) && tz == 0;
        let wrap = self.grid_wrap;
        let grid = self.grid.as_ivec2();
        offsets.into_iter().filter_map(move |o| {
            if leaf {
                return None;
            }
            let c = v + o;
            (wrap == WrapMode::Repeat || (c.cmpge(IVec2::ZERO).all() && c.cmplt(grid).all()))
                .then_some(c)
        })
    }

    /// The grid index of a vertex (wrapped on a repeating grid).
    #[inline]
    fn index(&self, v: IVec2) -> usize {
        let g = self.grid.as_ivec2();
        if v.cmpge(IVec2::ZERO).all() && v.cmplt(g).all() {
            return v.y as usize * self.grid.x as usize + v.x as usize;
        }
        let w = match self.grid_wrap {
            WrapMode::Repeat => v.rem_euclid(g),
            WrapMode::Clamp => v.clamp(IVec2::ZERO, g - 1),
        };
        w.y as usize * self.grid.x as usize + w.x as usize
    }

    /// The map texel whose height grid vertex `v` has: wrapped on a repeating map, clamped to
    /// the last texel past a clamped one.
    #[inline]
    fn texel_of(&self, v: IVec2) -> IVec2 {
        if v.cmpge(IVec2::ZERO).all() && v.cmplt(self.map_size.as_ivec2()).all() {
            return v;
        }
        match self.wrap {
            WrapMode::Repeat => v.rem_euclid(self.map_size.as_ivec2()),
            WrapMode::Clamp => v.clamp(IVec2::ZERO, self.map_size.as_ivec2() - 1),
        }
    }

    /// World position of vertex `v` at its true height.
    fn world(&self, v: IVec2) -> Vec3 {
        let ts = self.texel_size;
        Vec3::new(
            v.x as f32 * ts,
            self.heights[self.index(v)],
            v.y as f32 * ts,
        )
    }

    fn vertex_bounds(&self, v: IVec2, tz: u32, density: Option<&DensityMap>) -> [f32; 3] {
        let c = self.world(v);
        let [e0, e1] = self.edge_of(v, tz);
        let (w0, w1) = (self.world(e0), self.world(e1));
        let mut r = c.distance(w0).max(c.distance(w1));
        // How far the vertex lies off its edge: what splitting it in changes.
        let own_error = (c.y - 0.5 * (w0.y + w1.y)).abs();
        let mut child_error = 0.0f32;
        let mut d = match density.and_then(|dm| dm.level(0)) {
            Some(level) => {
                // Level 0's sample over the texel (as `DensityMap::density_at_texel`).
                let t = self.texel_of(v) / crate::density::DENSITY_DOWNSAMPLE as i32;
                let t = t.min(level.size().as_ivec2() - 1);
                f32::from(level.as_slice()[t.y as usize * level.width() as usize + t.x as usize])
                    / 255.0
            }
            None => 1.0,
        };
        for child in self.children_of(v, tz) {
            let [rc, dc, ec] = self.bounds[self.index(child)];
            r = r.max(c.distance(self.world(child)) + rc);
            d = d.max(dc);
            child_error = child_error.max(ec);
        }
        // A triangle split at `v` and left unsplit deviates from the full-resolution mesh by
        // at most its own vertex's offset plus the most either child triangle deviates.
        [r, d, own_error + child_error]
    }
}

impl TessHierarchy {
    /// The configuration.
    pub fn config(&self) -> &TessConfig {
        &self.config
    }

    /// Metres per texel.
    pub fn texel_size(&self) -> f32 {
        self.texel_size
    }

    /// The map's wrap mode.
    pub fn wrap(&self) -> WrapMode {
        self.wrap
    }

    /// How grid coordinates wrap: as a repeating map whose sides the patch size divides,
    /// clamped otherwise (what a GPU pass indexes [`TessHierarchy::bounds`] with).
    pub fn grid_wrap(&self) -> WrapMode {
        self.grid_wrap
    }

    /// Patches per axis.
    pub fn patches(&self) -> UVec2 {
        self.patches
    }

    /// Grid vertices per axis.
    pub fn grid_size(&self) -> UVec2 {
        self.grid
    }

    /// The saturated (radius m, density, error m) of every grid vertex, row by row: what the
    /// GPU pass uploads. The radius is that of a sphere around the vertex holding the spheres
    /// of every vertex its triangles split in; the density the largest among them; the error
    /// bounds how far the triangles split at the vertex, left unsplit, lie from the map
    /// (`|h - edge mean|` plus the children's error).
    pub fn bounds(&self) -> &[[f32; 3]] {
        &self.bounds
    }

    /// (lowest, highest) height of every patch, row by row.
    pub fn patch_bounds(&self) -> &[[f32; 2]] {
        &self.patch_bounds
    }

    /// True heights of the grid vertices, row by row (metres).
    pub fn heights(&self) -> &[f32] {
        &self.heights
    }

    /// The vertices split in by the triangles that split at grid vertex `v` (none for patch
    /// corners, the finest vertices and vertices off the grid): the children whose bounds `v`'s
    /// bounds contain.
    pub fn children(&self, v: IVec2) -> Vec<IVec2> {
        if v.cmplt(IVec2::ZERO).any() || v.cmpge(self.grid.as_ivec2()).any() {
            return Vec::new();
        }
        let tz = self.tz(v);
        if tz >= self.p {
            return Vec::new();
        }
        self.children_of(v, tz).collect()
    }

    /// The number of levels a triangle can have: `2 log2 P + 1`.
    pub fn level_count(&self) -> u32 {
        2 * self.p + 1
    }

    /// The frame's decision inputs for `view` (with this hierarchy's config).
    pub fn decision(&self, view: &CdlodView<'_>) -> Result<TessDecision, LodError> {
        for (what, value) in [
            ("camera.x", view.camera.x),
            ("camera.y", view.camera.y),
            ("camera.z", view.camera.z),
            ("viewport_width", view.viewport_width),
            ("hfov", view.hfov),
        ] {
            if !value.is_finite() {
                return Err(LodError::NonFinite { what, value });
            }
        }
        let k = view.k();
        if !(k.is_finite() && k > 0.0) {
            return Err(LodError::InvalidTessParam {
                what: "hfov",
                value: view.hfov.into(),
                allowed: "a field of view in (0, pi) and a positive viewport width",
            });
        }
        let c = &self.config;
        // Split only while the children's hypotenuse (P sqrt(2)^-l texels at level l + 1) is
        // at least the minimum size.
        let mut split_levels = 2 * self.p;
        while split_levels > 0 {
            let child_hyp = c.patch_size as f32
                * self.texel_size
                * std::f32::consts::FRAC_1_SQRT_2.powi(split_levels as i32 - 1);
            if child_hyp >= c.min_triangle_m {
                break;
            }
            split_levels -= 1;
        }
        Ok(TessDecision {
            camera: view.camera,
            scale: match c.max_error_px {
                Some(tau) => k / tau,
                None => k / (FLAT_SPHERE * c.triangle_width_px),
            },
            error_metric: c.max_error_px.is_some(),
            split_levels,
            use_density: c.use_density,
            inv_morph_range: if c.morph { 1.0 / c.morph_range } else { 0.0 },
        })
    }

    /// The split ratio `r` of vertex `v` (split in when > 1). Mirrors `tessellate.wgsl`.
    pub fn ratio(&self, d: &TessDecision, v: IVec2) -> f32 {
        let i = self.index(v);
        let [r, density, error] = self.bounds[i];
        let ts = self.texel_size;
        let c = Vec3::new(
            v.x as f32 * ts - d.camera.x,
            self.heights[i] - d.camera.y,
            v.y as f32 * ts - d.camera.z,
        );
        let dist = (c.length() - r).max(NEAR_M);
        if d.error_metric {
            return d.scale * error / dist;
        }
        let dens = if d.use_density { density } else { 1.0 };
        d.scale * r * dens / dist
    }

    /// Whether `t` splits, and if so the drawn height of its new vertex.
    fn split(&self, d: &TessDecision, t: &Tri) -> Option<(IVec2, f32)> {
        if t.level >= d.split_levels {
            return None;
        }
        let v = (t.l + t.r) / 2;
        let r = self.ratio(d, v);
        let threshold = split_threshold(t.level);
        // NaN splits nothing, as on the GPU (`r > threshold` there).
        if r.is_nan() || r <= threshold {
            return None;
        }
        let h = self.heights[self.index(v)];
        let k = if d.inv_morph_range > 0.0 {
            ((r - threshold) * d.inv_morph_range).min(1.0)
        } else {
            1.0
        };
        let mid = 0.5 * (t.hl + t.hr);
        Some((v, mid + (h - mid) * k))
    }

    /// The two level-0 triangles of patch `(px, py)`.
    fn base(&self, px: i32, py: i32) -> [Tri; 2] {
        let ps = self.config.patch_size as i32;
        let o = IVec2::new(px * ps, py * ps);
        let c00 = o;
        let c10 = o + IVec2::new(ps, 0);
        let c01 = o + IVec2::new(0, ps);
        let c11 = o + IVec2::splat(ps);
        let (e, apexes) = if (px + py) & 1 == 0 {
            ([c00, c11], [c10, c01])
        } else {
            ([c10, c01], [c00, c11])
        };
        apexes.map(|a| {
            // Counter-clockwise seen from above: (r - l) x (a - l) < 0 in (x, z).
            let (l, r) = if (e[1] - e[0]).perp_dot(a - e[0]) < 0 {
                (e[0], e[1])
            } else {
                (e[1], e[0])
            };
            let h = |p: IVec2| self.heights[self.index(p)];
            Tri {
                a,
                l,
                r,
                ha: h(a),
                hl: h(l),
                hr: h(r),
                level: 0,
            }
        })
    }

    /// Whether `t` (of patch `patch`) may be seen.
    fn visible(&self, view: &CdlodView<'_>, t: &Tri, patch: usize) -> bool {
        let Some(frustum) = view.frustum else {
            return true;
        };
        let ts = self.texel_size;
        let lo = t.a.min(t.l).min(t.r).as_vec2() * ts;
        let hi = t.a.max(t.l).max(t.r).as_vec2() * ts;
        let [hmin, hmax] = self.patch_bounds[patch];
        frustum.intersects_aabb(Vec3::new(lo.x, hmin, lo.y), Vec3::new(hi.x, hmax, hi.y))
    }

    /// The triangles of one frame for `view`: every patch's two triangles, split depth first
    /// while their edges ask for it, dropped where the frustum misses them.
    ///
    /// Fails on a non-finite camera or field of view, or when more than
    /// [`TessConfig::max_triangles`] would be emitted.
    pub fn select(&self, view: &CdlodView<'_>) -> Result<TessFrame, LodError> {
        let d = self.decision(view)?;
        let limit = self.config.max_triangles;
        let emitted = std::sync::atomic::AtomicUsize::new(0);
        let rows: Vec<u32> = (0..self.patches.y).collect();
        let per_row = crate::par::map_collect(&rows, |&py| {
            let mut tris = Vec::new();
            let mut culled = 0u32;
            let mut stack = Vec::with_capacity(2 * self.p as usize + 2);
            for px in 0..self.patches.x as i32 {
                let patch = py as usize * self.patches.x as usize + px as usize;
                let before = tris.len();
                for base in self.base(px, py as i32) {
                    stack.push(base);
                    while let Some(t) = stack.pop() {
                        if !self.visible(view, &t, patch) {
                            culled += 1;
                            continue;
                        }
                        match self.split(&d, &t) {
                            Some((v, hv)) => {
                                let [c0, c1] = t.children(v, hv);
                                stack.push(c1);
                                stack.push(c0);
                            }
                            None => {
                                tris.push(t.emit());
                                // A patch alone may hold 2 P^2 triangles: stop early.
                                let mine = tris.len() - before;
                                if mine % 1024 == 0
                                    && emitted.load(std::sync::atomic::Ordering::Relaxed) + mine
                                        > limit
                                {
                                    return None;
                                }
                            }
                        }
                    }
                }
                // Counted per patch: at most one patch per thread beyond the bound is held.
                let added = tris.len() - before;
                let total = emitted.fetch_add(added, std::sync::atomic::Ordering::Relaxed) + added;
                if total > limit {
                    return None;
                }
            }
            Some((tris, culled))
        });
        let mut frame = TessFrame::default();
        let mut rows = Vec::with_capacity(per_row.len());
        for row in per_row {
            let Some(row) = row else {
                return Err(LodError::SelectionTooLarge { limit });
            };
            rows.push(row);
        }
        frame
            .triangles
            .reserve_exact(rows.iter().map(|(t, _)| t.len()).sum());
        for (tris, culled) in rows {
            frame.triangles.extend_from_slice(&tris);
            frame.culled += culled;
        }
        if frame.triangles.len() > limit {
            return Err(LodError::SelectionTooLarge { limit });
        }
        Ok(frame)
    }

    /// The drawn height over texel position `p` for a frame decided for `view` (culling
    /// aside), or `None` off the patches: descends from the patch's triangle under `p`
    /// through the children under it. The CPU side of the popping metric.
    pub fn surface_height(&self, view: &CdlodView<'_>, p: Vec2) -> Option<f32> {
        let d = self.decision(view).ok()?;
        let ps = self.config.patch_size as f32;
        let patch = (p / ps).floor();
        if !(p.is_finite()
            && patch.cmpge(Vec2::ZERO).all()
            && patch.cmplt(self.patches.as_vec2()).all())
        {
            return None;
        }
        let (px, py) = (patch.x as i32, patch.y as i32);
        let mut t = self
            .base(px, py)
            .into_iter()
            .find(|t| contains(t, p))
            .unwrap_or(self.base(px, py)[0]);
        while let Some((v, hv)) = self.split(&d, &t) {
            let [c0, c1] = t.children(v, hv);
            t = if contains(&c0, p) { c0 } else { c1 };
        }
        let bary = barycentric(&t, p)?;
        Some(bary[0] * t.hl + bary[1] * t.hr + bary[2] * t.ha)
    }

    /// The largest projected height error of `frame`'s drawn triangles against the map, in
    /// pixels: at every texel inside every triangle, `K * |h_map - h_drawn| / distance`.
    pub fn max_screen_error_px(&self, frame: &TessFrame, view: &CdlodView<'_>) -> f32 {
        let k = view.k();
        let ts = self.texel_size;
        let chunks: Vec<&[TessTriangle]> = frame.triangles.chunks(1024).collect();
        crate::par::map_collect(&chunks, |chunk| {
            let mut max = 0.0f32;
            for tri in chunk.iter() {
                let p: [Vec2; 3] = tri.map(|v| Vec2::from(v.texel));
                let lo = p[0].min(p[1]).min(p[2]).as_ivec2();
                let hi = p[0].max(p[1]).max(p[2]).as_ivec2();
                let area = (p[1] - p[0]).perp_dot(p[2] - p[0]);
                if area == 0.0 {
                    continue;
                }
                for y in lo.y..=hi.y {
                    for x in lo.x..=hi.x {
                        let q = IVec2::new(x, y).as_vec2();
                        let w0 = (p[1] - q).perp_dot(p[2] - q) / area;
                        let w1 = (p[2] - q).perp_dot(p[0] - q) / area;
                        let w2 = 1.0 - w0 - w1;
                        if w0 < -1e-6 || w1 < -1e-6 || w2 < -1e-6 {
                            continue;
                        }
                        let drawn = w0 * tri[0].height + w1 * tri[1].height + w2 * tri[2].height;
                        let truth = self.heights[self.index(IVec2::new(x, y))];
                        let world = Vec3::new(x as f32 * ts, truth, y as f32 * ts);
                        let dist = world.distance(view.camera).max(NEAR_M);
                        max = max.max(k * (truth - drawn).abs() / dist);
                    }
                }
            }
            max
        })
        .into_iter()
        .fold(0.0, f32::max)
    }

    /// The popping metric: the largest screen-space jump, in pixels, of the drawn surface
    /// between a frame decided for `previous` and one for `view` at `probes` (texel positions),
    /// both on today's heights and projected with today's `view_proj` (world metres) onto a
    /// target `target` pixels, so only a change of the mesh counts. Probes off screen (either
    /// height outside the clip volume) do not count.
    pub fn max_height_jump(
        &self,
        view: &CdlodView<'_>,
        previous: &CdlodView<'_>,
        probes: &[Vec2],
        view_proj: glam::Mat4,
        target: Vec2,
    ) -> f32 {
        // Only what is on screen counts (a point beside the camera projects anywhere).
        let project = |p: Vec3| {
            let c = view_proj * p.extend(1.0);
            let on_screen = c.w > 1e-6 && c.x.abs() <= c.w && c.y.abs() <= c.w && c.z >= 0.0;
            on_screen.then(|| (Vec2::new(c.x, -c.y) / c.w * 0.5 + 0.5) * target)
        };
        let ts = self.texel_size;
        let mut max = 0.0f32;
        for &p in probes {
            let (Some(a), Some(b)) = (
                self.surface_height(view, p),
                self.surface_height(previous, p),
            ) else {
                continue;
            };
            let world = |h: f32| Vec3::new(p.x * ts, h, p.y * ts);
            if let (Some(pa), Some(pb)) = (project(world(a)), project(world(b))) {
                max = max.max(pa.distance(pb));
            }
        }
        max
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

/// Barycentric weights of `p` for `(l, r, a)`, if `p` lies in `t` (with a small tolerance).
fn barycentric(t: &Tri, p: Vec2) -> Option<[f32; 3]> {
    let (l, r, a) = (t.l.as_vec2(), t.r.as_vec2(), t.a.as_vec2());
    let area = (r - l).perp_dot(a - l);
    if area == 0.0 {
        return None;
    }
    let w0 = (r - p).perp_dot(a - p) / area;
    let w1 = (a - p).perp_dot(l - p) / area;
    let w2 = 1.0 - w0 - w1;
    let eps = -1e-4;
    (w0 >= eps && w1 >= eps && w2 >= eps).then_some([w0, w1, w2])
}

fn contains(t: &Tri, p: Vec2) -> bool {
    barycentric(t, p).is_some()
}
