//! Adaptive tessellation (Cervin 2012, sec. 2.3 and algorithm 3.1) as an implicit subdivision:
//! longest-edge bisection of right triangles over square patches (a 4-8 mesh), where every
//! edge decides for itself whether it is split, from the clip-space size of a sphere around it
//! for a target triangle width in pixels, scaled by the density map and clamped to a minimum
//! horizontal size. wgpu has no tessellation stage: `terrain-gpu`'s `TessellationPass` runs the
//! same decisions in a compute pass that writes the triangles and the indirect draw arguments;
//! [`TessHierarchy::select`] is its CPU reference (the same f32 operations in the same order:
//! on lavapipe the two emit the same triangles; a driver that fuses multiply-adds or rounds a
//! square root differently may flip a decision that lies within rounding of its threshold).
//!
//! Why bisection, how the split decisions stay nested (conforming), the split criterion of
//! the size and error metrics and the morph are derived in the repository's
//! `docs/derivations.md` ("Adaptive tessellation"). In short: a vertex is split in when its
//! saturated sphere projects above one, so every edge is decided once for both its triangles
//! and the mesh has no T-junctions by construction.
//!
//! This module holds the configuration, the frame types and the hierarchy's grid addressing;
//! `build` computes and updates the vertex bounds from a map, `select` decides and emits a
//! frame's triangles and measures them.

mod build;
mod select;
mod streamed;

pub use streamed::StreamedTessellation;

use crate::density::DensityMap;
use crate::error::LodError;
use glam::{IVec2, UVec2, Vec3};
use terrain_core::WrapMode;

/// `R / h` of a flat edge's saturated sphere for an edge (hypotenuse) `h` long, as the
/// hierarchy gets deep: `1 / (2 sqrt 2) / (1 - 1 / sqrt 2)`.
pub const FLAT_SPHERE: f32 = 1.207_106_8;

/// The smallest distance (metres) from the camera to a sphere that the ratio uses (the camera
/// inside a sphere asks for the finest level there).
pub const NEAR_M: f32 = 1e-3;

/// How much the split threshold rises per level: the ratios nest in exact arithmetic, and a
/// threshold `1 - (MAX_LEVELS - level) * SPLIT_MARGIN` keeps them nested under f32 rounding
/// (relative errors below `SPLIT_MARGIN`) while staying at most 1 (so the error metric's bound
/// holds).
pub const SPLIT_MARGIN: f32 = 1e-4;

/// The most triangle levels: `2 log2 MAX_PATCH_SIZE`.
pub const MAX_LEVELS: u32 = 16;

/// The ratio a vertex split in by triangles of `level` must exceed.
#[inline]
pub fn split_threshold(level: u32) -> f32 {
    1.0 - (MAX_LEVELS - level.min(MAX_LEVELS)) as f32 * SPLIT_MARGIN
}

/// The largest patch side in texels.
pub const MAX_PATCH_SIZE: u32 = 256;

/// The most grid vertices along a side (coordinates, doubled for a neighbour, fit in `i32`).
pub const MAX_GRID_SIDE: u64 = 1 << 30;

/// Parameters of the tessellation.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(default, deny_unknown_fields))]
pub struct TessConfig {
    /// Texels per side of a patch (two triangles at level 0): a power of two, 2 to 256
    /// (default 32).
    pub patch_size: u32,
    /// The target projected length of a triangle edge, pixels (Cervin 2012: "desired triangle
    /// width", 6 the lowest practical; default 8).
    pub triangle_width_px: f32,
    /// Triangles are not split below this horizontal hypotenuse length, metres (the "minimum
    /// horizontal size" of Cervin 2012, sec. 2.3; default 0: down to the texels).
    pub min_triangle_m: f32,
    /// Scale the edges' factors by the density map (default on).
    pub use_density: bool,
    /// Vertices move in from their edge instead of popping in (default on).
    pub morph: bool,
    /// How far past the split threshold a vertex reaches its true height: at
    /// `r = 1 + morph_range` (default 1).
    pub morph_range: f32,
    /// The most triangles one selection may emit (default 2^22): memory stays bounded for
    /// every view.
    pub max_triangles: usize,
    /// Split by projected geometric error instead of edge size: a vertex is split in while
    /// the saturated error of its triangles (see [`TessHierarchy::bounds`]) projects to more
    /// than this many pixels; the density map and the triangle width are then unused
    /// (default `None`: Cervin 2012's edge size).
    pub max_error_px: Option<f32>,
}

