//! Geometry clipmap (GPU Gems 2 ch. 2, Flower 2010, sec. 2.3.2, 2.4.3 and 3.1.3): the shared mesh of
//! part patterns, and the per-frame placement of the nested levels around the camera.
//!
//! # Levels
//!
//! A clipmap of `N = 2^k - 1` vertices per level side has `M = (N + 1) / 4`. Level `l` has grid
//! spacing `2^l` texels and covers a square of `N - 1 = 4M - 2` quads, `(N - 1) * 2^l` texels
//! per side. Level 0, the finest, is a full `N x N` grid. Every coarser level is a ring around
//! the level inside it; in level grid units `(x, z)` measured from the level's min corner:
//!
//! ```text
//!   z = 4M-2  +-----+-----+--+-----+-----+
//!             |  B  |  B  |FZ|  B  |  B  |
//!   z = 3M-1  +-----+-----+--+-----+-----+
//!             |  B  |              |  B  |
//!   z = 2M    +-----+              +-----+
//!             | FX  |     hole     | FX  |
//!   z = 2M-2  +-----+              +-----+
//!             |  B  |              |  B  |
//!   z = M-1   +-----+-----+--+-----+-----+
//!             |  B  |  B  |FZ|  B  |  B  |
//!   z = 0     +-----+-----+--+-----+-----+
//!      column boundaries at x = 0, M-1, 2M-2, 2M, 3M-1, 4M-2
//! ```
//!
//! The hole `[M-1, 3M-1]^2` (2M quads per side) holds the trim and the finer level, which is
//! `2M - 1` quads of this level wide.
//!
//! - 12 blocks `B` of `M x M` vertices, origins at `(bx, bz)` with `bx, bz` in
//!   `{0, M-1, 2M, 3M-1}`, minus the central 2 x 2;
//! - 4 fix-ups of `M x 3` vertices (2 quads wide) in the gaps in the middle of each side:
//!   [`PartKind::FixupX`] are the two whose `M` vertices run along X (min-X and max-X sides,
//!   `z` in `[2M-2, 2M]`), [`PartKind::FixupZ`] the two whose `M` vertices run along Z;
//! - the interior trim: an L one quad wide along two sides of the hole `[M-1, 3M-1]^2`
//!   (2M quads per side), on the sides the finer level (`2M - 1` quads of this level) leaves
//!   free; [`TrimSide`] names them and alternates as the camera moves;
//! - degenerate triangles `(v[2i], v[2i+1], v[2i+2])` along the level's outer edge (every
//!   level, level 0 included): zero-area triangles whose middle vertex is the T-junction an
//!   odd vertex of this level makes on an edge of the next coarser level.
//!
//! # Shared mesh and vertex count (Flower 2010, eq. 3.1)
//!
//! [`ClipmapMesh`] stores every pattern once, in five vertex ranges in the order of the terms
//! of eq. 3.1, `V = M^2 + 12M + N^2 + 6N - 1` (71 418 for `N = 255`, for any number of levels):
//!
//! | range | vertices | content (grid units, relative to the part's origin) |
//! |---|---|---|
//! | block | `M^2` | the lattice `[0, M-1]^2` |
//! | fix-ups | `4 * 3M` | the four fix-ups in place in the level frame (as in GPU Gems 2: one vertex set for all four); `FixupX` and `FixupZ` each index two of them and are drawn at the level origin |
//! | trim | `2(N+1) = 8M` | the outline of the hole window `[0, 2M]^2`, on which lie the two outer sides of the L of every orientation |
//! | degenerates | `4N - 3` | the level's outer boundary `[0, N-1]^2` walked once around, the first vertex repeated at the end |
//! | inner grid | `N^2` | the lattice `[0, N-1]^2` |
//!
//! The four trim orientations are mirror images of one another, and a draw can only
//! translate and scale, so no single set of `2(N+1)` vertices holds all four Ls (each L has
//! exactly `8M` vertices of its own). The trim range therefore holds what all four share, the
//! hole outline, and each [`PartKind::Trim`] part indexes its L's inner sides (the `4M - 1`
//! vertices one quad inside the outline, where the finer level meets the trim) in the inner
//! grid range, whose lattice contains those points relative to the same origin. Trim parts
//! use local indices relative to their `base_vertex` (the trim range) that run on into the
//! inner grid range, which follows it.
//!
//! All triangles are indexed as a triangle list, wound counter-clockwise seen from above
//! (+Y): for world positions `a, b, c`, `(b - a) x (c - a)` points up.
//!
//! # Placement
//!
//! [`ClipmapLayout::place`] puts level `l` at origin
//! `O_l = 2^(l+1) * (floor(c / 2^(l+1)) + 1 - M)` texels per axis, `c` the camera position
//! in texels: the level's centre is the centre of the `2^(l+1)` cell holding the camera, and
//! `O_l` is a multiple of the next coarser spacing, so level `l` sits in level `l + 1`'s hole
//! one coarse quad from one side or the other (the trim takes the free side). A mesh vertex of
//! a draw lands at texel `instance.offset + pos * instance.scale`, world
//! `(texel.x * texel_size, height, texel.y * texel_size)`. Instance offsets emitted:
//!
//! | part | offset |
//! |---|---|
//! | `InnerGrid` (level 0 only) | `O_0` |
//! | `Block` (12 per ring) | `O_l + (bx, bz) * 2^l` |
//! | `FixupX`, `FixupZ` (one draw each per ring) | `O_l` |
//! | `Trim(side)` (one per ring) | `O_l + (M - 1, M - 1) * 2^l`, the hole's min corner |
//! | `Degenerates` (every level) | `O_l` |

