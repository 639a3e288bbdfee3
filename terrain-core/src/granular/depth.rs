//! Depth from below (Persson 2019, sec. 4.1.2): an exact integer rasterizer of the lowest surface
//! of the objects above each column of an active area, in the map's fixed-point height units.
//! The GPU pass (`terrain_gpu::granular::DepthFromBelowPass`) runs the same integer program on
//! the same [`DepthTriangle`]s, so both give bit-identical depths on any conforming GPU.
//!
//! # The integer program
//!
//! The orthographic frustum looks up along +Y and covers the active area. Column `(x, y)` is
//! sampled at its map position, world `(x * texel_size, y * texel_size)` in X and Z (the crate
//! convention: sample `(x, y)` stands there). Per triangle, once, in f64 (IEEE-exact `/ * round`
//! only, so the same integers on every platform), [`depth_triangle`] makes a [`DepthTriangle`]:
//!
//! 1. **Snapping.** Each vertex is projected to texel units (`u = X / texel_size`,
//!    `v = Z / texel_size`) and snapped to the Q8 sub-texel grid, `U = round(256 u)` (half away
//!    from zero), absolutely, so a vertex shared by two triangles snaps to the same point and
//!    shared edges stay watertight. The per-triangle origin is `floor(min U / 256)` (in whole
//!    texels) and the vertices are stored relative to it (`0 <= U - 256 origin < 2^23`: a
//!    triangle spanning [`MAX_TRIANGLE_SPAN`] texels or more is refused with an error).
//!    After snapping, a triangle of zero area (a vertical face, or one thinner than the grid)
//!    covers nothing; otherwise it is oriented to positive area.
//! 2. **Heights.** Each vertex's height in units, `t = (Y - offset) / scale` (clamped to
//!    `±2^40`), is snapped to `H = round(t 2^f)` with `f` fractional bits; `base =
//!    floor(min H / 2^f)` and the vertex keeps `r = H - base 2^f >= 0`. `f` is 8, or less for a
//!    triangle whose area times height span would not fit (`r < 2^32` and `area2 * max r <
//!    2^62`, with `area2` twice the Q8 area); a triangle that fits with no `f` is refused.
//!
//! Per sample `P` (in Q8 relative to the origin, `256 (x - origin)`) inside the triangle's
//! bounding box, [`rasterize_triangle`] then computes, in exact integers:
//!
//! 3. **Coverage.** The edge functions `w_k = (e - s) x (P - s)` over the edges `(b, c)`,
//!    `(c, a)`, `(a, b)` (each below 2^47 in magnitude). The sample is covered when all three
//!    are positive, or zero on a top-left edge (`e - s` has `dy < 0`, or `dy == 0` and
//!    `dx > 0`), so a sample on an edge shared by two triangles is covered exactly once and a
//!    box from `a` to `b` covers the half-open footprint `[a, b)`.
//! 4. **Depth.** `q = floor((w_0 r_a + w_1 r_b + w_2 r_c) / area2)` (the numerator is
//!    non-negative and below 2^62, so floor and truncation agree), then
//!    `units = base + floor(q / 2^f)`, clamped to `0 ..= NO_OBJECT - 1`, minimised over all
//!    triangles of all objects. Uncovered samples hold [`NO_OBJECT`].
//!
//! Against the earlier f64 rasterizer this moves edges by at most 1/512 texel (a sample within
//! that of an edge may change sides: a box edge computed as 20.000001 texels now lies on the
//! sample and is covered by the top-left rule) and heights by at most a unit (the vertex
//! heights' 1/256 unit snapping, and the position snapping on steep faces).

use glam::{DVec2, IVec2, UVec2};

use super::{GranularError, GranularObject, check_area};
use crate::{CoreError, FixedPointMap, Grid, HeightEncoding, Rect};

/// Depth of a column that no object covers.
pub const NO_OBJECT: u32 = u32::MAX;

/// Sub-texel bits of snapped vertex positions (Q8: 1/256 texel).
pub const SUBTEXEL_BITS: u32 = 8;

/// Largest fractional bits of vertex heights (1/256 unit).
pub const MAX_HEIGHT_FRAC_BITS: u32 = 8;