impl Default for TessConfig {
    fn default() -> Self {
        Self {
            patch_size: 32,
            triangle_width_px: 8.0,
            min_triangle_m: 0.0,
            use_density: true,
            morph: true,
            morph_range: 1.0,
            max_triangles: 1 << 22,
            max_error_px: None,
        }
    }
}

impl TessConfig {
    /// Checks every field, naming the first that is out of range.
    pub fn validate(&self) -> Result<(), LodError> {
        let bad = |what: &'static str, value: f64, allowed: &'static str| {
            Err(LodError::InvalidTessParam {
                what,
                value,
                allowed,
            })
        };
        if !(self.patch_size.is_power_of_two() && (2..=MAX_PATCH_SIZE).contains(&self.patch_size)) {
            return bad(
                "patch_size",
                self.patch_size.into(),
                "a power of two from 2 to 256",
            );
        }
        if !(self.triangle_width_px.is_finite()
            && (0.01..=10_000.0).contains(&self.triangle_width_px))
        {
            return bad(
                "triangle_width_px",
                self.triangle_width_px.into(),
                "0.01 to 10 000 pixels",
            );
        }
        if !(self.min_triangle_m.is_finite() && self.min_triangle_m >= 0.0) {
            return bad(
                "min_triangle_m",
                self.min_triangle_m.into(),
                "a finite number >= 0",
            );
        }
        if !(self.morph_range.is_finite() && (0.01..=100.0).contains(&self.morph_range)) {
            return bad("morph_range", self.morph_range.into(), "0.01 to 100");
        }
        if let Some(e) = self.max_error_px
            && !(e.is_finite() && (0.01..=1000.0).contains(&e))
        {
            return bad("max_error_px", e.into(), "0.01 to 1000 pixels");
        }
        if !(1..=(1usize << 28)).contains(&self.max_triangles) {
            return bad(
                "max_triangles",
                self.max_triangles as f64,
                "1 to 2^28 triangles",
            );
        }
        Ok(())
    }
}

/// A drawn vertex: texel position (unwrapped) and drawn height in metres. The GPU pass writes
/// the same layout.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TessVertex {
    /// Texel position `(x, y)`: world `(x * texel_size, height, y * texel_size)`.
    pub texel: [f32; 2],
    /// Drawn (morphed) height, metres.
    pub height: f32,
}

/// A drawn triangle, wound counter-clockwise seen from above.
pub type TessTriangle = [TessVertex; 3];

/// The triangles of one frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TessFrame {
    /// In patch order, depth first within a patch.
    pub triangles: Vec<TessTriangle>,
    /// Triangles dropped by the frustum (with everything they would have split into).
    pub culled: u32,
}

impl TessFrame {
    /// Triangles drawn.
    pub fn triangle_count(&self) -> u64 {
        self.triangles.len() as u64
    }

    /// Distinct vertices drawn (what a tessellator's domain shader would run on).
    pub fn vertex_count(&self) -> u64 {
        let mut keys: Vec<u64> = self
            .triangles
            .iter()
            .flatten()
            .map(|v| ((v.texel[1] as i64 as u64) << 32) | (v.texel[0] as i64 as u32 as u64))
            .collect();
        keys.sort_unstable();
        keys.dedup();
        keys.len() as u64
    }
}

