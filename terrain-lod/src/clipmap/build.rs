//! Builds the shared clipmap mesh: one vertex range per pattern of Flower 2010, eq. 3.1, and the
//! index ranges of every part.

use super::{ClipmapMesh, ClipmapVertex, MeshPart, PartKind, TrimSide};
use glam::{I64Vec2, IVec2};

/// Number of vertices of the shared mesh, Flower 2010, eq. 3.1: `M^2 + 12M + N^2 + 6N - 1`.
pub(super) fn eq_3_1(n: u32, m: u32) -> u32 {
    m * m + 12 * m + n * n + 6 * n - 1
}

/// A rectangle of lattice vertices `[x0, x0 + w) x [z0, z0 + h)`, stored row by row.
#[derive(Clone, Copy)]
pub(super) struct Region {
    pub(super) x0: i32,
    pub(super) z0: i32,
    pub(super) w: i32,
    pub(super) h: i32,
}

impl Region {
    fn len(self) -> u32 {
        (self.w * self.h) as u32
    }

    fn index(self, x: i32, z: i32) -> u32 {
        ((z - self.z0) * self.w + (x - self.x0)) as u32
    }
}

/// The four fix-up regions in level grid units, in storage order: the two `FixupX` regions
/// (M vertices along X, 3 along Z, in the middle of the min-X and max-X sides of the ring),
/// then the two `FixupZ` regions (3 along X, M along Z, middle of the min-Z and max-Z sides).
pub(super) fn fixup_regions(m: i32) -> [(PartKind, Region); 4] {
    let mid = 2 * m - 2;
    let far = 3 * m - 1;
    [
        (
            PartKind::FixupX,
            Region {
                x0: 0,
                z0: mid,
                w: m,
                h: 3,
            },
        ),
        (
            PartKind::FixupX,
            Region {
                x0: far,
                z0: mid,
                w: m,
                h: 3,
            },
        ),
        (
            PartKind::FixupZ,
            Region {
                x0: mid,
                z0: 0,
                w: 3,
                h: m,
            },
        ),
        (
            PartKind::FixupZ,
            Region {
                x0: mid,
                z0: far,
                w: 3,
                h: m,
            },
        ),
    ]
}

/// Point `t` (`0 <= t < 4 * side`) of a walk once around the boundary of the square
/// `[0, side]^2`, starting at the origin: along z = 0 towards +X, then x = side towards +Z,
/// then z = side back towards -X, then x = 0 back towards -Z.
fn outline_point(t: i32, side: i32) -> (i32, i32) {
    match t / side {
        0 => (t, 0),
        1 => (side, t - side),
        2 => (3 * side - t, side),
        _ => (0, 4 * side - t),
    }
}

/// Inverse of [`outline_point`] for a point on the boundary of `[0, side]^2`.
fn outline_index(x: i32, z: i32, side: i32) -> Option<u32> {
    let t = if z == 0 && x < side {
        x
    } else if x == side && z < side {
        side + z
    } else if z == side && x > 0 {
        3 * side - x
    } else if x == 0 && z > 0 {
        4 * side - z
    } else {
        return None;
    };
    Some(t as u32)
}

/// Appends the two triangles of the unit quad with min corner `(x, z)`, wound
/// counter-clockwise seen from above (+Y): `(a, c, b)` and `(b, c, d)` with
/// `a = (x, z)`, `b = (x + 1, z)`, `c = (x, z + 1)`, `d = (x + 1, z + 1)`.
fn quad(indices: &mut Vec<u32>, x: i32, z: i32, index: &impl Fn(i32, i32) -> u32) {
    let a = index(x, z);
    let b = index(x + 1, z);
    let c = index(x, z + 1);
    let d = index(x + 1, z + 1);
    indices.extend_from_slice(&[a, c, b, b, c, d]);
}

struct MeshBuilder {
    vertices: Vec<ClipmapVertex>,
    indices: Vec<u32>,
    parts: Vec<MeshPart>,
}

impl MeshBuilder {
    fn push_vertex(&mut self, x: i32, z: i32) {
        self.vertices.push(ClipmapVertex {
            pos: [x as f32, z as f32],
        });
    }

    fn push_region(&mut self, region: Region) {
        for z in region.z0..region.z0 + region.h {
            for x in region.x0..region.x0 + region.w {
                self.push_vertex(x, z);
            }
        }
    }

    fn position(&self, base_vertex: i32, index: u32) -> I64Vec2 {
        let at = (i64::from(base_vertex) + i64::from(index)) as usize;
        let pos = self.vertices[at].pos;
        I64Vec2::new(pos[0] as i64, pos[1] as i64)
    }

    /// Records the indices appended since `first_index` as one part.
    fn finish_part(&mut self, kind: PartKind, first_index: usize, base_vertex: u32) {
        let base_vertex = base_vertex as i32;
        let mut min = IVec2::MAX;
        let mut max = IVec2::MIN;
        let mut triangles = 0;
        for tri in self.indices[first_index..].chunks_exact(3) {
            let p = [tri[0], tri[1], tri[2]].map(|i| self.position(base_vertex, i));
            for q in p {
                min = min.min(q.as_ivec2());
                max = max.max(q.as_ivec2());
            }
            let e1 = p[1] - p[0];
            let e2 = p[2] - p[0];
            if e1.x * e2.y - e1.y * e2.x != 0 {
                triangles += 1;
            }
        }
        self.parts.push(MeshPart {
            kind,
            indices: first_index as u32..self.indices.len() as u32,
            base_vertex,
            triangles,
            min,
            max,
        });
    }
}