mod build;

use crate::error::LodError;
use crate::frustum::Frustum;
use glam::{DVec2, I64Vec2, IVec2, Vec2, Vec3};
use std::ops::Range;

/// Smallest `k` in `N = 2^k - 1`.
pub const MIN_LOG2_N: u32 = 3;
/// Largest `k` in `N = 2^k - 1`.
pub const MAX_LOG2_N: u32 = 10;
/// Largest number of clipmap levels (level 0 and 15 rings).
pub const MAX_LEVELS: u32 = 16;
/// Largest camera distance from the texel origin, in texels, that [`ClipmapLayout::place`]
/// accepts (2^26: 6 700 km at 0.1 m per texel). The coarsest level then reaches at most about
/// 2^27 texels, so renderers can add a multiple of the map size to any emitted texel
/// coordinate (GLSL's `%` of negative integers is undefined) and stay inside `i32`.
pub const MAX_CAMERA_TEXELS: f64 = (1u64 << 26) as f64;

/// Which two sides of a ring's hole the L-shaped interior trim covers.
///
/// The finer level sits one quad of this level away from the hole's side that the trim
/// covers; which sides that are depends on where the camera is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TrimSide {
    /// The trim runs along the min-X and min-Z sides of the hole.
    MinXMinZ,
    /// The trim runs along the min-X and max-Z sides of the hole.
    MinXMaxZ,
    /// The trim runs along the max-X and min-Z sides of the hole.
    MaxXMinZ,
    /// The trim runs along the max-X and max-Z sides of the hole.
    MaxXMaxZ,
}

impl TrimSide {
    /// All four orientations.
    pub const ALL: [TrimSide; 4] = [
        TrimSide::MinXMinZ,
        TrimSide::MinXMaxZ,
        TrimSide::MaxXMinZ,
        TrimSide::MaxXMaxZ,
    ];

    /// The orientation covering the min-X side if `min_x` (else max-X) and the min-Z side if
    /// `min_z` (else max-Z).
    pub fn from_sides(min_x: bool, min_z: bool) -> Self {
        match (min_x, min_z) {
            (true, true) => TrimSide::MinXMinZ,
            (true, false) => TrimSide::MinXMaxZ,
            (false, true) => TrimSide::MaxXMinZ,
            (false, false) => TrimSide::MaxXMaxZ,
        }
    }

    /// Whether the trim covers the hole's min-X side (else its max-X side).
    pub fn covers_min_x(self) -> bool {
        matches!(self, TrimSide::MinXMinZ | TrimSide::MinXMaxZ)
    }

