//! The five curvature filters of Cervin 2012, sec. 3.3.1 on one texel of a heightfield, from the
//! height differences of its 3 x 3 neighbourhood (eq. 2.19, 2.26, 2.27, 2.30-2.32).
//!
//! Every filter returns a curvature magnitude in 1 / metre: the Laplacian `|h_xx + h_yy|`
//! (eq. 2.19), the root of the absolute Gaussian curvature `sqrt(|K|)` (eq. 2.27; the root puts
//! it in the same unit as the others, so one normalisation serves all five), the absolute mean
//! curvature `|H|` (eq. 2.26), and `|H|` from the cotangent Laplace-Beltrami operator over the
//! one-ring of the grid's triangulation, divided by the barycentric (triangle) area or by the
//! Voronoi area of eq. 2.32.

/// A curvature filter of Cervin 2012, sec. 3.3.1, in the order of its table 4.1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum CurvatureFilter {
    /// Second-order difference: `|h_xx + h_yy|` (eq. 2.19). The fastest, the least accurate.
    Laplace,
    /// Gaussian curvature by central differences, as `sqrt(|K|)` (eq. 2.27).
    Gaussian,
    /// Mean curvature by central differences, `|H|` (eq. 2.26): as fast as the Gaussian filter
    /// and more accurate (sec. 3.3.1), the default.
    #[default]
    Mean,
    /// `|H|` from the cotangent Laplace-Beltrami operator, divided by a third of the one-ring's
    /// triangle area (eq. 2.30, "no Voronoi area").
    LaplaceBeltramiArea,
    /// `|H|` from the cotangent Laplace-Beltrami operator, divided by the Voronoi area of the
    /// one-ring (eq. 2.31-2.32).
    LaplaceBeltramiVoronoi,
}

impl CurvatureFilter {
    /// Every filter, in the order of Cervin 2012, table 4.1.
    pub const ALL: [CurvatureFilter; 5] = [
        CurvatureFilter::Laplace,
        CurvatureFilter::Gaussian,
        CurvatureFilter::Mean,
        CurvatureFilter::LaplaceBeltramiArea,
        CurvatureFilter::LaplaceBeltramiVoronoi,
    ];

    /// A short name (`laplace`, `gaussian`, `mean`, `laplace_beltrami_area`,
    /// `laplace_beltrami_voronoi`), as in benchmarks and configuration files.
    pub fn name(self) -> &'static str {
        match self {
            CurvatureFilter::Laplace => "laplace",
            CurvatureFilter::Gaussian => "gaussian",
            CurvatureFilter::Mean => "mean",
            CurvatureFilter::LaplaceBeltramiArea => "laplace_beltrami_area",
            CurvatureFilter::LaplaceBeltramiVoronoi => "laplace_beltrami_voronoi",
        }
    }

    /// The code the GPU pass uses for this filter (0 to 4, the order of [`Self::ALL`]).
    pub fn code(self) -> u32 {
        match self {
            CurvatureFilter::Laplace => 0,
            CurvatureFilter::Gaussian => 1,
            CurvatureFilter::Mean => 2,
            CurvatureFilter::LaplaceBeltramiArea => 3,
            CurvatureFilter::LaplaceBeltramiVoronoi => 4,
        }
    }
}

/// The height differences around one texel, in metres: `d[k] = h(neighbour k) - h(centre)`,
/// neighbours in the order W, E, N, S, NW, NE, SW, SE, where E is `x + 1` and S is `y + 1`
/// (row `y` is world Z).
pub type Neighbourhood = [f32; 8];

const W: usize = 0;
const E: usize = 1;
const N: usize = 2;
const S: usize = 3;
const NW: usize = 4;
const NE: usize = 5;
const SW: usize = 6;
const SE: usize = 7;

/// The curvature magnitude (1 / metre) of `filter` at a texel whose neighbourhood differences
/// are `d`, on a grid of `spacing` metres. 0 where the surface is flat; always finite and
/// non-negative for finite input.
pub fn curvature(filter: CurvatureFilter, d: &Neighbourhood, spacing: f32) -> f32 {
    let v = match filter {
        CurvatureFilter::Laplace => {
            let inv2 = 1.0 / (spacing * spacing);
            ((d[E] + d[W]) + (d[S] + d[N])) * inv2
        }
        CurvatureFilter::Gaussian => {
            let (hx, hy, hxx, hyy, hxy) = derivatives(d, spacing);
            let g = 1.0 + hx * hx + hy * hy;
            ((hxx * hyy - hxy * hxy) / (g * g)).abs().sqrt()
        }
        CurvatureFilter::Mean => {
            let (hx, hy, hxx, hyy, hxy) = derivatives(d, spacing);
            let g = 1.0 + hx * hx + hy * hy;
            (hxx * (1.0 + hy * hy) - 2.0 * hxy * hx * hy + hyy * (1.0 + hx * hx))
                / (2.0 * g * g.sqrt())
        }
        CurvatureFilter::LaplaceBeltramiArea => laplace_beltrami(d, spacing, false),
        CurvatureFilter::LaplaceBeltramiVoronoi => laplace_beltrami(d, spacing, true),
    };
    let v = v.abs();
    if v.is_finite() { v } else { 0.0 }
}