/// Builds the shared mesh for `n = 4m - 1` vertices per level side (validated by the caller).
pub(super) fn build_mesh(n: u32, m: u32) -> ClipmapMesh {
    let n = n as i32;
    let m = m as i32;
    let hole = 2 * m;
    let mut b = MeshBuilder {
        vertices: Vec::with_capacity(eq_3_1(n as u32, m as u32) as usize),
        indices: Vec::new(),
        parts: Vec::new(),
    };

    // Vertex ranges, in the order of the terms of eq. 3.1.
    // 1. One M x M block.
    let block_start = b.vertices.len() as u32;
    let block = Region {
        x0: 0,
        z0: 0,
        w: m,
        h: m,
    };
    b.push_region(block);
    // 2. The four fix-ups, in place in the level frame: 4 x 3M.
    let fixup_start = b.vertices.len() as u32;
    let regions = fixup_regions(m);
    let mut region_first = [0u32; 4];
    let mut local = 0;
    for (first, (_, region)) in region_first.iter_mut().zip(regions) {
        *first = local;
        local += region.len();
        b.push_region(region);
    }
    // 3. The trim outline: the boundary of the (2M + 1)^2 hole window, 8M = 2(N + 1).
    let trim_start = b.vertices.len() as u32;
    for t in 0..4 * hole {
        let (x, z) = outline_point(t, hole);
        b.push_vertex(x, z);
    }
    // 4. The degenerate ring: the level's outer boundary walked once around and closed by
    //    repeating its first vertex, 4(N - 1) + 1 = 4N - 3.
    let ring_start = b.vertices.len() as u32;
    let side = n - 1;
    for t in 0..=4 * side {
        let (x, z) = outline_point(t % (4 * side), side);
        b.push_vertex(x, z);
    }
    // 5. The inner grid: N x N.
    let grid_start = b.vertices.len() as u32;
    let grid = Region {
        x0: 0,
        z0: 0,
        w: n,
        h: n,
    };
    b.push_region(grid);

    // Inner grid: (N - 1)^2 quads.
    let first = b.indices.len();
    let index = |x, z| grid.index(x, z);
    for z in 0..n - 1 {
        for x in 0..n - 1 {
            quad(&mut b.indices, x, z, &index);
        }
    }
    b.finish_part(PartKind::InnerGrid, first, grid_start);

    // Block: (M - 1)^2 quads.
    let first = b.indices.len();
    let index = |x, z| block.index(x, z);
    for z in 0..m - 1 {
        for x in 0..m - 1 {
            quad(&mut b.indices, x, z, &index);
        }
    }
    b.finish_part(PartKind::Block, first, block_start);

    // Fix-ups: each kind covers its two regions, both indexed into the one fix-up range.
    for kind in [PartKind::FixupX, PartKind::FixupZ] {
        let first = b.indices.len();
        for ((region_kind, region), region_first) in regions.into_iter().zip(region_first) {
            if region_kind != kind {
                continue;
            }
            let index = |x, z| region_first + region.index(x, z);
            for z in region.z0..region.z0 + region.h - 1 {
                for x in region.x0..region.x0 + region.w - 1 {
                    quad(&mut b.indices, x, z, &index);
                }
            }
        }
        b.finish_part(kind, first, fixup_start);
    }

    // Trims, in hole-local units: the L of the column at `cx` (2M quads) and the row at `cz`
    // (the other 2M - 1 quads). Vertices on the hole outline come from the trim range; the
    // L's inner corner and inner sides (one quad inside the outline, where the finer level
    // meets it) are indexed from the inner grid, whose lattice holds every such point.
    let grid_offset = grid_start - trim_start;
    let index = |x: i32, z: i32| {
        outline_index(x, z, hole).unwrap_or_else(|| grid_offset + grid.index(x, z))
    };
    for side in TrimSide::ALL {
        let first = b.indices.len();
        let cx = if side.covers_min_x() { 0 } else { hole - 1 };
        let cz = if side.covers_min_z() { 0 } else { hole - 1 };
        for z in 0..hole {
            quad(&mut b.indices, cx, z, &index);
        }
        for x in (0..hole).filter(|&x| x != cx) {
            quad(&mut b.indices, x, cz, &index);
        }
        b.finish_part(PartKind::Trim(side), first, trim_start);
    }

    // Degenerates: along each side of the ring, (v[2i], v[2i + 1], v[2i + 2]).
    let first = b.indices.len();
    for s in 0..4 {
        let side_first = (s * side) as u32;
        for i in 0..(side / 2) as u32 {
            let v = side_first + 2 * i;
            b.indices.extend_from_slice(&[v, v + 1, v + 2]);
        }
    }
    b.finish_part(PartKind::Degenerates, first, ring_start);

    ClipmapMesh {
        vertices: b.vertices,
        indices: b.indices,
        parts: b.parts,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outline_walk_round_trips() {
        for side in [2, 4, 6, 14] {
            for t in 0..4 * side {
                let (x, z) = outline_point(t, side);
                assert_eq!(
                    outline_index(x, z, side),
                    Some(t as u32),
                    "side {side} t {t}"
                );
            }
            assert_eq!(outline_index(1, 1, side), None);
        }
    }

    #[test]
    fn fixup_regions_fill_the_side_gaps() {
        for m in [2, 4, 8, 64] {
            let side = 4 * m - 2;
            let regions = fixup_regions(m);
            let quads: i32 = regions.iter().map(|(_, r)| (r.w - 1) * (r.h - 1)).sum();
            assert_eq!(quads, 4 * 2 * (m - 1));
            for (_, r) in regions {
                assert!(r.x0 >= 0 && r.z0 >= 0);
                assert!(r.x0 + r.w - 1 <= side && r.z0 + r.h - 1 <= side);
                assert_eq!(r.len(), 3 * m as u32);
            }
        }
    }
}
