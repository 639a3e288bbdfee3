//! CDLOD (Cervin 2012, sec. 1.1.4, after Strugar 2010): a quadtree over the heightfield with the
//! min / max heights and the geometric error of every node, a LOD range table, selection with
//! frustum culling and partial selection of children, one shared grid mesh drawn instanced per
//! selected quadrant, and the per-vertex morph that makes LOD changes continuous.
//!
//! Levels: LOD 0 is the leaves (finest), LOD `lod_count - 1` the roots. A node of LOD `l` is
//! `leaf_size * 2^l` texels wide and drawn as `grid_size x grid_size` quads (in four quadrant
//! instances of `grid_size / 2` quads each, so that a node can draw only some quadrants).
//!
//! The morph (Strugar's `morphVertex`): a vertex at grid position `g` of a node of LOD `l`, at
//! 3D distance `d` from the camera, moves by `frac(g / 2) * 2 * k` grid steps towards the
//! lower even grid line, `k = clamp(1 - (end_l - d) / (end_l - start_l), 0, 1)`: at `k = 1`
//! every odd vertex lies on an even one and the node's mesh is exactly its parent's.
//!
//! Why no cracks: the ranges are widened ([`CdlodTree::ranges`]) so that where a node of LOD
//! `l` meets one of LOD `l + 1`, every shared-edge vertex of the finer node is at least
//! `range_l` away (k = 1: it lies on the coarser grid) and every shared-edge vertex of the
//! coarser node is nearer than its morph start (k = 0), and neighbours differ by at most one
//! LOD. `tests/cdlod.rs` checks both on random views.

use crate::error::LodError;
use crate::frustum::Frustum;
use glam::{IVec2, UVec2, Vec2, Vec3};
use terrain_core::{HeightMap, HeightSample, Rect, WrapMode};

mod morph_reference;
mod streamed;

pub use morph_reference::{JumpProbes, morphed_vertex};

/// The largest number of LODs.
pub const MAX_CDLOD_LODS: u32 = 16;

/// The most nodes one selection visits: ranges far larger than the leaves (a finest range of
/// kilometres over leaves of metres) would otherwise select without bound.
pub const MAX_VISITED_NODES: usize = 1 << 20;

/// How the LOD range table is chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum LodMetric {
    /// Distance ranges: LOD `l` is used up to `finest_range * range_ratio^l` metres (each range
    /// twice the previous by default; Cervin 2012, fig. 1.1).
    Distance,
    /// Chunked LOD's screen-space error (Cervin 2012, eq. 1.1-1.2): `rho = delta / D * K` with
    /// `K = width / (2 tan(hfov / 2))`; LOD `l` is used from the distance where its largest
    /// geometric error `delta_l` projects to `tau` pixels, `D = delta_l K / tau`, up to the
    /// view distance of the distance table (`finest_range * range_ratio^(lod_count - 1)`).
    ScreenSpace {
        /// The largest screen-space error tolerated, in pixels (tau).
        tau_px: f32,
    },
}

/// Parameters of the quadtree and its range table (Cervin 2012, sec. 1.1.4).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(default, deny_unknown_fields))]
pub struct CdlodConfig {
    /// Texels per side of a leaf node: a power of two, 4 to 1024 (default 32).
    pub leaf_size: u32,
    /// Quads per side of a node's mesh: a power of two from 4 to `leaf_size` and at most 256
    /// (default 32: one vertex per texel at LOD 0).
    pub grid_size: u32,
    /// The number of LODs, 1 to 16 (default 8).
    pub lod_count: u32,
    /// The range of LOD 0 in metres (default 25).
    pub finest_range: f32,
    /// Each range over the previous one (default 2).
    pub range_ratio: f32,
    /// Where the morph starts, as a fraction of a range's own span (default 0.66: morph over
    /// the last third).
    pub morph_start_ratio: f32,
    /// Distance ranges or screen-space error.
    pub metric: LodMetric,
    /// Morph vertices (default on); off shows the popping CDLOD removes.
    pub morph: bool,
}

impl Default for CdlodConfig {
    fn default() -> Self {
        Self {
            leaf_size: 32,
            grid_size: 32,
            lod_count: 8,
            finest_range: 25.0,
            range_ratio: 2.0,
            morph_start_ratio: 0.66,
            metric: LodMetric::Distance,
            morph: true,
        }
    }
}

