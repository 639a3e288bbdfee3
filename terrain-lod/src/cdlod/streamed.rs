//! CDLOD over a heightfield the CPU never holds whole (a streamed world larger than memory):
//! the quadtree is built from the lowest and highest height under each leaf, which the caller
//! takes from wherever it has them (resident tiles exactly, a tile pyramid's per-tile bounds
//! otherwise), and kept current by re-asking for the leaves a change touched.
//!
//! Without the texels, a node's geometric error is bounded by its height span (the mesh and
//! the heights both lie between the node's min and max): exact for the distance metric's
//! selection (which reads only the boxes), conservative for the screen-space metric and for
//! [`CdlodTree::max_screen_error_px`].

use super::{CdlodConfig, CdlodTree, NodeBounds, touched};
use crate::error::LodError;
use glam::UVec2;
use terrain_core::{Rect, WrapMode};

/// The most nodes of all LODs a tree built from leaf bounds may have (a 16384^2 world of
/// 32-texel leaves has 350 000): its memory stays bounded for any map size.
pub const MAX_STREAMED_NODES: u64 = 1 << 24;

impl CdlodTree {
    /// The tree of a `map_size`-texel heightfield of `texel_size` metres per texel, clamped
    /// at its edges, from `leaf_bounds(rect)`: the lowest and highest height in metres of the
    /// texels of `rect` (a leaf's, its far edges included, clipped to the map). Each leaf is
    /// asked once.
    pub fn from_leaf_bounds(
        config: CdlodConfig,
        map_size: UVec2,
        texel_size: f32,
        mut leaf_bounds: impl FnMut(Rect) -> (f32, f32),
    ) -> Result<Self, LodError> {
        config.validate()?;
        if !(texel_size.is_finite() && texel_size > 0.0) {
            return Err(LodError::InvalidTexelSize { texel_size });
        }
        if map_size.min_element() == 0 || map_size.max_element() > 1 << 28 {
            return Err(LodError::InvalidCdlodParam {
                what: "map size (texels)",
                value: f64::from(map_size.max_element()),
                allowed: "1 to 2^28 texels per side",
            });
        }
        if config.lod_count >= 2
            && (u64::from(config.leaf_size) << (config.lod_count - 2))
                >= u64::from(map_size.max_element())
        {
            return Err(LodError::InvalidCdlodParam {
                what: "lod_count",
                value: config.lod_count.into(),
                allowed: "at most the LODs it takes for the root to cover the map",
            });
        }
        let mut levels = Vec::new();
        let mut nodes = 0u64;
        for l in 0..config.lod_count {
            let side = u64::from(config.leaf_size) << l;
            let n = UVec2::new(
                u64::from(map_size.x).div_ceil(side) as u32,
                u64::from(map_size.y).div_ceil(side) as u32,
            );
            nodes += u64::from(n.x) * u64::from(n.y);
            if nodes > MAX_STREAMED_NODES {
                return Err(LodError::InvalidCdlodParam {
                    what: "leaf_size",
                    value: config.leaf_size.into(),
                    allowed: "large enough that the tree has at most 2^24 nodes",
                });
            }
            levels.push((n, vec![NodeBounds::default(); n.x as usize * n.y as usize]));
        }
        let mut tree = Self {
            config,
            map_size,
            wrap: WrapMode::Clamp,
            texel_size,
            levels,
            cells: vec![(UVec2::ZERO, Vec::new()); config.lod_count as usize],
            streamed: true,
        };
        tree.update_leaf_bounds(Rect::from_size(map_size), &mut leaf_bounds)?;
        Ok(tree)
    }

