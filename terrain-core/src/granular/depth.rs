//! Depth from below (Persson 2019, sec. 4.1.2): an exact CPU rasterizer of the lowest surface of the
//! objects above each column of an active area, in the map's fixed-point height units.
//!
//! Rasterization rule: the orthographic frustum looks up along +Y and covers the active area.
//! Column `(x, y)` is sampled at its map position, world `(x * texel_size, y * texel_size)` in
//! X and Z (the crate convention: sample `(x, y)` stands there). Triangles are projected to the
//! XZ plane in texel units (`u = X / texel_size`, `v = Z / texel_size`), oriented to positive
//! area, and cover a sample when all three edge functions are positive, or zero on a
//! top-left edge (an edge whose inward normal points to `+u`, or to `+v` when horizontal), so a
//! sample on an edge shared by two triangles is covered exactly once and a box from `a` to `b`
//! covers the half-open footprint `[a, b)`. Triangles with zero projected area (vertical faces)
//! cover nothing. The depth is the height at the sample interpolated on the plane of each
//! covering triangle (f64), minimised over all triangles of all objects, and converted with
//! `floor((y - offset) / scale)` clamped to `0 ..= NO_OBJECT - 1`. Uncovered samples hold
//! [`NO_OBJECT`].

use glam::{DVec2, UVec2};

use super::{GranularError, GranularObject, check_area};
use crate::{FixedPointMap, Grid, HeightEncoding, Rect};

/// Depth of a column that no object covers.
pub const NO_OBJECT: u32 = u32::MAX;

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
    out.as_mut_slice().fill(NO_OBJECT);
    let ts = f64::from(texel_size);
    let scale = f64::from(encoding.scale);
    let offset = f64::from(encoding.offset);
    let (x0, y0) = (i64::from(area.min.x), i64::from(area.min.y));
    let (x1, y1) = (x0 + i64::from(area.size.x), y0 + i64::from(area.size.y));
    let width = area.size.x as usize;
    for object in objects {
        let verts = object.world_vertices()?;
        for tri in object.mesh.triangles() {
            let p = tri.map(|i| verts[i as usize].as_dvec3());
            let mut a = DVec2::new(p[0].x / ts, p[0].z / ts);
            let mut b = DVec2::new(p[1].x / ts, p[1].z / ts);
            let c = DVec2::new(p[2].x / ts, p[2].z / ts);
            let (mut ya, mut yb, yc) = (p[0].y, p[1].y, p[2].y);
            let mut area2 = (b - a).perp_dot(c - a);
            if area2 == 0.0 {
                continue;
            }
            if area2 < 0.0 {
                std::mem::swap(&mut a, &mut b);
                std::mem::swap(&mut ya, &mut yb);
                area2 = -area2;
            }
            let lo = a.min(b).min(c);
            let hi = a.max(b).max(c);
            let bx0 = (lo.x.ceil() as i64).max(x0);
            let by0 = (lo.y.ceil() as i64).max(y0);
            let bx1 = (hi.x.floor() as i64 + 1).min(x1);
            let by1 = (hi.y.floor() as i64 + 1).min(y1);
            let edges = [(b, c), (c, a), (a, b)];
            let top_left = edges.map(|(s, e)| {
                let d = e - s;
                d.y < 0.0 || (d.y == 0.0 && d.x > 0.0)
            });
            for y in by0..by1 {
                for x in bx0..bx1 {
                    let q = DVec2::new(x as f64, y as f64);
                    let mut w = [0.0f64; 3];
                    let mut inside = true;
                    for (k, (s, e)) in edges.iter().enumerate() {
                        let wk = (*e - *s).perp_dot(q - *s);
                        if wk < 0.0 || (wk == 0.0 && !top_left[k]) {
                            inside = false;
                            break;
                        }
                        w[k] = wk;
                    }
                    if !inside {
                        continue;
                    }
                    // w[0] weighs a (opposite edge b-c), w[1] weighs b, w[2] weighs c.
                    let h = (w[0] * ya + w[1] * yb + w[2] * yc) / area2;
                    let raw = ((h - offset) / scale).floor();
                    let units = if raw.is_nan() || raw <= 0.0 {
                        0
                    } else if raw >= f64::from(NO_OBJECT - 1) {
                        NO_OBJECT - 1
                    } else {
                        raw as u32
                    };
                    let idx = (y - y0) as usize * width + (x - x0) as usize;
                    let slot = &mut out.as_mut_slice()[idx];
                    *slot = (*slot).min(units);
                }
            }
        }
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
    let min = glam::IVec2::new(clampi(lo.x), clampi(lo.y));
    let max = glam::IVec2::new(clampi(hi.x) + 1, clampi(hi.y) + 1);
    Ok(Rect::new(
        min,
        UVec2::new((max.x - min.x) as u32, (max.y - min.y) as u32),
    ))
}
