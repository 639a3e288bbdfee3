//! Density maps (Cervin 2012, ch. 3): how finely the terrain mesh must be tessellated where, from
//! the heightfield's curvature, at a quarter of its resolution, with a max pyramid for coarser
//! levels of detail.
//!
//! The pipeline of sec. 3.3, per density sample `(i, j)` of level 0:
//! 1. a curvature filter ([`CurvatureFilter`]) at every height texel, normalised by the texel
//!    spacing (a curvature in 1 / m times the spacing in m: how far the surface turns from one
//!    sample to the next, so coarser maps are not artificially smooth);
//! 2. max-downsampling by 4 with the one-sample overlap of sec. 3.3.1: the maximum over texels
//!    `4i - 1 ..= 4i + 4` (and rows alike), so a change along one axis at the edge of a 4 x 4
//!    block is not lost;
//! 3. the preprocessing max filter of sec. 3.3.2: a square window of `filter_size` samples,
//!    and of `s_b = filter_size * 2^border_lod_skip` samples (eq. 3.8) on tile borders;
//! 4. the curvature scale, gain and exponent of sec. 3.3.4: `clamp(v * scale * gain, 0, 1)^exponent`
//!    (an exponent maps 1 to 1 and pushes low values down), stored as u8 (sec. 3.1.2);
//! 5. coarser levels by a max filter over the children (sec. 3.3.3), except on tile borders,
//!    which are point-sampled so neighbouring tiles of different levels agree on their shared
//!    edge (the preprocessing of step 3 is what keeps that point sampling from aliasing).
//!
//! After a deformation, [`DensityMap::update_rect`] recomputes only the samples the dirty rect
//! reaches, from the real curvature (sec. 3.5 only adds a fixed boost).

mod curvature;

pub use curvature::{CurvatureFilter, Neighbourhood, curvature};

use crate::error::LodError;
use glam::{IVec2, UVec2};
use terrain_core::{Grid, HeightMap, HeightSample, Rect, WrapMode};

/// Height texels per density sample along each axis (Cervin 2012, sec. 3.1.1: 128 / 4 = 32).
pub const DENSITY_DOWNSAMPLE: u32 = 4;

/// The largest preprocessing filter size accepted.
pub const MAX_FILTER_SIZE: u32 = 31;
/// The largest border LOD skip accepted (eq. 3.8's `l_skip`).
pub const MAX_BORDER_LOD_SKIP: u32 = 4;

/// Parameters of the density map (Cervin 2012, sec. 3.3.4), with the document's defaults where it
/// gives them.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(default, deny_unknown_fields))]
pub struct DensityParams {
    /// The curvature filter ("density map filter").
    pub filter: CurvatureFilter,
    /// Normalised curvature (1 / m times the texel spacing) that maps to full density before
    /// the gain: the "scaling constant" of sec. 3.3.1 that puts values in about `[0, 1]`.
    /// Default 0.5: a surface whose normal turns by 0.5 rad from one texel to the next asks for
    /// the full density (on the demo's procedural terrain at 0.1 m the mean filter's window
    /// maxima lie between 0.12 and 0.21 for 80 % of the samples, so values spread over the
    /// lower half of the range and crests stand out).
    pub full_density_bend: f32,
    /// "Curvature gain": scales every value (default 1).
    pub gain: f32,
    /// "Curvature exponent": `v^exponent` after the gain, 1 maps to 1 (default 1).
    pub exponent: f32,
    /// "Preprocess density map": run the max filter of step 3 (default on).
    pub preprocess: bool,
    /// "Density map filter size": the side of the preprocessing max filter in density
    /// samples, rounded up to odd (default 3; at most [`MAX_FILTER_SIZE`]).
    pub filter_size: u32,
    /// `l_skip` of eq. 3.8: border samples are max filtered over `filter_size * 2^l_skip`
    /// samples so they match the level `l_skip` above the finest (default 1; at most
    /// [`MAX_BORDER_LOD_SKIP`]).
    pub border_lod_skip: u32,
    /// Density samples per tile side: samples whose column or row is a multiple of it are tile
    /// borders (default 32, Cervin 2012, sec. 3.1.1). At least 2.
    pub tile_size: u32,
}

impl Default for DensityParams {
    fn default() -> Self {
        Self {
            filter: CurvatureFilter::Mean,
            full_density_bend: 0.5,
            gain: 1.0,
            exponent: 1.0,
            preprocess: true,
            filter_size: 3,
            border_lod_skip: 1,
            tile_size: 32,
        }
    }
}