    /// Whether the trim covers the hole's min-Z side (else its max-Z side).
    pub fn covers_min_z(self) -> bool {
        matches!(self, TrimSide::MinXMinZ | TrimSide::MaxXMinZ)
    }
}

/// The kinds of parts in the shared clipmap mesh; each has one [`MeshPart`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PartKind {
    /// The full `N x N` grid of level 0.
    InnerGrid,
    /// An `M x M` block (Flower 2010's "footprint"), drawn 12 times per ring.
    Block,
    /// The two `M x 3` fix-ups whose `M` vertices run along X (min-X and max-X sides).
    FixupX,
    /// The two `3 x M` fix-ups whose `M` vertices run along Z (min-Z and max-Z sides).
    FixupZ,
    /// The L-shaped interior trim of a ring, covering the given sides of the hole.
    Trim(TrimSide),
    /// The zero-area triangles along a level's outer edge.
    Degenerates,
}

impl PartKind {
    /// Every part kind, in the order of [`ClipmapMesh::parts`].
    pub const ALL: [PartKind; 9] = [
        PartKind::InnerGrid,
        PartKind::Block,
        PartKind::FixupX,
        PartKind::FixupZ,
        PartKind::Trim(TrimSide::MinXMinZ),
        PartKind::Trim(TrimSide::MinXMaxZ),
        PartKind::Trim(TrimSide::MaxXMinZ),
        PartKind::Trim(TrimSide::MaxXMaxZ),
        PartKind::Degenerates,
    ];

    /// Whether [`ClipmapLayout::place`] frustum-culls parts of this kind (blocks and fix-ups,
    /// Flower 2010, sec. 2.4.3; trims, degenerates and the finest level are always drawn).
    pub fn is_cullable(self) -> bool {
        matches!(self, PartKind::Block | PartKind::FixupX | PartKind::FixupZ)
    }
}

/// A vertex of the shared mesh: integer grid coordinates (stored as `f32`) relative to the
/// part's origin, in level grid units; `pos[0]` runs along world X, `pos[1]` along world Z.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ClipmapVertex {
    /// Grid coordinates `(x, z)`.
    pub pos: [f32; 2],
}

/// One part of the shared mesh: a range of the index buffer, drawn as a triangle list.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MeshPart {
    /// What this part is.
    pub kind: PartKind,
    /// Range of [`ClipmapMesh::indices`]; its length is a multiple of 3.
    pub indices: Range<u32>,
    /// Added to every index of the part to find its vertex (`draw_indexed`'s base vertex).
    pub base_vertex: i32,
    /// Number of non-degenerate triangles in the part.
    pub triangles: u32,
    /// Min corner of the part's vertices, grid units relative to the part's origin.
    pub min: IVec2,
    /// Max corner of the part's vertices, grid units relative to the part's origin.
    pub max: IVec2,
}

/// The clipmap mesh shared by all levels: one vertex buffer, one index buffer, and the index
/// range of every part (see the [module docs](self) for the layout).
#[derive(Clone, Debug, PartialEq)]
pub struct ClipmapMesh {
    /// All vertices, Flower 2010, eq. 3.1 of them.
    pub vertices: Vec<ClipmapVertex>,
    /// Triangle-list indices of all parts, each relative to its part's `base_vertex`.
    pub indices: Vec<u32>,
    /// One entry per [`PartKind`], in the order of [`PartKind::ALL`].
    pub parts: Vec<MeshPart>,
}

impl ClipmapMesh {
    /// The part of the given kind.
    pub fn part(&self, kind: PartKind) -> Option<&MeshPart> {
        self.parts.iter().find(|part| part.kind == kind)
    }

