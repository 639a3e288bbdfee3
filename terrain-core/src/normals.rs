//! Partial-derivative normal maps (Flower 2010, sec. 3.1.2, 3.2.2): the 4th-order difference of
//! eq. 3.3, packing to two signed 8-bit components, normal reconstruction, composite normals
//! (eq. 3.4) and regeneration limited to a dirty rect plus its 2-texel apron.
//!
//! A derivative map stores the height gradient `(dh/dX, dh/dZ)` in metres per metre. The unit
//! normal is `normalize(-dh/dX, 1, -dh/dZ)` (Y up): the `N = t x b` of Flower 2010, eq. 3.2.

use crate::error::CoreError;
use crate::grid::{Grid, WrapMode};
use crate::map::{HeightMap, HeightSample};
use crate::rect::Rect;
use crate::sample::{bilinear_taps, check_position};
use glam::{UVec2, Vec2, Vec3};

/// Texels the 4th-order difference reads on each side: a height change at a texel changes the
/// derivatives up to this far away, so regeneration covers the dirty rect plus this apron.
pub const DERIVATIVE_APRON: u32 = 2;

/// Slope stored at ±127 by [`DerivativeMap::to_snorm8`] by default. Flower 2010 packs derivatives
/// into two 8-bit channels and reconstructs with `N_y = 1`, limiting normals to a 45° cone:
/// a slope of 1 is the steepest it represents.
pub const DEFAULT_SNORM_MAX_SLOPE: f32 = 1.0;

/// Fewest texels regenerated on the pool's threads: below this (a 256 x 256 rect) handing
/// rows to another thread costs more than it saves.
const PARALLEL_TEXELS: usize = 1 << 16;

/// Height gradients of a map, one per texel, with the map's spacing and wrap mode.
#[derive(Debug, Clone, PartialEq)]
pub struct DerivativeMap {
    grid: Grid<Vec2>,
    texel_size: f32,
    wrap: WrapMode,
}

impl DerivativeMap {
    /// Computes the derivatives of every texel of `map`.
    pub fn from_map<T: HeightSample>(map: &HeightMap<T>) -> Self {
        let grid = map.grid().map(|_| Vec2::ZERO);
        let mut out = Self {
            grid,
            texel_size: map.texel_size(),
            wrap: map.wrap(),
        };
        out.fill(map, map.grid().rect());
        out
    }

    /// Recomputes the derivatives that a height change inside `dirty` can affect: `dirty` grown
    /// by [`DERIVATIVE_APRON`] texels, wrapped on a repeating map and clipped on a clamped one.
    ///
    /// Fails if `map` is not the size of this derivative map, or if `dirty` does not lie inside
    /// a clamped map.
    pub fn update_rect<T: HeightSample>(
        &mut self,
        map: &HeightMap<T>,
        dirty: Rect,
    ) -> Result<(), CoreError> {
        if map.size() != self.grid.size() {
            return Err(CoreError::SizeMismatch {
                expected: self.grid.size(),
                actual: map.size(),
            });
        }
        if let Some(region) = derivative_region(map.size(), map.wrap(), dirty)? {
            for piece in region.split_toroidal(map.size()) {
                self.fill(map, piece.map);
            }
        }
        Ok(())
    }