impl DensityParams {
    /// Checks every field, naming the first that is out of range.
    pub fn validate(&self) -> Result<(), LodError> {
        let bad = |what: &'static str, value: f64, allowed: &'static str| {
            Err(LodError::InvalidDensityParam {
                what,
                value,
                allowed,
            })
        };
        if !(self.full_density_bend.is_finite() && self.full_density_bend > 0.0) {
            return bad(
                "full_density_bend",
                self.full_density_bend.into(),
                "a finite number > 0",
            );
        }
        if !(self.gain.is_finite() && self.gain >= 0.0) {
            return bad("gain", self.gain.into(), "a finite number >= 0");
        }
        if !(self.exponent.is_finite() && self.exponent > 0.0 && self.exponent <= 64.0) {
            return bad("exponent", self.exponent.into(), "a number in (0, 64]");
        }
        if !(1..=MAX_FILTER_SIZE).contains(&self.filter_size) {
            return bad("filter_size", self.filter_size.into(), "1 to 31");
        }
        if self.border_lod_skip > MAX_BORDER_LOD_SKIP {
            return bad("border_lod_skip", self.border_lod_skip.into(), "0 to 4");
        }
        if !(2..=4096).contains(&self.tile_size) {
            return bad("tile_size", self.tile_size.into(), "2 to 4096");
        }
        Ok(())
    }

    /// The preprocessing window's radius off and on tile borders, in density samples (0, 0 when
    /// preprocessing is off).
    pub fn filter_radii(&self) -> (u32, u32) {
        if !self.preprocess {
            return (0, 0);
        }
        let inner = self.filter_size / 2;
        let border = (self.filter_size << self.border_lod_skip.min(MAX_BORDER_LOD_SKIP)) / 2;
        (inner, border.max(inner))
    }

    /// The factor from a normalised curvature to a density before the exponent.
    fn scale(&self) -> f32 {
        self.gain / self.full_density_bend
    }

    /// Step 4: a normalised curvature to the stored u8 density.
    pub fn quantize(&self, normalised: f32) -> u8 {
        let v = (normalised * self.scale()).clamp(0.0, 1.0);
        let v = if self.exponent == 1.0 {
            v
        } else {
            v.powf(self.exponent)
        };
        // `as` saturates and maps NaN to 0.
        (v * 255.0 + 0.5) as u8
    }
}

/// A density map with its max pyramid: level 0 at a quarter of the heightfield's resolution,
/// each coarser level half the previous, down to one sample.
///
/// Values are u8: 255 is full density (a tessellation factor kept as computed), 0 the least
/// (Cervin 2012, sec. 3.4: the density scales edge factors, which never fall below 1).
#[derive(Debug, Clone, PartialEq)]
pub struct DensityMap {
    params: DensityParams,
    map_size: UVec2,
    wrap: WrapMode,
    /// Level 0 before preprocessing: the normalised curvature maximum of each sample.
    raw: Grid<f32>,
    levels: Vec<Grid<u8>>,
}

impl DensityMap {
    /// Computes the density map of `map` with `params`.
    pub fn from_map<T: HeightSample>(
        map: &HeightMap<T>,
        params: DensityParams,
    ) -> Result<Self, LodError> {
        params.validate()?;
        let map_size = map.size();
        let size = density_size(map_size);
        let raw = Grid::new(size.x, size.y, 0.0f32).map_err(LodError::Core)?;
        let mut levels = Vec::new();
        let mut s = size;
        loop {
            levels.push(Grid::new(s.x, s.y, 0u8).map_err(LodError::Core)?);
            if s.x <= 1 && s.y <= 1 {
                break;
            }
            s = UVec2::new(s.x.div_ceil(2), s.y.div_ceil(2));
        }
        let mut out = Self {
            params,
            map_size,
            wrap: map.wrap(),
            raw,
            levels,
        };
        let all = Rect::from_size(size);
        out.fill_raw(map, all);
        out.finish(all);
        out.reduce(all);
        // (The same as `update_rect` over the whole map, without its bookkeeping.)
        Ok(out)
    }