    /// The triangles a draw produces, in texel coordinates (`offset + pos * scale`), degenerate
    /// ones included: the CPU reference of what the vertex stage computes. Empty if the
    /// draw's part is not in this mesh.
    pub fn draw_triangles(&self, draw: &ClipmapDraw) -> impl Iterator<Item = [I64Vec2; 3]> + '_ {
        let part = self.part(draw.part);
        let indices = part.map_or(&[][..], |p| {
            self.indices
                .get(p.indices.start as usize..p.indices.end as usize)
                .unwrap_or(&[])
        });
        let base = part.map_or(0, |p| i64::from(p.base_vertex));
        let offset = I64Vec2::new(
            i64::from(draw.instance.offset[0]),
            i64::from(draw.instance.offset[1]),
        );
        let scale = i64::from(draw.instance.scale);
        indices.chunks_exact(3).filter_map(move |tri| {
            let mut out = [I64Vec2::ZERO; 3];
            for (slot, &index) in out.iter_mut().zip(tri) {
                let at = usize::try_from(base + i64::from(index)).ok()?;
                let pos = self.vertices.get(at)?.pos;
                *slot = offset + I64Vec2::new(pos[0] as i64, pos[1] as i64) * scale;
            }
            Some(out)
        })
    }
}

/// The most part instances one level places: 12 blocks, 2 fix-up draws, 1 L-trim and the
/// degenerate ring (level 0 draws its inner grid and degenerates only). Renderers size their
/// instance buffers from it.
pub const MAX_DRAWS_PER_LEVEL: usize = 16;

/// Per-draw data for a part instance: where and at what scale to draw it.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ClipmapInstance {
    /// Texel coordinates of the part's grid origin. May be negative or beyond the map: the
    /// renderer wraps them into the toroidal coarse-map.
    pub offset: [i32; 2],
    /// Texels per grid unit, `2^level`.
    pub scale: u32,
    /// The clipmap level the part belongs to.
    pub level: u32,
}

/// One part instance to draw this frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClipmapDraw {
    /// Which part of the shared mesh.
    pub part: PartKind,
    /// Where to draw it.
    pub instance: ClipmapInstance,
}

/// Where one level lies this frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LevelPlacement {
    /// Level index, 0 the finest.
    pub level: u32,
    /// Texel coordinates of the level's min corner vertex.
    pub origin: IVec2,
    /// Texels per grid unit, `2^level`.
    pub scale: u32,
    /// Sides of the hole covered by the trim; `None` for level 0, which has no hole.
    pub trim: Option<TrimSide>,
}

/// The clipmap for one frame: level placements and every part instance to draw.
#[derive(Clone, Debug, PartialEq)]
pub struct ClipmapFrame {
    /// One entry per level, finest first.
    pub levels: Vec<LevelPlacement>,
    /// Every part instance to draw this frame (culled ones left out), finest level first.
    pub draws: Vec<ClipmapDraw>,
    /// Number of part instances dropped by the frustum.
    pub culled: u32,
}

impl ClipmapFrame {
    /// Number of non-degenerate triangles the frame's draws produce with `mesh`.
    pub fn triangle_count(&self, mesh: &ClipmapMesh) -> u64 {
        self.draws
            .iter()
            .map(|draw| mesh.part(draw.part).map_or(0, |p| u64::from(p.triangles)))
            .sum()
    }
}

/// A geometry clipmap of `N` vertices per level side and a number of levels, with its shared
/// mesh built once.
#[derive(Clone, Debug)]
pub struct ClipmapLayout {
    n: u32,
    m: u32,
    levels: u32,
    mesh: ClipmapMesh,
}

impl ClipmapLayout {
    /// A clipmap of `n = 2^k - 1` (`3 <= k <= 10`) vertices per level side and `levels`
    /// levels (`1..=16`: level 0 and `levels - 1` rings).
    pub fn new(n: u32, levels: u32) -> Result<Self, LodError> {
        let k = n
            .checked_add(1)
            .filter(|p| p.is_power_of_two())
            .map(u32::trailing_zeros);
        if !k.is_some_and(|k| (MIN_LOG2_N..=MAX_LOG2_N).contains(&k)) {
            return Err(LodError::InvalidClipmapSize { n });
        }
        if !(1..=MAX_LEVELS).contains(&levels) {
            return Err(LodError::InvalidLevelCount { levels });
        }
        let m = (n + 1) / 4;
        Ok(Self {
            n,
            m,
            levels,
            mesh: build::build_mesh(n, m),
        })
    }

    /// Vertices per level side, `N`.
    pub fn n(&self) -> u32 {
        self.n
    }

    /// Vertices per block side, `M = (N + 1) / 4`.
    pub fn m(&self) -> u32 {
        self.m
    }