/// What one frame's decisions are made from: the camera and the precomputed factors.
#[derive(Debug, Clone, Copy)]
pub struct TessDecision {
    /// Camera position, metres.
    pub camera: Vec3,
    /// `K / (FLAT_SPHERE * triangle_width_px)`: the ratio is `scale * R * density / distance`;
    /// with the error metric `K / max_error_px`, and the ratio `scale * E / distance`.
    pub scale: f32,
    /// Whether the ratio is the projected error rather than the edge size.
    pub error_metric: bool,
    /// Triangles of this level and finer are not split (`2 log2 P` or the minimum size's).
    pub split_levels: u32,
    /// Whether densities scale the ratio.
    pub use_density: bool,
    /// `1 / morph_range`, or 0 with the morph off (vertices drawn at their true height).
    pub inv_morph_range: f32,
    /// Texels drawn at full resolution whatever the view asks: every vertex whose
    /// descendants' square ([`descendant_reach`]) meets the rect from the first to the last
    /// corner (both included) is split in and drawn at its true height. Nested like the
    /// ratios (a child's square lies in its parents'), so the mesh stays conforming; another
    /// renderer can take over the rect and meet this mesh along its edge (the refined geometry
    /// of a detail layer, as the clipmap leaves it its finest cells).
    pub full_resolution: Option<(IVec2, IVec2)>,
}

/// The ratio of a vertex [`TessDecision::full_resolution`] forces: past every threshold and
/// morph range.
pub const FORCED_RATIO: f32 = 1e30;

/// The half side, in texels, of the square around a vertex split in by triangles of `level`
/// (of patches of `patch_size` texels) that holds every vertex split in below it: the sum of
/// the per-axis offsets from a vertex to those its triangles split in, level by level down
/// to the last that splits (0 from level `2 log2 patch_size - 1` on).
pub fn descendant_reach(patch_size: u32, level: u32) -> u32 {
    let levels = 2 * patch_size.trailing_zeros();
    (level..levels.saturating_sub(1))
        .map(|l| patch_size >> (l.div_ceil(2) + 1))
        .fold(0u32, u32::saturating_add)
}

impl TessDecision {
    /// Whether [`TessDecision::full_resolution`] forces vertex `v`, split in by triangles of
    /// `level` of patches of `patch_size` texels.
    pub fn forces(&self, v: IVec2, level: u32, patch_size: u32) -> bool {
        let Some((lo, hi)) = self.full_resolution else {
            return false;
        };
        let r = i64::from(descendant_reach(patch_size, level));
        let (v, lo, hi) = (v.as_i64vec2(), lo.as_i64vec2(), hi.as_i64vec2());
        (v - r).cmple(hi).all() && (v + r).cmpge(lo).all()
    }
}

/// The saturated bounds of every grid vertex of a heightfield's patches, kept current after
/// deformations, from which a frame's tessellation is decided.
#[derive(Debug, Clone, PartialEq)]
pub struct TessHierarchy {
    config: TessConfig,
    map_size: UVec2,
    wrap: WrapMode,
    /// How grid coordinates wrap: as the map when the patches tile a repeating map, clamped
    /// otherwise (a repeating map whose sides the patch does not divide is tessellated over
    /// whole patches, past its side, with wrapped heights).
    grid_wrap: WrapMode,
    texel_size: f32,
    /// log2 of the patch size.
    p: u32,
    /// Patches per axis.
    patches: UVec2,
    /// Vertices per axis (`patches * P + 1` on a clamped map, the map size on a repeating one).
    grid: UVec2,
    /// True height of every grid vertex (metres; clamped past a clamped map's edge).
    heights: Vec<f32>,
    /// Saturated sphere radius (metres), density (0 to 1) and error (metres) of every grid
    /// vertex.
    bounds: Vec<[f32; 3]>,
    /// Lowest and highest height over each patch (its edges included), metres.
    patch_bounds: Vec<[f32; 2]>,
    /// The density map's reach in texels: how far a height change moves densities.
    density_reach: u32,
}

