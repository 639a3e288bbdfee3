//! Objects that deform granular terrain: triangle meshes (box, wheel, foot or the user's own)
//! placed with an affine transform.

use glam::{Affine3A, Vec2, Vec3};

use super::GranularError;

/// Most vertices or triangles a mesh may have.
pub const MAX_MESH_ELEMENTS: usize = 1 << 22;
/// Largest distance of a vertex from the origin, in metres (in the mesh and in the world).
pub const MAX_COORDINATE_M: f32 = 1.0e6;

/// A triangle mesh in object space (metres). Winding does not matter to the granular passes:
/// the depth from below takes the lowest surface over each column whatever the face
/// orientation. The primitives ([`cuboid`](Self::cuboid), [`wheel`](Self::wheel),
/// [`foot`](Self::foot)) are closed and face outwards (counter-clockwise seen from outside),
/// so a renderer may cull their back faces.
#[derive(Debug, Clone, PartialEq)]
pub struct TriMesh {
    vertices: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    /// A mesh from vertices and triangles. Fails on an empty or oversized mesh, NaN / infinite /
    /// far-away vertices and out-of-range indices.
    pub fn new(vertices: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Result<Self, GranularError> {
        if vertices.is_empty() || triangles.is_empty() {
            return Err(GranularError::EmptyMesh {
                vertices: vertices.len(),
                triangles: triangles.len(),
            });
        }
        for (what, count) in [("vertices", vertices.len()), ("triangles", triangles.len())] {
            if count > MAX_MESH_ELEMENTS {
                return Err(GranularError::MeshTooLarge {
                    what,
                    count,
                    limit: MAX_MESH_ELEMENTS,
                });
            }
        }
        check_vertices(&vertices)?;
        for (t, tri) in triangles.iter().enumerate() {
            for &i in tri {
                if i as usize >= vertices.len() {
                    return Err(GranularError::IndexOutOfRange {
                        triangle: t,
                        index: i,
                        vertices: vertices.len(),
                    });
                }
            }
        }
        Ok(Self {
            vertices,
            triangles,
        })
    }

    /// An axis-aligned box centred on the origin with the given half extents (all `> 0`).
    pub fn cuboid(half_extents: Vec3) -> Result<Self, GranularError> {
        check_size(
            "half_extents",
            half_extents.min_element(),
            half_extents.max_element(),
        )?;
        let h = half_extents;
        let vertices = (0..8)
            .map(|i| {
                Vec3::new(
                    if i & 1 == 0 { -h.x } else { h.x },
                    if i & 2 == 0 { -h.y } else { h.y },
                    if i & 4 == 0 { -h.z } else { h.z },
                )
            })
            .collect();
        // Each face counter-clockwise seen from outside (vertex bit 0 is +X, bit 1 +Y,
        // bit 2 +Z): the -Z, +Z, -Y, +Y, -X and +X faces.
        let faces: [[u32; 4]; 6] = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let triangles = faces
            .iter()
            .flat_map(|f| [[f[0], f[1], f[2]], [f[0], f[2], f[3]]])
            .collect();
        Self::new(vertices, triangles)
    }

    /// A wheel: a closed cylinder whose axle is the X axis, centred on the origin, with
    /// `segments` (3..=1024) sides; vertex 0 of each rim is at the bottom (`-Y`), so the lowest
    /// point is exactly `-radius`.
    pub fn wheel(radius: f32, half_width: f32, segments: u32) -> Result<Self, GranularError> {
        check_size(
            "radius / half_width",
            radius.min(half_width),
            radius.max(half_width),
        )?;
        if !(3..=1024).contains(&segments) {
            return Err(GranularError::ParamOutOfRange {
                name: "segments",
                value: f64::from(segments),
                range: "3..=1024",
            });
        }
        let ring: Vec<Vec2> = (0..segments)
            .map(|i| {
                let a = i as f32 / segments as f32 * std::f32::consts::TAU;
                Vec2::new(a.sin(), -a.cos()) * radius
            })
            .collect();
        let n = segments;
        let mut vertices = Vec::with_capacity(ring.len() * 2 + 2);
        for &x in &[-half_width, half_width] {
            vertices.extend(ring.iter().map(|p| Vec3::new(x, p.y, p.x)));
        }
        vertices.push(Vec3::new(-half_width, 0.0, 0.0));
        vertices.push(Vec3::new(half_width, 0.0, 0.0));
        let mut triangles = Vec::with_capacity(4 * n as usize);
        for i in 0..n {
            let j = (i + 1) % n;
            // Counter-clockwise seen from outside: the tread, then the caps at -X and +X.
            triangles.push([i, n + j, j]);
            triangles.push([i, n + i, n + j]);
            triangles.push([2 * n, i, j]);
            triangles.push([2 * n + 1, n + j, n + i]);
        }
        Self::new(vertices, triangles)
    }

    /// A foot: a sole outline (rounded heel, wider ball, rounded toe) extruded `height` metres
    /// up from `y = 0`, `length` along Z (toes at `+Z`) and `width` along X, centred in X and Z.
    pub fn foot(length: f32, width: f32, height: f32) -> Result<Self, GranularError> {
        check_size(
            "foot size",
            length.min(width).min(height),
            length.max(width).max(height),
        )?;
        // Outline as (x, z) fractions of (width / 2, length / 2), convex, counter-clockwise in
        // the (x, z) plane.
        const OUTLINE: [(f32, f32); 10] = [
            (0.0, -1.0),
            (0.55, -0.9),
            (0.7, -0.5),
            (0.9, 0.2),
            (0.85, 0.7),
            (0.4, 1.0),
            (-0.3, 1.0),
            (-0.8, 0.6),
            (-0.75, -0.5),
            (-0.5, -0.9),
        ];
        let n = OUTLINE.len() as u32;
        let mut vertices: Vec<Vec3> = Vec::with_capacity(2 * OUTLINE.len());
        for y in [0.0, height] {
            vertices.extend(
                OUTLINE
                    .iter()
                    .map(|&(x, z)| Vec3::new(x * width * 0.5, y, z * length * 0.5)),
            );
        }
        let mut triangles = Vec::new();
        for i in 1..n - 1 {
            triangles.push([0, i, i + 1]);
            triangles.push([n, n + i + 1, n + i]);
        }
        // The outline runs counter-clockwise seen from below: the sole as it is, the top
        // reversed, the sides from the bottom edge up, all facing outwards.
        for i in 0..n {
            let j = (i + 1) % n;
            triangles.push([i, n + j, j]);
            triangles.push([i, n + i, n + j]);
        }
        Self::new(vertices, triangles)
    }

    /// Object-space vertices.
    pub fn vertices(&self) -> &[Vec3] {
        &self.vertices
    }

    /// Triangles as vertex indices.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }
}

fn check_size(name: &'static str, min: f32, max: f32) -> Result<(), GranularError> {
    if min.is_finite() && max.is_finite() && min > 0.0 && max <= MAX_COORDINATE_M {
        Ok(())
    } else {
        let value = if min.is_finite() && min > 0.0 {
            max
        } else {
            min
        };
        Err(GranularError::ParamOutOfRange {
            name,
            value: f64::from(value),
            range: "(0, 1e6] m",
        })
    }
}

fn check_vertices(vertices: &[Vec3]) -> Result<(), GranularError> {
    for (index, v) in vertices.iter().enumerate() {
        if !v.is_finite() || v.abs().max_element() > MAX_COORDINATE_M {
            return Err(GranularError::BadVertex {
                index,
                value: v.to_array(),
                limit: MAX_COORDINATE_M,
            });
        }
    }
    Ok(())
}

/// A mesh placed in the world (metres, Y up) for one step.
#[derive(Debug, Clone, Copy)]
pub struct GranularObject<'a> {
    /// The object's mesh.
    pub mesh: &'a TriMesh,
    /// Object space to world space.
    pub transform: Affine3A,
}

impl<'a> GranularObject<'a> {
    /// A mesh with its transform.
    pub fn new(mesh: &'a TriMesh, transform: Affine3A) -> Self {
        Self { mesh, transform }
    }

    /// World-space vertices; fails on a non-finite transform or vertices beyond
    /// [`MAX_COORDINATE_M`].
    pub fn world_vertices(&self) -> Result<Vec<Vec3>, GranularError> {
        let cols = self.transform.to_cols_array();
        if cols.iter().any(|v| !v.is_finite()) {
            return Err(GranularError::NonFiniteTransform(cols));
        }
        let out: Vec<Vec3> = self
            .mesh
            .vertices
            .iter()
            .map(|&v| self.transform.transform_point3(v))
            .collect();
        check_vertices(&out)?;
        Ok(out)
    }

    /// Checks the transform and the placed vertices.
    pub fn validate(&self) -> Result<(), GranularError> {
        self.world_vertices().map(|_| ())
    }
}