    /// Recomputes what a height change inside `dirty` (texels of `map`, which may wrap on a
    /// repeating map) can change: the raw samples whose windows reach it, the preprocessed
    /// samples whose filter reaches those, and the pyramid above them. The result equals
    /// [`DensityMap::from_map`] of the changed map.
    ///
    /// Fails if `map` is not the size this density map was made for.
    pub fn update_rect<T: HeightSample>(
        &mut self,
        map: &HeightMap<T>,
        dirty: Rect,
    ) -> Result<(), LodError> {
        if map.size() != self.map_size {
            return Err(LodError::SizeMismatch {
                expected: self.map_size,
                actual: map.size(),
            });
        }
        let regions = update_regions(self.map_size, self.wrap, &self.params, dirty);
        for &rect in &regions.raw {
            self.fill_raw(map, rect);
        }
        for &rect in &regions.finish {
            self.finish(rect);
        }
        for rect in regions.finish {
            self.reduce(rect);
        }
        Ok(())
    }

    /// The parameters the map was made with.
    pub fn params(&self) -> &DensityParams {
        &self.params
    }

    /// The size of the heightfield it describes.
    pub fn map_size(&self) -> UVec2 {
        self.map_size
    }

    /// The number of levels (level 0 and the pyramid above it).
    pub fn level_count(&self) -> usize {
        self.levels.len()
    }

    /// Level `k` of the pyramid (0 the finest), or `None` past the coarsest.
    pub fn level(&self, k: usize) -> Option<&Grid<u8>> {
        self.levels.get(k)
    }

    /// Level 0 before preprocessing and quantisation: the largest normalised curvature in each
    /// sample's window.
    pub fn raw(&self) -> &Grid<f32> {
        &self.raw
    }

    /// The density (0 to 1) of level `k` over height texel `(x, y)` (nearest sample; wrapped
    /// or clamped as the map), or `None` past the coarsest level.
    pub fn density_at_texel(&self, level: usize, texel: IVec2) -> Option<f32> {
        let g = self.levels.get(level)?;
        let t = IVec2::new(
            self.wrap.resolve(i64::from(texel.x), self.map_size.x) as i32,
            self.wrap.resolve(i64::from(texel.y), self.map_size.y) as i32,
        );
        let step = i64::from(DENSITY_DOWNSAMPLE) << level.min(40);
        let p = t.as_i64vec2().div_euclid(glam::I64Vec2::splat(step));
        let x = WrapMode::Clamp.resolve(p.x, g.width());
        let y = WrapMode::Clamp.resolve(p.y, g.height());
        Some(f32::from(g.as_slice()[g.index(x, y)]) / 255.0)
    }

    /// Steps 1 and 2 for the density samples of `rect` (inside the density grid).
    fn fill_raw<T: HeightSample>(&mut self, map: &HeightMap<T>, rect: Rect) {
        let h = map.grid();
        let wrap = map.wrap();
        let spacing = map.texel_size();
        let scale = map.encoding().scale;
        let filter = self.params.filter;
        let dw = self.raw.width() as usize;
        let (i0, i1) = (rect.min.x as usize, rect.max().x as usize);
        let (j0, j1) = (rect.min.y as usize, rect.max().y as usize);
        let d = DENSITY_DOWNSAMPLE as i64;
        // Texel columns the samples i0 .. i1 read: 4 i0 - 1 .. 4 i1 + 1 (one-sample overlap).
        let tx0 = i0 as i64 * d - 1;
        let tlen = (i1 - i0) * DENSITY_DOWNSAMPLE as usize + 2;
        let out = &mut self.raw.as_mut_slice()[j0 * dw..j1 * dw];
        crate::par::for_each_chunk(out, dw, |r, out_row| {
            let j = (j0 + r) as i64;
            // Column maxima over the window's six texel rows, then maxima over six columns.
            let mut colmax = vec![0.0f32; tlen];
            let mut rows: [Vec<f32>; 3] = std::array::from_fn(|_| Vec::with_capacity(tlen + 2));
            for ty in (j * d - 1)..=(j * d + 4) {
                for (k, row) in rows.iter_mut().enumerate() {
                    load_row(h, wrap, ty + k as i64 - 1, tx0 - 1, tlen + 2, row);
                }
                filter_row(filter, &rows, scale, spacing, &mut colmax);
            }
            for (k, o) in out_row[i0..i1].iter_mut().enumerate() {
                let a = k * DENSITY_DOWNSAMPLE as usize;
                let m = colmax[a..a + 6].iter().fold(0.0f32, |m, &v| m.max(v));
                *o = m * spacing;
            }
        });
    }