    /// Number of levels (level 0 and `levels - 1` rings).
    pub fn levels(&self) -> u32 {
        self.levels
    }

    /// Vertices of the shared mesh, Flower 2010, eq. 3.1: `M^2 + 12M + N^2 + 6N - 1`, whatever the
    /// number of levels (71 418 for `N = 255`).
    pub fn vertex_count(&self) -> u32 {
        build::eq_3_1(self.n, self.m)
    }

    /// The shared mesh.
    pub fn mesh(&self) -> &ClipmapMesh {
        &self.mesh
    }

    /// Side of level `level`'s square in texels, `(N - 1) * 2^level` (saturating).
    pub fn level_side_texels(&self, level: u32) -> u64 {
        1u64.checked_shl(level)
            .map_or(u64::MAX, |s| s.saturating_mul(u64::from(self.n - 1)))
    }

    /// Places the clipmap for a frame.
    ///
    /// `camera` is the camera position in world metres (world X, world Z) and `texel_size` the
    /// metres per texel of the coarse-map. Each level is centred on the camera with its origin
    /// snapped to the grid of the next coarser level (spacing `2^(l+1)` texels), so finer
    /// levels stay nested inside coarser ones (see the [module docs](self)). With `cull`,
    /// blocks and fix-ups whose world box (x / z from the placement, y from `height_range` in
    /// metres) lies outside the frustum are dropped and counted in
    /// [`ClipmapFrame::culled`]; trims, degenerates and the finest level are always drawn
    /// (Flower 2010, sec. 2.4.3). A fix-up part is the pair of fix-ups on opposite sides of a
    /// ring, so it is tested with the box around both.
    ///
    /// Errors: non-finite inputs, `texel_size <= 0`, a reversed height range, or a camera more
    /// than [`MAX_CAMERA_TEXELS`] texels from the origin.
    pub fn place(
        &self,
        camera: Vec2,
        texel_size: f32,
        height_range: (f32, f32),
        cull: Option<&Frustum>,
    ) -> Result<ClipmapFrame, LodError> {
        finite("camera.x", camera.x)?;
        finite("camera.y (world Z)", camera.y)?;
        finite("texel_size", texel_size)?;
        if texel_size <= 0.0 {
            return Err(LodError::InvalidTexelSize { texel_size });
        }
        finite("height_range.0", height_range.0)?;
        finite("height_range.1", height_range.1)?;
        if height_range.0 > height_range.1 {
            return Err(LodError::InvalidHeightRange {
                min: height_range.0,
                max: height_range.1,
            });
        }
        let out_of_range = LodError::CameraOutOfRange { camera, texel_size };
        let camera_texel = camera.as_dvec2() / f64::from(texel_size);
        if camera_texel.abs().max_element() > MAX_CAMERA_TEXELS {
            return Err(out_of_range);
        }

        let m = i64::from(self.m);
        let origins: Vec<I64Vec2> = (0..self.levels)
            .map(|l| level_origin(camera_texel, l, m))
            .collect();
        let to_ivec2 = |v: I64Vec2| -> Result<IVec2, LodError> {
            let x = i32::try_from(v.x).map_err(|_| out_of_range.clone())?;
            let y = i32::try_from(v.y).map_err(|_| out_of_range.clone())?;
            Ok(IVec2::new(x, y))
        };

        let mut cx = Culler {
            mesh: &self.mesh,
            frustum: cull,
            texel_size: f64::from(texel_size),
            height_range,
            draws: Vec::with_capacity(MAX_DRAWS_PER_LEVEL * self.levels as usize),
            culled: 0,
        };
        let mut levels = Vec::with_capacity(self.levels as usize);
        for (l, &origin) in (0..self.levels).zip(&origins) {
            let scale = 1i64 << l;
            let hole = origin + I64Vec2::splat((m - 1) * scale);
            // The finer level starts at the hole's min corner (trim on the max side) or one
            // quad of this level inside it (trim on the min side).
            let trim = l
                .checked_sub(1)
                .and_then(|f| origins.get(f as usize))
                .map(|&fine| TrimSide::from_sides(fine.x > hole.x, fine.y > hole.y));
            let origin_i = to_ivec2(origin)?;
            levels.push(LevelPlacement {
                level: l,
                origin: origin_i,
                scale: scale as u32,
                trim,
            });
            match trim {
                None => cx.emit(PartKind::InnerGrid, origin_i, l),
                Some(side) => {
                    for bz in 0..4 {
                        for bx in 0..4 {
                            if (1..=2).contains(&bx) && (1..=2).contains(&bz) {
                                continue;
                            }
                            let block = I64Vec2::new(block_start(bx, m), block_start(bz, m));
                            cx.emit(PartKind::Block, to_ivec2(origin + block * scale)?, l);
                        }
                    }
                    cx.emit(PartKind::FixupX, origin_i, l);
                    cx.emit(PartKind::FixupZ, origin_i, l);
                    cx.emit(PartKind::Trim(side), to_ivec2(hole)?, l);
                }
            }
            cx.emit(PartKind::Degenerates, origin_i, l);
        }
        Ok(ClipmapFrame {
            levels,
            draws: cx.draws,
            culled: cx.culled,
        })
    }
}