impl CdlodConfig {
    /// Checks every field, naming the first that is out of range.
    pub fn validate(&self) -> Result<(), LodError> {
        let bad = |what: &'static str, value: f64, allowed: &'static str| {
            Err(LodError::InvalidCdlodParam {
                what,
                value,
                allowed,
            })
        };
        if !(self.leaf_size.is_power_of_two() && (4..=1024).contains(&self.leaf_size)) {
            return bad(
                "leaf_size",
                self.leaf_size.into(),
                "a power of two, 4 to 1024",
            );
        }
        if !(self.grid_size.is_power_of_two()
            && (4..=256).contains(&self.grid_size)
            && self.grid_size <= self.leaf_size)
        {
            return bad(
                "grid_size",
                self.grid_size.into(),
                "a power of two from 4 to leaf_size, at most 256",
            );
        }
        if !(1..=MAX_CDLOD_LODS).contains(&self.lod_count) {
            return bad("lod_count", self.lod_count.into(), "1 to 16");
        }
        if !(self.finest_range.is_finite() && self.finest_range > 0.0 && self.finest_range < 1e7) {
            return bad(
                "finest_range",
                self.finest_range.into(),
                "a number of metres in (0, 1e7)",
            );
        }
        if !(self.range_ratio.is_finite() && (1.5..=8.0).contains(&self.range_ratio)) {
            return bad("range_ratio", self.range_ratio.into(), "1.5 to 8");
        }
        if !(self.morph_start_ratio.is_finite() && (0.05..=0.95).contains(&self.morph_start_ratio))
        {
            return bad(
                "morph_start_ratio",
                self.morph_start_ratio.into(),
                "0.05 to 0.95",
            );
        }
        if let LodMetric::ScreenSpace { tau_px } = self.metric
            && !(tau_px.is_finite() && (0.01..=1000.0).contains(&tau_px))
        {
            return bad("tau_px", tau_px.into(), "0.01 to 1000 pixels");
        }
        Ok(())
    }
}

/// Bounds and geometric error of one node.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NodeBounds {
    /// Lowest height under the node (metres), edge texels included.
    pub min: f32,
    /// Highest height.
    pub max: f32,
    /// The largest vertical distance between the map and the node's own (unmorphed) mesh, in
    /// metres: 0 where the mesh has a vertex on every texel.
    pub error: f32,
}

/// What a frame's selection is computed for: the camera and the view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CdlodView<'a> {
    /// Camera position in metres (world X, height, world Z).
    pub camera: Vec3,
    /// The view frustum, or `None` to select without culling.
    pub frustum: Option<&'a Frustum>,
    /// Viewport width in pixels and horizontal field of view in radians (for the
    /// screen-space metric and error).
    pub viewport_width: f32,
    /// Horizontal field of view, radians.
    pub hfov: f32,
}

impl CdlodView<'_> {
    /// `K = width / (2 tan(hfov / 2))` of Cervin 2012, eq. 1.2.
    pub fn k(&self) -> f32 {
        self.viewport_width / (2.0 * (self.hfov * 0.5).tan())
    }
}

/// The LOD range table of a frame: per LOD the range (metres) and the morph's start and end.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LodRanges {
    /// `range[l]`: LOD `l` is used up to this distance; the last is the view distance.
    pub range: Vec<f32>,
    /// `(start, end)` of each LOD's morph, metres (the coarsest does not morph: infinite).
    pub morph: Vec<(f32, f32)>,
}

impl LodRanges {
    /// The morph factor of a vertex of LOD `lod` at `distance` metres from the camera: 0 up to
    /// the morph's start, 1 from its end on (exactly: `1 - (end - d) / (end - start)`).
    pub fn morph_k(&self, lod: u32, distance: f32) -> f32 {
        let Some(&(start, end)) = self.morph.get(lod as usize) else {
            return 0.0;
        };
        if !end.is_finite() {
            return 0.0;
        }
        (1.0 - (end - distance) / (end - start)).clamp(0.0, 1.0)
    }
}

/// One drawn quadrant of a selected node: what a renderer puts in its instance buffer.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct CdlodInstance {
    /// Texel of the quadrant's first vertex (unwrapped: copies of a repeating map's roots lie
    /// outside it).
    pub origin: [i32; 2],
    /// Texels per grid step.
    pub step: u32,
    /// The node's LOD.
    pub lod: u32,
}

