//! Adaptive tessellation of a streamed world, a heightfield the CPU never holds whole: the
//! longest-edge bisection of [`TessHierarchy`](super::TessHierarchy), with each split decided
//! from a streamed CDLOD quadtree's node bounds (`CdlodTree::from_leaf_bounds`, kept current
//! after deformation by `update_leaf_bounds`) instead of per-vertex bounds, which take 16 bytes
//! for every texel of the map (4 GiB for a 16384^2 world). The drawn heights come from
//! wherever the caller holds them: terrain-gpu's pass samples its tile atlas, the CPU
//! reference takes a function.
//!
//! A vertex split in by triangles of level `l` is decided from a box: the square of
//! [`StreamedTessellation::reach`] texels around it (which holds every vertex split in below
//! it) between the lowest and highest height of the tree's nodes that cover the square. The
//! ratio is the level's flat sphere radius (the hierarchy's on a flat map: the triangles'
//! size) over the camera's distance to the box, so a triangle's edges project to at most the
//! target width wherever the triangle lies in its box. A child's square lies inside its
//! parent's and is looked up in the same or finer nodes, so every child's box lies inside its
//! parents' and its ratio is at most theirs: the decisions nest as the hierarchy's do, and the
//! mesh has no T-junctions (`docs/derivations.md`, "Streamed tessellation").
//!
//! The streamed form splits by edge size alone: it has no density map (that needs the
//! curvature of every texel), so [`TessConfig::use_density`] is ignored, and no error metric
//! (a node's height span bounds the error of a triangle as large as the node, not of the
//! smaller ones inside it, which would all split), so [`TessConfig::max_error_px`] is refused.

use super::select::{Tri, base_triangles, decision_for};
use super::{FORCED_RATIO, NEAR_M, TessConfig, TessDecision, TessFrame, split_threshold};
use crate::cdlod::{CdlodConfig, CdlodTree, CdlodView};
use crate::error::LodError;
use glam::{IVec2, UVec2, Vec3};

/// The adaptive tessellation of a streamed world (see the module docs): the configuration
/// and, per triangle level, the reach, flat radius and tree LOD of its split decisions.
#[derive(Debug, Clone, PartialEq)]
pub struct StreamedTessellation {
    config: TessConfig,
    map_size: UVec2,
    texel_size: f32,
    /// log2 of the patch size.
    p: u32,
    patches: UVec2,
    /// Per level: the half side (texels) of the square around a vertex the level splits in
    /// that holds every vertex split in below it.
    reach: Vec<u32>,
    /// Per level: the sphere radius (metres) of a vertex on a flat map.
    radius: Vec<f32>,
    /// Per level: the tree LOD whose nodes cover the square (at most 2 x 2 of them).
    lookup: Vec<u32>,
}

impl StreamedTessellation {
    /// The tessellation of the world `tree` covers, with `config`. Fails on a bad config, one
    /// with an error metric, a tree not built from leaf bounds, or one whose roots are smaller
    /// than the square a patch's first split looks at (about 3 patches: use smaller patches or
    /// more LODs; [`StreamedTessellation::tree_config`] proposes a tree).
    pub fn new(config: TessConfig, tree: &CdlodTree) -> Result<Self, LodError> {
        config.validate()?;
        if let Some(e) = config.max_error_px {
            return Err(LodError::InvalidTessParam {
                what: "max_error_px",
                value: e.into(),
                allowed: "None: a streamed world is tessellated by edge size",
            });
        }
        if !tree.is_streamed() {
            return Err(LodError::InvalidTessParam {
                what: "tree",
                value: 0.0,
                allowed: "a streamed world's tree (CdlodTree::from_leaf_bounds)",
            });
        }
        let map_size = tree.map_size();
        let ps = config.patch_size;
        let p = ps.trailing_zeros();
        let cells = (map_size.max(UVec2::splat(2)) - 1).as_u64vec2();
        let patches = UVec2::new(
            cells.x.div_ceil(u64::from(ps)) as u32,
            cells.y.div_ceil(u64::from(ps)) as u32,
        );
        if u64::from(patches.x) * u64::from(patches.y) > 1 << 28
            || u64::from(patches.max_element()) * u64::from(ps) > 1 << 30
        {
            return Err(LodError::InvalidTessParam {
                what: "patch_size",
                value: ps.into(),
                allowed: "large enough that the world has at most 2^28 patches",
            });
        }
        let levels = 2 * p as usize;
        // Per-axis offset from a level-l vertex to those its triangles split in, and the
        // distance: along an axis for even l, diagonal for odd l.
        let offset = |l: usize| ps >> (l.div_ceil(2) + 1);
        let reach: Vec<u32> = (0..levels as u32)
            .map(|l| super::descendant_reach(ps, l))
            .collect();
        let mut radius = vec![0.0f32; levels];
        let ts = tree.texel_size();
        for l in (0..levels).rev() {
            let half_hyp = ps as f32 * std::f32::consts::SQRT_2.powi(1 - l as i32) * 0.5 * ts;
            if l + 1 < levels {
                let o = offset(l);
                let d = if l % 2 == 0 {
                    o as f32
                } else {
                    o as f32 * std::f32::consts::SQRT_2
                };
                radius[l] = half_hyp.max(d * ts + radius[l + 1]);
            } else {
                radius[l] = half_hyp;
            }
        }
        let lods = tree.config().lod_count;
        let lookup = reach
            .iter()
            .map(|&r| {
                (0..lods)
                    .find(|&lod| tree.node_size(lod) >= 2 * u64::from(r))
                    .ok_or(LodError::InvalidTessParam {
                        what: "patch_size",
                        value: ps.into(),
                        allowed: "at most a third of the tree's root node (its LODs' largest \
                                  node must hold the square a patch's first split looks at)",
                    })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            config,
            map_size,
            texel_size: ts,
            p,
            patches,
            reach,
            radius,
            lookup,
        })
    }