/// A triangle's bounding box must span fewer texels than this on each axis (its snapped
/// vertices relative to its origin then fit in 23 bits, and every edge function product in 47).
pub const MAX_TRIANGLE_SPAN: i64 = 1 << 15;

/// Bound on the depth numerator `area2 * max r` (and so on every sum of weighted heights).
const NUMERATOR_LIMIT: i128 = 1 << 62;

/// One triangle of the depth program in integers (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DepthTriangle {
    /// Whole-texel origin in map columns: the floor of the snapped bounding box's minimum.
    pub origin: [i64; 2],
    /// Vertices `a, b, c` in Q8 texels relative to `origin`, in `0 .. 2^23`, oriented so that
    /// `area2 > 0`.
    pub verts: [[i32; 2]; 3],
    /// Twice the Q8 area: `(b - a) x (c - a)`, positive.
    pub area2: i64,
    /// Heights of `a, b, c` above `base`, in units of `2^-frac_bits`.
    pub rel: [u32; 3],
    /// Fixed-point units of the triangle's lowest vertex, floored (not clamped).
    pub base: i64,
    /// Fractional bits of `rel`, `0 ..= MAX_HEIGHT_FRAC_BITS`.
    pub frac_bits: u32,
    /// The samples the triangle may cover, in map columns: `min` inclusive, `max` exclusive.
    pub samples_min: [i64; 2],
    /// See `samples_min`.
    pub samples_max: [i64; 2],
}

impl DepthTriangle {
    /// The depth (clamped fixed-point units) of the triangle at column `(x, y)`, or `None` if
    /// it does not cover it: steps 3 and 4 of the program.
    pub fn depth_at(&self, x: i64, y: i64) -> Option<u32> {
        let p = [
            (x - self.origin[0]) << SUBTEXEL_BITS,
            (y - self.origin[1]) << SUBTEXEL_BITS,
        ];
        let v = self.verts.map(|v| [i64::from(v[0]), i64::from(v[1])]);
        let mut w = [0i64; 3];
        for (k, (s, e)) in [(v[1], v[2]), (v[2], v[0]), (v[0], v[1])]
            .into_iter()
            .enumerate()
        {
            let d = [e[0] - s[0], e[1] - s[1]];
            let wk = d[0] * (p[1] - s[1]) - d[1] * (p[0] - s[0]);
            let top_left = d[1] < 0 || (d[1] == 0 && d[0] > 0);
            if wk < 0 || (wk == 0 && !top_left) {
                return None;
            }
            w[k] = wk;
        }
        // w[0] weighs a (opposite edge b-c), w[1] weighs b, w[2] weighs c; each product and
        // the sum stay below 2^62 (checked when the triangle was made).
        let num = w[0] * i64::from(self.rel[0])
            + w[1] * i64::from(self.rel[1])
            + w[2] * i64::from(self.rel[2]);
        let q = num / self.area2;
        let units = self.base + (q >> self.frac_bits);
        Some(units.clamp(0, i64::from(NO_OBJECT - 1)) as u32)
    }
}

