//! Refinement patterns of Flower 2010, sec. 2.4.3 (eq. 2.2, fig. 2.7): the finest triangles near
//! the camera are split so detail heights can displace them. Every vertex of the coarse grid
//! carries a flag `t` (refine or not); a triangle's pattern is `rho = t0 + 2 t1 + 4 t2`:
//!
//! - `rho = 7`: all three sides split in thirds, nine sub-triangles (sec. 3.2.4: "tessellated
//!   into nine sub-triangles", one vertex per detail texel on a layer refined x3);
//! - `rho = 3, 5, 6`: the one side between the two flagged vertices split in thirds, three
//!   sub-triangles fanned to the third vertex;
//! - `rho = 0, 1, 2, 4`: the triangle as it is.
//!
//! A side is split exactly when both its vertices are flagged, so the two triangles sharing it
//! split it the same way: the mesh is crack-free (no T-junction) by construction, also where
//! refined triangles meet unrefined ones. [`RefineView::refine`] is the CPU reference of the GPU
//! pass (`terrain_gpu::RefinePass`): same region, same flags, same sub-triangles.
//!
//! Positions are integer *thirds* of a coarse texel relative to the camera's whole texel, so
//! both triangles of a side compute its split points bit for bit alike.
//!
//! ```
//! use glam::{IVec2, Vec2};
//! use terrain_lod::refine::{RefineView, pattern, pattern_index};
//!
//! assert_eq!(pattern_index([true, true, true]), 7);
//! assert_eq!(pattern(7).len(), 9);
//! assert_eq!(pattern(5).len(), 3);
//! assert_eq!(pattern(4).len(), 1);
//!
//! // Refined within 2 m of a camera at (10.25 m, 7.5 m) on a 0.5 m grid.
//! let view = RefineView::new(Vec2::new(10.25, 7.5), 0.5, 2.0)?;
//! assert_eq!(view.half_cells(), 5);
//! // Every vertex flagged where it is within the radius: the middle is split into ninths.
//! let triangles = view.refine(|_| true);
//! assert!(triangles.len() > view.base_triangles() as usize);
//! // Nothing flagged: the base triangles as they are, in thirds.
//! let plain = view.refine(|_| false);
//! assert_eq!(plain.len(), view.base_triangles() as usize);
//! assert_eq!(plain[0], view.base_triangle(0).map(|v| v * 3));
//! # Ok::<(), terrain_lod::LodError>(())
//! ```

use crate::LodError;
use glam::{IVec2, Vec2};

/// The largest half side (coarse cells) of a refined region: 2 x 256 cells a side, at most
/// 262 144 base triangles and 2.4 M refined ones.
pub const MAX_REFINE_HALF_CELLS: u32 = 256;

/// The pattern index of eq. 2.2 from the vertex flags `t` of `(v0, v1, v2)`.
pub fn pattern_index(t: [bool; 3]) -> u8 {
    u8::from(t[0]) | (u8::from(t[1]) << 1) | (u8::from(t[2]) << 2)
}

/// A sub-triangle as the barycentric weights (in thirds, summing to 3) of its three vertices.
pub type PatternTriangle = [[u8; 3]; 3];

const WHOLE: [PatternTriangle; 1] = [[[3, 0, 0], [0, 3, 0], [0, 0, 3]]];
/// `rho = 3`: side v0-v1 split, fanned to v2.
const SIDE_01: [PatternTriangle; 3] = [
    [[3, 0, 0], [2, 1, 0], [0, 0, 3]],
    [[2, 1, 0], [1, 2, 0], [0, 0, 3]],
    [[1, 2, 0], [0, 3, 0], [0, 0, 3]],
];
/// `rho = 5`: side v2-v0 split, fanned to v1.
const SIDE_20: [PatternTriangle; 3] = [
    [[0, 0, 3], [1, 0, 2], [0, 3, 0]],
    [[1, 0, 2], [2, 0, 1], [0, 3, 0]],
    [[2, 0, 1], [3, 0, 0], [0, 3, 0]],
];
/// `rho = 6`: side v1-v2 split, fanned to v0.
const SIDE_12: [PatternTriangle; 3] = [
    [[0, 3, 0], [0, 2, 1], [3, 0, 0]],
    [[0, 2, 1], [0, 1, 2], [3, 0, 0]],
    [[0, 1, 2], [0, 0, 3], [3, 0, 0]],
];
/// `rho = 7`: the six upward triangles of the thirds grid, then the three downward ones.
const NINE: [PatternTriangle; 9] = [
    [[3, 0, 0], [2, 1, 0], [2, 0, 1]],
    [[2, 1, 0], [1, 2, 0], [1, 1, 1]],
    [[2, 0, 1], [1, 1, 1], [1, 0, 2]],
    [[1, 2, 0], [0, 3, 0], [0, 2, 1]],
    [[1, 1, 1], [0, 2, 1], [0, 1, 2]],
    [[1, 0, 2], [0, 1, 2], [0, 0, 3]],
    [[0, 1, 2], [1, 0, 2], [1, 1, 1]],
    [[1, 1, 1], [2, 0, 1], [2, 1, 0]],
    [[0, 2, 1], [1, 1, 1], [1, 2, 0]],
];