    /// Writes the derivatives of `rect` (inside the map) from the heights of `map`, rows in
    /// parallel for a large rect. Eq. 3.3 on integer samples is an exact integer in f64
    /// (|sum| < 18 * 2^32), so the order of its terms does not matter and every path gives the
    /// same bits.
    fn fill<T: HeightSample>(&mut self, map: &HeightMap<T>, rect: Rect) {
        let h = map.grid();
        let wrap = map.wrap();
        let (w, hh) = (h.width() as usize, h.height());
        // Eq. 3.3 reorganised: h'(x) = (h(x-2) - 8 h(x-1) + 8 h(x+1) - h(x+2)) / (12 xi),
        // with heights in metres = offset + scale * raw (the offset cancels).
        let k = f64::from(map.encoding().scale) / (12.0 * f64::from(map.texel_size()));
        let (x0, x1) = (rect.min.x as usize, rect.max().x as usize);
        let (y0, y1) = (rect.min.y as usize, rect.max().y as usize);
        let out = &mut self.grid.as_mut_slice()[y0 * w..y1 * w];
        let diff = |a: T, b: T, c: T, d: T| {
            (a.to_raw_f64() - d.to_raw_f64()) + 8.0 * (c.to_raw_f64() - b.to_raw_f64())
        };
        // Columns whose 4 horizontal taps are inside the row need no wrapping. The others (at
        // most two on each side, where the rect meets the map's edge) have their columns
        // resolved once here, not in every row (wrapping costs an integer division).
        let (ia, ib) = (x0.max(2), x1.min(w.saturating_sub(2)).max(x0.max(2)));
        let border: Vec<(usize, [usize; 4])> = (x0..ia.min(x1))
            .chain(ib.max(x0)..x1)
            .map(|x| {
                (
                    x,
                    [-2, -1, 1, 2].map(|d| wrap.resolve(x as i64 + d, w as u32) as usize),
                )
            })
            .collect();
        let body = |j: usize, out_row: &mut [Vec2]| {
            let y = (y0 + j) as i64;
            let row_of = |d: i64| {
                let r = y + d;
                h.row(if (0..i64::from(hh)).contains(&r) {
                    r as u32
                } else {
                    wrap.resolve(r, hh)
                })
            };
            let (up2, up1, here, dn1, dn2) =
                (row_of(-2), row_of(-1), row_of(0), row_of(1), row_of(2));
            for &(x, [l2, l1, r1, r2]) in &border {
                let dx = diff(here[l2], here[l1], here[r1], here[r2]);
                let dz = diff(up2[x], up1[x], dn1[x], dn2[x]);
                out_row[x] = Vec2::new((dx * k) as f32, (dz * k) as f32);
            }
            if ia < ib {
                let n = ib - ia;
                let o = &mut out_row[ia..ib];
                let (hl2, hl1) = (&here[ia - 2..ib - 2], &here[ia - 1..ib - 1]);
                let (hr1, hr2) = (&here[ia + 1..ib + 1], &here[ia + 2..ib + 2]);
                let (u2, u1, d1, d2) = (&up2[ia..ib], &up1[ia..ib], &dn1[ia..ib], &dn2[ia..ib]);
                let taps = [hl2, hl1, hr1, hr2, u2, u1, d1, d2];
                if !interior_small::<T, u16>(taps, o, k) && !interior_small::<T, u8>(taps, o, k) {
                    for i in 0..n {
                        let dx = diff(hl2[i], hl1[i], hr1[i], hr2[i]);
                        let dz = diff(u2[i], u1[i], d1[i], d2[i]);
                        o[i] = Vec2::new((dx * k) as f32, (dz * k) as f32);
                    }
                }
            }
        };
        // Rows in parallel only where there are enough texels to pay for waking the pool.
        if (x1 - x0) * (y1 - y0) >= PARALLEL_TEXELS {
            crate::par::for_each_chunk(out, w, body);
        } else {
            for (j, out_row) in out.chunks_mut(w).enumerate() {
                body(j, out_row);
            }
        }
    }

    /// A derivative map from gradients computed elsewhere (a GPU pass's download).
    pub fn from_grid(grid: Grid<Vec2>, texel_size: f32, wrap: WrapMode) -> Result<Self, CoreError> {
        crate::map::check_texel_size(texel_size)?;
        Ok(Self {
            grid,
            texel_size,
            wrap,
        })
    }

    /// The gradients, one per texel.
    pub fn grid(&self) -> &Grid<Vec2> {
        &self.grid
    }

    /// Metres per texel of the map the derivatives came from.
    pub fn texel_size(&self) -> f32 {
        self.texel_size
    }