    /// Asks `leaf_bounds` again for every leaf whose texels (edges included) meet `dirty`
    /// (clipped to the map) and updates their ancestors: after a deformation, or when finer
    /// data for a region arrived. A tree built by [`CdlodTree::from_map`] is updated by
    /// [`CdlodTree::update_rect`] instead (an error here).
    pub fn update_leaf_bounds(
        &mut self,
        dirty: Rect,
        mut leaf_bounds: impl FnMut(Rect) -> (f32, f32),
    ) -> Result<(), LodError> {
        if !self.streamed {
            return Err(LodError::InvalidCdlodParam {
                what: "update_leaf_bounds of a tree built from a map",
                value: 0.0,
                allowed: "update_rect: the tree keeps per-texel errors",
            });
        }
        let Some(piece) = dirty.intersect(&Rect::from_size(self.map_size)) else {
            return Ok(());
        };
        let pieces = [piece];
        let map = Rect::from_size(self.map_size);
        // A leaf whose mesh has a vertex on every texel draws the heights exactly.
        let leaf_exact = Self::step_of(&self.config, 0) == 1;
        for l in 0..self.config.lod_count {
            let side = self.node_size(l) as i64;
            let n = self.levels[l as usize].0;
            for node in touched(&pieces, side, n, WrapMode::Clamp) {
                let b = if l == 0 {
                    let o = node.as_ivec2() * side as i32;
                    let texels = Rect::new(o, UVec2::splat(side as u32 + 1));
                    let Some(texels) = texels.intersect(&map) else {
                        continue;
                    };
                    let (min, max) = leaf_bounds(texels);
                    let (min, max) = (min.min(max), max.max(min));
                    let error = if leaf_exact {
                        0.0
                    } else {
                        (max - min).max(0.0)
                    };
                    NodeBounds { min, max, error }
                } else {
                    self.parent_bounds(l, node)
                };
                self.levels[l as usize].1[node.y as usize * n.x as usize + node.x as usize] = b;
            }
        }
        Ok(())
    }

    /// A node above the leaves from its children: their height range, the span as error.
    fn parent_bounds(&self, lod: u32, node: UVec2) -> NodeBounds {
        let (cn, children) = &self.levels[lod as usize - 1];
        let (mut min, mut max, mut error) = (f32::INFINITY, f32::NEG_INFINITY, 0.0f32);
        for q in 0..4u32 {
            let c = (node * 2 + UVec2::new(q & 1, q >> 1)).min(*cn - 1);
            let b = children[c.y as usize * cn.x as usize + c.x as usize];
            min = min.min(b.min);
            max = max.max(b.max);
            error = error.max(b.error);
        }
        NodeBounds {
            min,
            max,
            error: error.max(max - min),
        }
    }
}

/// The leaf rects (texels, edges included) of a tree of `config` over `map_size`: for tests
/// and callers that precompute bounds.
#[cfg(test)]
use glam::IVec2;