/// A node the selection chose, with the quadrants it draws itself.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SelectedNode {
    /// The node's first texel (unwrapped).
    pub origin: IVec2,
    /// Its side in texels.
    pub size: u32,
    /// Its LOD.
    pub lod: u32,
    /// Quadrants drawn: bit 0 (-X, -Z), 1 (+X, -Z), 2 (-X, +Z), 3 (+X, +Z).
    pub quadrants: u8,
    /// Its bounds.
    pub bounds: NodeBounds,
}

/// The selection of one frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CdlodFrame {
    /// Selected nodes.
    pub nodes: Vec<SelectedNode>,
    /// One instance per drawn quadrant.
    pub instances: Vec<CdlodInstance>,
    /// The range table used.
    pub ranges: LodRanges,
    /// Nodes dropped by the frustum.
    pub culled: u32,
    /// Nodes visited by the selection (bounded by [`MAX_VISITED_NODES`]).
    pub visited: usize,
}

/// The shared mesh: one quadrant, `(grid_size / 2)^2` quads, vertices at integer grid
/// positions, two triangles per quad with the diagonal from `(x, z)` to `(x + 1, z + 1)`,
/// wound counter-clockwise seen from above.
#[derive(Debug, Clone, PartialEq)]
pub struct CdlodMesh {
    /// Grid positions `(x, z)`.
    pub vertices: Vec<[f32; 2]>,
    /// Triangle list.
    pub indices: Vec<u32>,
}

impl CdlodMesh {
    /// The quadrant mesh for nodes of `grid_size` quads a side.
    pub fn new(grid_size: u32) -> Self {
        let q = (grid_size / 2).max(1);
        let side = q + 1;
        let mut vertices = Vec::with_capacity((side * side) as usize);
        for z in 0..side {
            for x in 0..side {
                vertices.push([x as f32, z as f32]);
            }
        }
        let mut indices = Vec::with_capacity((q * q * 6) as usize);
        for z in 0..q {
            for x in 0..q {
                let i = z * side + x;
                // Counter-clockwise seen from +Y (x right, z towards the viewer).
                indices.extend_from_slice(&[i, i + side + 1, i + 1, i, i + side, i + side + 1]);
            }
        }
        Self { vertices, indices }
    }

    /// Triangles per instance.
    pub fn triangles(&self) -> u64 {
        self.indices.len() as u64 / 3
    }
}

/// The CDLOD quadtree of a heightfield: per LOD a grid of node bounds, kept current by
/// [`CdlodTree::update_rect`] after deformations (only the nodes a dirty rect touches).
#[derive(Debug, Clone, PartialEq)]
pub struct CdlodTree {
    config: CdlodConfig,
    map_size: UVec2,
    wrap: WrapMode,
    texel_size: f32,
    /// Per LOD: nodes per axis and their bounds, row-major.
    levels: Vec<(UVec2, Vec<NodeBounds>)>,
    /// Per LOD: cells (one grid step of the node mesh) per axis and the largest error of the
    /// mesh inside each, row-major; empty where the mesh has a vertex on every texel. A node's
    /// error is the maximum of its cells', so a deformation recomputes only the cells it
    /// touches, not whole (root-sized) nodes.
    cells: Vec<(UVec2, Vec<f32>)>,
    /// Built from leaf bounds ([`CdlodTree::from_leaf_bounds`]): no cells, node errors bound
    /// by their height spans, kept current by [`CdlodTree::update_leaf_bounds`].
    streamed: bool,
}

impl CdlodTree {
    /// Builds the tree of `map`.
    pub fn from_map<T: HeightSample>(
        map: &HeightMap<T>,
        config: CdlodConfig,
    ) -> Result<Self, LodError> {
        config.validate()?;
        let map_size = map.size();
        let root = u64::from(config.leaf_size) << (config.lod_count - 1);
        if map.wrap() == WrapMode::Repeat
            && (!u64::from(map_size.x).is_multiple_of(root)
                || !u64::from(map_size.y).is_multiple_of(root))
        {
            // The roots must tile the map so that their repeats tile the plane.
            return Err(LodError::InvalidCdlodParam {
                what: "lod_count",
                value: config.lod_count.into(),
                allowed: "a count whose root node (leaf_size * 2^(lod_count - 1) texels) divides \
                          both sides of a repeating map",
            });
        }
        if map.wrap() == WrapMode::Clamp
            && config.lod_count >= 2
            && (u64::from(config.leaf_size) << (config.lod_count - 2))
                >= u64::from(map_size.max_element())
        {
            // Levels whose nodes are larger than the map cost time and memory for nothing
            // (their texels past the map are the clamped edge).
            return Err(LodError::InvalidCdlodParam {
                what: "lod_count",
                value: config.lod_count.into(),
                allowed: "at most the LODs it takes for the root to cover the map (the LOD below \
                          the root must be smaller than the map)",
            });
        }
        let mut levels = Vec::new();
        for l in 0..config.lod_count {
            let side = u64::from(config.leaf_size) << l;
            let n = UVec2::new(
                u64::from(map_size.x).div_ceil(side) as u32,
                u64::from(map_size.y).div_ceil(side) as u32,
            );
            levels.push((n, vec![NodeBounds::default(); n.x as usize * n.y as usize]));
        }
        let cells = (0..config.lod_count)
            .map(|l| {
                let step = Self::step_of(&config, l);
                if step == 1 {
                    return (UVec2::ZERO, Vec::new());
                }
                let n = levels[l as usize].0 * (config.grid_size);
                (n, vec![0.0f32; n.x as usize * n.y as usize])
            })
            .collect();
        let mut tree = Self {
            config,
            map_size,
            wrap: map.wrap(),
            texel_size: map.texel_size(),
            levels,
            cells,
            streamed: false,
        };
        tree.update_rect(map, Rect::from_size(map_size))?;
        Ok(tree)
    }