/// The sub-triangles of pattern `rho` (its low three bits), wound as their parent. The WGSL
/// pass holds the same table (`refine.wgsl`); the GPU == CPU test compares their output.
pub fn pattern(rho: u8) -> &'static [PatternTriangle] {
    match rho & 7 {
        3 => &SIDE_01,
        5 => &SIDE_20,
        6 => &SIDE_12,
        7 => &NINE,
        _ => &WHOLE,
    }
}

/// The square of coarse cells refined around a camera, and which of its vertices lie within
/// the refinement radius.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefineView {
    /// The camera's whole coarse texel (world X, Z over the texel size, floored).
    pub camera_texel: IVec2,
    /// The camera's position within that texel, in `[0, 1)`.
    pub camera_frac: Vec2,
    /// Metres per coarse texel.
    pub texel_size: f32,
    /// Vertices closer than this (metres, horizontally) to the camera may be refined.
    pub radius_m: f32,
}

impl RefineView {
    /// The view of a camera at world `(x, z)` = `camera_xz` metres over a grid of `texel_size`
    /// metres refining within `radius_m`. Fails for non-finite input, a texel size or radius
    /// not above zero, a radius over [`MAX_REFINE_HALF_CELLS`] - 1 texels, or a camera beyond
    /// +-2^30 texels.
    pub fn new(camera_xz: Vec2, texel_size: f32, radius_m: f32) -> Result<Self, LodError> {
        for (what, v) in [
            ("camera.x", camera_xz.x),
            ("camera.z", camera_xz.y),
            ("texel size", texel_size),
            ("refine radius", radius_m),
        ] {
            if !v.is_finite() {
                return Err(LodError::NonFinite { what, value: v });
            }
        }
        if texel_size <= 0.0 {
            return Err(LodError::InvalidTexelSize { texel_size });
        }
        let cells = radius_m / texel_size;
        if !(radius_m > 0.0 && cells <= (MAX_REFINE_HALF_CELLS - 1) as f32) {
            return Err(LodError::InvalidRefineRadius {
                radius_m,
                texel_size,
                max_texels: MAX_REFINE_HALF_CELLS - 1,
            });
        }
        let t = camera_xz / texel_size;
        let whole = t.floor();
        if whole.abs().max_element() > (1u32 << 30) as f32 {
            return Err(LodError::CameraOutOfRange {
                camera: camera_xz,
                texel_size,
            });
        }
        Ok(Self {
            camera_texel: whole.as_ivec2(),
            // At most just below 1 (and 0 for whole positions): (t - floor(t)) in f32.
            camera_frac: (t - whole).min(Vec2::splat(1.0 - f32::EPSILON)),
            texel_size,
            radius_m,
        })
    }

    /// Half the region's side in cells: every vertex on the region's edge lies at least the
    /// radius from the camera (so it is never refined and the edge meets the unrefined mesh).
    pub fn half_cells(&self) -> u32 {
        ((self.radius_m / self.texel_size).ceil() as u32 + 1).min(MAX_REFINE_HALF_CELLS)
    }

    /// The region's first and one-past-last vertex, in texels relative to the camera's whole
    /// texel: cells `-h .. h` on both axes.
    pub fn region(&self) -> (IVec2, IVec2) {
        let h = self.half_cells() as i32;
        (IVec2::splat(-h), IVec2::splat(h))
    }