/// Step 1 and 2 of the program for one world-space triangle: `None` when it has no area after
/// snapping or cannot cover a sample of `area`. Fails on a triangle spanning
/// [`MAX_TRIANGLE_SPAN`] texels or more, or whose vertices lie beyond `2^44` texels.
pub fn depth_triangle(
    p: [glam::DVec3; 3],
    encoding: HeightEncoding,
    texel_size: f32,
    area: Rect,
) -> Result<Option<DepthTriangle>, GranularError> {
    let ts = f64::from(texel_size);
    let q8 = f64::from(1u32 << SUBTEXEL_BITS);
    let limit = (1u64 << 52) as f64;
    let mut snapped = [[0i64; 2]; 3];
    for (k, v) in p.iter().enumerate() {
        for (j, c) in [v.x, v.z].into_iter().enumerate() {
            let s = (c / ts * q8).round();
            if s.is_nan() || s.abs() >= limit {
                return Err(CoreError::OutOfRange {
                    what: "granular vertex position in 1/256 texels",
                    value: s,
                    expected: "below 2^52 (world coordinate / texel size)",
                }
                .into());
            }
            snapped[k][j] = s as i64;
        }
    }
    let mut lo = [i64::MAX; 2];
    let mut hi = [i64::MIN; 2];
    for s in &snapped {
        for j in 0..2 {
            lo[j] = lo[j].min(s[j]);
            hi[j] = hi[j].max(s[j]);
        }
    }
    let one = 1i64 << SUBTEXEL_BITS;
    let origin = lo.map(|l| l.div_euclid(one));
    // Samples inside the snapped bounding box, clipped to the area.
    let area_min = [i64::from(area.min.x), i64::from(area.min.y)];
    let area_max = [
        area_min[0] + i64::from(area.size.x),
        area_min[1] + i64::from(area.size.y),
    ];
    let mut samples_min = [0i64; 2];
    let mut samples_max = [0i64; 2];
    for j in 0..2 {
        samples_min[j] = (lo[j] + one - 1).div_euclid(one).max(area_min[j]);
        samples_max[j] = (hi[j].div_euclid(one) + 1).min(area_max[j]);
        if samples_min[j] >= samples_max[j] {
            return Ok(None);
        }
    }
    let span = MAX_TRIANGLE_SPAN << SUBTEXEL_BITS;
    let mut verts = [[0i32; 2]; 3];
    for (k, s) in snapped.iter().enumerate() {
        for j in 0..2 {
            let r = s[j] - origin[j] * one;
            if r >= span {
                return Err(CoreError::OutOfRange {
                    what: "granular triangle extent in texels",
                    value: (hi[j] - lo[j]) as f64 / one as f64,
                    expected: "below MAX_TRIANGLE_SPAN (32768) texels on each axis: \
                               split the mesh's larger triangles",
                }
                .into());
            }
            verts[k][j] = r as i32;
        }
    }
    let scale = f64::from(encoding.scale);
    let offset = f64::from(encoding.offset);
    let height_limit = (1u64 << 40) as f64;
    let mut units = p.map(|v| ((v.y - offset) / scale).clamp(-height_limit, height_limit));
    let e = |a: [i32; 2], b: [i32; 2]| [i64::from(b[0] - a[0]), i64::from(b[1] - a[1])];
    let (ab, ac) = (e(verts[0], verts[1]), e(verts[0], verts[2]));
    let mut area2 = ab[0] * ac[1] - ab[1] * ac[0];
    if area2 == 0 {
        return Ok(None);
    }
    if area2 < 0 {
        verts.swap(0, 1);
        units.swap(0, 1);
        area2 = -area2;
    }
    for frac_bits in (0..=MAX_HEIGHT_FRAC_BITS).rev() {
        let scaled = units.map(|t| (t * f64::from(1u32 << frac_bits)).round() as i64);
        let base = scaled[0]
            .min(scaled[1])
            .min(scaled[2])
            .div_euclid(1i64 << frac_bits);
        let rel = scaled.map(|h| h - (base << frac_bits));
        let max_rel = rel[0].max(rel[1]).max(rel[2]);
        if max_rel <= i64::from(u32::MAX)
            && i128::from(area2) * i128::from(max_rel) < NUMERATOR_LIMIT
        {
            return Ok(Some(DepthTriangle {
                origin,
                verts,
                area2,
                rel: rel.map(|r| r as u32),
                base,
                frac_bits,
                samples_min,
                samples_max,
            }));
        }
    }
    Err(CoreError::OutOfRange {
        what: "granular triangle height span in units",
        value: (units[0].max(units[1]).max(units[2]) - units[0].min(units[1]).min(units[2])),
        expected: "small enough that twice its area in 1/256 texels times it stays below 2^62",
    }
    .into())
}