    /// The configuration.
    pub fn config(&self) -> &CdlodConfig {
        &self.config
    }

    /// The size of the map the tree covers (texels).
    pub fn map_size(&self) -> UVec2 {
        self.map_size
    }

    /// How the map wraps.
    pub fn wrap(&self) -> WrapMode {
        self.wrap
    }

    /// Whether the tree was built from leaf bounds (a streamed world): it holds height spans,
    /// no per-texel errors, and is kept current by `update_leaf_bounds`.
    pub fn is_streamed(&self) -> bool {
        self.streamed
    }

    /// Metres per texel.
    pub fn texel_size(&self) -> f32 {
        self.texel_size
    }

    /// The nodes of LOD `lod`: how many per axis and their bounds, row-major (`None` past
    /// the roots). What a GPU pass that reads the tree uploads.
    pub fn lod_nodes(&self, lod: u32) -> Option<(UVec2, &[NodeBounds])> {
        self.levels
            .get(lod as usize)
            .map(|(n, b)| (*n, b.as_slice()))
    }

    /// The side of a node of LOD `lod`, in texels.
    pub fn node_size(&self, lod: u32) -> u64 {
        u64::from(self.config.leaf_size) << lod.min(MAX_CDLOD_LODS)
    }

    /// The bounds of node `(x, y)` of LOD `lod` (indices wrapped on a repeating map), or `None`
    /// off a clamped map or past the roots.
    pub fn bounds(&self, lod: u32, node: IVec2) -> Option<NodeBounds> {
        let (n, nodes) = self.levels.get(lod as usize)?;
        let (x, y) = match self.wrap {
            WrapMode::Repeat => (
                node.x.rem_euclid(n.x as i32) as u32,
                node.y.rem_euclid(n.y as i32) as u32,
            ),
            WrapMode::Clamp => {
                if node.x < 0 || node.y < 0 || node.x as u32 >= n.x || node.y as u32 >= n.y {
                    return None;
                }
                (node.x as u32, node.y as u32)
            }
        };
        nodes.get(y as usize * n.x as usize + x as usize).copied()
    }

    /// Recomputes the bounds and errors of every node whose texels (edges included) meet
    /// `dirty` (wrapped on a repeating map, clipped on a clamped one).
    pub fn update_rect<T: HeightSample>(
        &mut self,
        map: &HeightMap<T>,
        dirty: Rect,
    ) -> Result<(), LodError> {
        if self.streamed {
            return Err(LodError::InvalidCdlodParam {
                what: "update_rect of a tree built from leaf bounds",
                value: 0.0,
                allowed: "update_leaf_bounds: the tree holds no per-texel errors",
            });
        }
        if map.size() != self.map_size {
            return Err(LodError::SizeMismatch {
                expected: self.map_size,
                actual: map.size(),
            });
        }
        if dirty.is_empty() {
            return Ok(());
        }
        let pieces: Vec<Rect> = match self.wrap {
            WrapMode::Repeat => {
                // A rect wider than the map covers it once.
                let size = dirty.size.min(self.map_size);
                Rect::new(dirty.min, size)
                    .split_toroidal(self.map_size)
                    .into_iter()
                    .map(|p| p.map)
                    .collect()
            }
            WrapMode::Clamp => dirty
                .intersect(&Rect::from_size(self.map_size))
                .into_iter()
                .collect(),
        };
        for l in 0..self.config.lod_count {
            // Cells of this LOD's mesh that the deformation reaches, then its nodes.
            let step = Self::step_of(&self.config, l);
            if step > 1 {
                let n = self.cells[l as usize].0;
                let cells = touched(&pieces, i64::from(step), n, self.wrap);
                let errors = crate::par::map_collect(&cells, |&c| self.cell_error(map, step, c));
                for (c, e) in cells.into_iter().zip(errors) {
                    self.cells[l as usize].1[c.y as usize * n.x as usize + c.x as usize] = e;
                }
            }
            let n = self.levels[l as usize].0;
            for node in touched(&pieces, self.node_size(l) as i64, n, self.wrap) {
                let b = self.node_bounds(map, l, node);
                self.levels[l as usize].1[node.y as usize * n.x as usize + node.x as usize] = b;
            }
        }
        Ok(())
    }