#[cfg(test)]
fn leaf_rects(config: &CdlodConfig, map_size: UVec2) -> Vec<Rect> {
    let side = config.leaf_size;
    let n = (map_size + side - 1) / side;
    let map = Rect::from_size(map_size);
    let mut out = Vec::new();
    for y in 0..n.y {
        for x in 0..n.x {
            let r = Rect::new(
                IVec2::new(x as i32, y as i32) * side as i32,
                UVec2::splat(side + 1),
            );
            out.extend(r.intersect(&map));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cdlod::{CdlodView, LodMetric};
    use glam::Vec3;
    use terrain_core::{CoarseMap, Grid, HeightEncoding};

    fn map() -> CoarseMap {
        let grid = Grid::from_fn(300, 200, |x, y| {
            ((x * 37 + y * 91) % 500 + (x / 7) * 3) as u16
        })
        .unwrap();
        CoarseMap::new(
            grid,
            HeightEncoding::new(0.05, -3.0).unwrap(),
            0.5,
            WrapMode::Clamp,
        )
        .unwrap()
    }

    fn exact(map: &CoarseMap) -> impl FnMut(Rect) -> (f32, f32) + '_ {
        move |r: Rect| {
            let g = map.grid().copy_rect(r).unwrap();
            let lo = *g.as_slice().iter().min().unwrap();
            let hi = *g.as_slice().iter().max().unwrap();
            let enc = map.encoding();
            (enc.to_metres(f64::from(lo)), enc.to_metres(f64::from(hi)))
        }
    }

    fn config() -> CdlodConfig {
        CdlodConfig {
            leaf_size: 16,
            grid_size: 16,
            lod_count: 4,
            metric: LodMetric::Distance,
            ..CdlodConfig::default()
        }
    }

    #[test]
    fn exact_leaf_bounds_select_what_the_map_tree_selects() {
        let map = map();
        let from_map = CdlodTree::from_map(&map, config()).unwrap();
        let streamed = CdlodTree::from_leaf_bounds(config(), map.size(), 0.5, exact(&map)).unwrap();
        for l in 0..4 {
            let n = streamed.levels[l].0;
            for y in 0..n.y as i32 {
                for x in 0..n.x as i32 {
                    let (a, b) = (
                        from_map.bounds(l as u32, IVec2::new(x, y)),
                        streamed.bounds(l as u32, IVec2::new(x, y)),
                    );
                    let (a, b) = (a.unwrap(), b.unwrap());
                    assert_eq!((a.min, a.max), (b.min, b.max), "lod {l} node ({x}, {y})");
                }
            }
        }
        for camera in [
            Vec3::new(10.0, 30.0, 10.0),
            Vec3::new(120.0, 5.0, 60.0),
            Vec3::new(-50.0, 80.0, 300.0),
        ] {
            let view = CdlodView {
                camera,
                frustum: None,
                viewport_width: 1280.0,
                hfov: 1.0,
            };
            let (a, b) = (
                from_map.select(&view).unwrap(),
                streamed.select(&view).unwrap(),
            );
            assert_eq!(a.instances, b.instances, "{camera}");
        }
    }

    #[test]
    fn updated_leaves_follow_a_deformation_and_their_ancestors_too() {
        let mut map = map();
        let mut tree = CdlodTree::from_leaf_bounds(config(), map.size(), 0.5, exact(&map)).unwrap();
        let dirty = Rect::new(IVec2::new(40, 40), UVec2::new(5, 3));
        for y in 40..43 {
            for x in 40..45 {
                *map.grid_mut().get_mut(x, y).unwrap() = 9_000;
            }
        }
        tree.update_leaf_bounds(dirty, exact(&map)).unwrap();
        let fresh = CdlodTree::from_leaf_bounds(config(), map.size(), 0.5, exact(&map)).unwrap();
        assert_eq!(tree, fresh);
        let top = tree.bounds(3, IVec2::ZERO).unwrap();
        assert_eq!(top.max, map.encoding().to_metres(9_000.0));
        // Off the map: nothing to do; a map-built tree refuses leaf updates, and the other way.
        tree.update_leaf_bounds(Rect::new(IVec2::splat(-50), UVec2::splat(10)), exact(&map))
            .unwrap();
        let mut from_map = CdlodTree::from_map(&map, config()).unwrap();
        assert!(from_map.update_leaf_bounds(dirty, exact(&map)).is_err());
        assert!(tree.update_rect(&map, dirty).is_err());
    }

    #[test]
    fn leaves_are_asked_once_each_and_absurd_sizes_are_refused() {
        let mut asked = Vec::new();
        let size = UVec2::new(300, 200);
        CdlodTree::from_leaf_bounds(config(), size, 0.5, |r| {
            asked.push(r);
            (0.0, 1.0)
        })
        .unwrap();
        assert_eq!(asked, leaf_rects(&config(), size));
        for (size, texel) in [
            (UVec2::new(0, 10), 0.5),
            (UVec2::splat(u32::MAX), 0.5),
            (UVec2::splat(300), f32::NAN),
            (UVec2::splat(300), 0.0),
        ] {
            assert!(CdlodTree::from_leaf_bounds(config(), size, texel, |_| (0.0, 1.0)).is_err());
        }
        // A world of 2^28 texels a side with 16-texel leaves: too many nodes, refused before
        // any allocation or call.
        let big = UVec2::splat(1 << 28);
        let cfg = CdlodConfig {
            lod_count: 16,
            ..config()
        };
        assert!(CdlodTree::from_leaf_bounds(cfg, big, 0.5, |_| unreachable!()).is_err());
    }
}