/// Every [`DepthTriangle`] of `objects` that may cover a column of `area`, appended to `out`
/// (cleared first) in object and mesh order.
pub fn depth_triangles(
    objects: &[GranularObject<'_>],
    encoding: HeightEncoding,
    texel_size: f32,
    area: Rect,
    out: &mut Vec<DepthTriangle>,
) -> Result<(), GranularError> {
    out.clear();
    for object in objects {
        let verts = object.world_vertices()?;
        for tri in object.mesh.triangles() {
            let mut p = [glam::DVec3::ZERO; 3];
            for (k, &i) in tri.iter().enumerate() {
                // Indices were checked by `TriMesh::new`; `get` keeps a bad one from panicking.
                p[k] = verts
                    .get(i as usize)
                    .ok_or(CoreError::OutOfRange {
                        what: "granular mesh vertex index",
                        value: f64::from(i),
                        expected: "below the mesh's vertex count",
                    })?
                    .as_dvec3();
            }
            if let Some(t) = depth_triangle(p, encoding, texel_size, area)? {
                out.push(t);
            }
        }
    }
    Ok(())
}

/// Writes `tri`'s depth into `out` (a grid of `area.size`, sample `(i, j)` at column
/// `area.min + (i, j)`) where it is lower than what `out` holds.
pub fn rasterize_triangle(tri: &DepthTriangle, area: Rect, out: &mut Grid<u32>) {
    let (x0, y0) = (i64::from(area.min.x), i64::from(area.min.y));
    let width = out.width() as usize;
    let bx0 = tri.samples_min[0].max(x0);
    let by0 = tri.samples_min[1].max(y0);
    let bx1 = tri.samples_max[0].min(x0 + i64::from(out.width()));
    let by1 = tri.samples_max[1].min(y0 + i64::from(out.height()));
    for y in by0..by1 {
        for x in bx0..bx1 {
            if let Some(units) = tri.depth_at(x, y) {
                let idx = (y - y0) as usize * width + (x - x0) as usize;
                let slot = &mut out.as_mut_slice()[idx];
                *slot = (*slot).min(units);
            }
        }
    }
}

/// The depth texture of `objects` over `area` (which must lie inside the map): a grid of
/// `area.size` whose sample `(i, j)` is column `area.min + (i, j)`.
pub fn depth_from_below(
    objects: &[GranularObject<'_>],
    map: &FixedPointMap,
    area: Rect,
) -> Result<Grid<u32>, GranularError> {
    check_area(area, map.size())?;
    let mut out = Grid::new(area.size.x, area.size.y, NO_OBJECT)?;
    depth_from_below_into(objects, map.encoding(), map.texel_size(), area, &mut out)?;
    Ok(out)
}

/// As [`depth_from_below`], into an existing grid of `area.size` (overwritten).
pub fn depth_from_below_into(
    objects: &[GranularObject<'_>],
    encoding: HeightEncoding,
    texel_size: f32,
    area: Rect,
    out: &mut Grid<u32>,
) -> Result<(), GranularError> {
    if out.size() != area.size {
        return Err(GranularError::SizeMismatch {
            expected: area.size,
            actual: out.size(),
        });
    }
    let mut triangles = Vec::new();
    depth_triangles(objects, encoding, texel_size, area, &mut triangles)?;
    out.as_mut_slice().fill(NO_OBJECT);
    for tri in &triangles {
        rasterize_triangle(tri, area, out);
    }
    Ok(())
}

/// The texel rect covered by an object's world bounding box (`floor(min) ..= ceil(max)` in
/// texel units), before clipping to the map.
pub fn object_footprint(
    object: &GranularObject<'_>,
    texel_size: f32,
) -> Result<Rect, GranularError> {
    let verts = object.world_vertices()?;
    let ts = f64::from(texel_size);
    let mut lo = DVec2::splat(f64::INFINITY);
    let mut hi = DVec2::splat(f64::NEG_INFINITY);
    for v in &verts {
        let p = DVec2::new(f64::from(v.x) / ts, f64::from(v.z) / ts);
        lo = lo.min(p);
        hi = hi.max(p);
    }
    let lo = lo.floor();
    let hi = hi.ceil();
    let clampi = |v: f64| v.clamp(-(1i64 << 30) as f64, (1i64 << 30) as f64) as i32;
    let min = IVec2::new(clampi(lo.x), clampi(lo.y));
    let max = IVec2::new(clampi(hi.x) + 1, clampi(hi.y) + 1);
    Ok(Rect::new(
        min,
        UVec2::new((max.x - min.x) as u32, (max.y - min.y) as u32),
    ))
}
