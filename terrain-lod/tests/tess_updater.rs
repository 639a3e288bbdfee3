//! The tessellation's hierarchy and density map kept current on a worker thread
//! (`TessUpdater`): after a flush they equal a rebuild, the frame's snapshot does not change
//! before a poll, and the rows taken cover every vertex that changed (what the GPU copy needs).

use glam::{IVec2, UVec2};
use proptest::prelude::*;
use terrain_core::{Grid, HeightEncoding, HeightMap, Rect, WrapMode};
use terrain_lod::{
    CdlodConfig, CdlodTree, DensityMap, DensityParams, LodError, TessConfig, TessHierarchy,
    TessState, TessUpdater,
};

fn map(w: u32, h: u32, wrap: WrapMode) -> HeightMap<u16> {
    let grid = Grid::from_fn(w, h, |x, y| {
        let (fx, fy) = (x as f32, y as f32);
        let v = 8_000.0 * ((fx * 0.11).sin() * (fy * 0.07).cos()) + 10.0 * fy;
        (30_000.0 + v) as u16
    })
    .unwrap();
    HeightMap::new(grid, HeightEncoding::new(0.001, 0.0).unwrap(), 0.5, wrap).unwrap()
}

fn state(m: &HeightMap<u16>, with_density: bool) -> TessState {
    let density = with_density.then(|| DensityMap::from_map(m, DensityParams::default()).unwrap());
    let hierarchy = TessHierarchy::from_map(m, density.as_ref(), TessConfig::default()).unwrap();
    TessState { hierarchy, density }
}

/// Lowers the texels of `rect` (wrapped on a repeating map, clipped on a clamped one).
fn dig(m: &mut HeightMap<u16>, rect: Rect, depth: u16) {
    let (size, wrap) = (m.size(), m.wrap());
    for j in 0..i64::from(rect.size.y.min(size.y)) {
        for i in 0..i64::from(rect.size.x.min(size.x)) {
            let (x, y) = (i64::from(rect.min.x) + i, i64::from(rect.min.y) + j);
            let inside = x >= 0 && y >= 0 && x < i64::from(size.x) && y < i64::from(size.y);
            if wrap == WrapMode::Clamp && !inside {
                continue;
            }
            let s = m
                .grid_mut()
                .get_mut(wrap.resolve(x, size.x), wrap.resolve(y, size.y))
                .unwrap();
            *s = s.saturating_sub(depth);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 16, ..ProptestConfig::default() })]

    #[test]
    fn after_a_flush_the_worker_holds_a_rebuild_and_its_rows_cover_the_changes(
        x in -20i32..140, y in -20i32..110, w in 1u32..40, h in 1u32..40,
        depth in 1u16..20_000, repeat in any::<bool>(), with_density in any::<bool>(),
    ) {
        let wrap = if repeat { WrapMode::Repeat } else { WrapMode::Clamp };
        let mut m = map(128, 96, wrap);
        let before = state(&m, with_density);
        let mut updater = TessUpdater::spawn(before.clone(), &m).unwrap();
        // Two changes, the second overlapping the first shifted: one batch or two.
        let first = Rect::new(IVec2::new(x, y), UVec2::new(w, h));
        let second = Rect::new(IVec2::new(x + 7, y - 5), UVec2::new(h, w));
        for rect in [first, second] {
            dig(&mut m, rect, depth);
            updater.submit(&m, rect).unwrap();
        }
        prop_assert_eq!(&**updater.state(), &before, "changed before a poll");
        updater.flush().unwrap();
        prop_assert_eq!(updater.pending(), 0);
        let after = updater.state().clone();
        prop_assert_eq!(&*after, &state(&m, with_density));
        let rows = updater.take_changes();
        prop_assert!(updater.take_changes().is_empty(), "taken twice");
        let g = after.hierarchy.grid_size().x as usize;
        let old = before.hierarchy.bounds().iter().zip(before.hierarchy.heights());
        let new = after.hierarchy.bounds().iter().zip(after.hierarchy.heights());
        for (i, (a, b)) in old.zip(new).enumerate() {
            let row = (i / g) as u32;
            prop_assert!(a == b || rows.iter().any(|r| r.contains(&row)), "row {} not taken", row);
        }
    }
}

#[test]
fn maps_of_another_size_and_trees_without_texel_errors_are_refused() {
    let m = map(64, 64, WrapMode::Clamp);
    let other = map(32, 64, WrapMode::Clamp);
    assert!(matches!(
        TessUpdater::spawn(state(&m, true), &other),
        Err(LodError::SizeMismatch { .. })
    ));
    let mut updater = TessUpdater::spawn(state(&m, false), &m).unwrap();
    assert!(matches!(
        updater.submit(&other, Rect::from_size(UVec2::splat(8))),
        Err(LodError::SizeMismatch { .. })
    ));
    // A rect off a clamped map is nothing to do.
    updater
        .submit(&m, Rect::new(IVec2::new(-50, 10), UVec2::new(20, 20)))
        .unwrap();
    assert_eq!(updater.pending(), 0);

    let config = CdlodConfig {
        leaf_size: 16,
        grid_size: 16,
        lod_count: 3,
        ..CdlodConfig::default()
    };
    let tree = CdlodTree::from_leaf_bounds(config, m.size(), 0.5, |_| (0.0, 1.0)).unwrap();
    assert!(matches!(
        terrain_lod::CdlodUpdater::spawn(tree, &m),
        Err(LodError::InvalidCdlodParam { .. })
    ));
}