    /// Gradient at texel `(x, y)`, or `None` outside the map.
    pub fn derivative(&self, x: u32, y: u32) -> Option<Vec2> {
        self.grid.get(x, y)
    }

    /// Unit normal at texel `(x, y)`, or `None` outside the map.
    pub fn normal(&self, x: u32, y: u32) -> Option<Vec3> {
        self.grid.get(x, y).map(normal_from_derivatives)
    }

    /// Gradient at world position `pos = (X, Z)` in metres, interpolated bilinearly with the
    /// map's wrap mode: what a detail map's gradient is looked up with for eq. 3.4.
    pub fn sample(&self, pos: Vec2) -> Result<Vec2, CoreError> {
        check_position(pos)?;
        let (taps, [fx, fz]) = bilinear_taps(pos / self.texel_size);
        let d = taps.map(|t| self.grid.get_wrapped(t, self.wrap));
        let (fx, fz) = (fx as f32, fz as f32);
        Ok(d[0].lerp(d[1], fx).lerp(d[2].lerp(d[3], fx), fz))
    }

    /// Packs the gradients into two signed 8-bit components: `round(clamp(d / max_slope, -1, 1)
    /// * 127)`, so ±127 stands for a slope of ±`max_slope` and one step is `max_slope / 127`.
    pub fn to_snorm8(&self, max_slope: f32) -> Result<Grid<[i8; 2]>, CoreError> {
        check_max_slope(max_slope)?;
        let pack = |v: f32| ((v / max_slope).clamp(-1.0, 1.0) * 127.0).round() as i8;
        Ok(self.grid.map(|d| [pack(d.x), pack(d.y)]))
    }

    /// Unpacks two signed 8-bit components written by [`DerivativeMap::to_snorm8`].
    pub fn from_snorm8(
        packed: &Grid<[i8; 2]>,
        max_slope: f32,
        texel_size: f32,
        wrap: WrapMode,
    ) -> Result<Self, CoreError> {
        check_max_slope(max_slope)?;
        crate::map::check_texel_size(texel_size)?;
        let unpack = |v: i8| f32::from(v.max(-127)) / 127.0 * max_slope;
        Ok(Self {
            grid: packed.map(|p| Vec2::new(unpack(p[0]), unpack(p[1]))),
            texel_size,
            wrap,
        })
    }
}

/// The gradient of one texel `(x, y)` of `map` by eq. 3.3, with the map's wrap mode: the same
/// bits as [`DerivativeMap::from_map`] gives there, for callers that need a few texels' slopes
/// (an overview's pixels) without a whole derivative map. `None` outside the map.
pub fn derivative_at<T: HeightSample>(map: &HeightMap<T>, x: u32, y: u32) -> Option<Vec2> {
    let h = map.grid();
    if x >= h.width() || y >= h.height() {
        return None;
    }
    let wrap = map.wrap();
    let k = f64::from(map.encoding().scale) / (12.0 * f64::from(map.texel_size()));
    let at = |dx: i64, dy: i64| {
        let col = wrap.resolve(i64::from(x) + dx, h.width());
        h.row(wrap.resolve(i64::from(y) + dy, h.height()))[col as usize].to_raw_f64()
    };
    let diff = |a: f64, b: f64, c: f64, d: f64| (a - d) + 8.0 * (c - b);
    let dx = diff(at(-2, 0), at(-1, 0), at(1, 0), at(2, 0));
    let dz = diff(at(0, -2), at(0, -1), at(0, 1), at(0, 2));
    Some(Vec2::new((dx * k) as f32, (dz * k) as f32))
}