    /// Texels per grid step of the mesh of LOD `lod` (at least 1).
    fn step_of(config: &CdlodConfig, lod: u32) -> u32 {
        ((config.leaf_size << lod) / config.grid_size).max(1)
    }

    /// Bounds of node `node` of LOD `lod`: from the texels for a leaf, from its children
    /// above (their texels, edges included, are the node's), the error from its cells.
    fn node_bounds<T: HeightSample>(
        &self,
        map: &HeightMap<T>,
        lod: u32,
        node: UVec2,
    ) -> NodeBounds {
        let (mut min, mut max) = (f32::INFINITY, f32::NEG_INFINITY);
        if lod == 0 {
            let side = self.node_size(0) as i64;
            let o = node.as_i64vec2() * side;
            for y in 0..=side {
                for x in 0..=side {
                    let v = self.height(map, o.x + x, o.y + y);
                    min = min.min(v);
                    max = max.max(v);
                }
            }
        } else {
            let (cn, children) = &self.levels[lod as usize - 1];
            for q in 0..4u32 {
                let c = node * 2 + UVec2::new(q & 1, q >> 1);
                // Past the last child row or column of a map that is not a whole number of
                // nodes, the clamped texels are the last child's.
                let c = c.min(*cn - 1);
                let b = children[c.y as usize * cn.x as usize + c.x as usize];
                min = min.min(b.min);
                max = max.max(b.max);
            }
        }
        let mut error = 0.0f32;
        let step = Self::step_of(&self.config, lod);
        if step > 1 {
            let (n, cells) = &self.cells[lod as usize];
            let g = self.config.grid_size;
            for cy in node.y * g..(node.y + 1) * g {
                let row = &cells[cy as usize * n.x as usize..][..n.x as usize];
                for &e in &row[(node.x * g) as usize..((node.x + 1) * g) as usize] {
                    error = error.max(e);
                }
            }
        }
        NodeBounds { min, max, error }
    }

    /// The height (metres) of texel `(x, y)`, wrapped or clamped.
    fn height<T: HeightSample>(&self, map: &HeightMap<T>, x: i64, y: i64) -> f32 {
        let g = map.grid();
        let v = g.as_slice()[g.index(
            self.wrap.resolve(x, self.map_size.x),
            self.wrap.resolve(y, self.map_size.y),
        )];
        map.encoding().to_metres(v.to_raw_f64())
    }

    /// The largest vertical distance between the map and a mesh cell of `step` texels (its two
    /// triangles, the diagonal from the cell's first corner to its last), edges included.
    fn cell_error<T: HeightSample>(&self, map: &HeightMap<T>, step: u32, cell: UVec2) -> f32 {
        let s = i64::from(step);
        let o = cell.as_i64vec2() * s;
        let g = map.grid();
        let (w, h) = (i64::from(self.map_size.x), i64::from(self.map_size.y));
        // Stored units throughout (the offset cancels); one scale to metres at the end.
        let inside = o.x >= 0 && o.y >= 0 && o.x + s < w && o.y + s < h;
        let raw = |x: i64, y: i64| -> f32 {
            let (x, y) = (o.x + x, o.y + y);
            let i = if inside {
                (y * w + x) as usize
            } else {
                g.index(
                    self.wrap.resolve(x, self.map_size.x),
                    self.wrap.resolve(y, self.map_size.y),
                )
            };
            g.as_slice()[i].to_raw_f64() as f32
        };
        let (c00, c10, c01, c11) = (raw(0, 0), raw(s, 0), raw(0, s), raw(s, s));
        let inv = 1.0 / s as f32;
        let mut error = 0.0f32;
        for y in 0..=s {
            let fy = y as f32 * inv;
            for x in 0..=s {
                let fx = x as f32 * inv;
                let m = if fx >= fy {
                    c00 + fx * (c10 - c00) + fy * (c11 - c10)
                } else {
                    c00 + fy * (c01 - c00) + fx * (c11 - c01)
                };
                error = error.max((raw(x, y) - m).abs());
            }
        }
        error * map.encoding().scale.abs()
    }