    /// Steps 3 and 4 for the samples of `rect` (inside level 0): the preprocessing max filter
    /// (separable: row maxima, then column maxima) and the quantisation.
    fn finish(&mut self, rect: Rect) {
        let (r, rb) = self.params.filter_radii();
        let params = self.params;
        let raw = &self.raw;
        let (w, hh) = (raw.width(), raw.height());
        let tile = i64::from(params.tile_size);
        let wrap = self.wrap;
        let level0 = &mut self.levels[0];
        let (i0, i1) = (rect.min.x as usize, rect.max().x as usize);
        let (j0, j1) = (rect.min.y as usize, rect.max().y as usize);
        let out = &mut level0.as_mut_slice()[j0 * w as usize..j1 * w as usize];
        // Separable: the maxima of each row the windows reach over columns `i - rad ..= i + rad`
        // (for both radii), once per row, then the maxima of `2 rad + 1` of those per sample:
        // O(samples * radius), not O(samples * radius^2).
        let ylo = j0 as i64 - i64::from(rb);
        let rows: Vec<i64> = (ylo..j1 as i64 + i64::from(rb)).collect();
        let row_maxima = |rad: u32| {
            crate::par::map_collect(&rows, |&y| {
                let row = raw.row(wrap.resolve(y, hh));
                let rad = i64::from(rad);
                (i0..i1)
                    .map(|i| {
                        let i = i as i64;
                        (i - rad..=i + rad)
                            .fold(0.0f32, |m, x| m.max(row[wrap.resolve(x, w) as usize]))
                    })
                    .collect::<Vec<f32>>()
            })
        };
        let inner = row_maxima(r);
        let border = if rb == r { None } else { Some(row_maxima(rb)) };
        crate::par::for_each_chunk(out, w as usize, |k, out_row| {
            let j = (j0 + k) as i64;
            for (i, o) in out_row.iter_mut().enumerate().take(i1).skip(i0) {
                let on_border = i as i64 % tile == 0 || j % tile == 0;
                let (rad, maxima) = match &border {
                    Some(b) if on_border => (rb, b),
                    _ => (if on_border { rb } else { r }, &inner),
                };
                let rad = i64::from(rad);
                let m = (j - rad..=j + rad)
                    .fold(0.0f32, |m, y| m.max(maxima[(y - ylo) as usize][i - i0]));
                *o = params.quantize(m);
            }
        });
    }

    /// Step 5: the pyramid above the level-0 samples of `rect`.
    fn reduce(&mut self, rect: Rect) {
        let tile = self.params.tile_size;
        let mut rect = rect;
        for k in 1..self.levels.len() {
            let Some(parent_rect) = parent_rect(rect, self.levels[k].size()) else {
                return;
            };
            rect = parent_rect;
            let (lo, hi) = self.levels.split_at_mut(k);
            let child = &lo[k - 1];
            let parent = &mut hi[0];
            let (cw, ch) = (child.width() as i32, child.height() as i32);
            let pw = parent.width() as usize;
            let (i0, i1) = (rect.min.x as usize, rect.max().x as usize);
            let (j0, j1) = (rect.min.y as usize, rect.max().y as usize);
            let out = &mut parent.as_mut_slice()[j0 * pw..j1 * pw];
            crate::par::for_each_chunk(out, pw, |r, out_row| {
                let j = (j0 + r) as i32;
                for (i, o) in out_row.iter_mut().enumerate().take(i1).skip(i0) {
                    let ii = i as i32;
                    let cx = (2 * ii).min(cw - 1);
                    let cy = (2 * j).min(ch - 1);
                    *o = if (ii as u32).is_multiple_of(tile) || (j as u32).is_multiple_of(tile) {
                        child.as_slice()[child.index(cx as u32, cy as u32)]
                    } else {
                        let mut m = 0u8;
                        for y in (cy - 1).max(0)..=(cy + 1).min(ch - 1) {
                            let row = child.row(y as u32);
                            for x in (cx - 1).max(0)..=(cx + 1).min(cw - 1) {
                                m = m.max(row[x as usize]);
                            }
                        }
                        m
                    };
                }
            });
        }
    }
}

/// What a density map recomputes after a height change: level-0 rects (inside the density
/// grid) whose raw samples (steps 1 and 2) change, and the rects whose preprocessed samples
/// (steps 3 and 4) change, from which the pyramid (step 5) follows by [`parent_rect`]. The
/// GPU pass records the same rects.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct DensityUpdate {
    /// Rects of raw samples to recompute.
    pub raw: Vec<Rect>,
    /// Rects of level-0 samples to preprocess and quantise again.
    pub finish: Vec<Rect>,
}