impl TessHierarchy {
    /// `min(trailing zeros of x, of y)`, at most log2 P (patch corners).
    fn tz(&self, v: IVec2) -> u32 {
        let t = |c: i32| {
            if c == 0 {
                self.p
            } else {
                c.trailing_zeros().min(self.p)
            }
        };
        t(v.x).min(t(v.y))
    }

    fn is_square_centre(&self, v: IVec2, tz: u32) -> bool {
        (v.x >> tz) & 1 == 1 && (v.y >> tz) & 1 == 1
    }

    /// The endpoints of the edge whose midpoint is `v` (of `tz < log2 P`).
    fn edge_of(&self, v: IVec2, tz: u32) -> [IVec2; 2] {
        let s = 1i32 << tz;
        let (ox, oy) = ((v.x >> tz) & 1, (v.y >> tz) & 1);
        match (ox, oy) {
            (1, 1) => {
                // A square's centre: the diagonal of the 4-8 mesh's checkerboard.
                if ((v.x >> (tz + 1)) + (v.y >> (tz + 1))) & 1 == 0 {
                    [v - s, v + s]
                } else {
                    [v + IVec2::new(s, -s), v + IVec2::new(-s, s)]
                }
            }
            (1, _) => [v - IVec2::new(s, 0), v + IVec2::new(s, 0)],
            _ => [v - IVec2::new(0, s), v + IVec2::new(0, s)],
        }
    }

    /// The vertices split in by the triangles that split at `v`.
    fn children_of(&self, v: IVec2, tz: u32) -> impl Iterator<Item = IVec2> + use<> {
        let s = 1i32 << tz;
        let offsets: [IVec2; 4] = if self.is_square_centre(v, tz) {
            [
                IVec2::new(s, 0),
                IVec2::new(-s, 0),
                IVec2::new(0, s),
                IVec2::new(0, -s),
            ]
        } else if tz == 0 {
            [IVec2::ZERO; 4]
        } else {
            let h = s / 2;
            [
                IVec2::new(h, h),
                IVec2::new(-h, h),
                IVec2::new(h, -h),
                IVec2::new(-h, -h),
            ]
        };
        let leaf = !self.is_square_centre(v, tz) && tz == 0;
        let wrap = self.grid_wrap;
        let grid = self.grid.as_ivec2();
        offsets.into_iter().filter_map(move |o| {
            if leaf {
                return None;
            }
            let c = v + o;
            (wrap == WrapMode::Repeat || (c.cmpge(IVec2::ZERO).all() && c.cmplt(grid).all()))
                .then_some(c)
        })
    }

    /// The grid index of a vertex (wrapped on a repeating grid).
    #[inline]
    fn index(&self, v: IVec2) -> usize {
        let g = self.grid.as_ivec2();
        if v.cmpge(IVec2::ZERO).all() && v.cmplt(g).all() {
            return v.y as usize * self.grid.x as usize + v.x as usize;
        }
        let w = match self.grid_wrap {
            WrapMode::Repeat => v.rem_euclid(g),
            WrapMode::Clamp => v.clamp(IVec2::ZERO, g - 1),
        };
        w.y as usize * self.grid.x as usize + w.x as usize
    }

    /// The map texel whose height grid vertex `v` has: wrapped on a repeating map, clamped to
    /// the last texel past a clamped one.
    #[inline]
    fn texel_of(&self, v: IVec2) -> IVec2 {
        if v.cmpge(IVec2::ZERO).all() && v.cmplt(self.map_size.as_ivec2()).all() {
            return v;
        }
        match self.wrap {
            WrapMode::Repeat => v.rem_euclid(self.map_size.as_ivec2()),
            WrapMode::Clamp => v.clamp(IVec2::ZERO, self.map_size.as_ivec2() - 1),
        }
    }

    /// World position of vertex `v` at its true height.
    fn world(&self, v: IVec2) -> Vec3 {
        let ts = self.texel_size;
        Vec3::new(
            v.x as f32 * ts,
            self.heights[self.index(v)],
            v.y as f32 * ts,
        )
    }