    /// The range table for `view`, widened where needed so that the morph is crack-free: the
    /// morph of LOD `l + 1` must not start before the farthest point of a node of that LOD
    /// that reaches range `l`, so `range_{l+1} - range_l >= diag_{l+1} / morph_start_ratio`
    /// (`diag` the node's 3D diagonal with the map's height span).
    pub fn ranges(&self, view: &CdlodView<'_>) -> LodRanges {
        let c = &self.config;
        let lods = c.lod_count as usize;
        let span = self.height_span();
        // The view distance: the last range of the distance table, for both metrics (the
        // screen-space table is capped by it, or a rough map would be drawn to the horizon).
        let view_distance = c.finest_range * c.range_ratio.powi(lods as i32 - 1);
        let mut range: Vec<f32> = Vec::with_capacity(lods);
        for l in 0..lods {
            let wanted = match c.metric {
                LodMetric::Distance => c.finest_range * c.range_ratio.powi(l as i32),
                LodMetric::ScreenSpace { .. } if l + 1 == lods => view_distance,
                LodMetric::ScreenSpace { tau_px } => {
                    // LOD l serves until LOD l + 1's error projects to tau (eq. 1.1 solved
                    // for the distance).
                    let next = self.max_error(l as u32 + 1);
                    (next * view.k() / tau_px)
                        .max(if l == 0 { 0.0 } else { range[l - 1] })
                        .min(view_distance)
                }
            };
            let floor = if l == 0 {
                0.0
            } else {
                let size = self.node_size(l as u32) as f32 * self.texel_size;
                let diag = (2.0 * size * size + span * span).sqrt();
                range[l - 1] + diag / c.morph_start_ratio * 1.001
            };
            let r: f32 = wanted.max(floor).max(if l == 0 { 1e-3 } else { 0.0 });
            range.push(r.min(f32::MAX / 4.0));
        }
        let mut morph = Vec::with_capacity(lods);
        for l in 0..lods {
            if l + 1 == lods || !c.morph {
                morph.push((f32::INFINITY, f32::INFINITY));
                continue;
            }
            let prev = if l == 0 { 0.0 } else { range[l - 1] };
            let end = range[l];
            morph.push((prev + (end - prev) * c.morph_start_ratio, end));
        }
        LodRanges { range, morph }
    }

    /// The map's height span (metres), from the roots.
    fn height_span(&self) -> f32 {
        let Some((_, roots)) = self.levels.last() else {
            return 0.0;
        };
        let min = roots.iter().map(|b| b.min).fold(f32::INFINITY, f32::min);
        let max = roots
            .iter()
            .map(|b| b.max)
            .fold(f32::NEG_INFINITY, f32::max);
        if max >= min { max - min } else { 0.0 }
    }

    /// The largest geometric error of any node of LOD `lod` (0 past the roots).
    pub fn max_error(&self, lod: u32) -> f32 {
        self.levels
            .get(lod as usize)
            .map(|(_, n)| n.iter().map(|b| b.error).fold(0.0, f32::max))
            .unwrap_or(0.0)
    }

    /// Selects the nodes to draw for `view` (Cervin 2012, fig. 1.2): from the roots, a node whose
    /// box reaches its range is refined where its children reach theirs; quadrants whose
    /// child is out of its range are drawn by the node itself; boxes outside the frustum are
    /// dropped. On a repeating map the roots repeat around the camera up to the view distance.
    /// A selection that would visit more than [`MAX_VISITED_NODES`] nodes is
    /// [`LodError::SelectionTooLarge`].
    pub fn select(&self, view: &CdlodView<'_>) -> Result<CdlodFrame, LodError> {
        self.select_bounded(view, MAX_VISITED_NODES)
    }