    /// The streamed quadtree a tessellation with patches of `patch_size` texels is best
    /// decided from (build it with `CdlodTree::from_leaf_bounds`): leaves of 16 texels (the
    /// finest triangles' boxes take their heights from a few leaves; larger leaves put them
    /// nearer the camera) and the LODs it takes for a node to hold the square a patch's first
    /// split looks at (about 3 patches). 1.4 million nodes for a 16384^2 world.
    pub fn tree_config(patch_size: u32) -> CdlodConfig {
        const LEAF: u32 = 16;
        let lod_count = (1..crate::cdlod::MAX_CDLOD_LODS)
            .find(|&n| u64::from(LEAF) << (n - 1) >= 3 * u64::from(patch_size))
            .unwrap_or(crate::cdlod::MAX_CDLOD_LODS);
        CdlodConfig {
            leaf_size: LEAF,
            grid_size: LEAF,
            lod_count,
            ..CdlodConfig::default()
        }
    }

    /// The configuration.
    pub fn config(&self) -> &TessConfig {
        &self.config
    }

    /// Patches per axis (of `patch_size` texels, from texel 0; the last ones reach past the
    /// world, where heights are the clamped edge's).
    pub fn patches(&self) -> UVec2 {
        self.patches
    }

    /// Per triangle level, the half side in texels of the square whose nodes bound a split.
    pub fn reach(&self) -> &[u32] {
        &self.reach
    }

    /// Per triangle level, the radius in metres a split's sphere has on a flat map (the
    /// ratio's numerator).
    pub fn radius(&self) -> &[f32] {
        &self.radius
    }

    /// Per triangle level, the tree LOD a split's square is looked up in.
    pub fn lookup_lods(&self) -> &[u32] {
        &self.lookup
    }

    /// The frame's decision inputs for `view`.
    pub fn decision(&self, view: &CdlodView<'_>) -> Result<TessDecision, LodError> {
        decision_for(&self.config, self.p, self.texel_size, view)
    }

    /// Fails unless `tree` covers the world this tessellation was made for.
    fn check(&self, tree: &CdlodTree) -> Result<(), LodError> {
        let lods_ok = self.lookup.iter().all(|&l| l < tree.config().lod_count);
        if tree.map_size() != self.map_size || !lods_ok || tree.texel_size() != self.texel_size {
            return Err(LodError::SizeMismatch {
                expected: self.map_size,
                actual: tree.map_size(),
            });
        }
        Ok(())
    }