/// The regions a height change in `dirty` (texels; may wrap on a repeating map, is clipped on
/// a clamped one) reaches, for a map of `map_size` texels.
pub fn update_regions(
    map_size: UVec2,
    wrap: WrapMode,
    params: &DensityParams,
    dirty: Rect,
) -> DensityUpdate {
    let mut out = DensityUpdate::default();
    if dirty.is_empty() {
        return out;
    }
    let size = density_size(map_size);
    let (min, max) = (dirty.min.as_i64vec2(), dirty.max().as_i64vec2());
    let cols = affected_samples(min.x, max.x, map_size.x, size.x, wrap);
    let rows = affected_samples(min.y, max.y, map_size.y, size.y, wrap);
    let (_, rb) = params.filter_radii();
    for &(y0, y1) in &rows {
        for &(x0, x1) in &cols {
            let raw = Rect::from_min_max(
                IVec2::new(x0 as i32, y0 as i32),
                IVec2::new(x1 as i32, y1 as i32),
            );
            out.raw.push(raw);
            // Every sample whose preprocessing window reaches the raw rect.
            let r = i64::from(rb);
            let (lo, hi) = (raw.min.as_i64vec2() - r, raw.max().as_i64vec2() + r);
            if let Some(fin) = clip_samples(size, wrap, lo, hi) {
                out.finish
                    .extend(fin.split_toroidal(size).into_iter().map(|p| p.map));
            }
        }
    }
    out
}

/// The samples of a pyramid level of `parent_size` whose value reads a sample of `child` (a
/// rect of the level below): the inner samples' 3 x 3 windows around `2 i` and the border
/// samples' point samples at `2 i`. `None` when none does.
pub fn parent_rect(child: Rect, parent_size: UVec2) -> Option<Rect> {
    if child.is_empty() {
        return None;
    }
    let min = (child.min - 1).div_euclid(IVec2::splat(2)).max(IVec2::ZERO);
    let max = ((child.max() + 2).div_euclid(IVec2::splat(2))).min(parent_size.as_ivec2());
    let r = Rect::from_min_max(min, max);
    (!r.is_empty()).then_some(r)
}

/// Clips (clamped maps) or caps (repeating maps: a range wider than the map covers it once,
/// moved to start inside it) the sample range `min .. max` of a density grid of `size`.
fn clip_samples(
    size: UVec2,
    wrap: WrapMode,
    min: glam::I64Vec2,
    max: glam::I64Vec2,
) -> Option<Rect> {
    let size = size.as_i64vec2();
    let (min, max) = match wrap {
        WrapMode::Clamp => (min.max(glam::I64Vec2::ZERO), max.min(size)),
        WrapMode::Repeat => {
            let max = max.min(min + size);
            let shift = min.div_euclid(size) * size;
            (min - shift, max - shift)
        }
    };
    if (max - min).cmple(glam::I64Vec2::ZERO).any() {
        return None;
    }
    Some(Rect::from_min_max(min.as_ivec2(), max.as_ivec2()))
}

/// The level-0 sample ranges (half-open, inside `0 .. samples`) along one axis whose values a
/// height change in texels `min .. max` of a map `texels` long can change.
///
/// A sample `s` reads the filtered values of texels `4s - 1 ..= 4s + 4` (wrapped or clamped
/// into the map), and a filtered value reads its texel's neighbours, so a texel `t` reaches the
/// samples whose window holds a texel within one of `t` or of one of its wrapped copies.
fn affected_samples(
    min: i64,
    max: i64,
    texels: u32,
    samples: u32,
    wrap: WrapMode,
) -> Vec<(i64, i64)> {
    let (n, s) = (i64::from(texels), i64::from(samples));
    let d = i64::from(DENSITY_DOWNSAMPLE);
    // Samples whose window meets the inclusive texel range lo ..= hi.
    let reach = |lo: i64, hi: i64| -> Option<(i64, i64)> {
        let a = (lo - 4).div_euclid(d).max(0);
        let b = ((hi + 1).div_euclid(d) + 1).min(s);
        (a < b).then_some((a, b))
    };
    let mut out: Vec<(i64, i64)> = Vec::new();
    match wrap {
        WrapMode::Clamp => {
            let (a, b) = (min.max(0), max.min(n));
            if a >= b {
                return out;
            }
            // A changed edge texel is what the clamped reads past the edge see, too.
            let lo = if a == 0 { i64::MIN / 2 } else { a - 1 };
            let hi = if b == n { i64::MAX / 2 } else { b };
            out.extend(reach(lo, hi));
        }
        WrapMode::Repeat => {
            // Windows reach texels -1 ..= 4 samples + 4 < n + 8: copies shifted by -n .. 2n.
            if max - min >= n || n <= 8 {
                return vec![(0, s)];
            }
            let a = min.rem_euclid(n);
            let b = a + (max - min);
            for shift in [-n, 0, n, 2 * n] {
                out.extend(reach(a - 1 + shift, b + shift));
            }
        }
    }
    out.sort_unstable();
    // Merge overlapping ranges so no sample is computed twice.
    let mut merged: Vec<(i64, i64)> = Vec::new();
    for (a, b) in out {
        match merged.last_mut() {
            Some(last) if a <= last.1 => last.1 = last.1.max(b),
            _ => merged.push((a, b)),
        }
    }
    merged
}