/// The interior loop of [`DerivativeMap::fill`] for u8 / u16 samples (when `T` is `S`): eq. 3.3
/// in i32 (exact: |sum| < 18 * 65 536), then the same f64 product and f32 rounding as the
/// generic loop, so the same bits. Returns false (and does nothing) for other sample types.
fn interior_small<T: HeightSample, S: bytemuck::Pod + Into<i32>>(
    taps: [&[T]; 8],
    out: &mut [Vec2],
    k: f64,
) -> bool {
    if std::any::TypeId::of::<T>() != std::any::TypeId::of::<S>() {
        return false;
    }
    let [
        Some(hl2),
        Some(hl1),
        Some(hr1),
        Some(hr2),
        Some(u2),
        Some(u1),
        Some(d1),
        Some(d2),
    ] = taps.map(|s| bytemuck::try_cast_slice::<T, S>(s).ok())
    else {
        return false;
    };
    interior_loop([hl2, hl1, hr1, hr2, u2, u1, d1, d2], out, k);
    true
}

/// Eq. 3.3 over `out.len()` texels from the eight tap rows, compiled for AVX-512 and AVX2 too
/// (integer and IEEE operations only: the same bits on every instruction set; the f64 steps
/// run 8 wide on AVX-512, a fifth faster).
#[multiversion::multiversion(targets(
    "x86_64+avx512f+avx512bw+avx512vl+avx512dq+avx2+fma",
    "x86_64+avx2+fma"
))]
fn interior_loop<S: bytemuck::Pod + Into<i32>>(taps: [&[S]; 8], out: &mut [Vec2], k: f64) {
    let d = |a: S, b: S, c: S, e: S| {
        let (a, b, c, e): (i32, i32, i32, i32) = (a.into(), b.into(), c.into(), e.into());
        f64::from((a - e) + 8 * (c - b))
    };
    let n = out.len();
    let [hl2, hl1, hr1, hr2, u2, u1, d1, d2] = taps.map(|t| &t[..n]);
    for i in 0..n {
        let dx = d(hl2[i], hl1[i], hr1[i], hr2[i]);
        let dz = d(u2[i], u1[i], d1[i], d2[i]);
        out[i] = Vec2::new((dx * k) as f32, (dz * k) as f32);
    }
}

/// The texels whose derivatives change when heights inside `dirty` change, on a map of
/// `map_size` texels: `dirty` grown by [`DERIVATIVE_APRON`], in unwrapped coordinates on a
/// repeating map (at most one period per axis) and clipped to a clamped map. `None` for an
/// empty `dirty`; an error if `dirty` is not inside a clamped map.
pub fn derivative_region(
    map_size: UVec2,
    wrap: WrapMode,
    dirty: Rect,
) -> Result<Option<Rect>, CoreError> {
    if dirty.is_empty() {
        return Ok(None);
    }
    let grown = dirty.expand(DERIVATIVE_APRON);
    match wrap {
        WrapMode::Repeat => {
            // Limit each axis to one period: beyond that the same texels would repeat.
            let mut r = grown;
            for axis in 0..2 {
                if r.size[axis] >= map_size[axis] {
                    r.min[axis] = 0;
                    r.size[axis] = map_size[axis];
                }
            }
            Ok(Some(r))
        }
        WrapMode::Clamp => {
            let map = Rect::from_size(map_size);
            if !map.contains_rect(&dirty) {
                return Err(CoreError::RegionOutOfBounds {
                    rect: dirty,
                    map_size,
                });
            }
            Ok(grown.intersect(&map))
        }
    }
}

fn check_max_slope(max_slope: f32) -> Result<(), CoreError> {
    if !max_slope.is_finite() || max_slope <= 0.0 {
        return Err(CoreError::OutOfRange {
            what: "derivative packing max_slope",
            value: f64::from(max_slope),
            expected: "finite and greater than 0",
        });
    }
    Ok(())
}

/// The unit normal of a height gradient: `normalize(-dh/dX, 1, -dh/dZ)`.
pub fn normal_from_derivatives(d: Vec2) -> Vec3 {
    Vec3::new(-d.x, 1.0, -d.y).normalize()
}

/// The composite normal of a coarse and a detail gradient at the same point (Flower 2010, eq. 3.4):
/// derivatives add, so no tangent space is needed.
pub fn composite_normal(coarse: Vec2, detail: Vec2) -> Vec3 {
    normal_from_derivatives(coarse + detail)
}