    /// The lowest and highest height (metres) of the nodes that cover the square of level
    /// `level`'s reach around `v`. Mirrors `tessellate_streamed.wgsl`.
    pub fn region(&self, tree: &CdlodTree, v: IVec2, level: u32) -> (f32, f32) {
        let l = (level as usize).min(self.reach.len() - 1);
        let lod = self.lookup[l];
        let Some((n, nodes)) = tree.lod_nodes(lod) else {
            return (0.0, 0.0);
        };
        let side = tree.node_size(lod) as i64;
        let r = i64::from(self.reach[l]);
        let node = |c: i32, n: u32, delta: i64| {
            ((i64::from(c) + delta).max(0) / side).min(i64::from(n) - 1) as usize
        };
        let (x0, x1) = (node(v.x, n.x, -r), node(v.x, n.x, r));
        let (y0, y1) = (node(v.y, n.y, -r), node(v.y, n.y, r));
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let b = nodes[y * n.x as usize + x];
                lo = lo.min(b.min);
                hi = hi.max(b.max);
            }
        }
        (lo, hi)
    }

    /// The split ratio of vertex `v` split in by triangles of `level` (split when above
    /// [`split_threshold`]): the flat radius of the level's triangles over the distance from the
    /// camera to the box of the square of the level's reach and the region's heights. Mirrors
    /// `tess_source_streamed.wgsl`.
    pub fn ratio(&self, tree: &CdlodTree, d: &TessDecision, v: IVec2, level: u32) -> f32 {
        let (lo, hi) = self.region(tree, v, level);
        let l = (level as usize).min(self.radius.len() - 1);
        let ts = self.texel_size;
        let r = self.reach[l] as f32 * ts;
        let dx = ((v.x as f32 * ts - d.camera.x).abs() - r).max(0.0);
        let dz = ((v.y as f32 * ts - d.camera.z).abs() - r).max(0.0);
        let dy = (lo - d.camera.y).max(d.camera.y - hi).max(0.0);
        let dist = (dx * dx + dy * dy + dz * dz).sqrt().max(NEAR_M);
        d.scale * self.radius[l] / dist
    }

    fn split(
        &self,
        tree: &CdlodTree,
        d: &TessDecision,
        t: &Tri,
        height: &(dyn Fn(IVec2) -> f32 + Sync),
    ) -> Option<(IVec2, f32)> {
        if t.level >= d.split_levels {
            return None;
        }
        let v = (t.l + t.r) / 2;
        let r = if d.forces(v, t.level, self.config.patch_size) {
            FORCED_RATIO
        } else {
            self.ratio(tree, d, v, t.level)
        };
        let threshold = split_threshold(t.level);
        if r.is_nan() || r <= threshold {
            return None;
        }
        let k = if d.inv_morph_range > 0.0 {
            ((r - threshold) * d.inv_morph_range).min(1.0)
        } else {
            1.0
        };
        let mid = 0.5 * (t.hl + t.hr);
        Some((v, mid + (height(v) - mid) * k))
    }

    /// The triangles of one frame for `view`, the drawn heights from `height` (metres at a
    /// texel; positions past the world's edge included): every patch's two triangles split
    /// depth first while their edges ask for it, dropped where the frustum misses the nodes
    /// around their patch. The CPU reference of terrain-gpu's streamed tessellation pass.
    ///
    /// Fails on a non-finite camera, a tree of another world, or more than
    /// [`TessConfig::max_triangles`].
    pub fn select(
        &self,
        tree: &CdlodTree,
        view: &CdlodView<'_>,
        height: &(dyn Fn(IVec2) -> f32 + Sync),
    ) -> Result<TessFrame, LodError> {
        self.select_with(tree, view, height, None)
    }

    /// As [`StreamedTessellation::select`], with the texels from the first to the last corner
    /// of `full_resolution` (both included) drawn at full resolution whatever the view asks
    /// (see [`TessDecision::full_resolution`]).
    pub fn select_with(
        &self,
        tree: &CdlodTree,
        view: &CdlodView<'_>,
        height: &(dyn Fn(IVec2) -> f32 + Sync),
        full_resolution: Option<(IVec2, IVec2)>,
    ) -> Result<TessFrame, LodError> {
        self.check(tree)?;
        let d = TessDecision {
            full_resolution,
            ..self.decision(view)?
        };
        let limit = self.config.max_triangles;
        let ps = self.config.patch_size as i32;
        let ts = self.texel_size;
        let rows: Vec<u32> = (0..self.patches.y).collect();
        let emitted = std::sync::atomic::AtomicUsize::new(0);
        let per_row = crate::par::map_collect(&rows, |&py| {
            let mut tris = Vec::new();
            let mut culled = 0u32;
            let mut stack = Vec::with_capacity(2 * self.p as usize + 2);
            for px in 0..self.patches.x as i32 {
                let centre = IVec2::new(px, py as i32) * ps + ps / 2;
                let (hmin, hmax) = self.region(tree, centre, 0);
                let visible = |t: &Tri| {
                    view.frustum.is_none_or(|f| {
                        let lo = t.a.min(t.l).min(t.r).as_vec2() * ts;
                        let hi = t.a.max(t.l).max(t.r).as_vec2() * ts;
                        f.intersects_aabb(Vec3::new(lo.x, hmin, lo.y), Vec3::new(hi.x, hmax, hi.y))
                    })
                };
                let before = tris.len();
                for base in base_triangles(self.config.patch_size, px, py as i32, height) {
                    stack.push(base);
                    while let Some(t) = stack.pop() {
                        if !visible(&t) {
                            culled += 1;
                            continue;
                        }
                        match self.split(tree, &d, &t, height) {
                            Some((v, hv)) => {
                                let [c0, c1] = t.children(v, hv);
                                stack.push(c1);
                                stack.push(c0);
                            }
                            None => tris.push(t.emit()),
                        }
                    }
                    // A patch alone may hold 2 P^2 triangles: stop early.
                    if tris.len() > limit {
                        return None;
                    }
                }
                let added = tris.len() - before;
                let total = emitted.fetch_add(added, std::sync::atomic::Ordering::Relaxed) + added;
                if total > limit {
                    return None;
                }
            }
            Some((tris, culled))
        });
        let mut frame = TessFrame::default();
        for row in per_row {
            let Some((tris, culled)) = row else {
                return Err(LodError::SelectionTooLarge { limit });
            };
            frame.triangles.extend_from_slice(&tris);
            frame.culled += culled;
        }
        Ok(frame)
    }
}