/// The size of level 0 for a heightfield of `map_size` texels: a quarter, rounded up.
pub fn density_size(map_size: UVec2) -> UVec2 {
    UVec2::new(
        map_size.x.div_ceil(DENSITY_DOWNSAMPLE),
        map_size.y.div_ceil(DENSITY_DOWNSAMPLE),
    )
}

/// Fills `out` with the `len` stored heights of row `y` from column `x0` on (wrapped or
/// clamped), as f32: exact below 2^24, so the filters' differences of u8 and u16 samples are
/// exact before they are scaled to metres.
fn load_row<T: HeightSample>(
    h: &Grid<T>,
    wrap: WrapMode,
    y: i64,
    x0: i64,
    len: usize,
    out: &mut Vec<f32>,
) {
    let row = h.row(wrap.resolve(y, h.height()));
    let w = h.width();
    out.clear();
    let direct = x0 >= 0 && x0 + len as i64 <= i64::from(w);
    if direct {
        let s = &row[x0 as usize..x0 as usize + len];
        out.extend(s.iter().map(|v| v.to_raw_f64() as f32));
    } else {
        out.extend(
            (0..len as i64).map(|k| row[wrap.resolve(x0 + k, w) as usize].to_raw_f64() as f32),
        );
    }
}

/// Applies `filter` to the texels `1 ..= colmax.len()` of the centre row of `rows` (stored
/// heights, each row one longer on both sides; `scale` metres per stored unit) and keeps the
/// column maxima in `colmax`. The filter is chosen once per row, not per texel.
fn filter_row(
    filter: CurvatureFilter,
    rows: &[Vec<f32>; 3],
    scale: f32,
    spacing: f32,
    colmax: &mut [f32],
) {
    match filter {
        CurvatureFilter::Laplace => filter_row_with(rows, scale, colmax, |d| {
            curvature(CurvatureFilter::Laplace, d, spacing)
        }),
        CurvatureFilter::Gaussian => filter_row_with(rows, scale, colmax, |d| {
            curvature(CurvatureFilter::Gaussian, d, spacing)
        }),
        CurvatureFilter::Mean => filter_row_with(rows, scale, colmax, |d| {
            curvature(CurvatureFilter::Mean, d, spacing)
        }),
        CurvatureFilter::LaplaceBeltramiArea => filter_row_with(rows, scale, colmax, |d| {
            curvature(CurvatureFilter::LaplaceBeltramiArea, d, spacing)
        }),
        CurvatureFilter::LaplaceBeltramiVoronoi => filter_row_with(rows, scale, colmax, |d| {
            curvature(CurvatureFilter::LaplaceBeltramiVoronoi, d, spacing)
        }),
    }
}

#[inline(always)]
fn filter_row_with(
    rows: &[Vec<f32>; 3],
    scale: f32,
    colmax: &mut [f32],
    f: impl Fn(&Neighbourhood) -> f32,
) {
    let [up, here, down] = rows;
    for (x, m) in colmax.iter_mut().enumerate() {
        let c = here[x + 1];
        // Differences of stored integers are exact; only the scale to metres rounds.
        let d: Neighbourhood = [
            (here[x] - c) * scale,
            (here[x + 2] - c) * scale,
            (up[x + 1] - c) * scale,
            (down[x + 1] - c) * scale,
            (up[x] - c) * scale,
            (up[x + 2] - c) * scale,
            (down[x] - c) * scale,
            (down[x + 2] - c) * scale,
        ];
        let v = f(&d);
        if v > *m {
            *m = v;
        }
    }
}
