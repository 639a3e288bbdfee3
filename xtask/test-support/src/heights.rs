//! What the LOD tests share about heights: a map's exact lowest and highest height over any
//! rect, in metres, which a streamed world's quadtree is built and updated from
//! (terrain-lod's `CdlodTree::from_leaf_bounds` and `update_leaf_bounds`).

use terrain_core::{HeightMap, Rect};

/// `(lowest, highest)` height in metres of `map`'s texels in each rect it is asked for (a
/// rect inside the map).
pub fn exact_bounds(map: &HeightMap<u16>) -> impl FnMut(Rect) -> (f32, f32) + '_ {
    move |r: Rect| {
        let g = map.grid().copy_rect(r).expect("a rect inside the map");
        let (lo, hi) = g
            .as_slice()
            .iter()
            .fold((u16::MAX, 0), |(a, b), &v| (a.min(v), b.max(v)));
        let enc = map.encoding();
        (enc.to_metres(f64::from(lo)), enc.to_metres(f64::from(hi)))
    }
}