    /// Base triangles of the region: two per cell.
    pub fn base_triangles(&self) -> u32 {
        let side = 2 * self.half_cells();
        2 * side * side
    }

    /// Whether vertex `v` (texels relative to the camera's whole texel) lies within the radius,
    /// in the f32 operations of the GPU pass.
    pub fn within(&self, v: IVec2) -> bool {
        let dx = (v.x as f32 - self.camera_frac.x) * self.texel_size;
        let dz = (v.y as f32 - self.camera_frac.y) * self.texel_size;
        dx * dx + dz * dz < self.radius_m * self.radius_m
    }

    /// Base triangle `index` (row-major cells, two per cell) as its vertices `(v0, v1, v2)`
    /// relative to the camera's whole texel: `v0 v1` is the cell's diagonal (the clipmap
    /// mesh's, from `(x, z + 1)` to `(x + 1, z)`), wound counter-clockwise seen from above.
    /// Indices past the region wrap around it.
    pub fn base_triangle(&self, index: u32) -> [IVec2; 3] {
        let side = 2 * self.half_cells();
        let cell = (index / 2) % (side * side);
        let (lo, _) = self.region();
        let a = lo + IVec2::new((cell % side) as i32, (cell / side) as i32);
        let (b, d, e) = (a + IVec2::X, a + IVec2::Y, a + IVec2::ONE);
        if index.is_multiple_of(2) {
            [d, b, a]
        } else {
            [b, d, e]
        }
    }