    fn vertex_bounds(&self, v: IVec2, tz: u32, density: Option<&DensityMap>) -> [f32; 3] {
        let c = self.world(v);
        let [e0, e1] = self.edge_of(v, tz);
        let (w0, w1) = (self.world(e0), self.world(e1));
        let mut r = c.distance(w0).max(c.distance(w1));
        // How far the vertex lies off its edge: what splitting it in changes.
        let own_error = (c.y - 0.5 * (w0.y + w1.y)).abs();
        let mut child_error = 0.0f32;
        let mut d = match density.and_then(|dm| dm.level(0)) {
            Some(level) => {
                // Level 0's sample over the texel (as `DensityMap::density_at_texel`).
                let t = self.texel_of(v) / crate::density::DENSITY_DOWNSAMPLE as i32;
                let t = t.min(level.size().as_ivec2() - 1);
                f32::from(level.as_slice()[t.y as usize * level.width() as usize + t.x as usize])
                    / 255.0
            }
            None => 1.0,
        };
        for child in self.children_of(v, tz) {
            let [rc, dc, ec] = self.bounds[self.index(child)];
            r = r.max(c.distance(self.world(child)) + rc);
            d = d.max(dc);
            child_error = child_error.max(ec);
        }
        // A triangle split at `v` and left unsplit deviates from the full-resolution mesh by
        // at most its own vertex's offset plus the most either child triangle deviates.
        [r, d, own_error + child_error]
    }
}

impl TessHierarchy {
    /// The configuration.
    pub fn config(&self) -> &TessConfig {
        &self.config
    }

    /// Metres per texel.
    pub fn texel_size(&self) -> f32 {
        self.texel_size
    }

    /// The size of the map the hierarchy was built from (texels).
    pub fn map_size(&self) -> UVec2 {
        self.map_size
    }

    /// The map's wrap mode.
    pub fn wrap(&self) -> WrapMode {
        self.wrap
    }

    /// How grid coordinates wrap: as a repeating map whose sides the patch size divides,
    /// clamped otherwise (what a GPU pass indexes [`TessHierarchy::bounds`] with).
    pub fn grid_wrap(&self) -> WrapMode {
        self.grid_wrap
    }

    /// Patches per axis.
    pub fn patches(&self) -> UVec2 {
        self.patches
    }

    /// Grid vertices per axis.
    pub fn grid_size(&self) -> UVec2 {
        self.grid
    }

    /// The saturated (radius m, density, error m) of every grid vertex, row by row: what the
    /// GPU pass uploads. The radius is that of a sphere around the vertex holding the spheres
    /// of every vertex its triangles split in; the density the largest among them; the error
    /// bounds how far the triangles split at the vertex, left unsplit, lie from the map
    /// (`|h - edge mean|` plus the children's error).
    pub fn bounds(&self) -> &[[f32; 3]] {
        &self.bounds
    }

    /// (lowest, highest) height of every patch, row by row.
    pub fn patch_bounds(&self) -> &[[f32; 2]] {
        &self.patch_bounds
    }

    /// True heights of the grid vertices, row by row (metres).
    pub fn heights(&self) -> &[f32] {
        &self.heights
    }

    /// The vertices split in by the triangles that split at grid vertex `v` (none for patch
    /// corners, the finest vertices and vertices off the grid): the children whose bounds `v`'s
    /// bounds contain.
    pub fn children(&self, v: IVec2) -> Vec<IVec2> {
        if v.cmplt(IVec2::ZERO).any() || v.cmpge(self.grid.as_ivec2()).any() {
            return Vec::new();
        }
        let tz = self.tz(v);
        if tz >= self.p {
            return Vec::new();
        }
        self.children_of(v, tz).collect()
    }

    /// The number of levels a triangle can have: `2 log2 P + 1`.
    pub fn level_count(&self) -> u32 {
        2 * self.p + 1
    }
}