    /// [`Self::select`] with a budget of nodes: a selection that would visit more than
    /// `max_nodes` nodes (at most [`MAX_VISITED_NODES`]: a larger budget is that) stops there
    /// and is [`LodError::SelectionTooLarge`], so that an engine can cap the CPU time and
    /// memory of one frame's selection below the built-in bound.
    pub fn select_bounded(
        &self,
        view: &CdlodView<'_>,
        max_nodes: usize,
    ) -> Result<CdlodFrame, LodError> {
        let limit = max_nodes.min(MAX_VISITED_NODES);
        for (what, v) in [
            ("camera.x", view.camera.x),
            ("camera.y", view.camera.y),
            ("camera.z", view.camera.z),
        ] {
            if !v.is_finite() {
                return Err(LodError::NonFinite { what, value: v });
            }
        }
        // Texel coordinates must stay far inside i32 (node origins, the shader's integers).
        let cam_texels =
            Vec2::new(view.camera.x, view.camera.z).as_dvec2() / f64::from(self.texel_size);
        if cam_texels.abs().max_element() > f64::from(1u32 << 28) {
            return Err(LodError::CameraOutOfRange {
                camera: Vec2::new(view.camera.x, view.camera.z),
                texel_size: self.texel_size,
            });
        }
        let ranges = self.ranges(view);
        let mut frame = CdlodFrame {
            ranges,
            ..CdlodFrame::default()
        };
        let top = self.config.lod_count - 1;
        let root = self.node_size(top) as f64 * f64::from(self.texel_size);
        let view_dist = f64::from(frame.ranges.range[top as usize]);
        let cam = Vec2::new(view.camera.x, view.camera.z).as_dvec2();
        let n = self.levels[top as usize].0;
        let (lo, hi) = match self.wrap {
            WrapMode::Clamp => (IVec2::ZERO, n.as_ivec2() - 1),
            WrapMode::Repeat => {
                let lo = ((cam - view_dist) / root).floor();
                let hi = ((cam + view_dist) / root).floor();
                // Bounded: at most 64 x 64 root copies (a view distance of 32 root sizes).
                if (hi - lo).max_element() > 64.0 || !lo.is_finite() || !hi.is_finite() {
                    return Err(LodError::CameraOutOfRange {
                        camera: Vec2::new(view.camera.x, view.camera.z),
                        texel_size: self.texel_size,
                    });
                }
                (lo.as_ivec2(), hi.as_ivec2())
            }
        };
        for y in lo.y..=hi.y {
            for x in lo.x..=hi.x {
                self.select_node(view, top, IVec2::new(x, y), limit, &mut frame);
            }
        }
        if frame.visited > limit {
            return Err(LodError::SelectionTooLarge { limit });
        }
        let half = (self.config.grid_size / 2).max(1) as i32;
        frame.instances.reserve(frame.nodes.len() * 4);
        for node in &frame.nodes {
            let step = (u64::from(node.size) / u64::from(self.config.grid_size)).max(1) as i32;
            for q in 0..4 {
                if node.quadrants & (1 << q) != 0 {
                    let o = node.origin + IVec2::new(q & 1, q >> 1) * half * step;
                    frame.instances.push(CdlodInstance {
                        origin: o.to_array(),
                        step: step as u32,
                        lod: node.lod,
                    });
                }
            }
        }
        Ok(frame)
    }

    /// The world box of node `node` of LOD `lod` (node indices unwrapped).
    fn node_box(&self, lod: u32, node: IVec2, b: &NodeBounds) -> (Vec3, Vec3) {
        let side = self.node_size(lod) as f32 * self.texel_size;
        let o = node.as_vec2() * side;
        (
            Vec3::new(o.x, b.min, o.y),
            Vec3::new(o.x + side, b.max, o.y + side),
        )
    }

    /// Strugar's recursive selection. Returns false when the node is out of its range (its
    /// parent draws that quadrant).
    fn select_node(
        &self,
        view: &CdlodView<'_>,
        lod: u32,
        node: IVec2,
        limit: usize,
        frame: &mut CdlodFrame,
    ) -> bool {
        // The bound is checked here, before any work, so that an oversized selection stops
        // after `limit` visits instead of running to the end first; `select_bounded` then
        // reports it (what was selected so far is discarded).
        frame.visited += 1;
        if frame.visited > limit {
            return true;
        }
        let Some(b) = self.bounds(lod, node) else {
            // Off a clamped map: nothing to draw, nothing for the parent to draw either.
            return true;
        };
        let (min, max) = self.node_box(lod, node, &b);
        let range = frame.ranges.range[lod as usize];
        if !sphere_meets_box(view.camera, range, min, max) {
            return false;
        }
        if let Some(f) = view.frustum
            && !f.intersects_aabb(min, max)
        {
            frame.culled += 1;
            return true;
        }
        let side = self.node_size(lod);
        let mut quadrants = 0u8;
        if lod == 0
            || !sphere_meets_box(view.camera, frame.ranges.range[lod as usize - 1], min, max)
        {
            quadrants = 0b1111;
        } else {
            for q in 0..4 {
                let child = node * 2 + IVec2::new(q & 1, q >> 1);
                if !self.select_node(view, lod - 1, child, limit, frame) {
                    quadrants |= 1 << q;
                }
            }
        }
        if quadrants != 0 {
            frame.nodes.push(SelectedNode {
                origin: node * side as i32,
                size: side as u32,
                lod,
                quadrants,
                bounds: b,
            });
        }
        true
    }
}

