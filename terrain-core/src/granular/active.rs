//! Active areas (Persson 2019, sec. 4.5): the rects a granular step runs over, one per object plus a
//! margin, with overlapping or nearby rects merged to cut dispatches.

use glam::UVec2;

use super::{GranularError, GranularObject, object_footprint};
use crate::Rect;

/// The rect a granular step runs over (map texels, inside the map).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ActiveArea {
    /// The texels simulated.
    pub rect: Rect,
}

impl ActiveArea {
    /// The whole map (the full-map mode, for comparison).
    pub fn full_map(map_size: UVec2) -> Self {
        Self {
            rect: Rect::from_size(map_size),
        }
    }

    /// Number of columns.
    pub fn columns(&self) -> u64 {
        self.rect.area()
    }
}

/// An object's active area: its footprint ([`object_footprint`]) grown by `margin` texels and
/// clipped to the map; `None` when it lies wholly outside the map.
pub fn object_active_area(
    object: &GranularObject<'_>,
    texel_size: f32,
    map_size: UVec2,
    margin: u32,
) -> Result<Option<ActiveArea>, GranularError> {
    let fp = object_footprint(object, texel_size)?;
    Ok(fp
        .expand(margin)
        .intersect(&Rect::from_size(map_size))
        .map(|rect| ActiveArea { rect }))
}

/// Merges areas until no area grown by `merge_distance` texels overlaps another (so merged
/// areas are disjoint and at least `merge_distance` texels apart); each merge replaces two
/// areas by their bounding rect. Empty areas are dropped. The result is sorted by
/// `(min.y, min.x)` and does not depend on the input order.
pub fn merge_active_areas(areas: &[ActiveArea], merge_distance: u32) -> Vec<ActiveArea> {
    let mut rects: Vec<Rect> = areas
        .iter()
        .map(|a| a.rect)
        .filter(|r| !r.is_empty())
        .collect();
    'outer: loop {
        for i in 0..rects.len() {
            for j in i + 1..rects.len() {
                let grown = rects[i].expand(merge_distance);
                if grown.intersect(&rects[j]).is_some() {
                    rects[i] = rects[i].union(&rects[j]);
                    rects.swap_remove(j);
                    continue 'outer;
                }
            }
        }
        break;
    }
    rects.sort_by_key(|r| (r.min.y, r.min.x, r.size.y, r.size.x));
    rects.into_iter().map(|rect| ActiveArea { rect }).collect()
}