/// Start, in level grid units, of block column / row `i` (`0..4`) of a ring.
fn block_start(i: i64, m: i64) -> i64 {
    match i {
        0 => 0,
        1 => m - 1,
        2 => 2 * m,
        _ => 3 * m - 1,
    }
}

/// Origin in texels of level `level`: `2^(l+1) * (floor(c / 2^(l+1)) + 1 - M)` per axis.
fn level_origin(camera_texel: DVec2, level: u32, m: i64) -> I64Vec2 {
    let snap = 1i64 << (level + 1);
    let cell = (camera_texel / snap as f64).floor().as_i64vec2();
    (cell + 1 - m) * snap
}

fn finite(what: &'static str, value: f32) -> Result<(), LodError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(LodError::NonFinite { what, value })
    }
}

/// Collects the draws of a frame, dropping cullable parts outside the frustum.
struct Culler<'a> {
    mesh: &'a ClipmapMesh,
    frustum: Option<&'a Frustum>,
    texel_size: f64,
    height_range: (f32, f32),
    draws: Vec<ClipmapDraw>,
    culled: u32,
}

impl Culler<'_> {
    fn emit(&mut self, kind: PartKind, offset: IVec2, level: u32) {
        let scale = 1u32 << level;
        if let (Some(frustum), Some(part)) = (self.frustum, self.mesh.part(kind))
            && kind.is_cullable()
        {
            let to_world = |grid: IVec2, y: f32| {
                let texel = offset.as_i64vec2() + grid.as_i64vec2() * i64::from(scale);
                let world = texel.as_dvec2() * self.texel_size;
                Vec3::new(world.x as f32, y, world.y as f32)
            };
            let min = to_world(part.min, self.height_range.0);
            let max = to_world(part.max, self.height_range.1);
            if !frustum.intersects_aabb(min, max) {
                self.culled += 1;
                return;
            }
        }
        self.draws.push(ClipmapDraw {
            part: kind,
            instance: ClipmapInstance {
                offset: offset.to_array(),
                scale,
                level,
            },
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SIZES: [u32; 6] = [7, 15, 31, 63, 127, 255];

    #[test]
    fn eq_3_1_vertex_count() {
        for levels in 1..=11 {
            let layout = ClipmapLayout::new(255, levels).unwrap();
            assert_eq!(layout.vertex_count(), 71_418);
            assert_eq!(layout.mesh().vertices.len(), 71_418);
        }
        for n in SIZES {
            let layout = ClipmapLayout::new(n, 3).unwrap();
            let m = (n + 1) / 4;
            let expected = m * m + 12 * m + n * n + 6 * n - 1;
            assert_eq!(layout.vertex_count(), expected, "n {n}");
            assert_eq!(layout.mesh().vertices.len(), expected as usize, "n {n}");
            // The per-term split of eq. 3.1 as documented.
            let sum = m * m + 4 * 3 * m + 2 * (n + 1) + (4 * n - 3) + n * n;
            assert_eq!(sum, expected);
        }
    }

    #[test]
    fn invalid_sizes_and_levels() {
        for n in [0, 1, 3, 8, 16, 2047, 4095, u32::MAX] {
            assert_eq!(
                ClipmapLayout::new(n, 3).unwrap_err(),
                LodError::InvalidClipmapSize { n },
                "n {n}"
            );
        }
        for levels in [0, 17, 100] {
            assert_eq!(
                ClipmapLayout::new(15, levels).unwrap_err(),
                LodError::InvalidLevelCount { levels }
            );
        }
        assert!(ClipmapLayout::new(1023, 16).is_ok());
        assert!(ClipmapLayout::new(7, 1).is_ok());
    }

    #[test]
    fn mesh_parts_are_well_formed() {
        for n in SIZES {
            let layout = ClipmapLayout::new(n, 2).unwrap();
            let mesh = layout.mesh();
            let m = layout.m() as i32;
            let n = n as i32;
            assert_eq!(mesh.parts.len(), PartKind::ALL.len());
            for (part, kind) in mesh.parts.iter().zip(PartKind::ALL) {
                assert_eq!(part.kind, kind);
                assert_eq!(part.indices.len() % 3, 0);
                for &i in &mesh.indices[part.indices.start as usize..part.indices.end as usize] {
                    let at = i64::from(part.base_vertex) + i64::from(i);
                    assert!((0..mesh.vertices.len() as i64).contains(&at), "{kind:?}");
                }
            }
            let quads = |kind| mesh.part(kind).unwrap().triangles as i32 / 2;
            assert_eq!(quads(PartKind::InnerGrid), (n - 1) * (n - 1));
            assert_eq!(quads(PartKind::Block), (m - 1) * (m - 1));
            assert_eq!(quads(PartKind::FixupX), 2 * 2 * (m - 1));
            assert_eq!(quads(PartKind::FixupZ), 2 * 2 * (m - 1));
            for side in TrimSide::ALL {
                assert_eq!(quads(PartKind::Trim(side)), 4 * m - 1);
            }
            let degenerates = mesh.part(PartKind::Degenerates).unwrap();
            assert_eq!(degenerates.triangles, 0);
            assert_eq!(degenerates.indices.len() as i32, 3 * 4 * (n - 1) / 2);
            let block = mesh.part(PartKind::Block).unwrap();
            assert_eq!((block.min, block.max), (IVec2::ZERO, IVec2::splat(m - 1)));
            let trim = mesh.part(PartKind::Trim(TrimSide::MaxXMinZ)).unwrap();
            assert_eq!((trim.min, trim.max), (IVec2::ZERO, IVec2::splat(2 * m)));
            // Each fix-up kind covers its own two regions: a band 3 vertices deep across the
            // level, along X for `FixupX` and along Z for `FixupZ`.
            let fx = mesh.part(PartKind::FixupX).unwrap();
            assert_eq!(
                (fx.min, fx.max),
                (IVec2::new(0, 2 * m - 2), IVec2::new(n - 1, 2 * m))
            );
            let fz = mesh.part(PartKind::FixupZ).unwrap();
            assert_eq!(
                (fz.min, fz.max),
                (IVec2::new(2 * m - 2, 0), IVec2::new(2 * m, n - 1))
            );
        }
    }

    #[test]
    fn triangles_are_wound_counter_clockwise_from_above() {
        let layout = ClipmapLayout::new(15, 2).unwrap();
        let mesh = layout.mesh();
        for part in &mesh.parts {
            let range = part.indices.start as usize..part.indices.end as usize;
            for tri in mesh.indices[range].chunks_exact(3) {
                let p = [tri[0], tri[1], tri[2]].map(|i| {
                    let v = mesh.vertices[(part.base_vertex + i as i32) as usize].pos;
                    Vec3::new(v[0], 0.0, v[1])
                });
                let normal = (p[1] - p[0]).cross(p[2] - p[0]);
                if part.kind == PartKind::Degenerates {
                    assert_eq!(normal, Vec3::ZERO);
                } else {
                    assert!(normal.y > 0.0, "{:?} {p:?}", part.kind);
                }
            }
        }
    }

    #[test]
    fn level_origins_snap_and_centre_on_the_camera() {
        let layout = ClipmapLayout::new(31, 5).unwrap();
        let camera = Vec2::new(123.4, -56.7);
        let frame = layout.place(camera, 0.5, (0.0, 1.0), None).unwrap();
        let camera_texel = camera / 0.5;
        for level in &frame.levels {
            let snap = 2 * level.scale as i32;
            assert_eq!(level.origin % snap, IVec2::ZERO, "{level:?}");
            let half = (layout.n() - 1) as f32 * level.scale as f32 / 2.0;
            let centre = level.origin.as_vec2() + Vec2::splat(half);
            let off = (centre - camera_texel).abs().max_element();
            assert!(off <= level.scale as f32, "{level:?} {off}");
        }
        assert_eq!(frame.levels[0].trim, None);
        assert!(frame.levels[1..].iter().all(|l| l.trim.is_some()));
    }

    #[test]
    fn draw_counts_without_culling() {
        let layout = ClipmapLayout::new(15, 4).unwrap();
        let frame = layout.place(Vec2::ZERO, 1.0, (0.0, 0.0), None).unwrap();
        let count = |f: fn(PartKind) -> bool| frame.draws.iter().filter(|d| f(d.part)).count();
        assert_eq!(count(|k| k == PartKind::InnerGrid), 1);
        assert_eq!(count(|k| k == PartKind::Block), 12 * 3);
        assert_eq!(count(|k| k == PartKind::FixupX), 3);
        assert_eq!(count(|k| k == PartKind::FixupZ), 3);
        assert_eq!(count(|k| matches!(k, PartKind::Trim(_))), 3);
        assert_eq!(count(|k| k == PartKind::Degenerates), 4);
        assert_eq!(frame.culled, 0);
        // Level 0: 14^2 quads; each ring: 14^2 - 7^2 quads of its own.
        let per_ring = 2 * (14 * 14 - 7 * 7);
        assert_eq!(
            frame.triangle_count(layout.mesh()),
            2 * 14 * 14 + 3 * per_ring
        );
    }

    #[test]
    fn placement_rejects_bad_input() {
        let layout = ClipmapLayout::new(15, 3).unwrap();
        let place = |camera, texel_size, heights| layout.place(camera, texel_size, heights, None);
        let ok = (0.0, 10.0);
        assert!(matches!(
            place(Vec2::new(f32::NAN, 0.0), 1.0, ok),
            Err(LodError::NonFinite {
                what: "camera.x",
                ..
            })
        ));
        assert!(matches!(
            place(Vec2::new(0.0, f32::INFINITY), 1.0, ok),
            Err(LodError::NonFinite { .. })
        ));
        assert!(matches!(
            place(Vec2::ZERO, f32::NAN, ok),
            Err(LodError::NonFinite {
                what: "texel_size",
                ..
            })
        ));
        for texel_size in [0.0, -0.0, -1.0] {
            assert_eq!(
                place(Vec2::ZERO, texel_size, ok),
                Err(LodError::InvalidTexelSize { texel_size })
            );
        }
        assert!(matches!(
            place(Vec2::ZERO, 1.0, (f32::NAN, 1.0)),
            Err(LodError::NonFinite { .. })
        ));
        assert_eq!(
            place(Vec2::ZERO, 1.0, (2.0, 1.0)),
            Err(LodError::InvalidHeightRange { min: 2.0, max: 1.0 })
        );
        let far = Vec2::new(3e9, 0.0);
        assert_eq!(
            place(far, 1.0, ok),
            Err(LodError::CameraOutOfRange {
                camera: far,
                texel_size: 1.0
            })
        );
        // Tiny texel sizes push a modest camera out of range too.
        assert!(matches!(
            place(Vec2::splat(100.0), 1e-8, ok),
            Err(LodError::CameraOutOfRange { .. })
        ));
        // The largest layout at the edge of the accepted range still places.
        let big = ClipmapLayout::new(1023, 16).unwrap();
        let edge = Vec2::splat(MAX_CAMERA_TEXELS as f32);
        assert!(big.place(edge, 1.0, ok, None).is_ok());
        assert!(big.place(-edge, 1.0, ok, None).is_ok());
    }
}