    /// The refined triangles of the region, in base-triangle order, each vertex in thirds of a
    /// texel relative to the camera's whole texel. A vertex is flagged when it lies within the
    /// radius and `has_detail` says it has detail around it (the GPU pass asks whether any
    /// detail tile with a slot lies within one coarse texel and the differences' reach).
    pub fn refine(&self, has_detail: impl Fn(IVec2) -> bool) -> Vec<[IVec2; 3]> {
        let flag = |v: IVec2| self.within(v) && has_detail(v);
        let mut out = Vec::with_capacity(self.base_triangles() as usize);
        for i in 0..self.base_triangles() {
            let v = self.base_triangle(i);
            let rho = pattern_index(v.map(flag));
            out.extend(pattern(rho).iter().map(|tri| {
                tri.map(|w| {
                    v[0] * i32::from(w[0]) + v[1] * i32::from(w[1]) + v[2] * i32::from(w[2])
                })
            }));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    /// Twice the signed area (thirds squared) of a triangle in the x-z plane.
    fn area2(t: &[IVec2; 3]) -> i64 {
        let (a, b, c) = (t[0].as_i64vec2(), t[1].as_i64vec2(), t[2].as_i64vec2());
        (b - a).perp_dot(c - a)
    }

    #[test]
    fn every_pattern_tiles_its_parent_with_its_winding() {
        let parent = [IVec2::new(0, 0), IVec2::new(9, 9), IVec2::new(9, 0)];
        let whole = area2(&parent);
        for rho in 0..8u8 {
            let subs: Vec<[IVec2; 3]> = pattern(rho)
                .iter()
                .map(|t| {
                    t.map(|w| {
                        parent[0] * i32::from(w[0])
                            + parent[1] * i32::from(w[1])
                            + parent[2] * i32::from(w[2])
                    })
                })
                .collect();
            for (t, w) in subs.iter().zip(pattern(rho)) {
                assert!(w.iter().all(|w| w.iter().sum::<u8>() == 3), "rho {rho}");
                assert_eq!(area2(t).signum(), whole.signum(), "rho {rho}: {t:?}");
            }
            let sum: i64 = subs.iter().map(area2).sum();
            assert_eq!(sum, whole * 9, "rho {rho}: areas add up to the parent's");
        }
    }

    #[test]
    fn pattern_index_is_eq_2_2() {
        for rho in 0..8u8 {
            let t = [rho & 1 != 0, rho & 2 != 0, rho & 4 != 0];
            assert_eq!(pattern_index(t), rho);
        }
        assert_eq!(pattern(3).len(), 3);
        assert_eq!(pattern(6).len(), 3);
        for rho in [0, 1, 2, 4] {
            assert_eq!(pattern(rho).len(), 1);
        }
    }

    /// Counts each undirected side of a mesh; sides of one triangle only lie on the region's
    /// edge in a mesh without cracks, and no side is used three times.
    fn side_counts(tris: &[[IVec2; 3]]) -> HashMap<(IVec2, IVec2), u32> {
        let mut sides = HashMap::new();
        for t in tris {
            for i in 0..3 {
                let (a, b) = (t[i], t[(i + 1) % 3]);
                let key = if (a.x, a.y) < (b.x, b.y) {
                    (a, b)
                } else {
                    (b, a)
                };
                *sides.entry(key).or_insert(0) += 1;
            }
        }
        sides
    }

    #[test]
    fn refined_meshes_have_no_t_junctions_whatever_the_flags() {
        for (cam, flags) in [
            (Vec2::new(3.3, -7.9), 0u32),
            (Vec2::new(0.0, 0.0), 1),
            (Vec2::new(101.7, 55.2), 2),
            (Vec2::new(-40.4, 12.9), 3),
        ] {
            let view = RefineView::new(cam, 0.5, 3.0).unwrap();
            let has = |v: IVec2| match flags {
                0 => true,
                1 => (v.x + v.y).rem_euclid(3) != 0,
                2 => v.x > 0,
                _ => (v.x * 7 + v.y * 13).rem_euclid(5) < 2,
            };
            let tris = view.refine(has);
            let (lo, hi) = view.region();
            let edge = |a: IVec2, b: IVec2| {
                let (a, b) = (a, b);
                (a.x == b.x && (a.x == lo.x * 3 || a.x == hi.x * 3))
                    || (a.y == b.y && (a.y == lo.y * 3 || a.y == hi.y * 3))
            };
            for ((a, b), n) in side_counts(&tris) {
                if edge(a, b) {
                    assert_eq!(n, 1, "{cam} flags {flags}: region edge {a} {b}");
                } else {
                    assert_eq!(n, 2, "{cam} flags {flags}: side {a} {b} used {n} times");
                }
            }
            let area: i64 = tris.iter().map(area2).sum();
            let side = i64::from(2 * view.half_cells()) * 3;
            assert_eq!(area.abs(), 2 * side * side, "the region is covered once");
            assert!(tris.iter().all(|t| area2(t) > 0 || area2(t) < 0));
        }
    }

    #[test]
    fn only_vertices_within_the_radius_are_refined_and_the_edge_never_is() {
        let view = RefineView::new(Vec2::new(12.34, 5.67), 0.25, 1.9).unwrap();
        let tris = view.refine(|_| true);
        let (lo, hi) = view.region();
        for y in lo.y..=hi.y {
            for x in lo.x..=hi.x {
                let v = IVec2::new(x, y);
                let on_edge = x == lo.x || x == hi.x || y == lo.y || y == hi.y;
                if on_edge {
                    assert!(!view.within(v), "edge vertex {v} within the radius");
                }
            }
        }
        // The refined count: 9 per triangle with all three within, 3 with two, else 1.
        let expected: usize = (0..view.base_triangles())
            .map(|i| pattern(pattern_index(view.base_triangle(i).map(|v| view.within(v)))).len())
            .sum();
        assert_eq!(tris.len(), expected);
        assert!(tris.len() > 4 * view.base_triangles() as usize / 2);
    }

    #[test]
    fn bad_views_are_refused() {
        let ok = Vec2::new(1.0, 2.0);
        assert!(RefineView::new(Vec2::new(f32::NAN, 0.0), 0.1, 1.0).is_err());
        assert!(RefineView::new(ok, 0.0, 1.0).is_err());
        assert!(RefineView::new(ok, -1.0, 1.0).is_err());
        assert!(RefineView::new(ok, 0.1, 0.0).is_err());
        assert!(RefineView::new(ok, 0.1, f32::INFINITY).is_err());
        assert!(RefineView::new(ok, 0.1, 25.6).is_err(), "256 texels");
        assert!(RefineView::new(ok, 0.1, 25.4).is_ok());
        assert!(RefineView::new(Vec2::new(1e30, 0.0), 0.1, 1.0).is_err());
        let v = RefineView::new(Vec2::new(-1e8, 3e7), 1.0, 254.9).unwrap();
        assert_eq!(v.half_cells(), MAX_REFINE_HALF_CELLS);
        assert!(v.camera_frac.max_element() < 1.0 && v.camera_frac.min_element() >= 0.0);
    }
}