/// Central differences: `(h_x, h_y, h_xx, h_yy, h_xy)` (Cervin 2012, eq. 3.1-3.5).
fn derivatives(d: &Neighbourhood, spacing: f32) -> (f32, f32, f32, f32, f32) {
    let inv = 1.0 / spacing;
    let inv2 = inv * inv;
    let hx = (d[E] - d[W]) * (0.5 * inv);
    let hy = (d[S] - d[N]) * (0.5 * inv);
    let hxx = (d[E] + d[W]) * inv2;
    let hyy = (d[S] + d[N]) * inv2;
    let hxy = ((d[SE] - d[NE]) - (d[SW] - d[NW])) * (0.25 * inv2);
    (hx, hy, hxx, hyy, hxy)
}

/// The one-ring of a texel in the triangulation whose diagonals run from `(x, y)` to
/// `(x + 1, y + 1)`: six neighbours in cyclic order (E, SE, S, W, NW, N), as (dx, dy, index
/// into the neighbourhood).
const RING: [(f32, f32, usize); 6] = [
    (1.0, 0.0, E),
    (1.0, 1.0, SE),
    (0.0, 1.0, S),
    (-1.0, 0.0, W),
    (-1.0, -1.0, NW),
    (0.0, -1.0, N),
];

/// `|H|` from the cotangent formula (eq. 2.30): the mean curvature normal is
/// `1 / (2 A) * sum_j (cot a_j + cot b_j) (v_j - v_i)` and `H` half its length. `A` is a third
/// of the one-ring's triangle area, or the Voronoi area of eq. 2.32 (`voronoi`). Cotangents
/// as eq. 3.7: the dot product over the length of the cross product.
fn laplace_beltrami(d: &Neighbourhood, spacing: f32, voronoi: bool) -> f32 {
    // Vertices relative to the centre, in metres (x, height, z).
    let v: [[f32; 3]; 6] = RING.map(|(dx, dy, k)| [dx * spacing, d[k], dy * spacing]);
    let mut sum = [0.0f32; 3];
    let mut area = 0.0f32;
    for j in 0..6 {
        let prev = v[(j + 5) % 6];
        let next = v[(j + 1) % 6];
        let vj = v[j];
        // Angle at `prev` in triangle (centre, prev, vj), and at `next` in (centre, vj, next).
        let cot_a = cot(neg(prev), sub(vj, prev));
        let cot_b = cot(neg(next), sub(vj, next));
        let w = cot_a + cot_b;
        for c in 0..3 {
            sum[c] += w * vj[c];
        }
        area += if voronoi {
            w * dot(vj, vj) / 8.0
        } else {
            // Triangle (centre, vj, next): a third of it belongs to the centre.
            length(cross(vj, next)) / 6.0
        };
    }
    if area <= 0.0 {
        return 0.0;
    }
    0.5 * length(sum) / (2.0 * area)
}

fn cot(a: [f32; 3], b: [f32; 3]) -> f32 {
    let c = length(cross(a, b));
    if c > 0.0 { dot(a, b) / c } else { 0.0 }
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn neg(a: [f32; 3]) -> [f32; 3] {
    [-a[0], -a[1], -a[2]]
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn length(a: [f32; 3]) -> f32 {
    dot(a, a).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn neighbourhood(f: impl Fn(f32, f32) -> f32, spacing: f32) -> Neighbourhood {
        let c = f(0.0, 0.0);
        let at = |dx: f32, dy: f32| f(dx * spacing, dy * spacing) - c;
        [
            at(-1.0, 0.0),
            at(1.0, 0.0),
            at(0.0, -1.0),
            at(0.0, 1.0),
            at(-1.0, -1.0),
            at(1.0, -1.0),
            at(-1.0, 1.0),
            at(1.0, 1.0),
        ]
    }

    #[test]
    fn a_plane_has_no_curvature() {
        let d = neighbourhood(|x, y| 0.3 * x - 0.7 * y, 0.5);
        for f in CurvatureFilter::ALL {
            assert!(curvature(f, &d, 0.5) < 1e-6, "{f:?}");
        }
    }

    #[test]
    fn codes_follow_the_table_order() {
        for (i, f) in CurvatureFilter::ALL.iter().enumerate() {
            assert_eq!(f.code(), i as u32);
        }
    }

    #[test]
    fn a_flat_one_ring_is_the_six_point_laplacian() {
        // With no height differences except the centre's, the cotangent weights of the
        // regular triangulation are 1 on the axis neighbours and 0 on the diagonal ones.
        let mut d = [0.0; 8];
        d[E] = 0.01;
        let lb = laplace_beltrami(&d, 1.0, false);
        let lap = curvature(CurvatureFilter::Laplace, &d, 1.0);
        assert!((lb - lap / 2.0).abs() < 1e-4, "{lb} vs {}", lap / 2.0);
    }
}