impl CdlodTree {
    /// The largest projected geometric error of what `frame` draws, in pixels: per drawn
    /// quadrant its node's error over the quadrant's nearest distance to the camera, times `K`
    /// (Cervin 2012, eq. 1.1). A bound of the error of the drawn (unmorphed) mesh against the
    /// full-resolution map, computed on the CPU.
    pub fn max_screen_error_px(&self, frame: &CdlodFrame, view: &CdlodView<'_>) -> f32 {
        let k = view.k();
        let ts = self.texel_size;
        let half = (self.config.grid_size / 2).max(1) as i32;
        frame
            .instances
            .iter()
            .map(|i| {
                let origin = IVec2::from(i.origin);
                let side = half * i.step as i32;
                let node_side = self.node_size(i.lod) as i32;
                let node = origin.div_euclid(IVec2::splat(node_side));
                let error = self.bounds(i.lod, node).map_or(0.0, |b| b.error);
                // The quadrant is the child node there: its heights bound the quadrant's.
                let heights = if i.lod == 0 {
                    self.bounds(0, node)
                } else {
                    self.bounds(i.lod - 1, origin.div_euclid(IVec2::splat(side)))
                };
                let Some(b) = heights else {
                    return 0.0;
                };
                let o = origin.as_vec2() * ts;
                let min = Vec3::new(o.x, b.min, o.y);
                let max = Vec3::new(o.x + side as f32 * ts, b.max, o.y + side as f32 * ts);
                let d = (view.camera.clamp(min, max) - view.camera)
                    .length()
                    .max(1e-3);
                error * k / d
            })
            .fold(0.0, f32::max)
    }
}

/// The items (nodes or cells of `side` texels, `n` per axis) whose texels `o ..= o + side`
/// meet one of `pieces` (inside the map), each once: the one before a piece's first column
/// too (its far edge is that column), wrapped on a repeating map.
fn touched(pieces: &[Rect], side: i64, n: UVec2, wrap: WrapMode) -> Vec<UVec2> {
    let mut out = std::collections::BTreeSet::new();
    for piece in pieces {
        let lo = (piece.min.as_i64vec2() - 1).div_euclid(glam::I64Vec2::splat(side));
        let hi = (piece.max().as_i64vec2() - 1).div_euclid(glam::I64Vec2::splat(side));
        for y in lo.y..=hi.y {
            for x in lo.x..=hi.x {
                let p = match wrap {
                    WrapMode::Repeat => UVec2::new(
                        x.rem_euclid(i64::from(n.x)) as u32,
                        y.rem_euclid(i64::from(n.y)) as u32,
                    ),
                    WrapMode::Clamp => {
                        if x < 0 || y < 0 || x >= i64::from(n.x) || y >= i64::from(n.y) {
                            continue;
                        }
                        UVec2::new(x as u32, y as u32)
                    }
                };
                out.insert((p.y, p.x));
            }
        }
    }
    out.into_iter().map(|(y, x)| UVec2::new(x, y)).collect()
}

/// Whether the sphere around `c` of radius `r` meets the box `min ..= max`.
fn sphere_meets_box(c: Vec3, r: f32, min: Vec3, max: Vec3) -> bool {
    let d = c.clamp(min, max) - c;
    d.length_squared() <= r * r
}

impl CdlodFrame {
    /// Vertices drawn (the shared quadrant mesh's vertices per instance).
    pub fn vertex_count(&self, mesh: &CdlodMesh) -> u64 {
        self.instances.len() as u64 * mesh.vertices.len() as u64
    }

    /// Triangles drawn.
    pub fn triangle_count(&self, mesh: &CdlodMesh) -> u64 {
        self.instances.len() as u64 * mesh.triangles()
    }
}
